"""The espeak-ng engine: the command line from the settings, streamed or written to a file.

espeak-ng runs as a child process for each utterance (text on stdin), so it
shares no state with this process and a hung one is simply killed.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from pathlib import Path

from hal.errors import VoiceError
from hal.voice.envelope import StreamMeter
from hal.voice.processes import finish, spawn, stop, telling_lines
from hal.voice.settings import VoiceSettings

# Bytes read from espeak-ng at a time when the stream passes through us (about 90 ms).
STREAM_CHUNK = 4096


def espeak_argv(settings: VoiceSettings) -> list[str]:
    """espeak-ng's command line reading text on stdin, without an output option.

    Volume 0.0 to 1.0 becomes espeak's amplitude 0 to 100; rate is words per minute;
    pitch is espeak's own 0 to 99.
    """
    return [
        settings.espeak_ng,
        "-v",
        settings.voice,
        "-s",
        str(settings.rate),
        "-a",
        str(round(settings.volume * 100)),
        "-p",
        str(settings.pitch),
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


async def stream_through(
    argv: list[str], player: list[str], text: str, meter: StreamMeter
) -> None:
    """As stream_to_player, but the samples pass through this process on their way, so
    that `meter` hears each piece as the player receives it (the mouth follows them).

    Raises VoiceError as stream_to_player; the meter is told of the end, cut or not.
    """
    synth = await spawn([*argv, "--stdout"], stdin=True, stdout=asyncio.subprocess.PIPE)
    try:
        playing = await spawn([*player, "-"], stdin=True)
    except BaseException:
        await stop(synth)
        meter.end(cut=True)
        raise
    cut = True
    try:
        assert synth.stdin is not None and synth.stdout is not None
        assert playing.stdin is not None
        synth.stdin.write(text.encode())
        synth.stdin.close()
        player_died = False
        while chunk := await synth.stdout.read(STREAM_CHUNK):
            try:
                meter.feed(chunk)
            except ValueError as error:
                raise VoiceError(f"espeak-ng: {error}") from error
            playing.stdin.write(chunk)
            try:
                await playing.stdin.drain()
            except (BrokenPipeError, ConnectionResetError):
                player_died = True  # its exit status says why, below
                break
        playing.stdin.close()
        # A dead player (no sound card) is asked first: espeak-ng, no longer read, is
        # blocked on its full pipe and would never end.
        order = (
            ((playing, "player"),) if player_died else ((synth, "espeak-ng"), (playing, "player"))
        )
        for process, what in order:
            await process.wait()
            if process.returncode != 0:
                assert process.stderr is not None
                detail = telling_lines((await process.stderr.read()).decode(errors="replace"))
                raise VoiceError(f"{what} exited with {process.returncode}: {detail}")
        cut = False
    finally:
        if synth.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                synth.kill()
        if synth.stdout is not None:
            # What it wrote and nobody read holds its pipe open (reading paused when the
            # buffer filled): read to its end, or reaping it below would never return.
            with contextlib.suppress(Exception):
                await synth.stdout.read()
        await stop(synth)
        await stop(playing)
        meter.end(cut=cut)


async def write_wav(argv: list[str], target: Path, text: str) -> None:
    """Render `text` into the WAV file `target`; VoiceError if espeak-ng fails."""
    process = await spawn([*argv, "-w", str(target)], stdin=True)
    try:
        await finish(process, "espeak-ng", text.encode())
    finally:
        await stop(process)
