"""The clock's state recorded and said; ages on the monotonic clock; a resume says what it found.

The wall clock's source is timedatectl's NTPSynchronized where systemd-timesyncd runs,
else "unsynchronised" (the commands injected here); a jump is the wall clock moving
against the monotonic one by more than the threshold. `check`, STATUS=, the live view,
`sessions` and the export say when the clock was not synchronised. The view's ages are
measured on the session's monotonic clock within one run of the daemon.
"""

from __future__ import annotations

import contextlib
import csv
import datetime as dt
import io
import json
from collections.abc import Sequence
from pathlib import Path

from research_fixtures import cut_after_trial

from kasparctl.bringup.readiness import clock_row
from kasparctl.cli import main
from kasparctl.game.jsonl import encode_record
from kasparctl.game.records import (
    ClockRecord,
    FaultRecord,
    FaultSource,
    SessionEvent,
    SessionRecord,
    StepRecord,
)
from kasparctl.game.session import PLAN_FILE, RECORDS_FILE, session_dirs
from kasparctl.game.wallclock import (
    SYNCHRONISED,
    UNSYNCHRONISED,
    ClockSource,
    ClockWatch,
    clock_source,
)
from kasparctl.service.status import CLOCK_WORDS, status_line
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo
from kasparctl.view.ages import Now, ago
from kasparctl.view.fold import SessionFold
from kasparctl.view.frame import fault_stamp, frame, plain_text
from kasparctl.view.live import live_now
from kasparctl.view.replay import Replay

YEARS_3 = 3 * 365 * 86400.0


def answers(**said: str | None) -> object:
    """A command runner answering as `said` maps a command's first two words."""

    def run(command: Sequence[str]) -> str | None:
        return said.get("_".join(command[:2]).replace("-", "_"))

    return run


def test_the_clock_is_synchronised_only_where_timesyncd_says_so() -> None:
    synced = answers(systemctl_is_active="active", timedatectl_show="yes")
    assert clock_source(synced).source == SYNCHRONISED  # type: ignore[arg-type]
    waiting = answers(systemctl_is_active="active", timedatectl_show="no")
    assert clock_source(waiting).source == UNSYNCHRONISED  # type: ignore[arg-type]
    # No timesyncd (fake-hwclock alone, chrony unknown here), or no systemd at all.
    assert clock_source(answers(systemctl_is_active="inactive")).source == UNSYNCHRONISED  # type: ignore[arg-type]
    assert clock_source(answers()).source == UNSYNCHRONISED  # type: ignore[arg-type]


def test_a_jump_is_the_wall_clock_moving_against_the_monotonic_one() -> None:
    wall, monotonic = [1_000_000.0], [50.0]
    watch = ClockWatch(
        run=lambda command: None,
        wall=lambda: wall[0],
        monotonic=lambda: monotonic[0],
        boot=lambda: "boot-1",
    )
    assert watch.jumped() is None  # the first look only takes the offset to measure from
    first = watch.read()
    assert (first.step, first.offset, first.boot) == (0.0, 999_950.0, "boot-1")
    wall[0] += 10.5
    monotonic[0] += 10.0  # half a second of drift: NTP slewing, no jump
    assert watch.jumped() is None
    wall[0] += YEARS_3  # a network appears
    jump = watch.jumped()
    assert jump is not None and jump.step == YEARS_3 + 0.5
    assert not jump.source.synchronised
    assert watch.jumped() is None  # measured from the new offset on
    wall[0] -= 7200.0  # and back
    back = watch.jumped()
    assert back is not None and back.step == -7200.0


def test_check_and_status_warn_while_the_clock_is_not_synchronised() -> None:
    warned = clock_row(ClockSource(UNSYNCHRONISED))
    assert warned.ok and warned.warning and "NOT synchronised" in warned.detail
    assert not clock_row(ClockSource(SYNCHRONISED)).warning
    assert status_line("idle", clock_unsynchronised=True).endswith(CLOCK_WORDS)
    assert CLOCK_WORDS not in status_line("idle")


def _cli(*argv: str) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main(list(argv)) == 0
    return out.getvalue()


