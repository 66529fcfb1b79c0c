"""`kasparctl say TEXT`: speak a line with Kaspar's voice, or write it to a WAV file."""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
from pathlib import Path
from typing import Any

import msgspec

from hal.voice.api import Spoken
from hal.voice.settings import VoiceSettings, voice_for_language
from hal.voice.sinks import WavSink
from hal.voice.speaker import Voice
from kasparctl.commands.arguments import language, output_file, path
from kasparctl.config import DEFAULT_CONFIG_PATH, Config, load_config
from kasparctl.log import configure_logging


def register(subparsers: Any) -> None:
    """Add the `say` subcommand."""
    parser = subparsers.add_parser("say", help="speak a line (or write it to a WAV file)")
    parser.add_argument("text", metavar="TEXT", help="what Kaspar says")
    parser.add_argument(
        "--wav", metavar="FILE", type=path, help="write a WAV file instead of playing it"
    )
    parser.add_argument(
        "--motion", metavar="CSV", type=output_file,
        help="also write the simulated robot's joint goals (time_s, joint, position_deg; "
        "time 0 = the WAV's first sample): the mouth following the line",
    )
    parser.add_argument("--key", help="phrase key: its recorded clip plays if one is configured")
    parser.add_argument("--engine", choices=("pyttsx3", "espeak-ng"), help="override the engine")
    parser.add_argument(
        "--language",
        type=language,
        metavar="L",
        help="speak with the voice of language L (en, nl, de, it, fr)"
    )
    parser.add_argument(
        "--config",
        default=None,
        type=path,
        help="kaspar.toml (default: $KASPAR_CONFIG, or /etc/kaspar/kaspar.toml if it exists)",
    )
    parser.set_defaults(run=run)


def voice_settings(arguments: argparse.Namespace) -> VoiceSettings:
    """The voice settings of the configuration, with the command line's overrides."""
    config_path = arguments.config or os.environ.get("KASPAR_CONFIG")
    if config_path is None and DEFAULT_CONFIG_PATH.exists():
        config_path = str(DEFAULT_CONFIG_PATH)
    settings = load_config(config_path).voice if config_path else VoiceSettings()
    if arguments.language:
        settings = msgspec.structs.replace(settings, voice=voice_for_language(arguments.language))
    if arguments.engine:
        settings = msgspec.structs.replace(settings, engine=arguments.engine)
    return settings


async def speak(settings: VoiceSettings, text: str, key: str | None, wav: str | None) -> Spoken:
    """Say `text` once (or render it into `wav`) and return how it went."""
    sink = WavSink(file=Path(wav)) if wav else None
    voice = Voice(settings, sink=sink)
    try:
        return await voice.say(text, key)
    finally:
        await voice.close()


def run(arguments: argparse.Namespace) -> int:
    """Say a line with the configured voice; exit 1 if it could not be said."""
    # Warnings (an engine falling back) go to stderr; stdout stays for results.
    configure_logging("warning", "console", stream=sys.stderr)
    settings = voice_settings(arguments)
    if arguments.wav:
        folder = Path(arguments.wav).resolve().parent
        if not folder.is_dir():
            print(f"error: --wav {arguments.wav}: no such directory: {folder}", file=sys.stderr)
            return 1
        if not os.access(folder, os.W_OK):
            print(f"error: --wav {arguments.wav}: {folder}: permission denied", file=sys.stderr)
            return 1
    if getattr(arguments, "motion", None):
        return say_motion(arguments, settings)
    spoken = asyncio.run(speak(settings, arguments.text, arguments.key, arguments.wav))
    if not spoken.finished:
        print(f"error: not spoken ({spoken.status.value}): {spoken.error}", file=sys.stderr)
        return 1
    if arguments.wav:
        print(f"wrote {arguments.wav} ({spoken.via})")
    return 0


def say_motion(arguments: argparse.Namespace, settings: VoiceSettings) -> int:
    """`say --motion`: the line rendered with the simulated body's mouth (commands.motion)."""
    from kasparctl.commands.motion import say_with_motion

    config_path = arguments.config or os.environ.get("KASPAR_CONFIG")
    if config_path is None and DEFAULT_CONFIG_PATH.exists():
        config_path = str(DEFAULT_CONFIG_PATH)
    config = load_config(config_path, poses=False) if config_path else demo_config()
    spoken, rows = say_with_motion(
        config, settings, arguments.text, arguments.key, arguments.wav, arguments.motion
    )
    if not spoken.finished:
        print(f"error: not spoken ({spoken.status.value}): {spoken.error}", file=sys.stderr)
        return 1
    also = f" and {arguments.wav}" if arguments.wav else ""
    print(f"wrote {arguments.motion} ({rows} goals){also}")
    return 0


def demo_config() -> Config:
    """Without a configuration: the demo's robot (kasparctl/sim/demo.toml) has a face."""
    from kasparctl.sim.demo import demo_config as built_in

    return built_in()
