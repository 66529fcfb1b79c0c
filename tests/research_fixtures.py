"""Recorded sessions for the research-data tests, made by the demo in simulated time.

Six sessions, one group each, covering what a morning in a school can leave:
both game variants, four conditions, first names in one plan, wrong feedback,
an undone answer, a session interrupted and resumed, one stopped by the
researcher, and one interrupted for good with a damaged and a torn line.
"""

from __future__ import annotations

import asyncio
import io
import json
import shutil
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
from rig_events import answer_the_check, on_event
from still_body import still_body

from hal.servos.api import FaultKind
from kasparctl.config import Config, SessionPlan
from kasparctl.game.session import RECORDS_FILE, STATE_FILE
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, DemoRig, build, demo_config, with_variant
from kasparctl.sim.teacher import Teacher

Scenario = Callable[[DemoRig], Coroutine[Any, Any, None]]

CHILDREN = ("Amira", "Ben", "Chloe")


@dataclass(frozen=True)
class Planned:
    group: str
    variant: str
    profile: str
    speak_uncertainty: bool
    seed: int
    status: str
    resumed: int = 0
    children: tuple[str, ...] = ()
    teacher: Teacher = field(default_factory=Teacher)


PLANNED = (
    Planned("G1", "names", "paper", True, 1, "finished", children=CHILDREN),
    Planned("G2", "names", "fast", False, 2, "finished", teacher=Teacher(p_wrong_green=0.2)),
    Planned("G3", "pilot", "slow", True, 3, "finished"),  # with an undone answer
    Planned("G4", "pilot", "paper", True, 4, "finished", 1, teacher=Teacher(p_no_answer=0.3)),
    Planned("G5", "names", "paper", True, 5, "stopped"),  # after a servo fault
    Planned("G6", "pilot", "paper", False, 6, "interrupted"),  # damaged and torn lines
)


@dataclass(frozen=True)
class Study:
    state_dir: Path
    # Session id -> what was planned for it.
    planned: dict[str, Planned]


def config_for(planned: Planned) -> Config:
    config = demo_config()
    plan = SessionPlan(
        group=planned.group,
        profile=planned.profile,
        speak_uncertainty=planned.speak_uncertainty,
        children=planned.children,
    )
    return msgspec.structs.replace(with_variant(config, planned.variant), sessions=(plan,))


def play(state_dir: Path, planned: Planned, scenario: Scenario | None = None) -> None:
    options = DemoOptions(
        state_dir=state_dir, seed=planned.seed, teacher=planned.teacher, out=io.StringIO()
    )

    async def main() -> None:
        rig = build(config_for(planned), options)
        side = asyncio.create_task(scenario(rig)) if scenario else None
        await asyncio.wait_for(rig.run(), timeout=20_000)
        if side is not None:
            side.cancel()
            await asyncio.gather(side, return_exceptions=True)

    simtime.run(main(), virtual=True)


def cut_after_trial(session_dir: Path, trial: int) -> None:
    """What a power cut right after a trial leaves: its records, no later ones, no snapshot."""
    lines = (session_dir / RECORDS_FILE).read_text().splitlines(keepends=True)
    kept = []
    for line in lines:
        kept.append(line)
        record = json.loads(line)
        if record["kind"] == "trial" and record["trial"] == trial:
            break
    (session_dir / RECORDS_FILE).write_text("".join(kept))
    (session_dir / STATE_FILE).unlink()


async def undo_second_answer(rig: DemoRig) -> None:
    await on_event(rig, "question", lambda info: info["trial"] == 2)
    await rig.command("undo")


async def fault_then_stop(rig: DemoRig) -> None:
    """A servo that stops answering at trial 4's question; the researcher ends the session."""
    await on_event(rig, "answered", lambda info: info["trial"] == 3)
    assert rig.children is not None
    # Nobody answers trial 4: an answer's happy pose would meet the dead servo mid-move.
    rig.game.listeners.remove(rig.children)
    answer_the_check(rig)
    await on_event(rig, "question", lambda info: info["trial"] == 4)
    fault = on_event(rig, "fault", lambda _: True)
    rig.servos.inject_fault("head_yaw", FaultKind.SILENT)
    await fault
    await asyncio.sleep(5)
    await rig.command("stop")


_BUILT: dict[Path, Study] = {}


def make_study(root: Path) -> Study:
    """The study's sessions in `root`/state: played once per test run (beside `root`, in the
    run's temporary directory), copied for each module that asks, which may change its copy."""
    original = _BUILT.get(root.parent)
    if original is None:
        with still_body():  # as a test's games: the fixtures asking are module-scoped
            original = _BUILT[root.parent] = _play_study(root.parent / "study-played-once")
    state_dir = shutil.copytree(original.state_dir, root / "state")
    return Study(state_dir, dict(original.planned))


def _play_study(root: Path) -> Study:
    state_dir = root / "state"
    (state_dir / "sessions").mkdir(parents=True)
    planned_by_id = {}
    for planned in PLANNED:
        scratch = root / f"scratch-{planned.group}"
        scenario = {"G3": undo_second_answer, "G5": fault_then_stop}.get(planned.group)
        play(scratch, planned, scenario)
        (session_dir,) = (scratch / "sessions").iterdir()
        if planned.group == "G4":
            cut_after_trial(session_dir, 4)
            play(scratch, planned)  # the robot restarts and resumes it
        elif planned.group == "G6":
            cut_after_trial(session_dir, 3)
            records = session_dir / RECORDS_FILE
            lines = records.read_text().splitlines(keepends=True)
            lines.insert(2, "\x00\x00 a damaged line\n")
            records.write_text("".join(lines) + '{"seq": 999, "kind": "tri')
        shutil.move(session_dir, state_dir / "sessions" / session_dir.name)
        planned_by_id[session_dir.name] = planned
    return Study(state_dir, planned_by_id)


def raw_records(session_dir: Path) -> list[dict[str, Any]]:
    """Records read the plain way, independently of kasparctl.game.jsonl.read_records."""
    records = []
    for line in (session_dir / RECORDS_FILE).read_text(errors="replace").splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def counted_trials(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    undone = {r["trial"] for r in records if r["kind"] == "undo"}
    return [r for r in records if r["kind"] == "trial" and r["trial"] not in undone]


DOCS = Path(__file__).resolve().parent.parent / "docs" / "research-data.md"


@dataclass(frozen=True)
class Documented:
    name: str  # "p_<toy>" for a column per toy
    type: str
    empty_when: str


def documented_columns(heading: str) -> list[Documented]:
    """The column table under `heading` in docs/research-data.md, as written there."""
    text = DOCS.read_text()
    section = text[text.index(heading) :]
    columns = []
    in_table = False
    for line in section.splitlines():
        if line.startswith("| column |"):
            in_table = True
            continue
        if in_table and line.startswith("|---"):
            continue
        if in_table and not line.startswith("|"):
            break
        if in_table:
            name, kind, empty_when, _ = (cell.strip() for cell in line.strip("|").split(" | ", 3))
            columns.append(
                Documented(name.replace("\\<", "<").replace("\\>", ">"), kind, empty_when)
            )
    return columns
