"""`kasparctl import`: a lab's published Kaspar content as kasparctl poses and behaviours.

Reads SOURCE (a directory of the published software's pos/, seq/ or seqs/, keyMaps/ and
sounds/, and a Kaspar-1c's robot.xml), converts every pose and sequence for the
profile's robot, checks each against it (nothing clamped), and writes poses.toml,
behaviours/imported.toml, sounds/ and report.md into --out, a new or empty directory;
the report is printed too (kasparctl.bringup.importing).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from kasparctl.bringup.importing import ROBOTS, import_content, write_imported
from kasparctl.commands.arguments import path
from kasparctl.config import default_config_path, load_config


def register(subparsers: Any) -> None:
    """Add the `import` subcommand."""
    parser = subparsers.add_parser(
        "import", help="a lab's published Kaspar poses, sequences and sounds as kasparctl's")
    parser.add_argument("source", type=path, help="the directory of published content")
    parser.add_argument("--robot", required=True, choices=ROBOTS,
                        help="the published robot the content was made for")
    parser.add_argument("--out", required=True, type=path,
                        help="a new or empty directory for poses.toml, behaviours/, sounds/, "
                             "report.md")
    parser.add_argument(
        "--config", default=None, type=path,
        help="the robot's profile (default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)")
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Import SOURCE for the profile's robot, write --out, print the report."""
    profile = arguments.config or default_config_path()
    config = load_config(profile)
    imported = import_content(Path(arguments.source), arguments.robot, config, profile)
    print(write_imported(imported, Path(arguments.out), config), end="")
    return 0
