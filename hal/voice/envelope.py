"""The loudness of what the player receives, frame by frame, for whoever moves the mouth.

A listener (kasparctl's body) is told, as each piece of audio is handed to the
player, the RMS level of its consecutive frames and the clock time at which the
first of them starts to sound (without the player's own output latency, which
the listener compensates). It is also told when a line ends, and whether it was
cut. Works for every engine and for recorded clips, since it reads the samples
themselves: a WAV file before it is played, or espeak-ng's stream as it passes
through to the player.
"""

from __future__ import annotations

import math
import struct
import wave
from array import array
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

from hal.clock import Clock

# 10 ms frames: fine enough for a mouth at 50 Hz, coarse enough to be cheap.
FRAME_S = 0.01


class EnvelopeListener(Protocol):
    """Told the levels of the audio as it is handed to the player; called on the event loop."""

    def on_envelope(self, start: float, frame_s: float, levels: Sequence[float]) -> None:
        """`levels` (RMS, 0 to 1 of full scale) of consecutive `frame_s` frames, the first
        handed to the player at clock time `start`."""
        ...

    def on_end(self, cut: bool) -> None:
        """No more audio for this line; `cut`: it was cancelled or failed, stop now."""
        ...


def frame_seconds(rate: int, frame_s: float = FRAME_S) -> float:
    """The true length of a frame at `rate`: a whole number of samples near `frame_s`."""
    return max(1, round(rate * frame_s)) / rate


def rms_levels(pcm: bytes, width: int, channels: int, rate: int, frame_s: float = FRAME_S
               ) -> list[float]:
    """RMS per frame of little-endian PCM (8-bit unsigned or 16-bit signed), 0 to 1.

    A last partial frame counts as a frame of its own. Channels are mixed.
    """
    if width == 2:
        samples = array("h")
        samples.frombytes(pcm[: len(pcm) - len(pcm) % 2])
        if struct.pack("=h", 1) != struct.pack("<h", 1):
            samples.byteswap()
        scale = 32768.0
        values: Sequence[float] = samples
    elif width == 1:
        values = [b - 128 for b in pcm]
        scale = 128.0
    else:
        raise ValueError(f"expected 8- or 16-bit samples, found {8 * width}-bit")
    per_frame = max(1, round(rate * frame_s)) * channels
    levels = []
    for begin in range(0, len(values), per_frame):
        chunk = values[begin : begin + per_frame]
        total = math.fsum(v * v for v in chunk)
        levels.append(min(1.0, math.sqrt(total / len(chunk)) / scale))
    return levels


def wav_levels(path: Path, frame_s: float = FRAME_S) -> tuple[list[float], float]:
    """RMS levels of a WAV file's frames and their length in seconds (frame_seconds of its
    rate); wave.Error or OSError if it cannot be read."""
    with wave.open(str(path), "rb") as audio:
        rate, width, channels = audio.getframerate(), audio.getsampwidth(), audio.getnchannels()
        pcm = audio.readframes(audio.getnframes())
    return rms_levels(pcm, width, channels, rate, frame_s), frame_seconds(rate, frame_s)


class StreamMeter:
    """Cuts a WAV byte stream (header then PCM) into frames and reports their levels.

    `feed` is called with each piece as it goes to the player; the first sample's
    time is the moment the first PCM reaches the player, and each later frame is
    placed after it by its sample count (the player plays at the stream's rate).
    """

    def __init__(self, listener: EnvelopeListener, clock: Clock) -> None:
        """Report to `listener`, stamping with `clock`."""
        self._listener = listener
        self._clock = clock
        self._header = b""
        self._format: tuple[int, int, int] | None = None  # rate, width, channels
        self._pending = b""
        self._anchor: float | None = None
        self._frames_sent = 0

    def feed(self, data: bytes) -> None:
        """Take the next bytes of the stream (header bytes are parsed, not reported)."""
        if self._format is None:
            self._header += data
            parsed = _parse_header(self._header)
            if parsed is None:
                return
            self._format, offset = parsed
            data, self._header = self._header[offset:], b""
        rate, width, channels = self._format
        if self._anchor is None and data:
            self._anchor = self._clock.now()
        self._pending += data
        frame_bytes = max(1, round(rate * FRAME_S)) * width * channels
        whole = len(self._pending) - len(self._pending) % frame_bytes
        if not whole:
            return
        chunk, self._pending = self._pending[:whole], self._pending[whole:]
        levels = rms_levels(chunk, width, channels, rate)
        assert self._anchor is not None
        frame = frame_seconds(rate)
        start = self._anchor + self._frames_sent * frame
        self._frames_sent += len(levels)
        self._listener.on_envelope(start, frame, levels)

    def end(self, cut: bool) -> None:
        """The stream is over: report a last partial frame (unless cut), then the end."""
        if self._format is not None and self._pending and not cut and self._anchor is not None:
            rate, width, channels = self._format
            levels = rms_levels(self._pending, width, channels, rate)
            frame = frame_seconds(rate)
            self._listener.on_envelope(self._anchor + self._frames_sent * frame, frame, levels)
        self._pending = b""
        self._listener.on_end(cut)


def _parse_header(data: bytes) -> tuple[tuple[int, int, int], int] | None:
    """((rate, width, channels), offset of the first PCM byte), or None until complete.

    espeak-ng's stream has sizes it cannot know (0x7fffffff): only the chunks' order
    and the fmt chunk are read.
    """
    if len(data) < 12:
        return None
    if data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise ValueError("the audio stream is not a WAV")
    position = 12
    found: tuple[int, int, int] | None = None
    while len(data) >= position + 8:
        kind, size = data[position : position + 4], struct.unpack_from("<I", data, position + 4)[0]
        body = position + 8
        if kind == b"data":
            if found is None:
                raise ValueError("the WAV stream has no fmt chunk before its data")
            return found, body
        if len(data) < body + size:
            return None
        if kind == b"fmt ":
            channels, rate = struct.unpack_from("<HI", data, body + 2)
            bits = struct.unpack_from("<H", data, body + 14)[0]
            found = (rate, bits // 8, channels)
        position = body + size + (size & 1)
    return None
