"""The service with its wall clock 2 h behind and 3 years ahead: the right session offered,
followed and aged.

Run on demand: .venv/bin/python bench/clock_scenarios.py [--json] [--source DIR]

The service (`kasparctl run --sim`, the demo robot with three planned sessions) runs
under bench/wallshift/wallshift.c, a faketime-like LD_PRELOAD shim built here with
cc: it moves CLOCK_REALTIME only (by the seconds in a file, so a running service can
be stepped), never the monotonic clock or the kernel's file times. Keys go to the
service's terminal keyfob (G next, b stop, l keyfob lost, k back).

1. Stopped session, for each (first, second) wall clock in ((0, -2 h), (+3 y, 0)):
   session 1 is started, stopped and closed under the first clock; session 2 started
   and stopped under the second; the service restarted under the second clock, and
   "next" pressed. Target: "next" reopens session 2 (no third session; before, by the
   directory names, it opened plan 3).
2. Watch: `watch`'s follower on that state directory follows session 2, the one
   begun last (by the sequence number; its name sorts first).
3. Ages: a session that starts on the right clock, has a keyfob fault, steps 3 years
   ahead, has a second fault; the live view (this process's clock right) and the
   replay at the last record show each fault's age. Target: the seconds since each
   fault, on the monotonic clock (before, on the wall clock: "just now" for the
   fault from the future, "1095 d ago" for the other in the replay).

`--source DIR` runs the service from another checkout's source (e.g. the code before
this change, for comparison).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))

from service_fixtures import DEMO_CONFIG, RunningService, running_service  # noqa: E402

from kasparctl.game.session import session_dirs  # noqa: E402
from kasparctl.game.wallclock import boot_id  # noqa: E402
from kasparctl.view.ages import ago  # noqa: E402
from kasparctl.view.follow import Follower  # noqa: E402
from kasparctl.view.frame import fault_stamp, frame, plain_text  # noqa: E402
from kasparctl.view.inotify import Inotify  # noqa: E402
from kasparctl.view.live import live_now  # noqa: E402
from kasparctl.view.model import WatchView  # noqa: E402
from kasparctl.view.replay import Replay  # noqa: E402

HOURS_2 = -2 * 3600.0
YEARS_3 = 3 * 365 * 86400.0
PLANS = """
[[sessions]]
group = "second"
profile = "paper"

[[sessions]]
group = "third"
profile = "paper"
"""
DEADLINE_S = 60.0


def build_shim(directory: Path) -> Path:
    """wallshift.so, compiled from bench/wallshift/wallshift.c."""
    shim = directory / "wallshift.so"
    source = REPO / "bench" / "wallshift" / "wallshift.c"
    subprocess.run(
        ["cc", "-shared", "-fPIC", "-O2", "-o", str(shim), str(source), "-ldl"], check=True
    )
    return shim


class Clock:
    """The service's wall clock: the shim's shift file."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / "shift"
        self.set(0.0)

    def set(self, seconds: float) -> None:
        self.path.write_text(f"{seconds}\n")


def wait(condition: Callable[[], Any], what: str, seconds: float = DEADLINE_S) -> Any:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if found := condition():
            return found
        time.sleep(0.02)
    raise AssertionError(f"not within {seconds} s: {what}")


def records(directory: Path) -> list[dict[str, Any]]:
    path = directory / "records.jsonl"
    if not path.exists():
        return []
    return [
        json.loads(line)
        for line in path.read_text().splitlines(keepends=True)
        if line.endswith("\n")
    ]


def folders(state_dir: Path) -> list[Path]:
    sessions = state_dir / "sessions"
    return (
        sorted(p for p in sessions.iterdir() if not p.name.startswith("."))
        if sessions.is_dir()
        else []
    )


def has(directory: Path, wanted: Callable[[dict[str, Any]], bool]) -> bool:
    return any(wanted(record) for record in records(directory))


