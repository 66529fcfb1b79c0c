"""A small study for the research toolkit's tests: children with codes, two conditions.

Four groups of three children, each group playing the pilot twice (uncertainty
spoken, then silent: a within-group design), twelve children with participant
codes and a participants.csv (diagnostic group, age, sex). The children err
(false greens and reds) and are sometimes silent until prompted, so every
teaching measure and both causes of Kaspar's errors occur.
"""

from __future__ import annotations

import io
import shutil
from dataclasses import dataclass
from pathlib import Path

import msgspec
from still_body import still_body

from kasparctl.config import SessionPlan
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, build, demo_config, with_variant
from kasparctl.sim.teacher import Teacher

GROUPS = {
    "G1": ("P01", "P02", "P03"),
    "G2": ("P04", "P05", "P06"),
    "G3": ("P07", "P08", "P09"),
    "G4": ("P10", "P11", "P12"),
}
DIAGNOSIS = {"G1": "ASC", "G2": "ASC", "G3": "TD", "G4": "TD"}
NAMES = ("Amira", "Ben", "Chloe")
TEACHER = Teacher(p_wrong_green=0.3, p_wrong_red=0.1, p_no_answer=0.25)


@dataclass(frozen=True)
class Cohort:
    state_dir: Path
    participants: Path


def participants_csv() -> str:
    lines = ["code,group,age,sex"]
    for index, (group, codes) in enumerate(GROUPS.items()):
        for offset, code in enumerate(codes):
            lines.append(f"{code},{DIAGNOSIS[group]},{7 + (index + offset) % 2},{'FM'[offset % 2]}")
    return "\n".join(lines) + "\n"


_BUILT: dict[Path, Cohort] = {}


def make_cohort(root: Path) -> Cohort:
    """The cohort's sessions in `root`: played once per test run (beside `root`, in the
    run's temporary directory), copied for each module that asks, which may change its copy."""
    original = _BUILT.get(root.parent)
    if original is None:
        with still_body():  # as a test's games: the fixtures asking are module-scoped
            original = _BUILT[root.parent] = _play_cohort(root.parent / "cohort-played-once")
    state_dir = shutil.copytree(original.state_dir, root / "state")
    participants = shutil.copy(original.participants, root / "participants.csv")
    return Cohort(state_dir, Path(participants))


def _play_cohort(root: Path) -> Cohort:
    state_dir = root / "state"
    (state_dir / "sessions").mkdir(parents=True)
    seed = 100
    for group, codes in GROUPS.items():
        for spoken in (True, False):
            seed += 1
            plan = SessionPlan(
                group=group,
                speak_uncertainty=spoken,
                participants=codes,
                children=NAMES if group == "G1" else (),
            )
            config = msgspec.structs.replace(
                with_variant(demo_config(), "pilot"), sessions=(plan,)
            )
            scratch = root / f"scratch-{seed}"
            options = DemoOptions(state_dir=scratch, seed=seed, teacher=TEACHER, out=io.StringIO())
            simtime.run(build(config, options).run(), virtual=True)
            (session,) = (scratch / "sessions").iterdir()
            # Two games of a group can start in the same second: the directory gets the seed.
            shutil.move(session, state_dir / "sessions" / f"{session.name}-{seed}")
            shutil.rmtree(scratch)
    participants = root / "participants.csv"
    participants.write_text(participants_csv())
    return Cohort(state_dir, participants)