def test_a_session_on_an_unsynchronised_clock_says_so_in_sessions_the_export_and_watch(
    tmp_path: Path,
) -> None:
    state_dir = tmp_path / "state"
    watch = ClockWatch(run=lambda command: None, boot=lambda: "")
    result = run_demo(
        demo_config(), DemoOptions(state_dir, seed=1, out=io.StringIO(), clock=watch), fast=True
    )
    assert (result.trials, result.learned) == (21, 6)  # the demo's seed-1 game, as ever
    (listed,) = json.loads(_cli("sessions", "--json", "--state-dir", str(state_dir)))
    assert listed["clock_synchronised"] is False
    assert "clock: " in _cli("sessions", "--state-dir", str(state_dir))
    out = tmp_path / "trials.csv"
    _cli("export", "--state-dir", str(state_dir), "--csv", str(out))
    rows = list(csv.DictReader(out.open()))
    assert rows and {row["clock_synchronised"] for row in rows} == {"FALSE"}
    (directory,) = session_dirs(state_dir)
    view = Replay(directory, screen=None).view_at(10**6)  # type: ignore[arg-type]
    text = [plain_text(line) for line in frame(view, dt.datetime.now(dt.UTC))]
    assert any(line.startswith("CLOCK unsynchronised") for line in text), text


def test_the_demo_without_a_watched_clock_writes_no_clock_record(tmp_path: Path) -> None:
    run_demo(demo_config(), DemoOptions(tmp_path, seed=1, out=io.StringIO()), fast=True)
    (directory,) = session_dirs(tmp_path)
    assert '"kind":"clock"' not in (directory / RECORDS_FILE).read_text()
    (listed,) = json.loads(_cli("sessions", "--json", "--state-dir", str(tmp_path)))
    assert listed["clock_synchronised"] is None


T0 = dt.datetime(2026, 3, 2, 12, 0, tzinfo=dt.UTC)


def at(seconds: float) -> str:
    return (T0 + dt.timedelta(seconds=seconds)).isoformat(timespec="milliseconds")


def stepping_session(directory: Path) -> None:
    """A session whose wall clock steps 3 years ahead between two faults."""
    fault = {"fault": FaultSource.KEYFOB, "detail": "lost", "state": "placing", "joint": None}
    records = [
        SessionRecord(event=SessionEvent.START, seq=1, time=at(0), clock=100.0),
        ClockRecord(
            synchronised=False,
            source="unsynchronised",
            offset=0.0,
            step=0.0,
            boot="b1",
            seq=2,
            time=at(0.1),
            clock=100.1,
        ),
        StepRecord(to="placing", seq=3, time=at(0.2), clock=100.2),
        FaultRecord(**fault, seq=4, time=at(1), clock=101.0),  # type: ignore[arg-type]
        ClockRecord(
            synchronised=False,
            source="unsynchronised",
            offset=YEARS_3,
            step=YEARS_3,
            boot="b1",
            seq=5,
            time=at(YEARS_3 + 5),
            clock=105.0,
        ),
        FaultRecord(**fault, seq=6, time=at(YEARS_3 + 6), clock=106.0),  # type: ignore[arg-type]
        StepRecord(to="stopped", seq=7, time=at(YEARS_3 + 10), clock=110.0),
    ]
    directory.mkdir(parents=True)
    (directory / PLAN_FILE).write_text(json.dumps({"session": directory.name, "group": "A1"}))
    (directory / RECORDS_FILE).write_bytes(b"".join(encode_record(r) + b"\n" for r in records))


def test_the_replay_ages_on_the_session_s_monotonic_clock_across_a_clock_step(
    tmp_path: Path,
) -> None:
    stepping_session(tmp_path / "s")
    replay = Replay(tmp_path / "s", screen=None)  # type: ignore[arg-type]
    end = len(replay.records)
    view, now = replay.view_at(end).session, replay.now_at(end)
    assert view is not None
    assert [ago(fault_stamp(f), now) for f in view.faults] == ["9 s ago", "4 s ago"]
    # On the wall clock, the first would read 1095 days.
    assert ago(view.faults[0].time, now.wall) == "1095 d ago"