@contextmanager
def service(
    base: Path, state_dir: Path, config: Path, shim: Path, clock: Clock, source: Path | None
) -> Iterator[RunningService]:
    environment = {"LD_PRELOAD": str(shim), "WALL_SHIFT_FILE": str(clock.path)}
    if source is not None:
        environment["PYTHONPATH"] = str(source)

    def command(state: Path) -> list[str]:
        # `-m` would put the working directory (this checkout) first on the path.
        start = (
            ["-m", "kasparctl"]
            if source is None
            else [
                "-c",
                f"import runpy, sys; sys.path.insert(0, {str(source)!r}); "
                "runpy.run_module('kasparctl', run_name='__main__')",
            ]
        )
        return [
            sys.executable,
            *start,
            "run",
            "--sim",
            "--config",
            str(config),
            "--state-dir",
            str(state),
        ]

    with running_service(base, environment, state_dir, command) as running:
        running.notify.wait_for("READY=1")
        yield running
        try:
            code = running.stop(signal.SIGTERM)
        except subprocess.TimeoutExpired:
            code = None  # killed by running_service: said, not hidden
        if code != 0:
            print(
                f"the service did not stop cleanly ({code}): {running.stderr.lines[-3:]}",
                file=sys.stderr,
            )


def step_in(directory: Path, to: str) -> Callable[[], bool]:
    return lambda: has(directory, lambda r: r["kind"] == "step" and r.get("to") == to)


def stopped_session(
    base: Path, shim: Path, first: float, second: float, source: Path | None
) -> dict[str, Any]:
    """Scenario 1 (and 2): which session "next" reopens, and which one watch follows."""
    work = Path(tempfile.mkdtemp(dir=base))
    config = work / "kaspar.toml"
    config.write_text(DEMO_CONFIG.read_text() + PLANS)
    state_dir = work / "state"
    clock = Clock(work)
    clock.set(first)
    with service(work, state_dir, config, shim, clock, source) as running:
        running.press("G")
        (one,) = wait(lambda: folders(state_dir), "session 1")
        wait(step_in(one, "placing"), "session 1 placing")
        running.press("b")
        wait(step_in(one, "stopped"), "session 1 stopped")
        # Stop again once the next game waits in idle: the stopped session is closed for
        # good (a press while the farewell is still said is ignored, and pressed again).
        closed = lambda: has(one, lambda r: r["kind"] == "session" and r.get("event") == "closed")  # noqa: E731
        for _ in range(30):
            running.press("b")
            try:
                wait(closed, "closed", 2.0)
                break
            except AssertionError:
                continue
        wait(closed, "session 1 closed")
    clock.set(second)
    with service(work, state_dir, config, shim, clock, source) as running:
        running.press("G")
        two = wait(lambda: [p for p in folders(state_dir) if p != one], "session 2")[0]
        wait(step_in(two, "placing"), "session 2 placing")
        running.press("b")
        wait(step_in(two, "stopped"), "session 2 stopped")
    with service(work, state_dir, config, shim, clock, source) as running:
        running.press("G")

        def what_next() -> str | None:
            if has(two, lambda r: r["kind"] == "session" and r.get("event") == "resumed"):
                return f"reopened session 2 ({two.name})"
            new = [p for p in folders(state_dir) if p not in (one, two)]
            if new and (new[0] / "plan.json").exists():
                group = json.loads((new[0] / "plan.json").read_text()).get("group")
                return f"opened a new session {new[0].name} (plan {group!r})"
            return None

        offered = wait(what_next, "what next did")
    with Inotify() as inotify:
        followed = Follower(state_dir, inotify).current
    return {
        "clocks": f"session 1 at {_shift(first)}, session 2 at {_shift(second)}",
        "names_in_order": [p.name for p in folders(state_dir)],
        "sessions_in_order": [p.name for p in session_dirs(state_dir)],
        "next": offered,
        "ok_next": offered.startswith("reopened session 2"),
        "watch_follows": followed.name if followed else None,
        "ok_watch": followed == two,
    }


def _shift(seconds: float) -> str:
    if seconds == 0:
        return "the right time"
    if abs(seconds) >= 86400 * 365:
        return f"{seconds / (86400 * 365):+.0f} y"
    return f"{seconds / 3600:+.0f} h"


