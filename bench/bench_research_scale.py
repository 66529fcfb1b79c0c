"""`sessions`, `export` and `report` over 200 MB of records: time and peak memory.

Run on demand: .venv/bin/python bench/bench_research_scale.py [--mb 200] [--sessions 1]
    [--dir DIR] [--json]
Targets, each command on its own: under 60 s and under 300 MB peak RSS (the
research commands stream the records: memory must not grow with them). Also
measured: `sessions` again under a 700 MB address-space limit (it must work,
not run out of memory), and `simulate --groups 60000`, whose statistics
accumulate: under 120 MB (holding its 180,000 problems' records took 190 MB).

The records are a real demo game's (the names game with wrong answers, prompts
and an undo), its guessing repeated with fresh trial and record numbers until
the records reach the size asked for: by default one session of 200 MB (the
worst case for a single command's memory); --sessions N spreads the same
size over N sessions. Made once into --dir (default a temporary directory,
removed after) in a few seconds.

Each command runs in its own process; its peak RSS is the kernel's high-water
mark of that process's memory (VmHWM in /proc/self/status, read as it ends:
unlike ru_maxrss it does not count the memory of the process it was forked
from), its time the wall clock.
"""

from __future__ import annotations

import argparse
import io
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

TARGET_S = 60.0
TARGET_MB = 300.0
COMMANDS = ("sessions", "export", "report")
LIMITED_AS_MB = 700  # the address-space limit `sessions` must work under
SIMULATE_GROUPS = 60_000
SIMULATE_TARGET_MB = 120.0


def template(scratch: Path) -> tuple[bytes, list[dict[str, Any]]]:
    """A real demo session: its plan.json and its records as JSON objects."""
    from kasparctl.log import configure_logging
    from kasparctl.sim.demo import DemoOptions, demo_config, run_demo
    from kasparctl.sim.teacher import Teacher

    # stdout is this script's JSON: what the game logs goes to stderr, warnings only.
    configure_logging("warning", "console", stream=sys.stderr)

    options = DemoOptions(
        state_dir=scratch,
        seed=7,
        teacher=Teacher(p_wrong_green=0.1, p_wrong_red=0.05, p_no_answer=0.2),
        out=io.StringIO(),
    )
    run_demo(demo_config(), options, fast=True)
    (session,) = (scratch / "sessions").iterdir()
    records = [json.loads(line) for line in (session / "records.jsonl").read_text().splitlines()]
    return (session / "plan.json").read_bytes(), records


def make(root: Path, megabytes: float, sessions: int) -> Path:
    """A state directory whose sessions' records add up to `megabytes`."""
    state = root / "state"
    (state / "sessions").mkdir(parents=True)
    plan_bytes, records = template(root / "template")
    plan = json.loads(plan_bytes)
    first_trial = next(i for i, r in enumerate(records) if r["kind"] == "trial")
    head, guessing = records[:first_trial], records[first_trial:]
    # The guessing without its end: repeated, then the end once.
    body = [r for r in guessing if not (r["kind"] == "step" and r["to"] == "finished")]
    per_session = megabytes * 1e6 / sessions
    for index in range(sessions):
        name = f"20260302T09{index // 60 % 60:02d}{index % 60:02d}-S{index:05d}"
        directory = state / "sessions" / name
        directory.mkdir(mode=0o700)
        mine = {**plan, "session": name, "uid": None, "group": f"S{index:05d}"}
        mine["plan"] = {**plan["plan"], "group": f"S{index:05d}"}
        (directory / "plan.json").write_text(json.dumps(mine))
        written = 0
        seq = 0
        trial_base = 0
        with (directory / "records.jsonl").open("w") as out:

            def emit(record: dict[str, Any]) -> None:
                nonlocal seq, written
                seq += 1
                line = json.dumps({**record, "seq": seq}, separators=(",", ":")) + "\n"
                out.write(line)
                written += len(line)

            for record in head:
                emit(record)
            while written < per_session:
                for record in body:
                    shifted = dict(record)
                    if "trial" in shifted and isinstance(shifted["trial"], int):
                        shifted["trial"] += trial_base
                    emit(shifted)
                trial_base += max(r.get("trial", 0) for r in body if r["kind"] == "trial")
            emit({"kind": "step", "time": head[-1]["time"], "clock": 0.0, "to": "finished"})
    shutil.rmtree(root / "template")
    return state


