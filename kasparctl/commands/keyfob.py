"""`kasparctl keyfob list/learn`: the input devices, and a remote learned into kaspar.toml.

`list` shows every event node (node, name, USB ids, interface, battery). `learn
researcher|keyfob DEVICE` asks for each command's button (or green's and red's), twice,
then writes the keys into kaspar.toml (atomically, comments kept) and the udev rule
naming that one node /dev/input/kaspar-researcher (or kaspar-keyfob).
"""

from __future__ import annotations

import argparse
from typing import Any

from kasparctl.bringup import remotes
from kasparctl.commands.arguments import number, path
from kasparctl.config import default_config_path


def register(subparsers: Any) -> None:
    """Add the `keyfob` command with its list and learn actions."""
    parser = subparsers.add_parser("keyfob", help="list input devices, learn a remote")
    actions = parser.add_subparsers(dest="keyfob_command", metavar="ACTION", required=True)

    listing = actions.add_parser("list", help="every input device: node, name, ids, battery")
    listing.add_argument("--sys", default="/sys", type=path, help="sysfs (default: /sys)")
    listing.set_defaults(run=run_list)

    learn = actions.add_parser("learn", help="learn a remote's buttons into kaspar.toml")
    learn.add_argument("role", choices=remotes.ROLES, help="whose device it is")
    learn.add_argument("device", help="its number in `keyfob list`, eventN, or its path")
    learn.add_argument(
        "--config", default=None, type=path,
        help="kaspar.toml to write (default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)",
    )  # fmt: skip
    learn.add_argument(
        "--rules-dir", default=remotes.RULES_DIR, type=path,
        help=f"where the udev rule is written (default: {remotes.RULES_DIR})",
    )  # fmt: skip
    learn.add_argument(
        "--timeout", type=number(1.0, 600.0, unit="s"), default=20.0,
        help="seconds to wait for each button (default: 20)",
    )  # fmt: skip
    learn.set_defaults(run=run_learn)


def run_list(arguments: argparse.Namespace) -> int:
    """Print the input devices."""
    for line in remotes.device_list(arguments.sys):
        print(line)
    return 0


def run_learn(arguments: argparse.Namespace) -> int:
    """Learn the device's buttons; write the configuration and the rule."""
    remotes.learn(
        arguments.config or default_config_path(),
        arguments.role,
        arguments.device,
        timeout=arguments.timeout,
        rules_dir=arguments.rules_dir,
    )
    return 0
