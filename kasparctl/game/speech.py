"""Kaspar's lines: picked from the phrase book, said by the voice, every failure named.

A step says its lines with `say`: a line cut short by a pause or a fault
raises SpeechCut, one nobody heard raises VoiceFailed (the game stops: a
session cannot go on unheard). The run loop says its lines with `announce`,
which never raises for the voice: a failing voice must not stop the game from
reacting. A line not heard to its end is reported to `unheard` (the game
records it).

Once a line has failed or timed out the voice counts as failing (`failing`
holds why) until a line is heard whole again, and `on_health` is told of each
change. While it fails, `announce` says its line in the background instead of
waiting for it: the researcher's stop or resume must not wait for a voice that
hangs until its timeout, or for a player that cannot play. `announce_soon`
always does: what Kaspar says about a fault must not keep the game from
hearing the next input (the keyfob back, the researcher's resume) meanwhile.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

from hal.errors import KasparError
from hal.voice.api import SpokenStatus, VoiceOutput
from kasparctl.game.phrases import PhraseBook, PhrasePicker
from kasparctl.game.records import HalEvent, HalRecord


class VoiceFailed(KasparError):
    """Kaspar could not say a line: the session cannot go on unheard."""


class SpeechCut(KasparError):
    """A line was cut short by voice.cancel(); not a task cancellation, which must
    never be swallowed (the daemon's stop cancels the game's own task)."""


class Speech:
    """What Kaspar says, through one voice, with one picker's memory of its last lines."""

    def __init__(
        self,
        picker: PhrasePicker,
        voice: VoiceOutput,
        unheard: Callable[[HalRecord], object],
        on_health: Callable[[str | None], object] = lambda failing: None,
    ) -> None:
        """Say `picker`'s lines with `voice`; report each line not heard whole to `unheard`,
        and each change of the voice's health to `on_health` (why it fails, or None)."""
        self.picker = picker
        self.voice = voice
        self._unheard = unheard
        self._on_health = on_health
        self.failing: str | None = None
        self._background: set[asyncio.Task[None]] = set()

    @property
    def book(self) -> PhraseBook:
        """The phrase book the lines come from."""
        return self.picker.book

    async def say(self, key: str, **values: str) -> str:
        """Say a line of `key`; returns its text once said. SpeechCut, VoiceFailed."""
        text = self.picker.line(key, **values)
        await self._speak(text, key)
        return text

    async def announce(self, key: str, **values: str) -> None:
        """Say a line from the run loop: a failing voice is recorded, never raised here.

        While the voice fails the line is said in the background (it is heard if the
        voice is back); a bug in picking the line is raised as ever.
        """
        text = self.picker.line(key, **values)
        if self.failing is None:
            await self._speak_quietly(text, key)
            return
        self._in_background(text, key)

    def announce_soon(self, key: str, **values: str) -> None:
        """Say a line after what is being said, without waiting for it (never raises for
        the voice; a bug in picking the line is raised at once)."""
        self._in_background(self.picker.line(key, **values), key)

    def sound_soon(self, key: str) -> None:
        """Play the recorded clip of `key` (a sound, no words), without waiting for it.

        Only for keys the voice has a clip for ([voice.clips]): the text is empty, so a
        clip that cannot be played says nothing rather than something else.
        """
        self._in_background("", key)

    async def finish(self) -> None:
        """Wait for the lines said in the background (the game is over: let them be heard)."""
        while self._background:
            await asyncio.gather(*list(self._background), return_exceptions=True)

    def _in_background(self, text: str, key: str) -> None:
        task = asyncio.get_running_loop().create_task(self._speak_quietly(text, key))
        self._background.add(task)
        task.add_done_callback(self._background.discard)

    def cut(self) -> None:
        """Stop the line being said (it raises SpeechCut in its step), and drop those queued."""
        self.voice.cancel()

    async def close(self) -> None:
        """Stop the lines still said in the background."""
        tasks = list(self._background)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    async def _speak_quietly(self, text: str, key: str) -> None:
        with contextlib.suppress(VoiceFailed, SpeechCut):
            await self._speak(text, key)

    async def _speak(self, text: str, key: str) -> None:
        spoken = await self.voice.say(text, key)
        if spoken.status is SpokenStatus.CANCELLED:
            raise SpeechCut(text)
        if spoken.status is SpokenStatus.FINISHED:
            self._health(None)
            return
        status = spoken.status.value
        self._unheard(HalRecord(event=HalEvent.VOICE, status=status, text=text, error=spoken.error))
        self._health(spoken.error or f"a line {status}")
        if spoken.status is SpokenStatus.FAILED:
            raise VoiceFailed(spoken.error or "the voice failed")

    def _health(self, failing: str | None) -> None:
        if failing != self.failing:
            self.failing = failing
            self._on_health(failing)
