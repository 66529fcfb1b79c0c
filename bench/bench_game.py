"""The game on the simulated robot: speed, latency, the cost of a record, and the study replicated.

Run on demand: .venv/bin/python bench/bench_game.py [--games N]
Figures:
- press to next robot action (a child's answer to Kaspar's reaction): p99, target < 10 ms;
- whole games per second in simulated time, target >= 50 (per variant, state on disk and on tmpfs);
- snapshot + record per trial (fsync included), median and p99;
- the demo's statistics beside `kasparctl simulate` for the same parameters.
"""

from __future__ import annotations

import argparse
import asyncio
import io
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import msgspec

from kasparctl.config import Config
from kasparctl.game.records import CommandRecord, TrialRecord
from kasparctl.game.session import Session
from kasparctl.game.state import GameState
from kasparctl.learning.study_stats import summarise
from kasparctl.log import configure_logging
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, build, demo_config, run_demo, with_variant
from kasparctl.sim.replicate import replicate
from kasparctl.sim.simulate import simulate_study
from kasparctl.sim.teacher import Teacher
from kasparctl.vocabulary import Command

LATENCY_TARGET_MS = 10.0
GAMES_TARGET = 50.0


def config_for(variant: str) -> Config:
    config = demo_config()
    return with_variant(config, variant)


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q * (len(ordered) - 1)))]


def press_to_action_ms(games: int, state_root: Path) -> list[float]:
    """Wall time from a child's answer reaching the game to Kaspar's next say() or move()."""
    latencies: list[float] = []

    async def one(seed: int) -> None:
        rig = build(
            config_for("pilot"),
            DemoOptions(state_dir=state_root / str(seed), seed=seed, out=io.StringIO()),
        )
        pending: list[float] = []
        next_event, say, move = rig.keyfob.next_event, rig.voice.say, rig.servos.move

        async def timed_next_event() -> Any:
            event = await next_event()
            if getattr(event, "kind", None) is not None and event.kind.value == "press":
                pending.append(time.perf_counter())
            return event

        def acted() -> None:
            if pending:
                latencies.append((time.perf_counter() - pending.pop()) * 1000.0)
                pending.clear()

        async def timed_say(text: str, key: str | None = None) -> Any:
            acted()
            return await say(text, key)

        async def timed_move(*args: Any, **kwargs: Any) -> Any:
            acted()
            return await move(*args, **kwargs)

        rig.keyfob.next_event = timed_next_event  # type: ignore[method-assign]
        rig.voice.say = timed_say  # type: ignore[method-assign]
        rig.servos.move = timed_move  # type: ignore[method-assign]
        await rig.run()

    for seed in range(games):
        simtime.run(one(seed), virtual=True)
    return latencies


def stop_to_rest_s(games: int, state_root: Path) -> list[float]:
    """Robot time from the researcher's both-buttons stop to every joint at rest."""
    took: list[float] = []

    async def one(seed: int) -> None:
        rig = build(
            config_for("pilot"),
            DemoOptions(state_dir=state_root / f"stop-{seed}", seed=seed, out=io.StringIO()),
        )
        asked = asyncio.Event()
        rig.game.listeners.append(
            lambda event, info: asked.set() if event == "question" and info["trial"] == 3 else None
        )

        async def researcher() -> None:
            await asked.wait()
            await asyncio.sleep(0.5)  # mid-reaction: Kaspar is talking and may be moving
            await rig.command("stop")

        stopper = asyncio.create_task(researcher())
        loop = asyncio.get_running_loop()
        await rig.run()
        stopper.cancel()
        # rest() returns once the last goal is sent; the joints still travel to it.
        rest = {j.name: j.rest_deg for j in rig.servos.settings.joints}
        while any(abs(rig.servos.true_position(j) - rest[j]) >= 1.0 for j in rest):
            await asyncio.sleep(0.02)
        ended = loop.time()
        session = rig.game.session
        assert session is not None
        both = next(
            r
            for r in session.records()
            if isinstance(r, CommandRecord) and r.command is Command.STOP
        )
        took.append(ended - both.at)

    for seed in range(games):
        simtime.run(one(seed), virtual=True)
    return took


def games_per_second(variant: str, games: int, state_root: Path, live: bool = True) -> float:
    """Whole demo games a second in simulated time, with the robot's live body or a still one."""
    config = config_for(variant)
    if not live:
        config = msgspec.structs.replace(
            config, body=msgspec.structs.replace(config.body, enabled=False))
    start = time.perf_counter()
    for seed in range(games):
        options = DemoOptions(
            state_dir=state_root / f"{variant}-{live}-{seed}", seed=seed, out=io.StringIO()
        )
        result = run_demo(config, options, fast=True)
        assert result.finished, result
    return games / (time.perf_counter() - start)


