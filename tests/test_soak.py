"""The fault-injection soak, short: every fault kind against the real game and drivers.

bench/soak.py runs the full 1000 games on demand; here seven games (one for each
kind as its first fault, SIGKILL included) must meet every target. The controls
show that the soak's checks catch what they claim to: a goal outside a joint's
range or too fast, and a trial lost or duplicated on disk.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parent.parent / "bench"
sys.path.insert(0, str(BENCH))

import soak  # noqa: E402
from soak_faults import KINDS  # noqa: E402
from soak_rig import MotionMonitor, Violation  # noqa: E402

from kasparctl.game.session import RECORDS_FILE  # noqa: E402
from kasparctl.sim.demo import demo_config  # noqa: E402


@pytest.fixture(scope="module")
def short_soak(tmp_path_factory: pytest.TempPathFactory) -> dict:
    root = tmp_path_factory.mktemp("soak")
    return soak.soak(games=len(KINDS), workers=2, seed=3, faults=3, root=root)


def test_a_short_soak_meets_every_target_with_every_fault_kind(short_soak: dict) -> None:
    report = short_soak
    assert report["games"] == len(KINDS)
    assert all(report["targets"].values()), (report["targets"], report["problems"],
                                             report["unrecorded_examples"],
                                             report["violation_examples"],
                                             report["worker_crashes"])
    for kind in KINDS:
        assert report["injected"][kind] >= 1, kind
    assert report["worker_restarts_after_sigkill"] >= 1
    assert report["goals_checked"] > 1000  # the monitor saw the arm move
    assert report["trials"] > 0 and report["finished"] >= 1
    # Behaviours on: every uncertainty mode played, the body's thinking and points among them.
    assert set(report["uncertainty_modes"]) == {"spoken", "body", "both", "none"}


def test_the_motion_monitor_flags_a_goal_outside_the_range_and_a_jump() -> None:
    settings = demo_config().servos
    found: list[Violation] = []
    monitor = MotionMonitor(settings, found.append)
    joint = next(j for j in settings.joints if j.name == "head_yaw")

    def raw(degrees: float) -> int:
        return joint.servo.to_raw(degrees, joint.direction, joint.offset_deg)

    monitor.torque(joint.id, True, raw(0.0))
    step = joint.max_speed_dps / settings.control_hz
    monitor.goal(joint.id, raw(step * 0.9))  # within the limit
    assert found == []
    monitor.goal(joint.id, raw(step * 0.9 + step * 3))  # three steps' worth at once
    monitor.torque(joint.id, True, raw(50.0))
    monitor.goal(joint.id, raw(70.0))  # beyond the 60 degree range, and 20 degrees at once
    assert [v.kind for v in found] == ["speed", "range", "speed"]
    assert monitor.violations == 3


def _game_with_trials(short_soak: dict, tmp_path: Path) -> Path:
    root = Path(short_soak["state_root"])
    for game in sorted(root.glob("game-*")):
        checked = soak.check_game(game)
        if checked["trials"] >= 3 and not checked["problems"]:
            copy = tmp_path / game.name
            shutil.copytree(game, copy, symlinks=True)
            return copy
    raise AssertionError("no game with trials in the short soak")


def _rewrite_records(game: Path, change) -> None:
    (session,) = (game / "state" / "sessions").iterdir()
    path = session / RECORDS_FILE
    records = [json.loads(line) for line in path.read_text().splitlines()]
    records = change(records)
    for seq, record in enumerate(records, 1):
        record["seq"] = seq
    path.write_text("".join(json.dumps(r) + "\n" for r in records))


def test_the_soak_finds_a_lost_trial(short_soak: dict, tmp_path: Path) -> None:
    game = _game_with_trials(short_soak, tmp_path)

    def drop_second_trial(records: list[dict]) -> list[dict]:
        second = next(r for r in records if r["kind"] == "trial" and r["trial"] == 2)
        return [r for r in records if r is not second]

    _rewrite_records(game, drop_second_trial)
    assert soak.check_game(game)["trials_lost"] == 1


def test_the_soak_finds_a_duplicated_trial(short_soak: dict, tmp_path: Path) -> None:
    game = _game_with_trials(short_soak, tmp_path)

    def repeat_first_trial(records: list[dict]) -> list[dict]:
        first = next(i for i, r in enumerate(records) if r["kind"] == "trial")
        return [*records[: first + 1], dict(records[first]), *records[first + 1 :]]

    _rewrite_records(game, repeat_first_trial)
    checked = soak.check_game(game)
    assert checked["trials_duplicated"] == 1 and checked["trials_lost"] == 0


def test_the_soak_reports_a_fault_that_left_no_record(short_soak: dict, tmp_path: Path) -> None:
    game = _game_with_trials(short_soak, tmp_path)
    with (game / "ledger.jsonl").open("a") as ledger:
        ledger.write(json.dumps({"event": "fault", "kind": "tts_hang", "info": {},
                                 "recorded_after": None, "recovered_after": None}) + "\n")
    report = soak.analyse(game.parent)
    assert report["injected"]["tts_hang"] == report["recorded"]["tts_hang"] + 1
    report["crashes"] = 0
    assert soak.verdict(report)["every injected fault recorded"] is False
