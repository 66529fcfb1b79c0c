"""Following a state directory with inotify, as the game writes it: each wait below ends
when the kernel reports the change, never after a sleep."""

from __future__ import annotations

import json
import selectors
import signal
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from view_records import PLAN, question, trial

from kasparctl.game.records import SessionEvent, SessionRecord, StepRecord
from kasparctl.game.session import RECORDS_FILE, Session
from kasparctl.view.follow import EVENTS_FILE, Follower, read_session
from kasparctl.view.frame import UNICODE, plain_text
from kasparctl.view.inotify import IN_CREATE, IN_MODIFY, Event, Inotify, parse_events
from kasparctl.view.live import LiveView
from kasparctl.view.model import WatchView

DEADLINE_S = 10.0


def wait_for(
    follower: Follower, inotify: Inotify, wanted: Callable[[WatchView], bool]
) -> WatchView:
    """The view once `wanted` holds, looking again only when inotify reports a change."""
    end = time.monotonic() + DEADLINE_S
    with selectors.DefaultSelector() as selector:
        selector.register(inotify, selectors.EVENT_READ)
        view = follower.observe()
        while not wanted(view):
            left = end - time.monotonic()
            assert left > 0, f"not seen within {DEADLINE_S} s: {view}"
            if selector.select(left):
                follower.handle(inotify.read())
                view = follower.observe()
    return view


def start_session(state_dir: Path, group: str = "G7") -> Session:
    """A session opened as the game opens one: its folder, its plan, its start record."""
    plan = {key: PLAN[key] for key in ("condition", "variant", "seed", "plan")}
    session = Session.create(state_dir, {**plan, "group": group})
    session.record(SessionRecord(event=SessionEvent.START, plan=session.plan), 0.0)
    return session


def test_parse_events_reads_names_and_masks() -> None:
    data = struct.pack("iIII", 1, IN_CREATE, 0, 16) + b"records.jsonl\0\0\0"
    data += struct.pack("iIII", 2, IN_MODIFY, 0, 0)
    assert parse_events(data) == [Event(1, IN_CREATE, "records.jsonl"), Event(2, IN_MODIFY, "")]


def test_a_state_directory_that_appears_later_then_a_session_in_it(tmp_path: Path) -> None:
    state_dir = tmp_path / "not" / "yet" / "state"
    with Inotify() as inotify:
        follower = Follower(state_dir, inotify)
        assert not follower.observe().exists
        session = start_session(state_dir)
        view = wait_for(
            follower, inotify, lambda v: v.session is not None and v.session.records == 1
        )
        assert view.exists and view.session is not None and view.session.group == "G7"
        asked = question(1)
        session.record(StepRecord(to="guessing"), 1.0)
        session.record(asked, 2.0)
        view = wait_for(
            follower, inotify, lambda v: v.session is not None and v.session.question is not None
        )
        assert view.session is not None and view.session.question is not None
        assert view.session.question.open and view.session.stage == "guessing"


def test_the_next_session_is_followed_and_a_resumed_older_one_too(tmp_path: Path) -> None:
    first = start_session(tmp_path, "A")
    with Inotify() as inotify:
        follower = Follower(tmp_path, inotify)
        assert follower.observe().session.group == "A"  # type: ignore[union-attr]
        second = start_session(tmp_path, "B")
        view = wait_for(
            follower, inotify, lambda v: v.session is not None and v.session.group == "B"
        )
        assert view.sessions == 2
        first.record(SessionRecord(event=SessionEvent.RESUMED, step="guessing", trials=0), 5.0)
        view = wait_for(
            follower, inotify, lambda v: v.session is not None and v.session.group == "A"
        )
        assert view.session is not None and view.session.resumes == 1
        second.close()
        first.close()