def record_and_snapshot_ms(state_root: Path, trials: int = 300) -> list[float]:
    config = config_for("names")
    session = Session.create(state_root, {"group": "bench"})
    state = GameState.new(config.game, config.profile(), seed=1)
    trial = TrialRecord(
        trial=1, problem_trial=1, step="guessing", target="bag 1", target_index=0,
        child="child one", child_index=0, candidates=list(config.game.toys),
        probabilities=[1 / 6] * 6, entropy=2.585, band="no_idea", spoken=["x" * 40] * 2,
        choice="lion", choice_index=0, feedback="green", question_end=0.0, feedback_at=1.0,
        reaction_time=1.0, reward=1.0, q_before=[0.0] * 6, q_after=[0.0] * 6,
        learner_rng=state.learner.rng.bit_generator.state, perseverative=False,
        win_shift=False, correct=None, feedback_right=None, learned=False,
    )
    times = []
    for number in range(1, trials + 1):
        start = time.perf_counter()
        session.record(msgspec.structs.replace(trial, trial=number), float(number))
        session.save_state(state)
        times.append((time.perf_counter() - start) * 1000.0)
    session.close()
    return times


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--games", type=int, default=100)
    arguments = parser.parse_args()
    configure_logging("error", "console", stream=sys.stderr)
    disk = Path(tempfile.mkdtemp(prefix="kaspar-bench-", dir="/var/tmp"))
    shm_root = Path("/dev/shm") if Path("/dev/shm").is_dir() else disk
    tmpfs = Path(tempfile.mkdtemp(prefix="kaspar-bench-", dir=shm_root))

    latencies = press_to_action_ms(20, disk)
    p99 = percentile(latencies, 0.99)
    print(
        f"press to next robot action: p50 {statistics.median(latencies):.2f} ms, "
        f"p99 {p99:.2f} ms over "
        f"{len(latencies)} answers, state on disk (target p99 < {LATENCY_TARGET_MS:g} ms) "
        f"{'PASS' if p99 < LATENCY_TARGET_MS else 'FAIL'}"
    )
    stops = stop_to_rest_s(10, disk)
    print(
        f"stop gesture (both held, from key-down) to every joint at rest: median "
        f"{statistics.median(stops):.2f} s, max {max(stops):.2f} s of robot time "
        f"(the 1 s hold, then the rest at each joint's speed limit, goodbye said on the way)"
    )
    for variant in ("pilot", "names"):
        for label, root in (("disk", disk), ("tmpfs", tmpfs)):
            rate = games_per_second(variant, arguments.games // 2, root)
            still = games_per_second(variant, arguments.games // 2, root, live=False)
            verdict = "PASS" if rate >= GAMES_TARGET else "FAIL"
            print(
                f"whole {variant} games in simulated time, state on {label}: {rate:.1f} games/s "
                f"with the live body (target >= {GAMES_TARGET:g}) {verdict}; {still:.1f} with a "
                f"still body, {still / rate:.1f}x (target <= 1.5x)"
            )
    costs = record_and_snapshot_ms(disk)
    print(
        f"record + snapshot per trial (fsync, rename, directory fsync) on disk: median "
        f"{statistics.median(costs):.2f} ms, p99 {percentile(costs, 0.99):.2f} ms"
    )

    config = config_for("pilot")
    for teacher in (Teacher(), Teacher(p_wrong_green=0.1, p_wrong_red=0.1)):
        games = replicate(config, arguments.games, first_seed=10_000, teacher=teacher)
        simulated = summarise(
            simulate_study(10_000, config.game, config.profile(), teacher, seed=1)
        )
        print(
            f"\nthe study replicated, teacher {teacher}: "
            f"{arguments.games} demo games vs 10,000 simulated groups"
        )
        print(f"{'':28}{'demo (game)':>14}{'simulate':>14}")
        for name in (
            "problems",
            "trials_mean",
            "trials_sd",
            "trials_min",
            "trials_max",
            "first_guess_correct_rate",
            "perseverative_error_rate",
            "win_shift_rate",
            "initial_entropy",
            "final_entropy_mean",
        ):
            a, b = getattr(games, name), getattr(simulated, name)
            show = (lambda v: f"{v:14.4f}") if isinstance(a, float) else (lambda v: f"{v:14}")
            print(f"{name:28}{show(a)}{show(b)}")
        pairs = list(zip(games.entropy_by_trial[:6], simulated.entropy_by_trial[:6], strict=False))
        print("entropy by trial 1-6          " + "  ".join(f"{a:.3f}/{b:.3f}" for a, b in pairs))


if __name__ == "__main__":
    asyncio.set_event_loop(None)
    main()
