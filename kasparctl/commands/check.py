"""`kasparctl check`: validate the configuration (and, later, the hardware)."""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
from typing import Any

from hal.clock import MonotonicClock
from hal.joints import Joints
from hal.servo_settings import ServoSettings
from kasparctl.config import DEFAULT_CONFIG_PATH, Config, ConfigError, load_config
from kasparctl.log import configure_logging
from kasparctl.phrases import PhraseError, load_phrasebook


def default_config_path() -> str:
    return os.environ.get("KASPAR_CONFIG", str(DEFAULT_CONFIG_PATH))


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("check", help="validate the configuration and phrases")
    parser.add_argument(
        "--config",
        default=None,
        help="kaspar.toml (default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)",
    )
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
    if config.servos.backend == "real":
        return check_servos(config)
    return 0


def check_servos(config: Config) -> int:
    """Ping every configured joint's servo; name each one that does not answer."""
    configure_logging("warning", "console", stream=sys.stderr)
    problems = asyncio.run(_missing_servos(config.servos))
    for problem in problems:
        print(f"error: {problem}", file=sys.stderr)
    if problems:
        return 1
    print(f"ok: all {len(config.servos.joints)} servos answered")
    return 0


async def _missing_servos(settings: ServoSettings) -> list[str]:
    joints = Joints.from_settings(settings, MonotonicClock())
    # Only pings: nothing is written, so checking a powered robot does not move it.
    await joints.start(poll=False, read=False)
    try:
        found = await joints.ping_all()
    finally:
        await joints.close()
    problems = []
    for joint in settings.joints:
        bus = settings.bus(joint.bus)
        where = f"bus {bus.name} on {bus.port}, id {joint.id}"
        model_number = found[joint.name]
        expected = joint.servo.model_number
        if model_number is None:
            problems.append(f"servo {joint.name} is missing ({where})")
        elif expected is not None and model_number != expected:
            problems.append(
                f"servo {joint.name} is not a {joint.model} (model number {model_number}, {where})"
            )
    return problems
