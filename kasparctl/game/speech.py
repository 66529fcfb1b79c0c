"""Kaspar's lines: picked from the phrase book, said by the voice, every failure named.

A step says its lines with `say`: a line cut short by a pause or a fault
raises SpeechCut, one nobody heard raises VoiceFailed (the game stops: a
session cannot go on unheard). The run loop says its lines with `announce`,
which never raises: a failing voice must not stop the game from reacting.
A line not heard to its end is reported to `unheard` (the game records it).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable

from hal.voice.api import SpokenStatus, VoiceOutput
from kasparctl.game.phrases import PhraseBook, PhrasePicker
from kasparctl.game.records import HalEvent, HalRecord


class VoiceFailed(Exception):
    """Kaspar could not say a line: the session cannot go on unheard."""


class SpeechCut(Exception):
    """A line was cut short by voice.cancel(); not a task cancellation, which must
    never be swallowed (the daemon's stop cancels the game's own task)."""


class Speech:
    """What Kaspar says, through one voice, with one picker's memory of its last lines."""

    def __init__(
        self, picker: PhrasePicker, voice: VoiceOutput, unheard: Callable[[HalRecord], object]
    ) -> None:
        """Say `picker`'s lines with `voice`; report each line not heard whole to `unheard`."""
        self.picker = picker
        self.voice = voice
        self._unheard = unheard

    @property
    def book(self) -> PhraseBook:
        """The phrase book the lines come from."""
        return self.picker.book

    async def say(self, key: str, **values: str) -> str:
        """Say a line of `key`; returns its text once said. SpeechCut, VoiceFailed."""
        text = self.picker.line(key, **values)
        spoken = await self.voice.say(text, key)
        if spoken.status is SpokenStatus.CANCELLED:
            raise SpeechCut(text)
        if spoken.status is not SpokenStatus.FINISHED:
            self._unheard(
                HalRecord(
                    event=HalEvent.VOICE,
                    status=spoken.status.value,
                    text=text,
                    error=spoken.error,
                )
            )
            if spoken.status is SpokenStatus.FAILED:
                raise VoiceFailed(spoken.error or "the voice failed")
        return text

    async def announce(self, key: str, **values: str) -> None:
        """Say a line from the run loop: a failing voice is recorded, never raised here."""
        with contextlib.suppress(VoiceFailed, SpeechCut):
            await self.say(key, **values)

    def cut(self) -> None:
        """Stop the line being said (it raises SpeechCut in its step)."""
        self.voice.cancel()
