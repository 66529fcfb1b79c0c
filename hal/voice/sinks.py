"""Where the voice's sound goes: a player command, or WAV files.

A Sink gives each engine a place to render into and plays (or keeps) what
was rendered; espeak-ng, which can stream, is run by the sink itself so that
a player hears its first words before the rest is synthesised.
"""

from __future__ import annotations

import asyncio
import shutil
import tempfile
import wave
from pathlib import Path
from typing import Protocol

from hal.clock import Clock, MonotonicClock
from hal.errors import InvalidArgument, VoiceError
from hal.voice import espeak
from hal.voice.envelope import EnvelopeListener, StreamMeter, wav_levels
from hal.voice.processes import run
from hal.voice.settings import VoiceSettings


class Sink(Protocol):
    """Where rendered speech goes; each method runs on the event loop."""

    def target(self, via: str) -> tuple[Path, bool]:
        """A path to render a WAV into, and whether that file is already the output."""
        ...

    async def play_file(self, path: Path, via: str) -> str | None:
        """Play (or store) a WAV; returns the stored file, if any. VoiceError on failure."""
        ...

    async def espeak(self, argv: list[str], text: str) -> str | None:
        """Run espeak-ng (argv without an output option) into the sink; the stored file, if any."""
        ...

    def close(self) -> None:
        """Release what the sink holds (temporary files); the voice calls it once, at close."""
        ...


class Listened:
    """What a sink shares: an optional envelope listener told of the audio it plays."""

    listener: EnvelopeListener | None = None
    clock: Clock = MonotonicClock()

    def listen(self, listener: EnvelopeListener | None, clock: Clock) -> None:
        """Tell `listener` (None: nobody) the levels of what is played, stamped by `clock`."""
        self.listener, self.clock = listener, clock

    async def _announce(self, path: Path) -> None:
        """Tell the listener the whole file's levels, starting now (it is about to sound)."""
        if self.listener is None:
            return
        try:
            levels, frame = await asyncio.to_thread(wav_levels, path)
        except (OSError, EOFError, wave.Error, ValueError) as error:
            raise VoiceError(f"{path}: not a WAV the mouth can follow: {error}") from error
        self.listener.on_envelope(self.clock.now(), frame, levels)

    def _ended(self, cut: bool) -> None:
        if self.listener is not None:
            self.listener.on_end(cut)


class PlayerSink(Listened):
    """Plays through a player command (aplay, or sox's play) that takes a WAV path or "-"."""

    def __init__(self, player: tuple[str, ...]) -> None:
        """Use `player` (argv without the file); rendered files go to a private temporary dir."""
        self._player = list(player)
        self._tmp = Path(tempfile.mkdtemp(prefix="kaspar-voice-"))
        self._count = 0

    @property
    def player(self) -> str:
        """The player program's name (its latency differs: see the body's mouth)."""
        return Path(self._player[0]).name

    def target(self, via: str) -> tuple[Path, bool]:
        """A fresh file in the temporary directory; it still has to be played."""
        self._count += 1
        return self._tmp / f"{self._count}-{via}.wav", False

    async def play_file(self, path: Path, via: str) -> str | None:
        """Play `path` to its end; VoiceError if the player fails. Nothing is stored."""
        cut = True
        try:
            await self._announce(path)
            await run([*self._player, str(path)], what="player")
            cut = False
        finally:
            self._ended(cut)
        return None

    def close(self) -> None:
        """Remove the temporary directory and anything left in it."""
        shutil.rmtree(self._tmp, ignore_errors=True)

    async def espeak(self, argv: list[str], text: str) -> str | None:
        """Stream espeak-ng straight into the player (through us when someone listens)."""
        if self.listener is None:
            await espeak.stream_to_player(argv, self._player, text)
        else:
            await espeak.stream_through(
                argv, self._player, text, StreamMeter(self.listener, self.clock)
            )
        return None


class WavSink(Listened):
    """Writes each utterance as a WAV file: numbered files in a directory, or one file."""

    def __init__(self, directory: str | Path | None = None, file: str | Path | None = None) -> None:
        """Exactly one of `directory` (created if missing) or `file` (overwritten each time).

        Raises InvalidArgument when both or neither are given.
        """
        if (directory is None) == (file is None):
            raise InvalidArgument("give a directory or a file")
        self._directory = Path(directory) if directory is not None else None
        self._file = Path(file) if file is not None else None
        if self._directory is not None:
            self._directory.mkdir(parents=True, exist_ok=True)
        self._count = 0

    def target(self, via: str) -> tuple[Path, bool]:
        """The next numbered file (NNNNN-via.wav), or the one file; either is the output."""
        if self._file is not None:
            return self._file, True
        assert self._directory is not None
        self._count += 1
        return self._directory / f"{self._count:05d}-{via}.wav", True

    def close(self) -> None:
        """Nothing to release: the files are the output."""

    async def play_file(self, path: Path, via: str) -> str | None:
        """Copy a WAV rendered elsewhere (a clip) to the next output file; returns that file."""
        target, _ = self.target(via)
        if path != target:
            await asyncio.to_thread(shutil.copyfile, path, target)
        await self.written(target)
        return str(target)

    async def written(self, target: Path) -> None:
        """A listener hears the file as if it started to play now, and ended (no cut)."""
        cut = True
        try:
            await self._announce(target)
            cut = False
        finally:
            self._ended(cut)

    async def espeak(self, argv: list[str], text: str) -> str | None:
        """Render into the next output file; VoiceError if espeak-ng fails or writes no audio."""
        target, _ = self.target("espeak-ng")
        await espeak.write_wav(argv, target, text)
        check_wav(target, "espeak-ng")
        await self.written(target)
        return str(target)


def sink_for(settings: VoiceSettings) -> Sink:
    """WAV files in `wav_dir` when it is set, else the configured player."""
    if settings.wav_dir is not None:
        return WavSink(directory=settings.wav_dir)
    return PlayerSink(settings.player)


def wav_frames(path: Path) -> int | None:
    """The number of frames in a WAV file, or None when it is missing or not a WAV."""
    try:
        with wave.open(str(path), "rb") as audio:
            return audio.getnframes()
    except (OSError, EOFError, wave.Error):
        return None


def check_wav(path: Path, what: str) -> None:
    """Raise VoiceError naming `what` unless `path` is a readable WAV with at least one frame.

    An engine that returns without error yet leaves no audio is a failure too.
    """
    try:
        with wave.open(str(path), "rb") as audio:
            frames = audio.getnframes()
    except (OSError, EOFError, wave.Error) as error:
        raise VoiceError(f"{what} wrote no usable WAV: {error}") from error
    if frames == 0:
        raise VoiceError(f"{what} wrote an empty WAV")
