"""Which session came first never trusts the wall clock; a session half made is never seen.

A robot without a real-time clock starts a session hours behind (fake-hwclock after a
power cut) or years ahead: the state directory's sequence number orders its sessions
for resume, reopen, `sessions`, the export, the ULIDs and `watch`. A session is built
under a hidden name and renamed in whole, and what a crash left of one is removed by
the next writer, never listed as damaged.
"""

from __future__ import annotations

import datetime as dt
import json
import os
from pathlib import Path

from kasparctl.cli import main
from kasparctl.game.opening import planned
from kasparctl.game.records import StepRecord
from kasparctl.game.resume import find_unfinished
from kasparctl.game.session import PLAN_FILE, RECORDS_FILE, Session, session_dirs
from kasparctl.game.state import GameState
from kasparctl.research.catalogue import find_sessions, open_sessions
from kasparctl.service.daemon import Daemon, DaemonOptions
from kasparctl.service.sdnotify import Notifier
from kasparctl.sim.demo import demo_config
from kasparctl.view.follow import Follower
from kasparctl.view.inotify import Inotify

NOON = dt.datetime(2026, 3, 2, 12, 0, tzinfo=dt.UTC)
BEHIND = NOON - dt.timedelta(hours=2)
AHEAD = NOON + dt.timedelta(days=3 * 365)
DEMO_CONFIG = Path(__file__).resolve().parents[1] / "kasparctl" / "sim" / "demo.toml"


def ended(stopped: bool = False) -> GameState:
    config = demo_config()
    state = GameState.new(config.game, config.profile(config.sessions[0].profile), seed=1)
    state.step = "stopped" if stopped else "finished"
    return state


def two_sessions(state_dir: Path, first: dt.datetime, second: dt.datetime) -> list[Session]:
    """Session 1 finished under the `first` clock; session 2 under `second`, left open."""
    config = demo_config()
    plan = planned(config, config.sessions[0], seed=1)
    one = Session.create(state_dir, plan, now=first)
    one.save_state(ended(), finished=True)
    one.close()
    two = Session.create(state_dir, plan, now=second)
    two.record(StepRecord(to="placing"), 1.0)
    two.close()
    return [one, two]


def test_sessions_are_numbered_in_the_order_they_began_whatever_the_clock(
    tmp_path: Path,
) -> None:
    for name, (first, second) in {"behind": (NOON, BEHIND), "ahead": (AHEAD, NOON)}.items():
        state_dir = tmp_path / name
        one, two = two_sessions(state_dir, first, second)
        assert two.id < one.id  # by name (the wall clock) the later sorts first
        assert [one.plan["sequence"], two.plan["sequence"]] == [1, 2]
        # The ULIDs sort as they began, though the clock stepped back in between.
        assert one.plan["uid"] < two.plan["uid"]
        assert list(session_dirs(state_dir)) == [one.directory, two.directory]
        assert find_unfinished(state_dir) == two.directory
        catalogue = open_sessions(find_sessions([state_dir], []))
        assert [s.name for s in catalogue.sessions] == [one.id, two.id]


def test_the_stopped_session_offered_for_reopening_is_the_last_begun(tmp_path: Path) -> None:
    # Session 2 stopped under a clock 2 h behind: its name sorts before session 1's.
    _one, two = two_sessions(tmp_path, NOON, BEHIND)
    stopped = Session.open(two.directory)[0]
    stopped.record(StepRecord(to="stopped"), 2.0)
    stopped.save_state(ended(stopped=True), finished=True)
    stopped.close()
    daemon = Daemon(
        DaemonOptions(str(DEMO_CONFIG), sim=True, state_dir=str(tmp_path)), Notifier("")
    )
    offered = daemon._stopped_waiting()
    assert offered is not None and offered.session.directory == two.directory
    offered.session.close()


def test_watch_follows_the_session_begun_last_not_the_newest_file(tmp_path: Path) -> None:
    one, two = two_sessions(tmp_path, AHEAD, NOON)
    # The kernel's clock was as wrong as the daemon's: session 1's files look newest.
    future = AHEAD.timestamp()
    for path in (one.directory / RECORDS_FILE, one.directory / PLAN_FILE):
        os.utime(path, (future, future))
    with Inotify() as inotify:
        assert Follower(tmp_path, inotify).current == two.directory


def test_what_a_crash_left_of_a_session_being_made_is_no_session_and_is_removed(
    tmp_path: Path,
) -> None:
    one = Session.create(tmp_path, {"group": "A1"}, now=NOON)
    one.close()
    sessions = tmp_path / "sessions"
    # A crash while building (the new way), and an empty folder or one holding only the
    # plan's temporary file (what the code before building aside left).
    building = sessions / ".20260302T130000-A2.new"
    building.mkdir()
    (building / PLAN_FILE).write_text('{"session": "20260302T130000-A2"}')
    (sessions / "20260302T140000-A3").mkdir()
    (sessions / "20260302T150000-A4").mkdir()
    (sessions / "20260302T150000-A4" / f".{PLAN_FILE}.tmp").write_text("{")
    listed = _sessions_json(tmp_path)
    assert [(row["session_name"], row["status"]) for row in listed] == [(one.id, "interrupted")]
    assert [p.name for p in session_dirs(tmp_path)] == [one.id]
    # The next writer removes them; the new session is numbered on.
    two = Session.create(tmp_path, {"group": "A5"}, now=NOON)
    assert sorted(p.name for p in sessions.iterdir()) == sorted([one.id, two.id])
    assert two.plan["sequence"] == 2


def test_a_session_is_in_sessions_whole_or_not_at_all(tmp_path: Path) -> None:
    session = Session.create(tmp_path, {"group": "A1"}, now=NOON)
    # Made under its hidden name: plan and records both there when it appears.
    assert sorted(p.name for p in session.directory.iterdir()) == [PLAN_FILE, RECORDS_FILE]
    assert not [p for p in (tmp_path / "sessions").iterdir() if p.name.startswith(".")]


def _sessions_json(state_dir: Path) -> list[dict[str, object]]:
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["sessions", "--json", "--state-dir", str(state_dir)]) == 0
    rows: list[dict[str, object]] = json.loads(out.getvalue())
    return rows
