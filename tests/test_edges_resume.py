"""An unfinished session that cannot be resumed never stops the daemon: it is abandoned.

The daemon itself (tests/fault_rig.py: its session loop, event log, STATUS=, lock, on
simulated hardware in simulated time) plays a pilot session of two guesses and is
stopped as systemd stops it, leaving the session unfinished; the test then damages it
as a person or a disk would (a profile removed from kaspar.toml, a byte that is not
UTF-8, a value of the wrong type, an empty plan.json, records.jsonl emptied or cut, the
game's toys changed) and starts the daemon again. Each time: READY, idle (no fault),
the session closed as "abandoned" with the reason (its last record, its snapshot's
marker, the event log), STATUS= naming it, Kaspar saying so, and long green starting
a new session of the same group, which plays. On the code before this work the daemon
met each of these in its fault stage, or (a profile gone) played on from a session it
never resumed, leaving the old one unfinished for ever.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from edge_fixtures import root  # noqa: F401  (a fixture, used by name)
from fault_rig import FaultRig, phrase_said, run_daemon

from kasparctl.game.events import GameEvent
from kasparctl.game.session import EVENTS_FILE, PLAN_FILE, RECORDS_FILE, STATE_FILE


def quick_profile(text: str) -> str:
    """The session planned with a profile of the configuration's own, "quick"."""
    text = text.replace('profile = "paper"', 'profile = "quick"')
    return text + "\n[learner.profiles.quick]\nalpha = 0.9\nbeta = 4.0\n"


def interrupted(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, edit: Callable[[str], str] | None = None
) -> Path:
    """A pilot session with two answered guesses, left unfinished by a stop; its directory."""

    async def scenario(rig: FaultRig) -> None:
        await rig.press("long green")
        await rig.event(GameEvent.ANSWERED, lambda info: info["trial"] >= 2)

    run_daemon(tmp_path, monkeypatch, scenario, variant="pilot", edit=edit)
    (directory,) = (tmp_path / "state" / "sessions").iterdir()
    return directory


def lines(path: Path) -> list[dict[str, Any]]:
    """The JSON lines of a log; a line the test damaged on purpose is read as it can be."""
    text = path.read_bytes().decode("utf-8", errors="replace")
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def restarted_after_damage(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, edit: Callable[[str], str] | None = None
) -> FaultRig:
    """The daemon started on the damaged directory: it abandons, says so, and plays anew."""

    async def scenario(rig: FaultRig) -> None:
        await rig.until("STATUS= naming the abandoned session", lambda: "abandoned" in rig.status())
        await rig.until("Kaspar saying so", lambda: phrase_said(rig, "session", "abandoned"))
        assert rig.stage == "idle", rig.stage
        await rig.press("long green")
        await rig.event(GameEvent.ANSWERED)

    return run_daemon(tmp_path, monkeypatch, scenario, variant="pilot", edit=edit)


def assert_abandoned(rig: FaultRig, directory: Path, reason: str) -> None:
    """Closed with the reason in its records, its snapshot and the event log; a new session
    of the same group played; nothing else of the old one changed."""
    last = lines(directory / RECORDS_FILE)[-1]
    assert last["kind"] == "session" and last["event"] == "abandoned", last
    assert reason in last["reason"], last["reason"]
    snapshot = json.loads((directory / STATE_FILE).read_bytes())
    assert snapshot["finished"] is True and reason in snapshot["abandoned"]
    assert snapshot["seq"] == last["seq"]
    events = [r for r in lines(rig.state_dir / EVENTS_FILE) if r.get("event") == "abandoned"]
    assert len(events) == 1 and directory.name in events[0]["reason"]
    assert reason in events[0]["reason"]
    status = next(s for s in rig.notifier.statuses if "abandoned" in s)
    assert status.startswith("waiting: 'next' starts group ") and " | session " in status
    assert directory.name in status
    sessions = sorted((rig.state_dir / "sessions").iterdir())
    assert len(sessions) == 2 and sessions[0] == directory
    new = lines(sessions[1] / RECORDS_FILE)
    assert new[0]["event"] == "start" and new[0]["plan"]["group"] == "demo"
    assert any(r["kind"] == "trial" and r["trial"] == 1 for r in new)
    assert not any(e is GameEvent.FAULT for e, _ in rig.events)
    # Shown until the next session opened, then gone.
    assert "abandoned" not in rig.notifier.statuses[-1]


