"""What the game sees of Kaspar's voice: say, cancel, close; and what the mouth hears of it.

The real voice (hal.voice.speaker.Voice) and the simulated one (hal.voice.sim.SimVoice)
both satisfy VoiceOutput. Speech failures are not exceptions: a session must
go on when the voice fails, so say() returns a Spoken record naming what
happened, and the game records the ones that are not "finished". Either voice can
be listened to (`listen`): an EnvelopeListener (the body's mouth) is told the
loudness of every line as it is played (hal.voice.envelope).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from hal.voice.settings import VoiceSettings


class SpokenStatus(StrEnum):
    """How an utterance ended; the value is what session records show."""

    FINISHED = "finished"
    # cancel() was called, or the task awaiting say() was cancelled.
    CANCELLED = "cancelled"
    # Cut at the utterance timeout; the engine has been recovered.
    TIMED_OUT = "timed_out"
    # Every engine failed (the error says why); nothing was heard.
    FAILED = "failed"


@dataclass(frozen=True, slots=True)
class Spoken:
    """What became of one say(): how it ended, through which engine, and when (clock seconds)."""

    status: SpokenStatus
    text: str
    # "pyttsx3", "espeak-ng", "clip" or "sim"; None when nothing was produced.
    via: str | None
    started: float
    ended: float
    # The WAV file written, when the voice writes files instead of playing them.
    wav: str | None = None
    error: str | None = None

    @property
    def finished(self) -> bool:
        """True when the utterance was spoken to its end."""
        return self.status is SpokenStatus.FINISHED


class EnvelopeListener(Protocol):
    """Told the levels of the audio as it is handed to the player; called on the event loop."""

    def on_envelope(self, start: float, frame_s: float, levels: Sequence[float]) -> None:
        """`levels` (RMS, 0 to 1 of full scale) of consecutive `frame_s` frames, the first
        handed to the player at clock time `start`."""
        ...

    def on_end(self, cut: bool) -> None:
        """No more audio for this line; `cut`: it was cancelled or failed, stop now."""
        ...


class VoiceOutput(Protocol):
    """Kaspar's voice as the game uses it; every method runs on the event loop."""

    async def say(self, text: str, key: str | None = None) -> Spoken:
        """Speak `text` (or the recorded clip for phrase `key`) after what is already queued.

        Returns when the utterance has finished, was cancelled, timed out or failed.
        """
        ...

    def cancel(self) -> None:
        """Stop talking now and drop everything queued (the researcher paused)."""
        ...

    async def close(self) -> None:
        """Cancel, then release the engine; idempotent."""
        ...

    def configure(self, settings: VoiceSettings) -> None:
        """Speak with `settings` from the next line on (a session's own voice, a reload);
        where the sound goes stays as the voice was built."""
        ...

    def listen(self, listener: EnvelopeListener | None) -> bool:
        """Tell `listener` the levels of every line as it is played (None: nobody); False
        when this voice's output cannot be listened to."""
        ...

    @property
    def player(self) -> str | None:
        """The player program the sound goes to (its latency delays what is heard); None
        when nothing is played through one (WAV files, a simulated voice)."""
        ...