def press_and_wait(
    running: RunningService, key: str, session: Path, field: str, value: str
) -> None:
    """Press `key`, and wait for one more record whose `field` is `value`."""

    def count() -> int:
        return sum(1 for r in records(session) if r.get(field) == value)

    before = count()
    running.press(key)
    wait(lambda: count() > before, value)


def ages(base: Path, shim: Path, source: Path | None) -> dict[str, Any]:
    """Scenario 3: a fault before and after a 3-year step, aged live and in the replay."""
    work = Path(tempfile.mkdtemp(dir=base))
    state_dir = work / "state"
    clock = Clock(work)
    faults_at: list[float] = []
    with service(work, state_dir, DEMO_CONFIG, shim, clock, source) as running:
        running.press("G")
        (session,) = wait(lambda: folders(state_dir), "the session")
        wait(step_in(session, "placing"), "placing")
        for shift in (0.0, YEARS_3):
            clock.set(shift)
            time.sleep(0.2)  # the shim reads its file every 50 ms
            press_and_wait(running, "l", session, "kind", "fault")
            faults_at.append(time.monotonic())
            time.sleep(2.0)
            press_and_wait(running, "k", session, "event", "keyfob_back")
        time.sleep(2.0)
        # The session goes on: its last record is written now, 3 years ahead.
        running.press("b")
        wait(step_in(session, "stopped"), "stopped")
        stopped_at = time.monotonic()
        with Inotify() as inotify:
            follower = Follower(state_dir, inotify)
            view = follower.observe()
        live = _fault_ages(
            view, live_now(view, dt.datetime.now(dt.UTC), time.monotonic(), boot_id())
        )
        live_wall = _fault_ages(view, dt.datetime.now(dt.UTC), wall_only=True)
        expected_live = [round(time.monotonic() - at) for at in faults_at]
    replay = Replay(session, screen=None)  # type: ignore[arg-type]
    shown = len(replay.records)
    replay_view = replay.view_at(shown)
    at_end = replay.now_at(shown)
    in_replay = _fault_ages(replay_view, at_end)
    replay_wall = _fault_ages(replay_view, at_end.wall, wall_only=True)
    expected_replay = [round(stopped_at - at) for at in faults_at]
    jumps = [r for r in records(session) if r["kind"] == "clock" and abs(r["step"]) > 1e7]
    return {
        "clock_jump_recorded": [{"step_s": r["step"], "source": r["source"]} for r in jumps],
        "live_view": live,
        "live_view_on_the_wall_clock_would_read": live_wall,
        "live_expected_about_s": expected_live,
        "replay_at_the_last_record": in_replay,
        "replay_on_the_wall_clock_would_read": replay_wall,
        "replay_expected_about_s": expected_replay,
        "clock_warning_shown": any(
            "CLOCK" in plain_text(line) for line in frame(view, dt.datetime.now(dt.UTC), 100, 40)
        ),
    }


def _fault_ages(view: WatchView, now: Any, wall_only: bool = False) -> list[str]:
    session = view.session
    assert session is not None
    return [ago(fault.time if wall_only else fault_stamp(fault), now) for fault in session.faults]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--source", type=Path, help="run the service from this source tree")
    arguments = parser.parse_args()
    with tempfile.TemporaryDirectory() as temporary:
        base = Path(temporary)
        shim = build_shim(base)
        results: dict[str, Any] = {
            "shim": "LD_PRELOAD bench/wallshift/wallshift.c: CLOCK_REALTIME moved, monotonic not",
            "stopped_session": [
                stopped_session(base, shim, first, second, arguments.source)
                for first, second in ((0.0, HOURS_2), (YEARS_3, 0.0))
            ],
            "ages": ages(base, shim, arguments.source),
        }
    print(json.dumps(results, indent=1))
    ok = all(r["ok_next"] and r["ok_watch"] for r in results["stopped_session"])
    return 0 if ok else 1


if __name__ == "__main__":
    os.environ.setdefault("KASPAR_DEBUG", "0")
    sys.exit(main())