# Runs `kasparctl ARGV` and, as it ends, writes its peak memory (kB) as the last line of stderr.
PEAK = """
import re, sys
from kasparctl.cli import main
try:
    code = main(sys.argv[1:])
finally:
    status = open("/proc/self/status").read()
    print("VmHWM", re.search(r"VmHWM:\\s+(\\d+) kB", status).group(1), file=sys.stderr)
sys.exit(code)
"""


def measure(argv: list[str], address_space_mb: int | None = None) -> tuple[float, float, int]:
    """(seconds, peak RSS in MB, exit code) of `kasparctl ARGV` in its own process,
    under an address-space limit when one is given."""

    def limit() -> None:
        if address_space_mb is not None:
            size = address_space_mb << 20
            resource.setrlimit(resource.RLIMIT_AS, (size, size))

    started = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-c", PEAK, *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=limit,
    )
    elapsed = time.perf_counter() - started
    lines = reversed(result.stderr.splitlines())
    peak = next(int(line.split()[1]) for line in lines if line.startswith("VmHWM"))
    return elapsed, peak / 1024, result.returncode


def bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--mb", type=float, default=200.0)
    parser.add_argument("--sessions", type=int, default=1)
    parser.add_argument("--dir", type=Path, default=None)
    parser.add_argument("--json", action="store_true")
    arguments = parser.parse_args()
    root = arguments.dir or Path(tempfile.mkdtemp(prefix="kaspar-bench-scale-"))
    try:
        started = time.perf_counter()
        state = make(root, arguments.mb, arguments.sessions)
        size = sum(p.stat().st_size for p in state.rglob("records.jsonl"))
        made_s = time.perf_counter() - started
        out = root / "out"
        out.mkdir()
        argv = {
            "sessions": ["sessions", "--state-dir", str(state)],
            "export": [
                "export",
                "--state-dir",
                str(state),
                "--csv",
                str(out / "trials.csv"),
                "--events",
                str(out / "events.csv"),
            ],
            "report": ["report", "--state-dir", str(state), "--out", str(out / "report")],
        }
        # (name, argv, address-space limit in MB, peak-memory target in MB, time target in s)
        runs: list[tuple[str, list[str], int | None, float | None, float | None]] = [
            *((name, argv[name], None, TARGET_MB, TARGET_S) for name in COMMANDS),
            (f"sessions under {LIMITED_AS_MB} MB address space", argv["sessions"],
             LIMITED_AS_MB, None, None),
            (f"simulate --groups {SIMULATE_GROUPS}",
             ["simulate", "--groups", str(SIMULATE_GROUPS), "--seed", "1", "--json"],
             None, SIMULATE_TARGET_MB, None),
        ]
        results = {}
        for name, command, address_space_mb, most_mb, most_s in runs:
            seconds, peak_mb, code = measure(command, address_space_mb)
            results[name] = {
                "seconds": round(seconds, 2),
                "peak_rss_mb": round(peak_mb, 1),
                "exit_code": code,
                "ok": code == 0 and (most_mb is None or peak_mb < most_mb)
                and (most_s is None or seconds < most_s),
            }
        summary = {
            "records_mb": round(size / 1e6, 1),
            "sessions": arguments.sessions,
            "made_s": round(made_s, 1),
            "targets": {"seconds": TARGET_S, "peak_rss_mb": TARGET_MB,
                        "simulate_peak_rss_mb": SIMULATE_TARGET_MB},
            "commands": results,
        }
        if arguments.json:
            print(json.dumps(summary))
        else:
            print(
                f"{summary['records_mb']} MB of records in {arguments.sessions} session(s), "
                f"made in {made_s:.1f} s; targets < {TARGET_S:.0f} s and "
                f"< {TARGET_MB:.0f} MB each, simulate < {SIMULATE_TARGET_MB:.0f} MB"
            )
            for name, result in results.items():
                verdict = "ok" if result["ok"] else "OVER TARGET"
                print(
                    f"  {name:36} {result['seconds']:6.1f} s  {result['peak_rss_mb']:6.1f} MB  "
                    f"exit {result['exit_code']}  {verdict}"
                )
    finally:
        if arguments.dir is None:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    bench()