def test_the_live_view_ages_on_the_monotonic_clock_of_its_own_boot(tmp_path: Path) -> None:
    stepping_session(tmp_path / "s")
    replay = Replay(tmp_path / "s", screen=None)  # type: ignore[arg-type]
    watch = replay.view_at(len(replay.records))
    assert watch.session is not None
    faults = watch.session.faults
    viewer_wall = T0 + dt.timedelta(seconds=12)  # the viewer's clock is right
    here = live_now(watch, viewer_wall, 112.0, "b1")
    assert [ago(fault_stamp(f), here) for f in faults] == ["11 s ago", "6 s ago"]
    # Another boot's monotonic clock tells nothing: the wall clock (the future: "just now").
    elsewhere = live_now(watch, viewer_wall, 112.0, "b2")
    assert [ago(fault_stamp(f), elsewhere) for f in faults] == ["11 s ago", "just now"]


def test_a_new_run_of_the_daemon_ages_the_old_one_s_records_on_the_wall_clock() -> None:
    fold = SessionFold({"session": "s", "group": "A1"})
    fault = FaultRecord(fault=FaultSource.KEYFOB, detail="lost", state="placing", joint=None)
    fold.apply(SessionRecord(event=SessionEvent.START, seq=1, time=at(0), clock=500.0))
    fold.apply(FaultRecord(**{**_plain(fault), "seq": 2, "time": at(1), "clock": 501.0}))
    # Restarted after a reboot: its monotonic clock began again near 0.
    fold.apply(SessionRecord(event=SessionEvent.RESUMED, seq=3, time=at(60), clock=3.0))
    (seen,) = fold.view.faults
    now = Now(T0 + dt.timedelta(seconds=61), 4.0, fold.view.run)
    assert ago(fault_stamp(seen), now) == "1 min ago"


def _plain(record: FaultRecord) -> dict[str, object]:
    return {"fault": record.fault, "detail": record.detail, "state": record.state, "joint": None}


def test_a_resume_that_repaired_a_torn_record_says_so(tmp_path: Path) -> None:
    config = demo_config()
    run_demo(config, DemoOptions(tmp_path, seed=1, out=io.StringIO()), fast=True)
    (directory,) = session_dirs(tmp_path)
    cut_after_trial(directory, 5)
    with (directory / RECORDS_FILE).open("ab") as records:
        records.write(b'{"kind":"press","seq":')  # a power cut during the next write
    listed = _cli("sessions", "--state-dir", str(tmp_path))
    assert "recovered: " in listed and "repaired when it resumes" in listed
    run_demo(config, DemoOptions(tmp_path, seed=1, out=io.StringIO()), fast=True)
    lines = [json.loads(line) for line in (directory / RECORDS_FILE).read_text().splitlines()]
    (resumed,) = [r for r in lines if r["kind"] == "session" and r["event"] == "resumed"]
    (repair,) = resumed["repaired"]
    assert repair.startswith("records.jsonl: the last line was torn (22 bytes"), repair
    listed = _cli("sessions", "--state-dir", str(tmp_path))
    assert "a crash tore its last record (23 bytes" in listed, listed


def test_the_service_s_status_says_the_resume_repaired_a_torn_record(tmp_path: Path) -> None:
    import asyncio

    from kasparctl.service.daemon import Daemon, DaemonOptions
    from kasparctl.service.sdnotify import Notifier

    config_path = Path(__file__).resolve().parents[1] / "kasparctl" / "sim" / "demo.toml"
    run_demo(demo_config(), DemoOptions(tmp_path, seed=1, out=io.StringIO()), fast=True)
    (directory,) = session_dirs(tmp_path)
    cut_after_trial(directory, 5)
    with (directory / RECORDS_FILE).open("ab") as records:
        records.write(b'{"kind":"press","seq":')
    daemon = Daemon(
        DaemonOptions(str(config_path), sim=True, state_dir=str(tmp_path)), Notifier("")
    )

    async def resume() -> None:
        opened = daemon._resume()
        assert opened is not None
        opened.session.close()

    asyncio.run(resume())
    assert daemon._notice is not None
    assert daemon._notice.startswith(f"session {directory.name} resumed after a crash: ")
    assert "records.jsonl: the last line was torn (22 bytes" in daemon._notice
