"""`kasparctl install --print`: how to install the service on a robot, with systemd/install.sh.

The script is the one source of truth for the steps (packages, /opt/kasparctl,
the kaspar user, kernel modules, udev rules, the configuration, the unit); this
command only says how to run it, and its --dry-run prints every step without
doing any. It prints rather than runs: installing a service that drives a robot
is for a person to decide, as root.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

# Where the script is when kasparctl runs from a checkout (an editable install);
# a wheel does not carry it, so otherwise the path is given relative to a checkout.
CHECKOUT_SCRIPT = Path(__file__).resolve().parents[2] / "systemd" / "install.sh"


def script_path() -> str:
    """The install script: its absolute path in this checkout, else its place in any checkout."""
    return str(CHECKOUT_SCRIPT) if CHECKOUT_SCRIPT.is_file() else "systemd/install.sh"


def instructions(script: str) -> str:
    """The text printed: how to run the script, its dry run first."""
    return (
        "# Install kasparctl as a service on Debian 12 or Raspberry Pi OS (bookworm).\n"
        "# One script does every step: Debian packages, a venv in /opt/kasparctl, the kaspar\n"
        "# user, the serial adapters' kernel modules, udev rules, /etc/kaspar/kaspar.toml\n"
        "# (never overwritten) and the unit, enabled and started. Run it as root (su -, or\n"
        "# sudo) from a checkout of kasparctl; it is safe to run again.\n"
        f"bash {script} --dry-run     # prints each step, changes nothing\n"
        f"bash {script}\n"
        "# Removing it keeps the research records (/var/lib/kaspar) and the configuration:\n"
        f"bash {script} --uninstall\n"
    )


def register(subparsers: Any) -> None:
    """Add the `install` subcommand."""
    parser = subparsers.add_parser(
        "install", help="print how to install the service (systemd/install.sh)"
    )
    parser.add_argument(
        "--print",
        action="store_true",
        required=True,
        dest="print_only",
        help="print the commands (nothing is run)",
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Print the instructions; exit 0."""
    del arguments
    sys.stdout.write(instructions(script_path()))
    return 0
