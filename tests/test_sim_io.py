"""The simulated keyfob and voice: same gestures as the real keyfob, lines on the clock."""

from __future__ import annotations

import asyncio
import io
import os
import shutil
from pathlib import Path

import pytest

from hal.errors import HalError, InvalidArgument
from hal.keyfob.api import InputEvent, KeyfobBack, KeyfobInput, KeyfobLost
from hal.keyfob.gestures import ANSWERS_ONLY, Gesture, GestureKind, GestureTimings
from hal.keyfob.sim import ScriptedKeyfob, SimKeyfob, TerminalKeyfob, parse_script
from hal.voice.api import Spoken, SpokenStatus
from hal.voice.settings import VoiceSettings
from hal.voice.sim import SimVoice, speaking_time
from hal.voice.speaker import Voice

WAIT = 10.0


class JumpClock:
    """Virtual time: sleeping jumps ahead at once."""

    def __init__(self) -> None:
        self.t = 500.0

    def now(self) -> float:
        """The virtual time."""
        return self.t

    async def sleep(self, seconds: float) -> None:
        """Moves the virtual time on at once, then lets the other tasks run."""
        self.t += max(0.0, seconds)
        await asyncio.sleep(0)


async def drain(keyfob: KeyfobInput, count: int) -> list[InputEvent]:
    return [await asyncio.wait_for(keyfob.next_event(), WAIT) for _ in range(count)]


def describe(event: InputEvent) -> str:
    if isinstance(event, Gesture):
        return f"{event.kind.value} {event.button}"
    return type(event).__name__


async def test_script_gives_every_gesture_of_the_real_keyfob() -> None:
    clock = JumpClock()
    script = (
        "1 green; 1 red; 1 long green; 1 long red; 1 double red; 1 both; "
        "1 lost; 1 back; 1 command pause"
    )
    keyfob = ScriptedKeyfob(script, clock, commands=("pause",))
    await keyfob.start()
    events = await drain(keyfob, 9)
    await asyncio.wait_for(keyfob.done.wait(), WAIT)
    await keyfob.close()
    assert [describe(e) for e in events] == [
        "press green",
        "press red",
        "long green",
        "long red",
        "double red",
        "both both",
        "KeyfobLost",
        "KeyfobBack",
        "command pause",
    ]
    gestures = [e for e in events if isinstance(e, Gesture)]
    red = gestures[1]
    # Red has a double-press meaning: its press waits out the window after the release.
    assert red.decided - red.at == pytest.approx(0.1 + 0.4)
    long_green = gestures[2]
    assert long_green.decided - long_green.at == pytest.approx(1.0)
    assert [g.at for g in gestures] == sorted(g.at for g in gestures)


async def test_answers_only_presses_are_immediate() -> None:
    clock = JumpClock()
    keyfob = SimKeyfob(clock, needs=ANSWERS_ONLY)
    await keyfob.perform("red")
    (press,) = await drain(keyfob, 1)
    assert isinstance(press, Gesture)
    assert press.kind is GestureKind.PRESS and press.decided == press.at


async def test_lost_keyfob_delivers_nothing_until_back() -> None:
    keyfob = SimKeyfob(JumpClock(), timings=GestureTimings())
    await keyfob.perform("lost")
    await keyfob.perform("green")
    await keyfob.perform("back")
    await keyfob.perform("red")
    events = await drain(keyfob, 3)
    assert isinstance(events[0], KeyfobLost) and isinstance(events[1], KeyfobBack)
    assert describe(events[2]) == "press red"
    assert keyfob.connected


def test_script_errors() -> None:
    assert parse_script("0.5 green;\n1 long red") == [(0.5, "green"), (1.0, "long red")]
    with pytest.raises(InvalidArgument, match="SECONDS ACTION"):
        parse_script("soon green")
    with pytest.raises(InvalidArgument, match="unknown keyfob action 'purple'"):
        ScriptedKeyfob("1 purple", JumpClock())


