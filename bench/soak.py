"""The fault-injection soak: many whole games in simulated time, each with faults, then the proof.

Each game runs on the robot's own game, sessions, safety layer and HerkuleX
driver, talking to a pty emulator (bench/soak_rig.py), with faults injected one
at a time (bench/soak_faults.py): a servo that stops answering, corrupt replies
(absorbed by the bus's retries, or one more than it retries), the USB adapter
unplugged and back, the keyfob unplugged and back, the voice engine hanging,
and SIGKILL followed by a restart that resumes the session. Workers run in
parallel processes; this script restarts a killed worker and reads back what
is on disk: the session records, the log and each game's fault ledger.

Targets: 0 crashes, 0 trials lost or duplicated, 0 joint-limit or speed
violations, every injected fault recorded.

Run: .venv/bin/python bench/soak.py [--games 1000] [--workers 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "bench")]

from soak_faults import KINDS  # noqa: E402

from kasparctl.game.jsonl import read_json_lines  # noqa: E402
from kasparctl.game.session import RECORDS_FILE  # noqa: E402

WORKER = ROOT / "bench" / "soak_worker.py"
MAX_CRASHES_PER_WORKER = 5


@dataclass
class Worker:
    games: list[int]
    process: subprocess.Popen[bytes] | None = None
    kills: int = 0
    crashes: list[str] = field(default_factory=list)
    done: bool = False


def run_workers(root: Path, games: int, workers: int, seed: int, faults: int) -> list[Worker]:
    pool = [Worker(list(range(start, games, workers))) for start in range(workers)]

    def start(worker: Worker) -> None:
        argv = [sys.executable, str(WORKER), "--root", str(root), "--seed", str(seed),
                "--faults", str(faults), *map(str, worker.games)]
        # A file, not a pipe: a chatty worker must never block on a full pipe.
        with (root / f"worker-{worker.games[0]}.err").open("ab") as stderr:
            worker.process = subprocess.Popen(
                argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=stderr
            )

    for worker in pool:
        start(worker)
    while not all(w.done for w in pool):
        time.sleep(0.05)
        for worker in pool:
            if worker.done or worker.process is None or worker.process.poll() is None:
                continue
            code = worker.process.returncode
            stderr = (root / f"worker-{worker.games[0]}.err").read_text(errors="replace")
            if code == 0:
                worker.done = True
            elif code == -9:  # the injector's SIGKILL: restart, as systemd would
                worker.kills += 1
                start(worker)
            else:
                worker.crashes.append(stderr[-2000:] or f"exit {code}")
                if len(worker.crashes) >= MAX_CRASHES_PER_WORKER:
                    worker.done = True
                else:
                    start(worker)
    return pool


def percentiles(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"n": 0, "p50": None, "p95": None, "max": None}
    ordered = sorted(values)
    p95 = ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]
    return {"n": len(values), "p50": statistics.median(ordered), "p95": p95, "max": ordered[-1]}


def check_game(directory: Path) -> dict[str, Any]:
    """What one game's files prove: its trials, its faults and what became of them."""
    out: dict[str, Any] = {"game": directory.name, "problems": []}
    result_path = directory / "result.json"
    result = json.loads(result_path.read_text()) if result_path.exists() else None
    out["result"] = result
    if result is None:
        out["problems"].append("no result: the worker never finished this game")
    elif result.get("stalled"):
        out["problems"].append(f"stalled in state {result.get('final_state')}")
    if result and result.get("injector_error"):
        out["problems"].append(f"the fault injector failed: {result['injector_error']}")
    out["stalled"] = bool(result and result.get("stalled"))
    ledger_path = directory / "ledger.jsonl"
    ledger = [json.loads(line) for line in ledger_path.read_text().splitlines() if line.strip()]
    out["faults"] = [e for e in ledger if e["event"] == "fault"]
    out["violations"] = [e for e in ledger if e["event"] == "violation"]
    sessions = sorted((directory / "state" / "sessions").glob("*"))
    out["sessions"] = len(sessions)
    # The uncertainty mode the game played (its body's thinking and points in body and both).
    out["uncertainty"] = None
    for session in sessions:
        plan_path = session / "plan.json"
        if plan_path.exists():
            out["uncertainty"] = json.loads(plan_path.read_text()).get("uncertainty")
    if len(sessions) != 1:
        out["problems"].append(f"{len(sessions)} sessions, expected 1")
    records: list[dict[str, Any]] = []
    torn = 0
    for session in sessions:
        read = read_json_lines(session / RECORDS_FILE)
        records += read.records
        torn += len(read.warnings)
        torn_file = session / (RECORDS_FILE + ".torn")
        torn += torn_file.read_bytes().count(b"\n") + 1 if torn_file.exists() else 0
    out["torn"] = torn
    seqs = [r["seq"] for r in records]
    if seqs != list(range(1, len(seqs) + 1)):
        out["problems"].append("record sequence has gaps or repeats")
    trials = [r["trial"] for r in records if r["kind"] == "trial"]
    counts = Counter(trials)
    out["trials"] = len(trials)
    out["trials_duplicated"] = sum(n - 1 for n in counts.values() if n > 1)
    out["trials_lost"] = (max(trials) - len(counts)) if trials else 0
    out["software_faults"] = [
        r for r in records if r["kind"] == "fault" and r.get("fault") == "software"
    ]
    steps = [r["to"] for r in records if r["kind"] == "step"]
    out["final_step"] = steps[-1] if steps else None
    # A SIGKILL is recorded when the restarted robot wrote that it resumed the session.
    resumed_seqs = [
        r["seq"] for r in records if r["kind"] == "session" and r.get("event") == "resumed"
    ]
    resumed_walls = [e["wall"] for e in ledger if e["event"] == "resumed"]
    for kill in (f for f in out["faults"] if f["kind"] == "sigkill"):
        after = [s for s in resumed_seqs if s > kill["records_at_kill"]]
        kill["recorded_after"] = 0.0 if after else None
        walls = [w for w in resumed_walls if w > kill["wall"]]
        kill["recovered_after"] = walls[0] - kill["wall"] if walls else None
        if not after and result and result.get("recovered_from_disk"):
            kill["landed_after_end"] = True  # the game had finished: nothing to resume
    return out


