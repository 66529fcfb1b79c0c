"""`kasparctl behaviour check/play/record`: behaviour files checked, played and recorded.

check: every behaviour file (the shipped phrases/behaviours/, or body.behaviours_dir)
against the configured joints: an unknown joint, a keyframe that would be clamped or
a move faster than a joint's limit is named with its file, behaviour and keyframe.
play: on simulated servos by default (in simulated time, at once), or with --real on
the configured servos as `pose play` does. record: by demonstration, as `pose record`:
the joints go limp, each green press (or Enter) takes a keyframe, a long green press
(or "s" and Enter) saves, red (or "q" and Enter) cancels.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import random
import sys
import threading
from pathlib import Path
from typing import Any, TextIO

from hal.clock import Clock, LoopClock, MonotonicClock
from hal.errors import HalError
from hal.keyfob.gestures import ANSWER, ANSWER_OR_LONG, GREEN, RED, GestureKind, GestureNeeds
from hal.servos.joints import Joints
from kasparctl.body.behaviours import BehaviourError, load_library, parse
from kasparctl.body.check import problems
from kasparctl.body.engine import LiveBody
from kasparctl.commands.arguments import number
from kasparctl.commands.bringup import (
    BringUpError,
    Engineer,
    hold_others,
    open_servos,
    select_joints,
    start_servos,
    write_atomically,
)
from kasparctl.commands.motion import powered_sim, trajectory, write_csv
from kasparctl.config import Config, ConfigError, default_config_path, load_config
from kasparctl.log import configure_logging
from kasparctl.sim import simtime

# A recorded joint that moved less than this in every keyframe is left out of the file.
RECORD_STILL_DEG = 0.5


def register(subparsers: Any) -> None:
    """Add the `behaviour` command with its check, play and record actions."""
    parser = subparsers.add_parser("behaviour", help="check, play and record Kaspar's behaviours")
    actions = parser.add_subparsers(dest="behaviour_command", metavar="ACTION", required=True)

    def common(action: argparse.ArgumentParser) -> None:
        action.add_argument("--config", default=None,
                            help="kaspar.toml (default: $KASPAR_CONFIG or /etc/kaspar)")

    check = actions.add_parser("check", help="every behaviour file against the configured robot")
    common(check)
    check.add_argument("--json", action="store_true", help="print the problems as JSON")
    check.set_defaults(run=run_check)

    play = actions.add_parser("play", help="play a behaviour (simulated unless --real)")
    play.add_argument("name")
    common(play)
    play.add_argument("--strength", type=number(0, 1), default=1.0, help="0 to 1 (default 1)")
    play.add_argument("--real", action="store_true",
                      help="on the configured servos (servos.backend), as `pose play`")
    play.add_argument("--motion", metavar="CSV", help="simulated: write the joint goals sent")
    play.set_defaults(run=run_play)

    record = actions.add_parser("record", help="record a behaviour by moving the joints by hand")
    record.add_argument("name")
    common(record)
    which = record.add_mutually_exclusive_group()
    which.add_argument("--group", help="the group to move (default: every joint)")
    which.add_argument("--joints", type=lambda t: [n for n in t.split(",") if n],
                       help="joints to move, e.g. head_yaw,head_pitch")
    record.add_argument("--quiet", action="store_true", help="print the prompts, do not speak")
    record.set_defaults(run=run_record)


def _config(arguments: argparse.Namespace) -> Config:
    return load_config(arguments.config or default_config_path(), poses=False)


def _fail(error: Exception) -> int:
    print(f"error: {error}", file=sys.stderr)
    return 1


# --- check ------------------------------------------------------------------------------


def run_check(arguments: argparse.Namespace) -> int:
    """Print every problem (exit 1), or how many behaviours fit (exit 0)."""
    try:
        config = _config(arguments)
        library = load_library(config.body.behaviours_dir)
    except (ConfigError, BehaviourError) as error:
        return _fail(error)
    found = problems(library, config.servos)
    if arguments.json:
        print(json.dumps({"behaviours": sorted(library), "problems": found}))
    else:
        for line in found:
            print(line)
        if not found:
            print(f"{len(library)} behaviours fit the robot's {len(config.servos.joints)} joints: "
                  + ", ".join(sorted(library)))
    return 1 if found else 0


# --- play -------------------------------------------------------------------------------


def run_play(arguments: argparse.Namespace) -> int:
    """Play one behaviour; exit 1 if it is unknown or cannot be played."""
    configure_logging("warning", "console", stream=sys.stderr)
    try:
        config = _config(arguments)
        library = load_library(config.body.behaviours_dir)
        if arguments.name not in library:
            raise BringUpError(f"no behaviour {arguments.name!r} (behaviours: "
                               f"{', '.join(sorted(library))})")
        if arguments.real:
            moved = asyncio.run(play_real(config, library, arguments))
        else:
            moved = simtime.run(play_sim(config, library, arguments), virtual=True)
    except (ConfigError, BehaviourError, BringUpError, HalError) as error:
        return _fail(error)
    where = "on the robot" if arguments.real else "on the simulated robot"
    print(f"played {arguments.name!r} {where} (strength {arguments.strength:g}): "
          + (", ".join(f"{joint} {low:+.1f}..{high:+.1f}" for joint, (low, high) in moved.items())
             or "nothing moved"))
    return 0


async def _perform(servos: Joints, config: Config, library: Any, clock: Clock,
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


async def play_sim(config: Config, library: Any, arguments: argparse.Namespace
                   ) -> dict[str, tuple[float, float]]:
    """On the configured joints, simulated, in simulated time; --motion writes the goals."""
    servos = await powered_sim(config)
    clock = LoopClock()
    origin = clock.now()
    seen = await _perform(servos, config, library, clock, arguments.name, arguments.strength)
    if arguments.motion:
        write_csv(trajectory(servos, origin), Path(arguments.motion))
    return seen


async def play_real(config: Config, library: Any, arguments: argparse.Namespace
                    ) -> dict[str, tuple[float, float]]:
    """On the configured servos: the behaviour's joints turned on (holding), then played."""
    clock = MonotonicClock()
    servos = open_servos(config, clock)
    await start_servos(servos)
    try:
        for joint in library[arguments.name].joints:
            if joint in servos.joints:
                await servos.set_compliant(joint, False)
        return await _perform(servos, config, library, clock, arguments.name, arguments.strength)
    finally:
        await servos.close()


# --- record -----------------------------------------------------------------------------


def run_record(arguments: argparse.Namespace) -> int:
    """Record one behaviour into body.behaviours_dir; exit 0 when saved."""
    configure_logging("warning", "console", stream=sys.stderr)
    try:
        config = _config(arguments)
        if config.body.behaviours_dir is None:
            raise BringUpError(
                "body.behaviours_dir is not set: recorded behaviours go to a directory of "
                "your own (copy the shipped phrases/behaviours/ there first)"
            )
        clock = MonotonicClock()
        servos = open_servos(config, clock)
        engineer = Engineer(config, clock, seconds=None, quiet=arguments.quiet, out=sys.stdout)
        saved = asyncio.run(record(config, servos, engineer, arguments.name,
                                   select_joints(servos, arguments.joints, arguments.group)))
    except (ConfigError, BehaviourError, BringUpError, HalError) as error:
        return _fail(error)
    if saved is None:
        print("cancelled: nothing saved")
        return 1
    print(f"behaviour {arguments.name!r} saved in {saved}")
    return 0


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
