"""Settings of Kaspar's voice (the `[voice]` table of kaspar.toml).

A key's own limits are on its field (msgspec.Meta, held while decoding and
worded by kasparctl.config from the Meta); __post_init__ holds what a Meta
cannot say: the player's first word and the clips' phrase keys.
"""

from __future__ import annotations

import re
from typing import Annotated, Literal

import msgspec

from hal.errors import SettingsError

_PHRASE_KEY = re.compile(r"[A-Za-z0-9_.-]+")

# An espeak-ng voice (`espeak-ng --voices=en` lists them).
VoiceName = Annotated[
    str,
    msgspec.Meta(
        pattern=r"^[A-Za-z0-9][A-Za-z0-9_+/-]*\Z",
        extra={"expected": "a voice name like 'en-gb'"},
    ),
]
# A recorded clip; the service runs from /, so a relative path would depend on how
# it was started.
ClipPath = Annotated[
    str, msgspec.Meta(pattern=r"(?is)^/.*\.wav\Z", extra={"expected": "an absolute .wav path"})
]


# The espeak-ng voice of each language Kaspar speaks (`espeak-ng --voices` lists them);
# the configuration takes it from its language unless [voice] names a voice.
LANGUAGE_VOICES = {"en": "en-gb", "nl": "nl", "de": "de", "it": "it", "fr": "fr-fr"}


def voice_for_language(language: str) -> str:
    """The voice for `language`: LANGUAGE_VOICES', else espeak-ng's voice of that name."""
    return LANGUAGE_VOICES.get(language, language.lower().replace("_", "-"))


class VoiceSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Engine, voice, rate, volume, timeout, recorded clips and where the sound goes."""

    # "sim": hal.voice.sim prints each line instead of speaking it.
    backend: Literal["real", "sim"] = "real"
    # espeak-ng as a child process: 2 ms slower to the first sample than pyttsx3
    # (inaudible) but a hung one is killed, and it shares no state with this
    # process (docs/keyfob-and-voice.md has the bench). The other is the fallback.
    engine: Literal["pyttsx3", "espeak-ng"] = "espeak-ng"
    # The default is English's; kaspar.toml's language chooses another (LANGUAGE_VOICES).
    voice: VoiceName = "en-gb"
    # A little slower than espeak's 175 for young listeners.
    rate: Annotated[int, msgspec.Meta(ge=80, le=450, extra={"unit": "words per minute"})] = 150
    # 1.0 is espeak's normal amplitude.
    volume: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 1.0
    # espeak-ng's pitch, 0 to 99 (50 its own); the pyttsx3 engine has no pitch to set.
    pitch: Annotated[int, msgspec.Meta(ge=0, le=99)] = 50
    # An utterance not finished after this long is cut and the engine recovered.
    timeout: Annotated[float, msgspec.Meta(ge=1.0, le=300.0, extra={"unit": "s"})] = 20.0
    # Phrase key -> recorded WAV that is played instead of the text.
    clips: dict[str, ClipPath] = {}
    # Plays a WAV file given as its last argument ("-" for standard input).
    player: tuple[str, ...] = ("aplay", "-q")
    # When set, each utterance is written there as a numbered WAV file instead of
    # being played: for machines without a sound card, and for the tests.
    wav_dir: str | None = None
    espeak_ng: str = "espeak-ng"

    def __post_init__(self) -> None:
        """The player names a program and every clip a phrase key; SettingsError otherwise."""
        if not self.player or not self.player[0]:
            raise SettingsError("player: expected a command such as ['aplay', '-q']")
        for key in self.clips:
            if not _PHRASE_KEY.fullmatch(key):
                raise SettingsError(f"clips: expected a phrase key, found {key!r}")
