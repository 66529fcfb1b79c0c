"""A calibration by hand: limp, demonstrate, propose, show the diff, and write if asked.

The chosen joints go limp (the rest hold); the engineer moves each through its
whole safe travel (told on the terminal, and aloud with a real voice), then
presses green or Enter. The positions seen become a proposal per joint
(kasparctl.bringup.calibration), shown as a diff of the configuration and
written only when asked, every comment kept.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from hal.clock import MonotonicClock
from hal.servos.joints import Joints
from hal.servos.sim import SimServos
from kasparctl.bringup.calibration import Proposal, Sweep, diff, edit_config, propose
from kasparctl.bringup.engineer import (
    BringUpError,
    Ending,
    Engineer,
    hold_others,
    open_servos,
    select_joints,
    start_servos,
    write_atomically,
)
from kasparctl.config import Config, ConfigError, load_config, parse_config

SAMPLE_EVERY_S = 0.05
PROGRESS_EVERY_S = 2.0
DEFAULT_MARGIN_DEG = 2.0
SIM_SWEEP_SECONDS = 6.0  # the simulated hand's sweep when the engineer ends it


@dataclass
class Result:
    """What a calibration found and did: proposals, the diff, whether it was written."""

    ending: Ending
    proposals: list[Proposal]
    diff: str
    written: bool
    warnings: list[str]

    def as_json(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "ending": self.ending.value,
            "joints": [p.as_json() for p in self.proposals],
            "diff": self.diff,
            "written": self.written,
            "warnings": self.warnings,
        }


async def calibrate(
    config_path: str,
    joints: Sequence[str] | None,
    group: str | None,
    *,
    margin: float,
    seconds: float | None,
    quiet: bool,
    sim_sweep: float | None,
    write: bool,
    out: TextIO,
) -> Result:
    """The whole calibration: limp, demonstrate, propose, diff, and write if asked.

    `sim_sweep`: on simulated servos, a hand sweeps each joint that many degrees
    beyond its configured range (scripts, tests).
    """
    path = Path(config_path)
    text = path.read_text(encoding="utf-8")
    config = load_config(path, poses=False)
    clock = MonotonicClock()
    servos = open_servos(config, clock)
    chosen = select_joints(servos, joints, group)
    settings = {j.name: j for j in config.servos.joints}
    blind = [name for name in chosen if settings[name].servo.off_reading is not None]
    if blind:
        raise BringUpError(
            f"{', '.join(blind)}: a {settings[blind[0]].model} has no position feedback, so it "
            "cannot be calibrated by hand; leave it out (--joints or --group)"
        )
    if sim_sweep is not None and not isinstance(servos, SimServos):
        raise BringUpError("--sim-sweep moves simulated servos: servos.backend is 'real'")
    engineer = Engineer(config, clock, seconds=seconds, quiet=quiet, out=out)
    await start_servos(servos)
    try:
        await engineer.start()
        ending, sweeps = await _demonstrate(servos, chosen, engineer, sim_sweep)
    finally:
        await engineer.close()
        await servos.close()
    proposals = [propose(sweeps[name], settings[name], margin) for name in chosen]
    if ending is Ending.CANCELLED:
        return Result(ending, proposals, "", False, [])
    edited = edit_config(text, proposals)
    warnings = _check_edited(edited, str(path), config)
    written = False
    if write and edited != text:
        write_atomically(path, edited)
        written = True
    return Result(ending, proposals, diff(text, edited, str(path)), written, warnings)


async def _demonstrate(
    servos: Joints, chosen: list[str], engineer: Engineer, sim_sweep: float | None
) -> tuple[Ending, dict[str, Sweep]]:
    left_limp = await hold_others(servos, chosen)
    for name in chosen:
        await servos.set_compliant(name, True)
    start = await servos.read_positions()
    sweeps = {name: Sweep(name, start[name]) for name in chosen if name in start}
    if isinstance(servos, SimServos) and sim_sweep is not None:
        _sweep_by_hand(servos, chosen, sim_sweep, engineer.seconds)
    if left_limp:
        engineer.say(f"Also limp, outside their safe range: {', '.join(left_limp)}.")
    joined = ", ".join(name.replace("_", " ") for name in chosen)
    engineer.say(
        f"Calibrating {joined}. Torque is off. Start at rest, move each joint first the way "
        "its angle should grow, then through its whole safe travel, and leave it at rest. "
        "Then press the green button, or Enter."
    )
    last_progress = [engineer.clock.now()]

    async def sample() -> None:
        positions = await servos.read_positions()
        for name, sweep in sweeps.items():
            if name in positions:
                sweep.see(positions[name])
        now = engineer.clock.now()
        if engineer.seconds is None and now - last_progress[0] >= PROGRESS_EVERY_S:
            last_progress[0] = now
            seen = "  ".join(
                f"{s.joint} {s.low:.0f}..{s.high:.0f}" for s in sweeps.values() if s.samples
            )
            print(f"  seen: {seen}", file=engineer.out, flush=True)

    ending = await engineer.demonstrate(sample, SAMPLE_EVERY_S)
    engineer.say("Calibration cancelled." if ending is Ending.CANCELLED else "Thank you.")
    return ending, sweeps


def _sweep_by_hand(
    servos: SimServos, chosen: list[str], beyond: float, seconds: float | None
) -> None:
    """A simulated hand: rest, up past the high end, down past the low end, back to rest.

    It dwells at each end, as an engineer does, so that the samples catch it there.
    """
    begin = servos.clock.now()
    window = (seconds or SIM_SWEEP_SECONDS) * 0.9
    for name in chosen:
        joint = next(j for j in servos.settings.joints if j.name == name)
        low, high = joint.range_deg[0] - beyond, joint.range_deg[1] + beyond
        rest = joint.rest_deg
        marks = [(0.0, rest), (0.25, high), (0.35, high), (0.6, low), (0.7, low),
                 (1.0, rest)]

        def path(now: float, marks: list[tuple[float, float]] = marks) -> float:
            t = min(1.0, max(0.0, (now - begin) / window))
            for (t0, d0), (t1, d1) in itertools.pairwise(marks):
                if t <= t1:
                    return d0 + (d1 - d0) * (t - t0) / (t1 - t0)
            return marks[-1][1]

        servos.hand(name, path)


def _check_edited(edited: str, source: str, config: Config) -> list[str]:
    """The edited configuration must load; poses that now break a range are warnings."""
    base = Path(source).parent
    parse_config(edited, source, base_dir=base, poses=False)  # ConfigError: never written
    if config.poses_file is None or not Path(config.poses_file).exists():
        return []
    try:
        parse_config(edited, source, base_dir=base)
    except ConfigError as error:
        return [f"{error}: record the pose again (kasparctl pose record)"]
    return []


def print_result(result: Result, config_path: str, out: TextIO) -> None:
    """The proposal of each joint, the diff, whether it was written, and any warning."""
    if result.ending is Ending.CANCELLED:
        print("cancelled: nothing written", file=out)
        return
    for proposal in result.proposals:
        seen = "not seen" if proposal.seen is None else (
            f"seen {proposal.seen[0]:.1f} to {proposal.seen[1]:.1f} deg"
        )
        changes = ", ".join(f"{k} {_show(v)}" for k, v in proposal.proposed.items()) or "no change"
        print(f"{proposal.joint:<20} {seen:<28} {changes}", file=out)
        for note in proposal.notes:
            print(f"{'':<20} {note}", file=out)
    if result.diff:
        print(file=out)
        print(result.diff, end="", file=out)
        where = "written" if result.written else "not written (add --write)"
        print(f"\n{config_path}: {where}", file=out)
    for warning in result.warnings:
        print(f"warning: {warning}", file=out)
    print("The calibrated joints are left limp.", file=out)


def _show(value: Any) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    if isinstance(value, float) and math.isfinite(value):
        return f"{value:.1f}"
    return str(value)
