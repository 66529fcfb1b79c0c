"""The simulated voice: each line printed with its clock time, for as long as it would take to say.

Optionally it also speaks (or writes WAV files) through a real voice, e.g.
hal.voice.speaker.Voice with engine "espeak-ng", so the demo can be heard.

It can be listened to, as the real voice can: the mouth is told the envelope of each
line, the real voice's own (its samples) when it has one and it can be listened to,
else the envelope of the line's syllables, spread over its speaking time
(hal.voice.envelope.syllable_envelope), so a simulated game shows lip sync too. While
the real voice renders a line, simulated time stands still (hal.clock.thread_work), so
in a game in simulated time the sound starts as the line does.

Faults can be injected as the real voice has them: a player that fails at
once (no sound card: every line FAILED with the player's error, the line
being said cut), or one that hangs (every line TIMED_OUT after the voice's
timeout, as hal.voice.speaker.Voice reports a hung engine).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Mapping
from typing import TextIO

from hal.clock import Clock, thread_work
from hal.voice.api import EnvelopeListener, Spoken, SpokenStatus, VoiceOutput
from hal.voice.envelope import FRAME_S, syllable_envelope
from hal.voice.settings import VoiceSettings

PAUSE_AFTER_LINE = 0.3


def speaking_time(text: str, rate: int) -> float:
    """Seconds a line takes at `rate` words per minute, with a short pause after it."""
    return len(text.split()) * 60.0 / rate + PAUSE_AFTER_LINE


def sounding_time(text: str, rate: int) -> float:
    """Seconds of a line's speaking time that sound (without the pause after it)."""
    return speaking_time(text, rate) - PAUSE_AFTER_LINE


class SimVoice:
    """Satisfies hal.voice.api.VoiceOutput without a sound card."""

    def __init__(
        self,
        stream: TextIO,
        clock: Clock,
        *,
        rate: int = 150,
        also: VoiceOutput | None = None,
        prefix: str = "Kaspar",
        clips: Mapping[str, str] | None = None,
        timeout: float = 20.0,
    ) -> None:
        """Print each line to `stream` as it would be spoken at `rate` words per minute.

        `also` is a real voice that speaks (or writes) each line too; `prefix` names
        the speaker in the printed line; a phrase key in `clips` is marked as a clip;
        `timeout` is how long a hung line takes to time out (see inject_fault).
        """
        self._stream = stream
        self._clock = clock
        self._rate = rate
        self._also = also
        self._prefix = prefix
        self._clips = dict(clips or {})
        self._turn = asyncio.Lock()
        self._current: asyncio.Task[None] | None = None
        self._cancelled_at = 0  # lines queued before the last cancel() are dropped
        self._serial = 0
        self._timeout = timeout
        self._failure: str | None = None
        self._hangs = False
        self.lines: list[Spoken] = []
        self._listener: EnvelopeListener | None = None
        # The real voice tells the listener its own envelope (the sound's samples).
        self._heard_through_also = False
        # Called with each line's text as Kaspar starts to say it (a test waits on it).
        self.on_line: Callable[[str], None] | None = None

    def listen(self, listener: EnvelopeListener | None) -> bool:
        """Tell `listener` the envelope of every line as it starts (None: nobody): the real
        voice's, when one is given and can be listened to, else the syllables'. Always True."""
        self._listener = listener
        self._heard_through_also = self._also is not None and self._also.listen(listener)
        return True

    @property
    def player(self) -> str | None:
        """The real voice's player, if it plays through one; None otherwise (no latency)."""
        return self._also.player if self._also is not None else None

    def configure(self, settings: VoiceSettings) -> None:
        """Time each line at `settings`' rate from the next line on, with its clips and
        timeout (and the real voice it also speaks with, if any, takes them all)."""
        self._rate = settings.rate
        self._clips = dict(settings.clips)
        self._timeout = settings.timeout
        if self._also is not None:
            self._also.configure(settings)

    def inject_fault(self, error: str | None, *, hang: bool = False) -> None:
        """From now on every line fails with `error` (the line being said ends at once);
        with `hang`, every line times out instead; None: the voice works again."""
        self._failure, self._hangs = error, hang and error is not None
        if error is not None and not hang and self._current is not None:
            self._current.cancel()  # the player died mid-line

    async def say(self, text: str, key: str | None = None) -> Spoken:
        """Print the line, then wait on the clock as long as it takes to say.

        Lines queue in order; one queued before a cancel() is dropped. Returns
        CANCELLED when cut by cancel() or by the caller's cancellation.
        """
        self._serial += 1
        serial = self._serial
        async with self._turn:
            started = self._clock.now()
            if serial <= self._cancelled_at:
                return self._record(SpokenStatus.CANCELLED, text, started)
            if self._failure is not None and not self._hangs:
                return self._record(SpokenStatus.FAILED, text, started, self._failure)
            # The game names every line's phrase key; only a configured clip replaces TTS.
            clip = f" [clip {key}]" if key is not None and key in self._clips else ""
            hung = self._hangs
            if not hung:
                self._stream.write(f"[{started:10.3f}] {self._prefix}: {text}{clip}\n")
                self._stream.flush()
                if self.on_line is not None:
                    self.on_line(text)
            self._current = asyncio.get_running_loop().create_task(self._speak(text, key, hung))
            try:
                await asyncio.wait({self._current})
            finally:
                if not self._current.done():
                    self._current.cancel()  # our caller was cancelled
                    await asyncio.wait({self._current})
            cancelled = self._current.cancelled()
            self._current = None
        if hung and not cancelled:
            return self._record(
                SpokenStatus.TIMED_OUT, text, started, f"no end after {self._timeout} s"
            )
        if cancelled and self._failure is not None and not self._hangs:
            return self._record(SpokenStatus.FAILED, text, started, self._failure)
        status = SpokenStatus.CANCELLED if cancelled else SpokenStatus.FINISHED
        return self._record(status, text, started)

    async def _speak(self, text: str, key: str | None, hung: bool = False) -> None:
        if hung:
            await self._clock.sleep(self._timeout)
            return
        listener = None if self._heard_through_also else self._listener
        if listener is not None:
            levels = syllable_envelope(text, sounding_time(text, self._rate))
            listener.on_envelope(self._clock.now(), FRAME_S, levels)
        cut = True
        try:
            waits = [self._clock.sleep(speaking_time(text, self._rate))]
            if self._also is not None:
                waits.append(self._also_say(text, key))
            await asyncio.gather(*waits)
            cut = False
        finally:
            if listener is not None:
                listener.on_end(cut)

    async def _also_say(self, text: str, key: str | None) -> None:
        assert self._also is not None
        try:
            # Simulated time stands still while the real voice renders (no effect on a
            # real clock): the line sounds from its start, as it would on the robot.
            with thread_work(asyncio.get_running_loop()):
                await self._also.say(text, key)
        except asyncio.CancelledError:
            self._also.cancel()
            raise

    def _record(
        self, status: SpokenStatus, text: str, started: float, error: str | None = None
    ) -> Spoken:
        via = None if status is SpokenStatus.FAILED else "sim"
        spoken = Spoken(status, text, via, started, self._clock.now(), error=error)
        self.lines.append(spoken)
        return spoken

    def cancel(self) -> None:
        """Cut the current line and drop every line queued before now."""
        self._cancelled_at = self._serial
        if self._current is not None:
            self._current.cancel()

    async def close(self) -> None:
        """Cancel, then close the real voice given as `also` (its failure is ignored)."""
        self.cancel()
        if self._also is not None:
            with contextlib.suppress(Exception):
                await self._also.close()
