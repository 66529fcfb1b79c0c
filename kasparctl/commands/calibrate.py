"""`kasparctl servos calibrate`: ranges, rest positions and directions shown by hand.

Torque goes off for the chosen joints only (the rest hold); the engineer moves
each through its whole safe travel (told on the terminal, and aloud with a real
voice), then presses green or Enter. The proposal is printed as a diff of the
configuration and written only with --write, every comment kept.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from hal.clock import MonotonicClock
from hal.errors import HalError
from hal.servos.joints import Joints
from hal.servos.sim import SimServos
from kasparctl.commands.arguments import number
from kasparctl.commands.bringup import (
    BringUpError,
    Ending,
    Engineer,
    hold_others,
    open_servos,
    select_joints,
    start_servos,
    write_atomically,
)
from kasparctl.commands.calibration import Proposal, Sweep, diff, edit_config, propose
from kasparctl.commands.toml_patch import TomlPatchError
from kasparctl.config import Config, ConfigError, load_config, parse_config
from kasparctl.log import configure_logging

SAMPLE_EVERY_S = 0.05
PROGRESS_EVERY_S = 2.0
DEFAULT_MARGIN_DEG = 2.0
SIM_SWEEP_SECONDS = 6.0  # the simulated hand's sweep when the engineer ends it


def register(commands: Any) -> None:
    """Add `servos calibrate` to the `servos` actions."""
    parser = commands.add_parser(
        "calibrate",
        help="move joints by hand; propose their ranges, rest positions and directions",
    )
    parser.add_argument("--config", required=True, help="kaspar.toml (edited with --write)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--joints", type=_names, help="joints to calibrate, e.g. left_elbow,smile")
    which.add_argument("--group", help="a group to calibrate, e.g. left_arm (default: all joints)")
    parser.add_argument(
        "--margin", type=number(0, 45, unit="deg"), default=DEFAULT_MARGIN_DEG,
        help=f"degrees kept inside each end seen (default {DEFAULT_MARGIN_DEG})",
    )
    parser.add_argument(
        "--seconds", type=number(0, 3600, low_open=True, unit="s"), default=None,
        help="end after N seconds instead of waiting for a press or Enter (scripts)",
    )
    parser.add_argument("--write", action="store_true", help="write the proposal to --config")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--quiet", action="store_true", help="print the prompts, do not speak")
    parser.add_argument(
        "--sim-sweep", type=number(0, 180, unit="deg"), default=None, metavar="DEG",
        help="simulated servos only: a hand sweeps each joint DEG beyond its configured range",
    )
    parser.set_defaults(run=run)


def _names(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected joint names like a,b, found {text!r}")
    return names


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


def run(arguments: argparse.Namespace) -> int:
    """Calibrate; exit 0 when done (and written if asked), 1 on any error or warning."""
    configure_logging("warning", "console", stream=sys.stderr)
    out = sys.stderr if arguments.json else sys.stdout
    try:
        result = asyncio.run(calibrate(arguments, out))
    except (ConfigError, BringUpError, HalError, TomlPatchError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if arguments.json:
        print(json.dumps(result.as_json()))
    else:
        _print_result(result, arguments, out)
    if result.ending is Ending.CANCELLED:
        return 1
    return 1 if result.warnings else 0


async def calibrate(arguments: argparse.Namespace, out: TextIO) -> Result:
    """The whole calibration: limp, demonstrate, propose, diff, and write if asked."""
    path = Path(arguments.config)
    text = path.read_text(encoding="utf-8")
    config = load_config(path, poses=False)
    clock = MonotonicClock()
    servos = open_servos(config, clock)
    chosen = select_joints(servos, arguments.joints, arguments.group)
    settings = {j.name: j for j in config.servos.joints}
    blind = [name for name in chosen if settings[name].servo.off_reading is not None]
    if blind:
        raise BringUpError(
            f"{', '.join(blind)}: a {settings[blind[0]].model} has no position feedback, so it "
            "cannot be calibrated by hand; leave it out (--joints or --group)"
        )
    if arguments.sim_sweep is not None and not isinstance(servos, SimServos):
        raise BringUpError("--sim-sweep moves simulated servos: servos.backend is 'real'")
    engineer = Engineer(config, clock, seconds=arguments.seconds, quiet=arguments.quiet, out=out)
    await start_servos(servos)
    try:
        await engineer.start()
        ending, sweeps = await _demonstrate(servos, chosen, engineer, arguments)
    finally:
        await engineer.close()
        await servos.close()
    proposals = [propose(sweeps[name], settings[name], arguments.margin) for name in chosen]
    if ending is Ending.CANCELLED:
        return Result(ending, proposals, "", False, [])
    edited = edit_config(text, proposals)
    warnings = _check_edited(edited, str(path), config)
    written = False
    if arguments.write and edited != text:
        write_atomically(path, edited)
        written = True
    return Result(ending, proposals, diff(text, edited, str(path)), written, warnings)


async def _demonstrate(
    servos: Joints, chosen: list[str], engineer: Engineer, arguments: argparse.Namespace
) -> tuple[Ending, dict[str, Sweep]]:
    left_limp = await hold_others(servos, chosen)
    for name in chosen:
        await servos.set_compliant(name, True)
    start = await servos.read_positions()
    sweeps = {name: Sweep(name, start[name]) for name in chosen if name in start}
    if isinstance(servos, SimServos) and arguments.sim_sweep is not None:
        _sweep_by_hand(servos, chosen, arguments.sim_sweep, arguments.seconds)
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


def _print_result(result: Result, arguments: argparse.Namespace, out: TextIO) -> None:
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
        print(f"\n{arguments.config}: {where}", file=out)
    for warning in result.warnings:
        print(f"warning: {warning}", file=out)
    print("The calibrated joints are left limp.", file=out)


def _show(value: Any) -> str:
    if isinstance(value, tuple):
        return "[" + ", ".join(_show(v) for v in value) + "]"
    if isinstance(value, float) and math.isfinite(value):
        return f"{value:.1f}"
    return str(value)
