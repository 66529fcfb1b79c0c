"""Make tests/data/sessions-v1 with the code of commit 9c84157 (before the house-game refactor).

Run from the repository root: python /path/to/make_sessions_v1.py OUT
"""

from __future__ import annotations

import asyncio
import io
import shutil
import subprocess
import sys
from pathlib import Path

import msgspec

sys.path.insert(0, "tests")
from rig_events import on_event

from hal.servos.api import FaultKind
from kasparctl.config import SessionPlan
from kasparctl.game.session import STATE_FILE
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, build, demo_config
from kasparctl.sim.teacher import Teacher

OUT = Path(sys.argv[1])
STATE = OUT / "state"
KASPARCTL = [sys.executable, "-m", "kasparctl"]


def demo(*arguments: str) -> None:
    subprocess.run([*KASPARCTL, "demo", "--fast", *arguments], check=True, capture_output=True)


# A: a finished names session; B: a finished pilot session, from the demo command.
demo("--seed", "11", "--p-wrong-green", "0.1", "--state-dir", str(STATE))
demo("--seed", "12", "--variant", "pilot", "--p-no-answer", "0.3", "--state-dir", str(STATE))

# C: a names session interrupted mid-guessing, with first names in its plan, an undo,
# a lost keyfob, a servo fault, a pause and an extra press, then a crash (its task
# cancelled with no shutdown record) while Kaspar asks trial 9's question.
SNAPSHOTS = OUT / "snapshots"
SNAPSHOTS.mkdir(parents=True)
scratch = OUT / "scratch"
plan = SessionPlan(group="C13", children=("Amira", "Ben", "Chloe"))
config = msgspec.structs.replace(demo_config(), sessions=(plan,))


def keep_snapshot(rig, name: str) -> None:
    (session_dir,) = (scratch / "sessions").iterdir()
    shutil.copy(session_dir / STATE_FILE, SNAPSHOTS / f"{name}.json")


async def scenario(rig) -> None:
    await on_event(rig, "teach", lambda info: info["round"] == 1 and info["bag"] == 2)
    keep_snapshot(rig, "teaching-round-2")
    await on_event(rig, "question", lambda info: info["trial"] == 3)
    keep_snapshot(rig, "guessing-with-undo")
    await rig.keyfob.perform("double red")  # takes back trial 2's answer
    await on_event(rig, "question", lambda info: info["trial"] == 3)  # asked again
    keep_snapshot(rig, "after-undo")
    await on_event(rig, "question", lambda info: info["trial"] == 4)
    await rig.keyfob.perform("lost")
    await asyncio.sleep(20)
    await rig.keyfob.perform("back")
    await on_event(rig, "question", lambda info: info["trial"] == 5)
    rig.servos.inject_fault("right_elbow", FaultKind.OVERHEATING)
    await on_event(rig, "fault")
    await asyncio.sleep(1.0)
    rig.servos.inject_fault("right_elbow", None)
    await on_event(rig, "answered", lambda info: info["trial"] == 5)
    await on_event(rig, "point")
    await asyncio.sleep(1.5)  # pointing done, saying how sure it is
    paused = on_event(rig, "state", lambda info: info["state"] == "paused")
    await rig.keyfob.perform("long red")
    await paused
    keep_snapshot(rig, "paused")
    await asyncio.sleep(10)
    await rig.keyfob.perform("long red")
    await on_event(rig, "answered", lambda info: info["trial"] == 6)
    await rig.keyfob.perform("green")  # a second child, a moment too late: an extra press
    await on_event(rig, "question", lambda info: info["trial"] == 9)


async def interrupted() -> None:
    options = DemoOptions(state_dir=scratch, seed=13, teacher=Teacher(p_wrong_green=0.15),
                          out=io.StringIO())
    rig = build(config, options)
    playing = asyncio.create_task(rig.run())
    async with asyncio.timeout(20_000):
        await scenario(rig)
    playing.cancel()  # the crash: records and snapshot stay as they were
    await asyncio.gather(playing, return_exceptions=True)


simtime.run(interrupted(), virtual=True)
(session_c,) = (scratch / "sessions").iterdir()
rig_session = session_c
rig_session.joinpath(".records.jsonl.tmp").unlink(missing_ok=True)
shutil.move(str(session_c), STATE / "sessions" / session_c.name)
shutil.rmtree(scratch)
print("C:", session_c.name)

# What today's code makes of them: exports, the report's summary, the session list.
EXPECTED = OUT / "expected"
EXPECTED.mkdir()
subprocess.run([*KASPARCTL, "export", "--state-dir", str(STATE), "--csv",
                str(EXPECTED / "trials.csv"), "--events", str(EXPECTED / "events.csv")], check=True)
subprocess.run([*KASPARCTL, "export", "--state-dir", str(STATE), "--anonymise", "--csv",
                str(EXPECTED / "trials-anonymised.csv"), "--events",
                str(EXPECTED / "events-anonymised.csv")], check=True)
report = OUT / "report-scratch"
subprocess.run([*KASPARCTL, "report", "--state-dir", str(STATE), "--out", str(report)],
               check=True)
shutil.copy(report / "summary.json", EXPECTED / "summary.json")
shutil.copy(report / "summary.md", EXPECTED / "summary.md")
shutil.rmtree(report)
listing = subprocess.run([*KASPARCTL, "sessions", "--state-dir", str(STATE), "--json"],
                         check=True, capture_output=True, text=True).stdout
(EXPECTED / "sessions.json").write_text(listing)

# The interrupted session resumed to its end by today's code, from its snapshot and,
# with the snapshot removed, from its records alone: the two must agree.
for name, drop_snapshot in (("resumed", False), ("resumed-from-records", True)):
    copy = OUT / f"{name}-scratch"
    shutil.copytree(STATE / "sessions" / session_c.name, copy / "sessions" / session_c.name)
    if drop_snapshot:
        (copy / "sessions" / session_c.name / STATE_FILE).unlink()
    demo("--seed", "13", "--state-dir", str(copy))
    shutil.copy(copy / "sessions" / session_c.name / "records.jsonl",
                EXPECTED / f"{name}.records.jsonl")
    shutil.rmtree(copy)
