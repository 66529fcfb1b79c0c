"""`kasparctl report` (and `export`) over 720 simulated sessions in 24 conditions.

Run on demand: .venv/bin/python bench/bench_report.py [--sessions N] [--games N]
                 [--cache DIR] [--fresh] [--profile FILE] [--keep DIR]
                 [--against CHECKOUT] [--workers N]
Figures: the whole report (read every session, the paper's statistics per condition,
intervals and contrasts, every figure as 300-dpi PNG and PDF, summary.md and .json,
children.csv) in a child process: its wall time (target < 15 s), its CPU seconds, and its
peak RSS (target < 300 MB), the sum over the report's process and the workers drawing its
figures. The machine is shared, so a baseline is timed in the same run (the CSV export of
the same sessions, which reads every record and draws nothing) and the report is also
given as a ratio to it; the CPU seconds are what the load moves least. --profile FILE
writes a cProfile of one more report run and prints what dominates.

Last measured (--games 144 --against a checkout of main at f351b14, load average 2.4 to
3.5): 27.9 s, 24.1 s of CPU, 241 MB, against main's 49.7 s, 37.5 s of CPU, 236 MB (0.56 of
its time, 0.64 of its CPU): the 15 s target is not met (docs/research-data.md, "Scale of a
usual study", says what dominates).

The sessions are real demo games in simulated time: three learner profiles x four
uncertainty modes x both variants (24 conditions), three children a group with
participant codes (every twelfth group without codes, and some codes without a
diagnosis in participants.csv), so every figure meets the case that scaled badly.
They are made once into a cache directory (default ~/.cache/kasparctl/bench-report-<N>,
a few minutes on two idle cores; a run cut short is resumed) and reused; --fresh makes
them again. On a machine too busy to play them all, --games 144 plays 144 (six of each
condition) and makes the rest copies of those, each with its own group, codes and uid:
the report's cost is in the counts, which a copy has like a game.
"""

from __future__ import annotations

import argparse
import io
import multiprocessing
import os
import pstats
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import msgspec

from kasparctl.config import SessionPlan
from kasparctl.log import configure_logging
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo, with_variant
from kasparctl.sim.teacher import Teacher

TARGET_S = 15.0
TARGET_MB = 300.0
DEFAULT_SESSIONS = 720
PROFILES = ("paper", "fast", "slow")
MODES = ("spoken", "body", "both", "none")
VARIANTS = ("names", "pilot")
CHILDREN = 3
# Every UNCODED-th group plays without participant codes: the figures must show them.
UNCODED = 12
# Written last: a cache without it was cut short and is made again.
COMPLETE = "complete"