async def test_an_unknown_action_performed_is_named() -> None:
    keyfob = SimKeyfob(JumpClock())
    with pytest.raises(InvalidArgument, match="unknown keyfob action 'long blue'") as caught:
        await keyfob.perform("long blue")
    assert isinstance(caught.value, HalError) and isinstance(caught.value, ValueError)


async def test_terminal_keys_become_gestures() -> None:
    read_end, write_end = os.pipe()
    stream = os.fdopen(read_end, "r")
    keyfob = TerminalKeyfob(JumpClock(), stream=stream)
    await keyfob.start()
    try:
        os.write(write_end, b"gRxb")  # x is not a key
        events = await drain(keyfob, 3)
        assert [describe(e) for e in events] == ["press green", "long red", "both both"]
    finally:
        await keyfob.close()
        os.close(write_end)
        stream.close()


async def test_sim_voice_prints_lines_with_times_and_takes_their_time() -> None:
    clock = JumpClock()
    out = io.StringIO()
    voice = SimVoice(out, clock, rate=120, clips={"greeting": "/clips/hello.wav"})
    first = await voice.say("I think it is the lion.", key="guess.names")
    second = await voice.say("Hello!", key="greeting")
    assert first.status is SpokenStatus.FINISHED and first.via == "sim"
    assert first.ended - first.started == pytest.approx(speaking_time("I think it is the lion.", 120))
    assert second.started == pytest.approx(first.ended)
    assert out.getvalue().splitlines() == [
        "[   500.000] Kaspar: I think it is the lion.",
        f"[{first.ended:10.3f}] Kaspar: Hello! [clip greeting]",
    ]


class StuckClock(JumpClock):
    """A clock on which every line lasts until it is cancelled."""

    async def sleep(self, seconds: float) -> None:
        """Never ends by itself."""
        await asyncio.Event().wait()


class WatchedOutput(io.StringIO):
    """The simulated voice's output, telling a waiting test when a line is printed."""

    def __init__(self) -> None:
        super().__init__()
        self._written = asyncio.Event()

    def write(self, text: str) -> int:
        """Writes, and wakes whoever waits for a line."""
        self._written.set()
        return super().write(text)

    async def printed(self, text: str) -> None:
        """Returns once `text` has been printed."""
        while text not in self.getvalue():
            self._written.clear()
            await self._written.wait()


async def test_sim_voice_cancel_stops_the_line_and_drops_the_queue() -> None:
    out = WatchedOutput()
    voice = SimVoice(out, StuckClock())
    first = asyncio.create_task(voice.say("a long line"))
    await asyncio.wait_for(out.printed("a long line"), WAIT)  # being said

    queued = asyncio.Event()

    async def say_after_the_first() -> Spoken:
        queued.set()  # say() runs on from here up to waiting for its turn, in this step
        return await voice.say("queued")

    second = asyncio.create_task(say_after_the_first())
    await asyncio.wait_for(queued.wait(), WAIT)
    voice.cancel()
    results = await asyncio.wait_for(asyncio.gather(first, second), WAIT)
    assert [r.status for r in results] == [SpokenStatus.CANCELLED] * 2
    assert "queued" not in out.getvalue()

    third = asyncio.create_task(voice.say("after the pause"))
    await asyncio.wait_for(out.printed("after the pause"), WAIT)  # a new line plays
    voice.cancel()
    assert (await asyncio.wait_for(third, WAIT)).status is SpokenStatus.CANCELLED


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng not installed")
async def test_sim_voice_can_also_speak_with_espeak_ng(tmp_path: Path) -> None:
    real = Voice(VoiceSettings(engine="espeak-ng", wav_dir=str(tmp_path)))
    voice = SimVoice(io.StringIO(), JumpClock(), also=real)
    try:
        spoken = await asyncio.wait_for(voice.say("Shall we play?"), WAIT)
    finally:
        await voice.close()
    assert spoken.status is SpokenStatus.FINISHED
    assert [p.suffix for p in tmp_path.iterdir()] == [".wav"]
