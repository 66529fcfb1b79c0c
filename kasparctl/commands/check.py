"""`kasparctl check`: validate the configuration (and, later, the hardware)."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from kasparctl.config import DEFAULT_CONFIG_PATH, ConfigError, load_config
from kasparctl.phrases import PhraseError, load_phrasebook


def default_config_path() -> str:
    return os.environ.get("KASPAR_CONFIG", str(DEFAULT_CONFIG_PATH))


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("check", help="validate the configuration and phrases")
    parser.add_argument("--config", default=None, help="kaspar.toml (default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)")
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    path = arguments.config or default_config_path()
    try:
        config = load_config(path)
        phrasebook = load_phrasebook(config.language, config.phrases_dir)
    except (ConfigError, PhraseError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    print(f"ok: {path} ({len(config.sessions)} planned sessions, phrases from {phrasebook.source})")
    return 0
