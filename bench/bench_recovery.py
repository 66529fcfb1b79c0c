"""A game that recovers: bags learned wrong and the longest run on one bag, before and after.

Run on demand: .venv/bin/python bench/bench_recovery.py [--games N] [--demo-games N] [--json]

Names games (6 bags, 6 toys, the paper's learner) with a noisy teacher: a green for
a wrong guess 10 % of the time, a red for the right one 5 %. One wrongly learned name
is withdrawn from the later bags, so the bag it belongs to cannot be learned right.
Each game is played twice on the same seed: as before (nobody re-opens anything) and
with recovery (kasparctl.game.recovery: Kaspar says it is confused, and a researcher
who knows the bags re-opens the names learned last down to the one learned wrong).

1. The scalar simulator (kasparctl.sim.simulate, `--recover`), `--games` games.
2. The whole game on the simulated robot (kasparctl demo: records, the researcher's
   reopen key, the lines Kaspar says), `--demo-games` games, with recovery.

Targets: with recovery at most 1 % of bags learned wrong (before: about 2 %), no bag
given up, and the longest run of guesses on one bag below the give-up limit (30).
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from kasparctl.game.records import ConfusedRecord, ReopenRecord, TrialRecord
from kasparctl.game.session import Session
from kasparctl.log import configure_logging
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo, with_variant
from kasparctl.sim.simulate import iter_groups
from kasparctl.sim.teacher import Teacher

TEACHER = Teacher(p_wrong_green=0.10, p_wrong_red=0.05)
SEED = 2027
TARGET_WRONG = 0.01


def simulated(games: int, recover: bool) -> dict[str, Any]:
    """Figures of `games` simulated names games (the same seeds either way)."""
    config = demo_config()
    game = with_variant(config, "names").game
    params = config.profile("paper")
    bags = wrong = given_up = longest = trials = reopened = 0
    for problems in iter_groups(games, game, params, TEACHER, SEED, recover=recover):
        for problem in problems:
            bags += 1
            trials += len(problem.trials)
            wrong += problem.learned is not None and problem.learned != problem.answer
            given_up += problem.learned is None
            longest = max(longest, len(problem.trials))
            reopened += problem.reopened
    return {
        "games": games,
        "bags": bags,
        "learned_wrong": wrong,
        "learned_wrong_share": wrong / bags,
        "given_up": given_up,
        "longest_run": longest,
        "trials_per_game": trials / games,
        "reopens_per_game": reopened / games,
    }


def demo_games(games: int) -> dict[str, Any]:
    """The whole game on the simulated robot, with recovery, `games` seeds."""
    config = with_variant(demo_config(), "names")
    bags = wrong = given_up = longest = trials = reopens = confused = finished = 0
    for seed in range(games):
        with tempfile.TemporaryDirectory() as directory:
            options = DemoOptions(
                state_dir=Path(directory), seed=SEED + seed, teacher=TEACHER, out=io.StringIO()
            )
            result = run_demo(config, options, fast=True)
            finished += result.finished
            (path,) = (Path(directory) / "sessions").iterdir()
            session, _ = Session.open(path)
            records = session.records()
            session.close()
        key = [config.game.toys.index(t) for t in session.plan["plan"]["answer_key"]]
        runs: dict[int, int] = {}
        learned: dict[int, int | None] = {}
        for record in records:
            if isinstance(record, TrialRecord):
                runs[record.target_index] = runs.get(record.target_index, 0) + 1
                learned[record.target_index] = record.choice_index if record.learned else None
            elif isinstance(record, ReopenRecord):
                learned[record.target_index] = (
                    None if record.taken_back is not True else record.name_index
                )
                reopens += record.taken_back is not True
            elif isinstance(record, ConfusedRecord):
                confused += 1
        trials += sum(runs.values())
        longest = max(longest, *runs.values())
        for target in range(len(key)):
            bags += 1
            label = learned.get(target)
            wrong += label is not None and label != key[target]
            given_up += label is None
    return {
        "games": games,
        "finished": finished,
        "bags": bags,
        "learned_wrong": wrong,
        "learned_wrong_share": wrong / bags if bags else 0.0,
        "given_up": given_up,
        "longest_run": longest,
        "trials_per_game": trials / games if games else 0.0,
        "confused_per_game": confused / games if games else 0.0,
        "reopens_per_game": reopens / games if games else 0.0,
    }


def main() -> int:
    """Print the figures against the targets; 1 when a target is missed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--games", type=int, default=1000)
    parser.add_argument("--demo-games", type=int, default=20)
    parser.add_argument("--json", action="store_true")
    arguments = parser.parse_args()
    configure_logging(level="error")
    started = time.perf_counter()
    before = simulated(arguments.games, recover=False)
    after = simulated(arguments.games, recover=True)
    demo = demo_games(arguments.demo_games) if arguments.demo_games else None
    elapsed = time.perf_counter() - started
    met = (
        after["learned_wrong_share"] <= TARGET_WRONG
        and after["given_up"] == 0
        and after["longest_run"] < 30
        and (
            demo is None
            or (demo["learned_wrong_share"] <= TARGET_WRONG and demo["finished"] == demo["games"])
        )
    )
    figures = {"before": before, "after": after, "demo_after": demo, "seconds": round(elapsed, 1)}
    if arguments.json:
        print(json.dumps({**figures, "target_met": met}))
        return 0 if met else 1
    print(
        f"names games, teacher: wrong green {TEACHER.p_wrong_green}, wrong red "
        f"{TEACHER.p_wrong_red}; seed {SEED}; {elapsed:.0f} s"
    )
    rows = [
        ("bags learned wrong", "learned_wrong_share", lambda v: f"{100 * v:.2f} %"),
        ("bags given up", "given_up", str),
        ("longest run on one bag", "longest_run", str),
        ("guesses per game", "trials_per_game", lambda v: f"{v:.2f}"),
        ("re-opens per game", "reopens_per_game", lambda v: f"{v:.3f}"),
    ]
    if demo:
        print(f"Kaspar confused per whole game: {demo['confused_per_game']:.2f}")
    print(f"{'':28}{'before':>12}{'after':>12}" + (f"{'game, after':>14}" if demo else ""))
    for label, key, show in rows:
        line = f"{label:28}{show(before[key]):>12}{show(after[key]):>12}"
        if demo:
            line += f"{show(demo[key]):>14}"
        print(line)
    print(
        f"({before['games']} simulated games each way"
        + (
            f"; {demo['games']} whole games on the simulated robot, {demo['finished']} finished)"
            if demo
            else ")"
        )
    )
    print(
        f"target: at most {100 * TARGET_WRONG:.0f} % of bags learned wrong, none given up, "
        f"the longest run under 30: {'met' if met else 'MISSED'}"
    )
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
