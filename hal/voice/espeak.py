"""The espeak-ng engine: the command line from the settings, streamed or written to a file.

espeak-ng runs as a child process for each utterance (text on stdin), so it
shares no state with this process and a hung one is simply killed.
"""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

from hal.voice.processes import finish, spawn, stop
from hal.voice.settings import VoiceSettings


def espeak_argv(settings: VoiceSettings) -> list[str]:
    """espeak-ng's command line reading text on stdin, without an output option.

    Volume 0.0 to 1.0 becomes espeak's amplitude 0 to 100; rate is words per minute.
    """
    return [
        settings.espeak_ng,
        "-v",
        settings.voice,
        "-s",
        str(settings.rate),
        "-a",
        str(round(settings.volume * 100)),
        "--stdin",
    ]


async def stream_to_player(argv: list[str], player: list[str], text: str) -> None:
    """Speak `text` with espeak-ng's WAV piped into `player` (which reads "-", stdin).

    The first words are heard while the rest is still being synthesised. Raises
    VoiceError when either process cannot start or exits non-zero; both are
    killed and reaped however this ends.
    """
    read_end, write_end = os.pipe()
    try:
        synth = await spawn([*argv, "--stdout"], stdin=True, stdout=write_end)
        try:
            playing = await spawn([*player, "-"], stdin=read_end)
        except BaseException:
            await stop(synth)
            raise
    finally:
        os.close(read_end)
        os.close(write_end)
    try:
        await asyncio.gather(
            finish(synth, "espeak-ng", text.encode()), finish(playing, "player", None)
        )
    finally:
        await stop(synth)
        await stop(playing)


async def write_wav(argv: list[str], target: Path, text: str) -> None:
    """Render `text` into the WAV file `target`; VoiceError if espeak-ng fails."""
    process = await spawn([*argv, "-w", str(target)], stdin=True)
    try:
        await finish(process, "espeak-ng", text.encode())
    finally:
        await stop(process)
