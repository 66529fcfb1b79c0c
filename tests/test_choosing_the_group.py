"""Choosing the group in idle: the researcher steps through the planned sessions, marks a
group absent without opening it, chooses it again, and starts it; Kaspar says nothing.

The daemon itself on the simulated rig (tests/fault_rig.py), in simulated time.
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import pytest
from fault_rig import FaultRig, run_daemon, write_config

from kasparctl.cli import main
from kasparctl.config import load_config
from kasparctl.game.events import GameEvent
from kasparctl.game.opening import PlanQueue
from kasparctl.view.follow import Follower
from kasparctl.view.frame import frame, plain_text
from kasparctl.view.inotify import Inotify

GROUPS = ("A1", "B2", "C3")


def three_groups(tmp_path: Path) -> Path:
    """The rig's pilot robot with three groups planned, in the order A1, B2, C3."""

    def edit(text: str) -> str:
        first, _, rest = text.partition('group = "demo"')
        key = rest.split("\n", 2)[1]  # the answer key of the rig's plan
        more = "".join(f'\n[[sessions]]\ngroup = "{g}"\n{key}\n' for g in GROUPS[1:])
        text = first + f'group = "{GROUPS[0]}"' + rest
        return text.replace("\n[servos]", more + "\n[servos]", 1)

    return write_config(tmp_path, "pilot", edit)


def shown(state_dir: Path) -> list[str]:
    """The live view's lines, as `kasparctl watch` draws them from the state directory."""
    with Inotify() as inotify:
        view = Follower(state_dir, inotify).observe()
    return [plain_text(line) for line in frame(view, dt.datetime.now(dt.UTC))]


def test_idle_choose_absent_choose_next(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    statuses: dict[str, str] = {}

    async def chosen(rig: FaultRig, name: str, command: str) -> None:
        mark = len(rig.events)
        await rig.command(command)
        await rig.event(GameEvent.CHOSEN, since=mark)
        statuses[name] = rig.status()

    async def scenario(rig: FaultRig) -> None:
        statuses["idle"] = rig.status()
        await chosen(rig, "choose B2", "choose")
        await chosen(rig, "B2 absent", "absent")
        await chosen(rig, "choose again", "choose")  # A1 is what next would start: on to B2
        await chosen(rig, "choose C3", "choose")
        await chosen(rig, "C3 absent", "absent")
        await chosen(rig, "choose B2 again", "choose")
        statuses["view"] = " / ".join(shown(rig.state_dir))
        statuses["said before next"] = " / ".join(rig.said())
        mark = len(rig.events)
        await rig.press("long green")  # next: starts the group chosen, B2
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 2, since=mark)
        await rig.press("both")  # stop
        await rig.stage_is("idle")
        await rig.press("both")  # stop in idle: B2's session closed for good
        await rig.until("STATUS= naming A1", lambda: "A1" in rig.status())
        statuses["after"] = rig.status()

    config = three_groups(tmp_path)
    rig = run_daemon(tmp_path, monkeypatch, scenario, "pilot", config=config)
    assert statuses["idle"].startswith("waiting: 'next' starts group A1, session 1")
    assert statuses["choose B2"].startswith("waiting: 'next' starts group B2, session 1")
    # Marked absent, B2 is not offered: "next" would start A1 again.
    assert statuses["B2 absent"].startswith("waiting: 'next' starts group A1, session 1")
    assert statuses["choose again"].startswith("waiting: chosen group B2, session 1, marked absent")
    assert statuses["C3 absent"].startswith("waiting: 'next' starts group A1, session 1")
    assert statuses["choose B2 again"].startswith("waiting: chosen group B2, session 1, marked")
    # Nothing was said to the children while the researcher chose (no chime configured).
    assert statuses["said before next"] == ""
    assert statuses["after"].startswith("waiting: 'next' starts group A1, session 1")
    # The live view names the group chosen; the absences are no session it follows.
    assert "CHOSEN group B2, session 1: 'next' starts it" in statuses["view"]
    assert "No session yet" in statuses["view"]

    by_plan = {}
    for directory in (rig.state_dir / "sessions").iterdir():
        plan = json.loads((directory / "plan.json").read_text())
        lines = (directory / "records.jsonl").read_text().splitlines()
        by_plan[plan["group"], plan.get("absent", False)] = [json.loads(line) for line in lines]
    assert set(by_plan) == {("B2", True), ("C3", True), ("B2", False)}
    assert [(r["kind"], r["event"]) for r in by_plan["B2", True]] == [
        ("session", "absent"),
        ("session", "present"),  # chosen again and started: the mark taken back
    ]
    assert [(r["kind"], r["event"]) for r in by_plan["C3", True]] == [("session", "absent")]
    started = next(r for r in by_plan["B2", False] if r["kind"] == "command")
    assert (started["command"], started["group"], started["number"]) == ("next", "B2", 1)
    # The researcher's choices are in the event log, each naming its group.
    events = [
        json.loads(line)
        for line in (rig.state_dir / "events.jsonl").read_text().splitlines()
    ]
    choices = [(e["command"], e["confirm"], e["group"]) for e in events if e["kind"] == "command"]
    assert choices == [
        ("choose", "choose", "B2"),
        ("absent", "absent", "B2"),
        ("choose", "choose", "B2"),
        ("choose", "choose", "C3"),
        ("absent", "absent", "C3"),
        ("choose", "choose", "B2"),
    ]
    # After a restart C3 is still absent, and not what "next" opens.
    queue = PlanQueue(rig.state_dir, lambda: load_config(str(config)))
    assert [(o.group, o.absent) for o in queue.offered()] == [("A1", False), ("C3", True)]
    assert queue.take(lambda: 0.0).group == "A1"


def test_sessions_lists_an_absent_group_as_absent(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = load_config(str(three_groups(tmp_path)))
    state_dir = tmp_path / "state"
    queue = PlanQueue(state_dir, lambda: config)
    queue.choose()
    queue.choose()  # C3
    assert queue.toggle_absent(1.0).absent
    assert main(["sessions", "--state-dir", str(state_dir), "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert (row["group"], row["status"], row["trials"]) == ("C3", "absent", 0)
    queue.choose()
    queue.choose()  # C3 again, marked
    assert not queue.toggle_absent(2.0).absent  # taken back
    assert main(["sessions", "--state-dir", str(state_dir), "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["status"] == "absent, taken back"
    assert [o.absent for o in queue.offered()] == [False, False, False]