def analyse(root: Path) -> dict[str, Any]:
    games = [check_game(d) for d in sorted(root.glob("game-*"))]
    injected: Counter[str] = Counter()
    recorded: Counter[str] = Counter()
    detection: dict[str, list[float]] = defaultdict(list)
    recovery: dict[str, list[float]] = defaultdict(list)
    unrecorded: list[dict[str, Any]] = []
    for game in games:
        for fault in game["faults"]:
            kind = fault["kind"]
            if fault.get("landed_after_end"):
                continue
            injected[kind] += 1
            if fault.get("recorded_after") is not None:
                recorded[kind] += 1
                detection[kind].append(fault["recorded_after"])
            else:
                unrecorded.append({"game": game["game"], **fault})
            if fault.get("recovered_after") is not None:
                recovery[kind].append(fault["recovered_after"])
    finished = sum(1 for g in games if g["final_step"] == "finished")
    stopped = sum(1 for g in games if g["final_step"] == "stopped")
    problems = [(g["game"], p) for g in games for p in g["problems"]]
    return {
        "games": len(games),
        "finished": finished,
        "stopped_by_researcher": stopped,
        "trials": sum(g["trials"] for g in games),
        "uncertainty_modes": dict(Counter(str(g["uncertainty"]) for g in games)),
        "trials_lost": sum(g["trials_lost"] for g in games),
        "trials_duplicated": sum(g["trials_duplicated"] for g in games),
        "torn_lines_repaired": sum(g["torn"] for g in games),
        "software_faults": sum(len(g["software_faults"]) for g in games),
        "goals_checked": sum((g["result"] or {}).get("goals_checked", 0) or 0 for g in games),
        "violations": sum(len(g["violations"]) for g in games),
        "violation_examples": [v for g in games for v in g["violations"]][:5],
        "injected": {k: injected[k] for k in KINDS},
        "recorded": {k: recorded[k] for k in KINDS},
        "unrecorded_examples": unrecorded[:5],
        "detection_s": {k: percentiles(detection[k]) for k in KINDS},
        "recovery_s": {k: percentiles(recovery[k]) for k in KINDS},
        "kills_after_end": sum(
            1 for g in games for f in g["faults"] if f.get("landed_after_end")
        ),
        "stalled": sum(g["stalled"] for g in games),
        "problems": problems[:20],
        "problem_count": len(problems),
    }


