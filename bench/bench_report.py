"""`kasparctl report` (and `export`) over 1000 simulated sessions.

Run on demand: .venv/bin/python bench/bench_report.py [--sessions N] [--cache DIR] [--fresh]
Figure: the whole report (read every session, the paper's statistics per
condition, four figures as PNG and SVG, summary.md and .json), target < 30 s.
The CSV export of the same sessions is timed beside it, without a target.

The sessions are real demo games in simulated time, in four conditions and
both variants. Making 1000 takes one to two minutes, so they are made once
into a cache directory (default ~/.cache/kasparctl/bench-report-<N>) and
reused; --fresh makes them again.
"""

from __future__ import annotations

import argparse
import io
import multiprocessing
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import msgspec

from kasparctl.cli import main
from kasparctl.config import SessionPlan
from kasparctl.log import configure_logging
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo, with_variant
from kasparctl.sim.teacher import Teacher

TARGET_S = 30.0
CONDITIONS = (("paper", True), ("paper", False), ("fast", True), ("slow", True))
# Written last: a cache without it was cut short and is made again.
COMPLETE = "complete"


def make_one(arguments: tuple[Path, int]) -> None:
    state_dir, index = arguments
    profile, spoken = CONDITIONS[index % len(CONDITIONS)]
    config = demo_config()
    variant = "names" if (index // len(CONDITIONS)) % 2 == 0 else "pilot"
    # One group code per session: parallel workers never race for a session id.
    plan = SessionPlan(group=f"B{index:04d}", profile=profile, speak_uncertainty=spoken)
    config = msgspec.structs.replace(with_variant(config, variant), sessions=(plan,))
    # Its own state directory while it plays: the demo resumes any unfinished session
    # it finds, and would take over another worker's game in progress.
    scratch = state_dir / ".making" / str(index)
    options = DemoOptions(
        state_dir=scratch,
        seed=index,
        teacher=Teacher(p_wrong_green=0.02, p_no_answer=0.02),
        out=io.StringIO(),
    )
    run_demo(config, options, fast=True)
    (session_dir,) = (scratch / "sessions").iterdir()
    session_dir.rename(state_dir / "sessions" / session_dir.name)
    shutil.rmtree(scratch)


def ensure_sessions(cache: Path, count: int, fresh: bool) -> None:
    if (cache / COMPLETE).exists() and not fresh:
        print(f"using the {count} cached sessions in {cache} (--fresh makes them again)")
        return
    shutil.rmtree(cache, ignore_errors=True)
    (cache / "sessions").mkdir(parents=True)
    workers = os.cpu_count() or 1
    print(f"making {count} demo sessions in {cache} with {workers} workers (once)...", flush=True)
    started = time.perf_counter()
    with multiprocessing.Pool(workers, initializer=configure_logging, initargs=("error",)) as pool:
        for done, _ in enumerate(
            pool.imap_unordered(make_one, [(cache, i) for i in range(count)], chunksize=8), 1
        ):
            if done % 100 == 0:
                print(f"  {done}/{count}", flush=True)
    shutil.rmtree(cache / ".making", ignore_errors=True)
    (cache / COMPLETE).write_text(f"{count}\n")
    print(f"made in {time.perf_counter() - started:.0f} s")


def timed(argv: list[str]) -> float:
    started = time.perf_counter()
    code = main(argv)
    elapsed = time.perf_counter() - started
    if code != 0:
        sys.exit(f"kasparctl {' '.join(argv)} failed with {code}")
    return elapsed


def bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sessions", type=int, default=1000)
    parser.add_argument("--cache", type=Path, default=None)
    parser.add_argument("--fresh", action="store_true")
    arguments = parser.parse_args()
    cache = arguments.cache or Path.home() / ".cache" / "kasparctl" / (
        f"bench-report-{arguments.sessions}"
    )
    ensure_sessions(cache, arguments.sessions, arguments.fresh)
    with tempfile.TemporaryDirectory(prefix="kaspar-bench-report-") as scratch:
        out = Path(scratch)
        report_s = timed(["report", "--state-dir", str(cache), "--out", str(out / "report")])
        export_s = timed(
            [
                "export",
                "--state-dir",
                str(cache),
                "--csv",
                str(out / "trials.csv"),
                "--events",
                str(out / "events.csv"),
            ]
        )
        rows = (out / "trials.csv").read_text().count("\n") - 1
    verdict = "ok" if report_s < TARGET_S else "OVER TARGET"
    print(
        f"report over {arguments.sessions} sessions: {report_s:.1f} s "
        f"(target < {TARGET_S:.0f} s) {verdict}"
    )
    print(f"export of the same ({rows} trial rows, and the events): {export_s:.1f} s")


if __name__ == "__main__":
    bench()