def test_a_torn_last_line_is_shown_as_unread_and_the_repair_is_followed(tmp_path: Path) -> None:
    session = start_session(tmp_path)
    asked = question(1)
    session.record(asked, 1.0)
    records = session.directory / RECORDS_FILE
    with Inotify() as inotify:
        follower = Follower(tmp_path, inotify)
        # A power cut in the middle of the answer's line.
        with open(records, "ab") as stream:
            stream.write(b'{"kind":"trial","seq":3,"tri')
        view = wait_for(
            follower, inotify, lambda v: v.session is not None and bool(v.session.warnings)
        )
        assert view.session is not None and view.session.records == 2
        assert view.session.question is not None and view.session.question.open
        # The daemon starts again: the torn tail is moved aside, the log cut back, resumed.
        session.close()
        resumed, warnings = Session.open(session.directory)
        assert warnings
        resumed.record(SessionRecord(event=SessionEvent.RESUMED, step="guessing", trials=0), 9.0)
        resumed.record(trial(asked, "green"), 10.0)
        view = wait_for(
            follower, inotify, lambda v: v.session is not None and v.session.trials == 1
        )
        assert view.session is not None and view.session.warnings == ()
        assert view.session.resumes == 1
        # Folded on record by record as they came, it is the view of the whole log.
        assert view.session == read_session(session.directory)
        resumed.close()


def test_the_daemons_event_log_is_read_when_it_changes(tmp_path: Path) -> None:
    with Inotify() as inotify:
        follower = Follower(tmp_path, inotify)
        line = {
            "kind": "fault",
            "fault": "keyfob",
            "time": "2026-03-02T09:00:00+00:00",
            "detail": "no device",
        }
        (tmp_path / EVENTS_FILE).write_text(json.dumps(line) + "\n")
        view = wait_for(follower, inotify, lambda v: bool(v.daemon))
        assert [(e.name, e.fault, e.detail) for e in view.daemon] == [("keyfob", True, "no device")]


class Frames:
    """A screen that keeps the frames drawn, for a LiveView run in a thread."""

    live = True
    glyphs = UNICODE

    def __init__(self) -> None:
        self.frames: list[str] = []
        self.changed = threading.Condition()

    def size(self) -> tuple[int, int]:
        return 80, 24

    def draw(self, lines) -> None:
        with self.changed:
            self.frames.append("\n".join(plain_text(line) for line in lines))
            self.changed.notify_all()

    def close(self) -> None:
        pass

    def wait_for(self, text: str) -> str:
        with self.changed:
            found = self.changed.wait_for(
                lambda: bool(self.frames) and text in self.frames[-1], timeout=DEADLINE_S
            )
            assert found, (
                f"{text!r} not drawn; last frame:\n{self.frames[-1] if self.frames else ''}"
            )
            return self.frames[-1]


def test_the_live_loop_draws_each_record_and_the_writer_leaving(tmp_path: Path) -> None:
    """The writer holds the state directory's lock: the view names it, and sees it exit."""
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from pathlib import Path; from kasparctl.game.lock import StateDirLock;"
            "lock = StateDirLock(Path(sys.argv[1])); lock.acquire(); print('held', flush=True);"
            "sys.stdin.read()",
            str(tmp_path),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        session = start_session(tmp_path)
        screen = Frames()
        view = LiveView(tmp_path, screen)
        thread = threading.Thread(target=view.run)
        thread.start()
        try:
            screen.wait_for(f"daemon running (pid {holder.pid})")
            session.record(StepRecord(to="guessing"), 1.0)
            session.record(question(1, choice="zebra"), 2.0)
            frame = screen.wait_for("◀ guess")
            assert "STEP 4 GUESSING" in frame
            holder.send_signal(signal.SIGKILL)
            holder.wait()
            screen.wait_for("daemon unknown")
        finally:
            view.stop()
            thread.join()
            view.close()
            session.close()
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait()


def test_what_cannot_be_followed_is_said_not_taken_for_missing(tmp_path: Path) -> None:
    not_a_directory = tmp_path / "state"
    not_a_directory.write_text("")
    with Inotify() as inotify:
        view = Follower(not_a_directory, inotify).observe()
        assert view.problem == f"{not_a_directory}: cannot watch: Not a directory"
    session = start_session(tmp_path / "other")
    session.close()
    records = session.directory / RECORDS_FILE
    records.unlink()
    records.mkdir()  # a records file that cannot be read
    with Inotify() as inotify:
        view = Follower(tmp_path / "other", inotify).observe()
        assert view.problem == f"{records}: cannot read: Is a directory"