def verdict(report: dict[str, Any]) -> dict[str, bool]:
    return {
        "0 crashes": report["crashes"] == 0,
        "0 trials lost or duplicated": report["trials_lost"] + report["trials_duplicated"] == 0,
        "0 joint-limit or speed violations": report["violations"] == 0,
        "every injected fault recorded": report["injected"] == report["recorded"],
        "every game ended cleanly (finished or stopped, no problem found)":
        report["problem_count"] == 0
        and report["finished"] + report["stopped_by_researcher"] == report["games"],
    }


def soak(games: int, workers: int, seed: int, faults: int, root: Path) -> dict[str, Any]:
    started = time.monotonic()
    pool = run_workers(root, games, workers, seed, faults)
    report = analyse(root)
    report["wall_s"] = time.monotonic() - started
    report["worker_restarts_after_sigkill"] = sum(w.kills for w in pool)
    report["worker_crashes"] = [c for w in pool for c in w.crashes]
    report["crashes"] = (
        len(report["worker_crashes"]) + report["software_faults"]
        + report["stalled"]
    )
    report["targets"] = verdict(report)
    report["state_root"] = str(root)
    return report


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def print_report(report: dict[str, Any]) -> None:
    rate = report["games"] / report["wall_s"] * 60
    print(f"soak: {report['games']} games in {report['wall_s']:.0f} s wall "
          f"({rate:.0f} games/min), state in {report['state_root']}")
    print(f"  finished {report['finished']}, stopped by the researcher "
          f"{report['stopped_by_researcher']}, trials {report['trials']}")
    modes = ", ".join(f"{mode} {n}" for mode, n in sorted(report["uncertainty_modes"].items()))
    print(f"  games by uncertainty mode: {modes}")
    print(f"  crashes {report['crashes']} (worker {len(report['worker_crashes'])}, software faults "
          f"{report['software_faults']}), worker restarts after SIGKILL "
          f"{report['worker_restarts_after_sigkill']}")
    print(f"  trials lost {report['trials_lost']}, duplicated {report['trials_duplicated']}; "
          f"torn record lines repaired {report['torn_lines_repaired']}")
    print(f"  goals checked {report['goals_checked']}, violations {report['violations']}")
    print("  fault kind       injected recorded  detect p50/max (s)  recover p50/p95/max (s)")
    for kind in KINDS:
        det, rec = report["detection_s"][kind], report["recovery_s"][kind]
        unit = " real" if kind == "sigkill" else ""
        print(f"  {kind:<16} {report['injected'][kind]:>8} {report['recorded'][kind]:>8}  "
              f"{_fmt(det['p50']):>7}/{_fmt(det['max']):<7}     "
              f"{_fmt(rec['p50'])}/{_fmt(rec['p95'])}/{_fmt(rec['max'])}{unit}")
    for name, met in report["targets"].items():
        print(f"  target {name}: {'met' if met else 'MISSED'}")
    for game, problem in report["problems"]:
        print(f"  problem: {game}: {problem}")
    for crash in report["worker_crashes"][:3]:
        print("  worker crash:", crash[-600:])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--games", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--faults", type=int, default=3, help="faults per game (at most)")
    parser.add_argument("--out", type=Path, help="where the games' state goes (kept)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    args = parser.parse_args(argv)
    root = args.out or Path(tempfile.mkdtemp(prefix="kaspar-soak-"))
    root.mkdir(parents=True, exist_ok=True)
    report = soak(args.games, args.workers, args.seed, args.faults, root)
    if args.json:
        print(json.dumps(report, sort_keys=True))
    else:
        print_report(report)
    return 0 if all(report["targets"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
