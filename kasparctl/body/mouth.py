"""The mouth that follows the voice: the audio's envelope, as the player receives it, to an opening.

hal.voice tells the mouth (an EnvelopeListener) the RMS level of each 10 ms frame
of audio as it is handed to the player, with the clock time it was handed over.
The sound is heard `latency` seconds later (the player's buffer and the sound
card); the mouth opens with the level heard at each moment, closed in silence,
closed at the end of a line, and at once when a line is cut.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Sequence

from hal.clock import Clock

# Seconds from the samples reaching the player to their sound, by player, when the
# configuration does not say (body.latency_s): aplay and sox's play start once their
# buffer holds about a tenth of a second; pw-play and paplay go through a sound
# server with its own. WAV files (no player, `say --wav`) are heard at their first sample.
PLAYER_LATENCY_S = {"aplay": 0.1, "play": 0.1, "paplay": 0.05, "pw-play": 0.05}
UNKNOWN_PLAYER_LATENCY_S = 0.1
# Below this level (of full scale) the mouth is closed: espeak's pauses are true silence.
SILENCE_LEVEL = 0.01
# After the last sound the mouth is held closed this long, then left to the other layers.
CLOSE_TAIL_S = 0.3


def player_latency(player: str | None) -> float:
    """The default latency of a player program (None: lines are written to WAV files)."""
    if player is None:
        return 0.0
    return PLAYER_LATENCY_S.get(player, UNKNOWN_PLAYER_LATENCY_S)


class Mouth:
    """An EnvelopeListener that says how open the mouth is at each moment (0 to 1)."""

    def __init__(self, clock: Clock, latency_s: float, full_level: float, window_s: float) -> None:
        """Levels heard `latency_s` after they reach the player; `full_level` opens it fully;
        each opening averages the levels over `window_s` (the control loop's period)."""
        self._clock = clock
        self.latency_s = latency_s
        self._full = full_level
        self._window = window_s
        self._starts: list[float] = []  # when each frame is heard
        self._levels: list[float] = []
        self._frame = 0.01
        self._until: float | None = None  # the mouth is claimed until then
        # Told of every new sound or cut (the body's loop wakes for it).
        self.on_news: Callable[[], None] = lambda: None

    def on_envelope(self, start: float, frame_s: float, levels: Sequence[float]) -> None:
        """Schedule the frames of a piece of audio handed to the player at `start`."""
        heard = start + self.latency_s
        self._frame = frame_s
        if self._starts and heard < self._starts[-1]:
            self._drop_after(heard)  # a new line overlapping what was scheduled: it wins
        for index, level in enumerate(levels):
            self._starts.append(heard + index * frame_s)
            self._levels.append(level)
        end = heard + len(levels) * frame_s + CLOSE_TAIL_S
        self._until = max(self._until or end, end)
        self.on_news()

    def on_end(self, cut: bool) -> None:
        """A line ended; cut, the mouth closes now (what was scheduled is dropped)."""
        if cut:
            self.cut()

    def cut(self) -> None:
        """Close now: forget every level still to come, hold closed for the tail."""
        now = self._clock.now()
        self._drop_after(now - 1.0)
        self._until = now + CLOSE_TAIL_S
        self.on_news()

    def silence(self) -> None:
        """Stop at once: nothing scheduled, the mouth no longer claimed (the body's cancel)."""
        self._starts.clear()
        self._levels.clear()
        self._until = None

    @property
    def claimed(self) -> bool:
        """Whether a line is near: the mouth has levels to follow or a close to hold."""
        return self._until is not None

    def opening(self, now: float) -> float | None:
        """How open (0 to 1) at `now`; None when no line is near (the mouth is not claimed).
        A moment past the line's end releases the mouth."""
        if self._until is None:
            return None
        if now > self._until:
            self._until = None
            self._starts.clear()
            self._levels.clear()
            return None
        self._forget_before(now - 1.0)
        return self.level_at(now)

    def ends_by(self, now: float) -> bool:
        """Whether opening(now) would release the mouth (a line near, its end passed)."""
        return self._until is not None and now > self._until

    def level_at(self, now: float) -> float | None:
        """opening(now) without changing anything (a look ahead within the claim)."""
        if self._until is None:
            return None
        low = bisect.bisect_right(self._starts, now - self._window / 2) - 1
        high = bisect.bisect_left(self._starts, now + self._window / 2)
        chosen = [
            self._levels[i] for i in range(max(0, low), high)
            if self._starts[i] + self._frame > now - self._window / 2
        ]
        if not chosen:
            return 0.0
        level = sum(chosen) / len(chosen)
        if level <= SILENCE_LEVEL:
            return 0.0
        return min(1.0, (level - SILENCE_LEVEL) / (self._full - SILENCE_LEVEL))

    def _drop_after(self, moment: float) -> None:
        keep = bisect.bisect_right(self._starts, moment)
        del self._starts[keep:]
        del self._levels[keep:]

    def _forget_before(self, moment: float) -> None:
        drop = bisect.bisect_left(self._starts, moment)
        if drop > 256:  # trim in batches: the loop runs 50 times a second
            del self._starts[:drop]
            del self._levels[:drop]
