"""The simulated voice's lip sync: a line's syllables as the envelope the mouth follows.

Without a sound card or an engine, the simulated voice tells the body's mouth (an
EnvelopeListener) what a line would sound like: a swell per syllable, silence between
words and at the pauses, over the line's speaking time; a real voice given beside it
tells its own.
"""

from __future__ import annotations

import asyncio
import io
import itertools

from hal.clock import LoopClock
from hal.voice.envelope import FRAME_S, syllable_envelope, syllables
from hal.voice.sim import SimVoice, sounding_time
from kasparctl.sim import simtime


def test_a_line_sounds_as_its_syllables_swell_and_its_pauses_fall_silent():
    assert [syllables(w) for w in ("I", "lion", "elephant", "zebra", "3")] == [1, 2, 3, 2, 1]
    levels = syllable_envelope("Hello there, elephant.", 2.0)
    assert len(levels) == round(2.0 / FRAME_S)
    swells = [i for i in range(1, len(levels) - 1)
              if levels[i - 1] < levels[i] >= levels[i + 1] and levels[i] > 0.1]
    assert len(swells) == 2 + 2 + 3
    silent = [level for level in levels if level < 0.01]
    assert len(silent) >= 20  # the words' gaps and the comma's pause
    assert max(levels) <= 0.25 and syllable_envelope("", 1.0) == []
    assert syllable_envelope("Hello.", 0.0) == []


class Heard:
    def __init__(self) -> None:
        self.pieces: list[tuple[float, float, list[float]]] = []
        self.ends: list[bool] = []

    def on_envelope(self, start, frame_s, levels) -> None:
        self.pieces.append((start, frame_s, list(levels)))

    def on_end(self, cut: bool) -> None:
        self.ends.append(cut)


def test_the_simulated_voice_tells_the_mouth_each_line_and_when_it_is_cut():
    async def run() -> tuple[Heard, float]:
        voice = SimVoice(io.StringIO(), LoopClock())
        heard = Heard()
        assert voice.listen(heard) and voice.player is None
        start = LoopClock().now()
        await voice.say("Child 1, is it the lion?")
        cut = asyncio.ensure_future(voice.say("This line is cut short by the researcher."))
        await asyncio.sleep(0.5)
        voice.cancel()
        await cut
        return heard, start

    heard, start = simtime.run(run(), virtual=True)
    (first_start, frame, levels), (second_start, _, _) = heard.pieces
    assert first_start == start and frame == FRAME_S
    assert len(levels) == round(sounding_time("Child 1, is it the lion?", 150) / FRAME_S)
    assert second_start > first_start and heard.ends == [False, True]


def test_the_simulated_voice_leaves_the_envelope_to_a_real_voice_that_tells_it():
    class Real:
        """A real voice's stand-in, whose sink can (or cannot) be listened to."""

        def __init__(self, listened: bool) -> None:
            self.listened = listened
            self.listener = None

        def listen(self, listener) -> bool:
            self.listener = listener if self.listened else None
            return self.listened

        @property
        def player(self) -> str | None:
            return "aplay"

        async def say(self, text, key=None):
            return None

        def cancel(self) -> None: ...

        async def close(self) -> None: ...

    async def run(listened: bool) -> tuple[Heard, Real, SimVoice]:
        real = Real(listened)
        voice = SimVoice(io.StringIO(), LoopClock(), also=real)  # type: ignore[arg-type]
        heard = Heard()
        voice.listen(heard)
        await voice.say("Hello there.")
        return heard, real, voice

    heard, real, voice = simtime.run(run(True), virtual=True)
    assert heard.pieces == [] and real.listener is heard and voice.player == "aplay"
    heard, real, _ = simtime.run(run(False), virtual=True)
    assert len(heard.pieces) == 1 and heard.ends == [False]


def test_the_body_built_on_the_simulated_voice_opens_the_mouth_with_each_syllable():
    import random

    from hal.servos.sim import SimServos
    from kasparctl.body.build import make_body
    from kasparctl.body.engine import LiveBody
    from kasparctl.sim.demo import demo_config

    config = demo_config()
    text = "Hello there, children."

    async def run() -> list[tuple[float, float, str]]:
        clock = LoopClock()
        servos = SimServos(config.servos, clock)
        voice = SimVoice(io.StringIO(), clock)
        body = make_body(config, servos, voice, rng=random.Random(0))
        assert isinstance(body, LiveBody)
        await servos.start(poll=False)
        for group in servos.groups:
            await servos.set_compliant(group, False)
        goals: list[tuple[float, float, str]] = []
        servos.on_goals(lambda g: goals.append((g.time, g.degrees, g.source))
                        if g.joint == config.body.mouth_joint else None)
        await body.start()
        await voice.say(text)
        await asyncio.sleep(0.5)
        await body.close()
        return goals

    goals = simtime.run(run(), virtual=True)
    assert {source for _, _, source in goals} == {"mouth"}
    openings = [degrees for _, degrees, _ in goals]
    # Each syllable opens the mouth and the gaps close it: six swells, closed at the end.
    opened = sum(1 for a, b in itertools.pairwise(openings) if a < 5.0 <= b)
    assert opened == 6 and openings[-1] == 0.0
    assert goals[-1][0] - goals[0][0] >= sounding_time(text, 150)
