"""Settings of Kaspar's voice (the `[voice]` table of kaspar.toml)."""

from __future__ import annotations

import re
from typing import Literal

import msgspec

_VOICE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_+/-]*")
_PHRASE_KEY = re.compile(r"[A-Za-z0-9_.-]+")


class VoiceSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Engine, voice, rate, volume, timeout, recorded clips and where the sound goes."""

    # "sim": hal.voice.sim prints each line instead of speaking it.
    backend: Literal["real", "sim"] = "real"
    # espeak-ng as a child process: 2 ms slower to the first sample than pyttsx3
    # (inaudible) but a hung one is killed, and it shares no state with this
    # process (docs/keyfob-and-voice.md has the bench). The other is the fallback.
    engine: Literal["pyttsx3", "espeak-ng"] = "espeak-ng"
    # An espeak-ng voice (`espeak-ng --voices=en` lists them).
    voice: str = "en-gb"
    # Words per minute; a little slower than espeak's 175 for young listeners.
    rate: int = 150
    # 0.0 to 1.0; 1.0 is espeak's normal amplitude.
    volume: float = 1.0
    # An utterance not finished after this many seconds is cut and the engine recovered.
    timeout: float = 20.0
    # Phrase key -> absolute path of a recorded WAV that is played instead of the text.
    clips: dict[str, str] = {}
    # Plays a WAV file given as its last argument ("-" for standard input).
    player: tuple[str, ...] = ("aplay", "-q")
    # When set, each utterance is written there as a numbered WAV file instead of
    # being played: for machines without a sound card, and for the tests.
    wav_dir: str | None = None
    espeak_ng: str = "espeak-ng"

    def __post_init__(self) -> None:
        if not _VOICE_NAME.fullmatch(self.voice):
            raise ValueError(f"voice: expected a voice name like 'en-gb', found {self.voice!r}")
        if not 80 <= self.rate <= 450:
            raise ValueError(f"rate: expected 80 to 450 words per minute, found {self.rate}")
        if not 0.0 <= self.volume <= 1.0:
            raise ValueError(f"volume: expected 0.0 to 1.0, found {self.volume}")
        if not 1.0 <= self.timeout <= 300.0:
            raise ValueError(f"timeout: expected 1 to 300 seconds, found {self.timeout}")
        if not self.player or not self.player[0]:
            raise ValueError("player: expected a command such as ['aplay', '-q']")
        for key, path in self.clips.items():
            if not _PHRASE_KEY.fullmatch(key):
                raise ValueError(f"clips: expected a phrase key, found {key!r}")
            # The service runs from /, so a relative path would depend on how it was started.
            if not path.startswith("/") or not path.lower().endswith(".wav"):
                raise ValueError(f"clips.{key}: expected an absolute .wav path, found {path!r}")
