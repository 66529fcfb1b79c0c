"""The loudness of what the player receives, frame by frame, for whoever moves the mouth.

A listener (kasparctl's body) is told, as each piece of audio is handed to the
player, the RMS level of its consecutive frames and the clock time at which the
first of them starts to sound (without the player's own output latency, which
the listener compensates). It is also told when a line ends, and whether it was
cut. Works for every engine and for recorded clips, since it reads the samples
themselves: a WAV file before it is played, or espeak-ng's stream as it passes
through to the player. A voice with no samples (the simulated one) gives the
envelope a line's syllables would have (syllable_envelope).
"""

from __future__ import annotations

import math
import re
import struct
import wave
from array import array
from collections.abc import Sequence
from pathlib import Path

from hal.clock import Clock
from hal.voice.api import EnvelopeListener

__all__ = ["FRAME_S", "EnvelopeListener", "StreamMeter", "frame_seconds", "rms_levels",
           "syllable_envelope", "syllables", "wav_levels"]

# 10 ms frames: fine enough for a mouth at 50 Hz, coarse enough to be cheap.
FRAME_S = 0.01


# A syllable swells to this level (RMS of full scale) and back; the first of a word is
# stressed. Louder than the mouth's default full level (0.2): the mouth opens fully.
STRESSED_LEVEL = 0.24
UNSTRESSED_LEVEL = 0.16
# Silences, in syllables' lengths: between words, and at a comma or a full stop.
WORD_GAP = 0.25
COMMA_PAUSE = 1.0
STOP_PAUSE = 1.5
_VOWEL_GROUP = re.compile(r"[aeiouyàáâãäåæèéêëìíîïòóôõöøœùúûüý]+", re.IGNORECASE)
# Two vowels side by side that are mostly said apart (li-on, vi-de-o, u-su-al), but not
# in -tion, -cial or after a q or g (ques-tion, so-cial, lan-guage).
_HIATUS = re.compile(r"(?<![tscxg])i(?=[aou])|e(?=o)|(?<![qg])u(?=[ao])")
_TOKENS = re.compile(r"[^\W_]+(?:['\u2019][^\W_]+)*|[,;:]|[.!?]+")


def syllables(word: str) -> int:
    """Syllables of a word: its groups of vowels, a group with two vowels heard apart (li-on,
    ra-di-o) counting two; a word of consonants or digits, one."""
    word = word.lower()
    return max(1, len(_VOWEL_GROUP.findall(word)) + len(_HIATUS.findall(word)))


def syllable_envelope(text: str, seconds: float, frame_s: float = FRAME_S) -> list[float]:
    """The levels of `frame_s` frames a voice saying `text` in `seconds` would give: each
    syllable a swell (the first of each word louder), silence between words, longer at
    a comma and a full stop. Nothing to say (no word, no time): no frames."""
    # (length in syllables, peak level); a peak of 0 is silence.
    pieces: list[tuple[float, float]] = []
    for token in _TOKENS.findall(text):
        if token[0] in ",;:":
            pieces.append((COMMA_PAUSE, 0.0))
        elif token[0] in ".!?":
            pieces.append((STOP_PAUSE, 0.0))
        else:
            if pieces and pieces[-1][1] > 0.0:
                pieces.append((WORD_GAP, 0.0))
            count = syllables(token)
            pieces += [(1.0, STRESSED_LEVEL)] + [(1.0, UNSTRESSED_LEVEL)] * (count - 1)
    while pieces and pieces[-1][1] == 0.0:
        pieces.pop()  # the line ends with its last syllable
    total = sum(length for length, _ in pieces)
    frames = round(seconds / frame_s)
    if not total or frames <= 0:
        return []
    levels: list[float] = []
    unit = frames / total  # frames per syllable
    begin = 0.0
    for length, peak in pieces:
        end = begin + length * unit
        count = round(end) - round(begin)
        for index in range(count):
            levels.append(peak * math.sin(math.pi * (index + 0.5) / count))
        begin = end
    return levels


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