def test_a_session_whose_profile_was_removed_resumes_with_the_learner_it_began_with(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    directory = interrupted(tmp_path, monkeypatch, edit=quick_profile)
    plan = json.loads((directory / PLAN_FILE).read_bytes())
    assert plan["learner"] == {
        "profile": "quick", "alpha": 0.9, "beta": 4.0, "gamma": 0.0,
        "reward_green": 1.0, "reward_red": -1.0, "initial_q": 0.0,
    }  # fmt: skip

    async def scenario(rig: FaultRig) -> None:
        await rig.event(GameEvent.RESUMED, since=0)
        await rig.event(GameEvent.ANSWERED, lambda info: info["trial"] >= 3, since=0)

    rig = run_daemon(tmp_path, monkeypatch, scenario, variant="pilot")  # no "quick" any more
    records = lines(directory / RECORDS_FILE)
    assert any(r["kind"] == "session" and r["event"] == "resumed" for r in records)
    third = next(r for r in records if r["kind"] == "trial" and r["trial"] == 3)
    choice = third["choice_index"]
    before, after = third["q_before"][choice], third["q_after"][choice]
    assert after == pytest.approx(before + 0.9 * (third["reward"] - before))  # alpha of "quick"
    assert not (rig.state_dir / EVENTS_FILE).exists() or not any(
        r.get("event") == "abandoned" for r in lines(rig.state_dir / EVENTS_FILE)
    )


def drop_frozen_learner(directory: Path) -> None:
    """As plan.json was written before the learner was kept in it."""
    plan = json.loads((directory / PLAN_FILE).read_bytes())
    del plan["learner"]
    (directory / PLAN_FILE).write_text(json.dumps(plan))


def bad_utf8(directory: Path) -> None:
    path = directory / RECORDS_FILE
    data = path.read_bytes().splitlines(keepends=True)
    data[2] = data[2].replace(b'"kind"', b'"k\xffnd"', 1)
    path.write_bytes(b"".join(data))


def wrong_type(directory: Path) -> None:
    path = directory / RECORDS_FILE
    records = lines(path)
    trial = next(r for r in records if r["kind"] == "trial")
    trial["trial"] = "one"
    path.write_text("".join(json.dumps(r) + "\n" for r in records))


def empty_plan(directory: Path) -> None:
    (directory / PLAN_FILE).write_bytes(b"")


def emptied_records(directory: Path) -> None:
    (directory / RECORDS_FILE).write_bytes(b"")


def cut_records(directory: Path) -> None:
    path = directory / RECORDS_FILE
    path.write_bytes(b"".join(path.read_bytes().splitlines(keepends=True)[:3]))


# The damage, what the reason says, and whether the session was planned with "quick"
# (a profile the configuration of the second run no longer has).
DAMAGE: dict[str, tuple[Callable[[Path], None], str, bool]] = {
    "profile_gone_old_plan": (drop_frozen_learner, "learner profile 'quick' is no longer", True),
    "invalid_utf8_record": (bad_utf8, "line 3: skipped, not a JSON record", False),
    "wrong_typed_record": (
        wrong_type, "skipped, not a valid record (Expected `int`, got `str`", False
    ),
    "empty_plan": (empty_plan, "plan.json: not a session plan", False),
    "emptied_records": (emptied_records, "records were lost: the log ends at record 0", False),
    "cut_records": (cut_records, "records were lost: the log ends at record 3", False),
}


@pytest.mark.parametrize("damage", DAMAGE)
def test_a_damaged_unfinished_session_is_abandoned_and_the_next_one_starts(
    damage: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    change, reason, quick = DAMAGE[damage]
    directory = interrupted(tmp_path, monkeypatch, edit=quick_profile if quick else None)
    kept = {p.name: p.read_bytes() for p in directory.iterdir()}
    change(directory)
    damaged = {p.name: p.read_bytes() for p in directory.iterdir()}
    rig = restarted_after_damage(tmp_path, monkeypatch)  # the plain config: no "quick"
    assert_abandoned(rig, directory, reason)
    # Nothing of the damaged session was changed but the abandon's own line and marker.
    records = (directory / RECORDS_FILE).read_bytes()
    assert records.startswith(damaged[RECORDS_FILE])
    assert records.count(b"\n") == damaged[RECORDS_FILE].count(b"\n") + 1
    assert (directory / PLAN_FILE).read_bytes() == damaged[PLAN_FILE]
    assert kept.keys() <= {p.name for p in directory.iterdir()}


def five_toys(text: str) -> str:
    fewer = '"lion", "elephant", "giraffe", "monkey", "zebra"]'
    return text.replace('"lion", "elephant", "giraffe", "monkey", "zebra", "crocodile"]', fewer)


def test_a_session_recorded_before_settings_of_a_game_that_changed_is_abandoned(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    directory = interrupted(tmp_path, monkeypatch)
    plan = json.loads((directory / PLAN_FILE).read_bytes())
    del plan["settings"]  # as plan.json was before it kept the session's settings
    (directory / PLAN_FILE).write_text(json.dumps(plan), encoding="utf-8")
    rig = restarted_after_damage(tmp_path, monkeypatch, edit=five_toys)
    assert_abandoned(rig, directory, "the game has changed since the session began")


def test_a_session_of_a_game_that_changed_since_resumes_with_its_own_settings(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """plan.json keeps the session's settings: it plays on with its six toys."""
    directory = interrupted(tmp_path, monkeypatch)

    async def scenario(rig: FaultRig) -> None:
        await rig.event(GameEvent.RESUMED, since=0)
        await rig.event(GameEvent.ANSWERED, lambda info: info["trial"] >= 3, since=0)

    run_daemon(tmp_path, monkeypatch, scenario, variant="pilot", edit=five_toys)
    trials = [r for r in lines(directory / RECORDS_FILE) if r["kind"] == "trial"]
    assert [r["trial"] for r in trials][:3] == [1, 2, 3]
    assert {len(r["probabilities"]) for r in trials} == {6}
    assert not any(r.get("event") == "abandoned" for r in lines(directory / RECORDS_FILE))


def test_a_snapshot_that_is_not_json_is_rebuilt_from_the_records(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The records are the truth and the snapshot a cache: nothing to abandon."""
    directory = interrupted(tmp_path, monkeypatch)
    (directory / STATE_FILE).write_bytes(b"\x00\x00not json")

    async def scenario(rig: FaultRig) -> None:
        await rig.event(GameEvent.RESUMED, since=0)
        await rig.event(GameEvent.ANSWERED, lambda info: info["trial"] >= 3, since=0)

    run_daemon(tmp_path, monkeypatch, scenario, variant="pilot")
    trials = [r["trial"] for r in lines(directory / RECORDS_FILE) if r["kind"] == "trial"]
    assert trials[:3] == [1, 2, 3]


@pytest.fixture
def read_only(tmp_path: Path) -> Iterator[Callable[[Path], None]]:
    """Makes a directory read-only with a real read-only bind mount (as root); undone after."""
    mounted: list[Path] = []

    def make(directory: Path) -> None:
        subprocess.run(["mount", "--bind", str(directory), str(directory)], check=True)
        mounted.append(directory)
        subprocess.run(["mount", "-o", "remount,ro,bind", str(directory)], check=True)

    try:
        yield make
    finally:
        for directory in reversed(mounted):
            subprocess.run(["umount", "--lazy", str(directory)], check=False)


def undo_read_only(directory: Path) -> None:
    # Writable again under the same mount: descriptors the daemon holds work again too.
    subprocess.run(["mount", "-o", "remount,rw,bind", str(directory)], check=True)


@pytest.mark.usefixtures("root")
def test_a_read_only_state_directory_is_a_storage_fault_and_the_session_resumes_once_writable(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, read_only: Callable[[Path], None]
) -> None:
    directory = interrupted(tmp_path, monkeypatch)
    state_dir = tmp_path / "state"
    # A torn last line: the resume must move it aside, which a read-only disk refuses.
    with (directory / RECORDS_FILE).open("ab") as log:
        log.write(b'{"kind": "press", "seq"')
    read_only(state_dir)

    async def scenario(rig: FaultRig) -> None:
        await rig.until("the fault stage", lambda: rig.stage == "fault")
        await rig.until("STATUS= saying so", lambda: "CANNOT SAVE" in rig.status())
        assert "Read-only file system" in rig.status()
        await rig.until("Kaspar saying so", lambda: phrase_said(rig, "fault", "storage"))
        await rig.press("long green")  # refused: no session starts unsaved
        await rig.press("long red")
        await rig.until("still in its fault stage", lambda: rig.stage == "fault")
        assert len(list((state_dir / "sessions").iterdir())) == 1
        undo_read_only(state_dir)
        await rig.press("long red")
        await rig.event(GameEvent.RESUMED, since=0)
        await rig.event(GameEvent.ANSWERED, lambda info: info["trial"] >= 3, since=0)

    run_daemon(tmp_path, monkeypatch, scenario, variant="pilot")
    records = lines(directory / RECORDS_FILE)
    assert [r["trial"] for r in records if r["kind"] == "trial"][:3] == [1, 2, 3]
    assert (directory / (RECORDS_FILE + ".torn")).exists()
    events = lines(state_dir / EVENTS_FILE)
    assert any(r["kind"] == "fault" and r["fault"] == "storage" for r in events)
