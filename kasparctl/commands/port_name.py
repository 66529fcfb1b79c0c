"""`kasparctl port-name DEVICE`: the stable names of one of Kaspar 3's Maestro ports (for udev).

systemd/99-kaspar-serial.rules runs it as PROGRAM= for every Maestro tty; it prints
the names, space-separated, that the rule gives as SYMLINK+="%c". A tty that is not
a Maestro port, or whose board cannot be read, prints nothing and exits 1 (udev then
makes no link, and `kasparctl check` says the bus's port is missing).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from kasparctl.bringup.ports import LOCK_DIR, port_names
from kasparctl.commands.arguments import path
from kasparctl.log import configure_logging


def register(subparsers: Any) -> None:
    """Add `port-name` and its options to the command line."""
    parser = subparsers.add_parser(
        "port-name",
        help="name a Kaspar 3 Maestro port by its board's channel 17 (udev's PROGRAM=)",
        description=__doc__,
    )
    parser.add_argument("device", type=path,
                        help="the tty's kernel name (udev's %%k), or its /dev path")
    parser.add_argument("--sysfs", type=path, default="/sys", help="sysfs root (default /sys)")
    parser.add_argument("--dev", type=path, default="/dev", help="device directory (default /dev)")
    parser.add_argument("--lock-dir", type=path, default=str(LOCK_DIR),
                        help=f"where the per-board locks are (default {LOCK_DIR})")
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Print the port's names on one line."""
    # stdout is udev's %c: the HAL's log goes to stderr, errors only.
    configure_logging("error", "console", stream=sys.stderr)
    names = port_names(arguments.device, Path(arguments.sysfs), Path(arguments.dev),
                       Path(arguments.lock_dir))
    print(" ".join(names))
    return 0
