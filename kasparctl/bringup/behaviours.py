"""Behaviours at the robot: played through a LiveBody, and recorded by demonstration.

`perform` plays one behaviour through the body's own loop and layers and notes
each joint's extremes; `play_real` does so on the configured servos. `record`
takes keyframes by demonstration: the chosen joints go limp, each green press
(or Enter) takes a keyframe, a long green press (or "s" and Enter) saves, red
(or "q" and Enter) cancels; the file is checked against the robot before it is
written.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import random
import sys
import threading
from pathlib import Path
from typing import Any, TextIO

from hal.clock import Clock, MonotonicClock
from hal.errors import HalError
from hal.keyfob.gestures import ANSWER, ANSWER_OR_LONG, GREEN, RED, GestureKind, GestureNeeds
from hal.servos.joints import Joints
from kasparctl.body.behaviours import parse
from kasparctl.body.check import problems
from kasparctl.body.engine import LiveBody
from kasparctl.bringup.engineer import (
    BringUpError,
    Engineer,
    hold_others,
    open_servos,
    start_servos,
    write_atomically,
)
from kasparctl.config import Config

# A recorded joint that moved less than this in every keyframe is left out of the file.
RECORD_STILL_DEG = 0.5


async def perform(servos: Joints, config: Config, library: Any, clock: Clock,
                  name: str, strength: float) -> dict[str, tuple[float, float]]:
    """Play through a LiveBody (its loop, its layers) and note each joint's extremes."""
    body = LiveBody(servos, config.body, config.servos, library, clock, rng=random.Random(0))
    seen: dict[str, tuple[float, float]] = {}
    original = body.step

    async def noting(now: float) -> dict[str, float]:
        sent = await original(now)
        for joint, value in sent.items():
            low, high = seen.get(joint, (math.inf, -math.inf))
            seen[joint] = (min(low, value), max(high, value))
        return sent

    body.step = noting  # type: ignore[method-assign]
    await body.start()
    try:
        await body.perform(name, strength)
        await clock.sleep(2 * body.period)
    finally:
        await body.close()
    return seen


async def play_real(config: Config, library: Any, name: str, strength: float
                    ) -> dict[str, tuple[float, float]]:
    """On the configured servos: the behaviour's joints turned on (holding), then played."""
    clock = MonotonicClock()
    servos = open_servos(config, clock)
    await start_servos(servos)
    try:
        for joint in library[name].joints:
            if joint in servos.joints:
                await servos.set_compliant(joint, False)
        return await perform(servos, config, library, clock, name, strength)
    finally:
        await servos.close()


async def record(config: Config, servos: Joints, engineer: Engineer, name: str,
                 chosen: list[str], presses: asyncio.Queue[str] | None = None) -> Path | None:
    """Limp `chosen`, take a keyframe per "key", save on "save", cancel on "cancel".

    `presses` gives those words (tests); without it they come from the keyfob
    (green, long green, red) and the terminal (Enter, s, q).
    """
    assert config.body.behaviours_dir is not None
    await start_servos(servos)
    queue = presses or asyncio.Queue()
    readers: list[asyncio.Task[None]] = []
    try:
        await engineer.start()
        await hold_others(servos, chosen)
        for joint in chosen:
            await servos.set_compliant(joint, True)
        if presses is None:
            _read_terminal(queue)
            readers.append(asyncio.create_task(_read_keyfob(config, engineer.clock, queue)))
        engineer.say(f"Recording behaviour {name.replace('_', ' ')}. Move the joints; press "
                     "green (or Enter) for each keyframe, hold green (or type s) to save, "
                     "red (or q) to cancel.")
        start = await servos.read_positions()
        began = engineer.clock.now()
        keyframes: list[tuple[float, dict[str, float]]] = []
        while (word := await queue.get()) == "key":
            positions = await servos.read_positions()
            at = round(engineer.clock.now() - began, 2)
            keyframes.append((at, {j: round(positions[j] - start[j], 1)
                                   for j in chosen if j in positions and j in start}))
            engineer.say(f"Keyframe {len(keyframes)}.")
        if word != "save" or not keyframes:
            engineer.say("Behaviour not saved.")
            return None
        path = Path(config.body.behaviours_dir) / f"{name}.toml"
        text = behaviour_toml(name, keyframes)
        parse(text, str(path))  # refuses what could not be read back
        found = problems(parse(text, str(path)), config.servos)
        if found:
            raise BringUpError("not saved: " + "; ".join(found))
        if path.exists():
            write_atomically(path, text)
        else:
            path.write_text(text, encoding="utf-8")
        for joint in chosen:
            with contextlib.suppress(HalError):
                await servos.set_compliant(joint, False)
        engineer.say(f"Behaviour {name.replace('_', ' ')} saved.")
        return path
    finally:
        for reader in readers:
            reader.cancel()
        await engineer.close()
        await servos.close()


def behaviour_toml(name: str, keyframes: list[tuple[float, dict[str, float]]]) -> str:
    """The behaviour file of recorded keyframes: offsets from the first pose, joints that moved."""
    moved = sorted({j for _, pose in keyframes for j, v in pose.items()
                    if abs(v) >= RECORD_STILL_DEG})
    lines = [f"# Recorded with `kasparctl behaviour record {name}`.", "", f"[{name}]",
             'description = "recorded by demonstration"', "keyframes = ["]
    for at, pose in keyframes:
        joints = ", ".join(f"{j} = {pose[j]:.1f}" for j in moved if j in pose)
        lines.append(f"  {{ time = {at:g}, pose = {{ {joints} }} }},")
    lines.append("]")
    return "\n".join(lines) + "\n"


def _read_terminal(queue: asyncio.Queue[str], stream: TextIO | None = None) -> None:
    loop = asyncio.get_running_loop()
    source = stream or sys.stdin

    def read() -> None:
        for line in source:
            word = {"": "key", "s": "save", "q": "cancel"}.get(line.strip().lower(), "key")
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(queue.put_nowait, word)
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(queue.put_nowait, "cancel")

    threading.Thread(target=read, name="enter", daemon=True).start()


async def _read_keyfob(config: Config, clock: Clock, queue: asyncio.Queue[str]) -> None:
    if config.keyfob.backend != "real":
        return
    from hal.keyfob.reader import Keyfob

    keyfob = Keyfob(config.keyfob, clock,
                    needs=GestureNeeds(green=ANSWER_OR_LONG, red=ANSWER, both=False))
    await keyfob.start()
    try:
        while True:
            event = await keyfob.next_event()
            button, kind = getattr(event, "button", None), getattr(event, "kind", None)
            if button == GREEN:
                queue.put_nowait("save" if kind is GestureKind.LONG else "key")
            elif button == RED:
                queue.put_nowait("cancel")
    finally:
        await keyfob.close()