def condition_of(index: int) -> tuple[str, str, str]:
    profile = PROFILES[index % len(PROFILES)]
    mode = MODES[(index // len(PROFILES)) % len(MODES)]
    variant = VARIANTS[(index // (len(PROFILES) * len(MODES))) % len(VARIANTS)]
    return profile, mode, variant


def codes_of(index: int) -> tuple[str, ...]:
    if index % UNCODED == UNCODED - 1:
        return ()
    return tuple(f"C{index:04d}{child}" for child in range(CHILDREN))


def make_one(arguments: tuple[Path, int]) -> None:
    state_dir, index = arguments
    profile, mode, variant = condition_of(index)
    # One group code per session: parallel workers never race for a session id.
    plan = SessionPlan(
        group=f"B{index:04d}", profile=profile, uncertainty=mode, participants=codes_of(index)
    )  # type: ignore[arg-type]
    config = msgspec.structs.replace(with_variant(demo_config(), variant), sessions=(plan,))
    # Its own state directory while it plays: the demo resumes any unfinished session
    # it finds, and would take over another worker's game in progress.
    scratch = state_dir / ".making" / str(index)
    options = DemoOptions(
        state_dir=scratch,
        seed=index,
        teacher=Teacher(p_wrong_green=0.05, p_wrong_red=0.03, p_no_answer=0.05),
        out=io.StringIO(),
    )
    run_demo(config, options, fast=True)
    (session_dir,) = (scratch / "sessions").iterdir()
    session_dir.rename(state_dir / "sessions" / session_dir.name)
    shutil.rmtree(scratch)


def participants_csv(count: int) -> str:
    lines = ["code,group,age"]
    for index in range(count):
        for child, code in enumerate(codes_of(index)):
            # Some children have no diagnosis recorded: an empty cell, never "None".
            group = "" if (index + child) % 17 == 0 else ("ASC", "TD")[index % 2]
            lines.append(f"{code},{group},{6 + (index + child) % 5}")
    return "\n".join(lines) + "\n"


def played(cache: Path) -> dict[int, Path]:
    """The sessions in the cache by index (a run cut short is resumed, not started again)."""
    found = {}
    for directory in (cache / "sessions").iterdir():
        group = directory.name.rsplit("-", 1)[-1]
        if group.startswith("B") and group[1:].isdigit():
            found[int(group[1:])] = directory
    return found


CROCKFORD = "0123456789ABCDEFGHJKMNPQRSTVWXYZ"


def clone(original: Path, source: int, index: int) -> None:
    """Session `source` again as session `index`: its group, codes and uid made its own.

    For a machine too slow to play every game: the report's cost is in its counts
    (sessions, trials, children, conditions), which a copy has like a game."""
    old_group, new_group = f"B{source:04d}", f"B{index:04d}"
    target = original.parent / original.name.replace(old_group, new_group)
    target.mkdir()
    meta = msgspec.json.decode((original / "plan.json").read_bytes())
    uid = meta["uid"]
    suffix = "".join(CROCKFORD[(index >> shift) & 31] for shift in (15, 10, 5, 0))
    replacements = [(old_group, new_group), (uid, uid[:-4] + suffix)]
    replacements += [
        (f'"C{source:04d}{child}"', f'"C{index:04d}{child}"') for child in range(CHILDREN)
    ]
    for file in original.iterdir():
        text = file.read_text(encoding="utf-8")
        for old, new in replacements:
            text = text.replace(old, new)
        (target / file.name).write_text(text, encoding="utf-8")
        (target / file.name).chmod(0o600)


def ensure_sessions(cache: Path, count: int, games: int, fresh: bool) -> None:
    """`count` sessions in `cache`: at least `games` (a multiple of 24) of them played,
    the rest copies of those."""
    if games % (len(PROFILES) * len(MODES) * len(VARIANTS)):
        sys.exit(f"--games must be a multiple of 24 (the conditions), not {games}")
    if (cache / COMPLETE).exists() and not fresh:
        print(f"using the {count} cached sessions in {cache} (--fresh makes them again)")
        return
    if fresh:
        shutil.rmtree(cache, ignore_errors=True)
    (cache / "sessions").mkdir(parents=True, exist_ok=True)
    shutil.rmtree(cache / ".making", ignore_errors=True)
    done = played(cache)
    todo = [i for i in range(games) if i not in done]
    workers = os.cpu_count() or 1
    print(f"playing {len(todo)} demo games in {cache} with {workers} workers (once)...", flush=True)
    started = time.perf_counter()
    with multiprocessing.Pool(workers, initializer=configure_logging, initargs=("error",)) as pool:
        for finished, _ in enumerate(
            pool.imap_unordered(make_one, [(cache, i) for i in todo], chunksize=4), 1
        ):
            if finished % 50 == 0:
                print(f"  {finished}/{len(todo)}", flush=True)
    shutil.rmtree(cache / ".making", ignore_errors=True)
    done = played(cache)
    real = len(done)
    # Copies keep their original's condition and codes: index i copies i mod `games`, and
    # conditions and uncoded groups cycle every 24 indices, so with `games` a multiple
    # of 24 a copy is what its index would have played.
    for index in range(count):
        if index not in done:
            clone(done[index % games], index % games, index)
    (cache / "participants.csv").write_text(participants_csv(count))
    (cache / COMPLETE).write_text(f"{count} sessions, {real} of them played\n")
    print(f"made in {time.perf_counter() - started:.0f} s")


# Runs one command and reports its own peak RSS (kB on Linux) and the CPU seconds of it and
# its workers as its last line on stderr.
MEASURED = """
import resource, sys
from kasparctl.cli import main
code = main(sys.argv[1:])
own = resource.getrusage(resource.RUSAGE_SELF)
workers = resource.getrusage(resource.RUSAGE_CHILDREN)
cpu = own.ru_utime + own.ru_stime + workers.ru_utime + workers.ru_stime
print("maxrss", own.ru_maxrss, cpu, file=sys.stderr)
sys.exit(code)
"""


PAGE = os.sysconf("SC_PAGE_SIZE")


def tree_rss(root: int) -> tuple[int, int]:
    """The RSS and the PSS (bytes) of process `root` and all its descendants, each summed,
    from /proc (PSS shares a page between the processes mapping it: the memory used)."""
    parents: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as stat:
                # The command name may hold spaces: the fields start after its ")".
                fields = stat.read().rsplit(b")", 1)[1].split()
        except OSError:
            continue
        parents[int(entry)] = int(fields[1])
    family, grew = {root}, True
    while grew:
        more = {pid for pid, parent in parents.items() if parent in family} - family
        family |= more
        grew = bool(more)
    rss = pss = 0
    for pid in family:
        try:
            with open(f"/proc/{pid}/statm", "rb") as statm:
                rss += int(statm.read().split()[1]) * PAGE
            with open(f"/proc/{pid}/smaps_rollup", "rb") as rollup:
                for line in rollup:
                    if line.startswith(b"Pss:"):
                        pss += int(line.split()[1]) * 1024
                        break
        except OSError:
            continue
    return rss, pss


def run(argv: list[str], code: Path | None = None) -> tuple[float, float, float, float]:
    """One kasparctl command in a child process: its wall time (s) and peak RSS (MB), the
    RSS of the command and of every worker process it starts, summed while they run
    (sampled every 50 ms), or the command's own peak if that is higher; the peak of
    their PSS summed; and the CPU seconds they used (on a shared box, what the load
    does not move).

    `code`: a checkout of another version of kasparctl to run instead of this one."""
    environment = dict(os.environ)
    if code is not None:
        environment["PYTHONPATH"] = str(code)
    started = time.perf_counter()
    child = subprocess.Popen(
        [sys.executable, "-c", MEASURED, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=environment,
        # Not in this checkout: `python -c` puts the working directory first on sys.path.
        cwd=tempfile.gettempdir(),
    )
    highest = [0, 0]
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(0.05):
            rss, pss = tree_rss(child.pid)
            highest[:] = max(highest[0], rss), max(highest[1], pss)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, stderr = child.communicate()
    elapsed = time.perf_counter() - started
    stop.set()
    sampler.join()
    if child.returncode != 0:
        sys.exit(f"kasparctl {' '.join(argv)} failed with {child.returncode}:\n{stderr}")
    _, maxrss, cpu = stderr.strip().splitlines()[-1].split()
    own = int(maxrss) * 1024
    return elapsed, max(own, highest[0]) / 2**20, highest[1] / 2**20, float(cpu)


def profiled(argv: list[str], where: Path) -> None:
    """A cProfile of one report, and what dominates it."""
    subprocess.run(
        [sys.executable, "-m", "cProfile", "-o", str(where), "-m", "kasparctl", *argv],
        capture_output=True,
        check=True,
    )
    stats = pstats.Stats(str(where), stream=sys.stdout)
    print(f"cProfile of one report ({where}), by cumulative time:")
    stats.sort_stats("cumulative").print_stats(
        r"research/(report|conditions|inference|figures|summary|catalogue)|savefig|draw_all", 25
    )


def bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sessions", type=int, default=DEFAULT_SESSIONS)
    parser.add_argument("--cache", type=Path, default=None)
    parser.add_argument(
        "--games",
        type=int,
        default=None,
        help="play only this many games (a multiple of 24) and copy them up to --sessions",
    )
    parser.add_argument("--fresh", action="store_true")
    parser.add_argument("--profile", type=Path, default=None, metavar="FILE")
    parser.add_argument(
        "--against",
        type=Path,
        default=None,
        metavar="CHECKOUT",
        help="also time the report of another version (a checkout, e.g. the main branch's)",
    )
    parser.add_argument(
        "--workers", type=int, default=None, help="the report's --workers (default: its own)"
    )
    parser.add_argument("--keep", type=Path, default=None, metavar="DIR", help="keep the report")
    arguments = parser.parse_args()
    cache = arguments.cache or Path.home() / ".cache" / "kasparctl" / (
        f"bench-report-{arguments.sessions}"
    )
    ensure_sessions(
        cache, arguments.sessions, arguments.games or arguments.sessions, arguments.fresh
    )
    with tempfile.TemporaryDirectory(prefix="kaspar-bench-report-") as scratch:
        out = Path(scratch)
        report = [
            "report",
            "--state-dir",
            str(cache),
            "--participants",
            str(cache / "participants.csv"),
            *(["--workers", str(arguments.workers)] if arguments.workers else []),
            "--out",
            str(out / "report"),
        ]
        if arguments.against:
            other_s, other_mb, _, other_cpu = run(
                [*report[:-1], str(out / "other")], arguments.against
            )
        report_s, report_mb, report_pss, report_cpu = run(report)
        export = ["export", "--state-dir", str(cache), "--csv", str(out / "trials.csv")]
        export_s, _, _, _ = run(export)
        rows = (out / "trials.csv").read_text().count("\n") - 1
        figures = sorted(p.name for p in (out / "report").iterdir() if p.suffix == ".png")
        if arguments.keep:
            shutil.copytree(out / "report", arguments.keep, dirs_exist_ok=True)
        if arguments.profile:
            profiled([*report[:-1], str(out / "profiled")], arguments.profile)
    time_verdict = "ok" if report_s < TARGET_S else "OVER TARGET"
    rss_verdict = "ok" if report_mb < TARGET_MB else "OVER TARGET"
    print(f"{arguments.sessions} sessions, {rows} trial rows, {len(figures)} PNG pages")
    print(
        f"report: {report_s:.1f} s (target < {TARGET_S:.0f} s) {time_verdict}; "
        f"{report_cpu:.1f} s of CPU"
    )
    print(
        f"report peak RSS, its processes summed: {report_mb:.0f} MB "
        f"(target < {TARGET_MB:.0f} MB) {rss_verdict}; peak PSS summed {report_pss:.0f} MB"
    )
    if arguments.against:
        print(
            f"the same report by {arguments.against}: {other_s:.1f} s ({other_cpu:.1f} s of CPU), "
            f"peak RSS {other_mb:.0f} MB; this one takes {report_s / other_s:.2f} of its time "
            f"and {report_cpu / other_cpu:.2f} of its CPU"
        )
    print(
        f"baseline, the trials export of the same sessions: {export_s:.1f} s; "
        f"report / baseline = {report_s / export_s:.2f}"
    )


if __name__ == "__main__":
    bench()
