"""`kasparctl install --print`: the exact commands that install the service on a fresh robot.

It prints rather than runs them: installing a service that drives a robot is
for a person to read and do, one step at a time.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

PREFIX = "/opt/kasparctl"

STEPS = (
    (
        "Debian packages: speech, playback, and a compiler for python-evdev",
        "sudo apt-get install -y python3-venv python3-dev gcc espeak-ng alsa-utils",
    ),
    (
        "kasparctl in its own virtual environment (run from this checkout)",
        f"sudo python3 -m venv {PREFIX} && sudo {PREFIX}/bin/pip install .",
    ),
    (
        "the service's user, in the dialout, input and audio groups",
        "sudo install -m 0644 systemd/kasparctl-sysusers.conf /etc/sysusers.d/kasparctl.conf"
        " && sudo systemd-sysusers",
    ),
    (
        "the serial adapters' kernel modules at boot (DeviceAllow= needs their groups)",
        "sudo install -m 0644 systemd/kasparctl-modules.conf /etc/modules-load.d/kasparctl.conf",
    ),
    (
        "stable device names for the servo buses and the keyfob (edit the ids first)",
        "sudo install -m 0644 systemd/99-kaspar-serial.rules systemd/99-kaspar-keyfob.rules"
        " /etc/udev/rules.d/ && sudo udevadm control --reload && sudo udevadm trigger",
    ),
    (
        "the configuration (start from the robot's: kaspar-1c.toml or kaspar-3.toml)",
        "sudo install -d -m 0755 /etc/kaspar && sudo install -m 0644 systemd/kaspar.toml"
        " /etc/kaspar/kaspar.toml",
    ),
    (
        "check it: configuration, servos, keyfob and voice",
        f"sudo -u kaspar {PREFIX}/bin/kasparctl check --config /etc/kaspar/kaspar.toml",
    ),
    (
        "the service, started now and at every boot",
        "sudo install -m 0644 systemd/kasparctl.service /etc/systemd/system/"
        " && sudo systemctl daemon-reload && sudo systemctl enable --now kasparctl.service",
    ),
    ("follow it", "journalctl -u kasparctl -f"),
)


def register(subparsers: Any) -> None:
    """Add `install --print` to the command line."""
    parser = subparsers.add_parser("install", help="print the commands that install the service")
    parser.add_argument(
        "--print",
        action="store_true",
        required=True,
        dest="print_only",
        help="print the commands (nothing is run)",
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Print the numbered install steps; nothing is run."""
    del arguments
    out = sys.stdout
    out.write("# Install kasparctl on a fresh robot. Run from a checkout of kasparctl.\n")
    for number, (why, command) in enumerate(STEPS, start=1):
        out.write(f"\n# {number}. {why}\n{command}\n")
    return 0
