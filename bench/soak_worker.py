"""One soak worker: plays its games one after another in simulated time, injecting faults.

Run by bench/soak.py, which restarts it after each SIGKILL the injector deals it:
a restarted worker resumes the interrupted session, as the daemon does at boot,
and goes on with its other games. Each game keeps its state, log, ledger and
result in its own directory.
"""

from __future__ import annotations

import argparse
import asyncio
import io
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "bench")]

import msgspec  # noqa: E402
import numpy as np  # noqa: E402
from soak_faults import KINDS, MAX_KILLS_PER_GAME, Injector, Ledger, StateWatch  # noqa: E402
from soak_rig import (  # noqa: E402
    EmulatedServos,
    HangingSink,
    MonitoredHerkulex,
    MotionMonitor,
    Violation,
    emulated_settings,
)

from hal.clock import LoopClock  # noqa: E402
from hal.voice.speaker import Voice  # noqa: E402
from kasparctl.config import UNCERTAINTY_MODES, Config  # noqa: E402
from kasparctl.game.jsonl import read_json_lines  # noqa: E402
from kasparctl.game.resume import find_unfinished  # noqa: E402
from kasparctl.game.session import RECORDS_FILE  # noqa: E402
from kasparctl.game.storage import write_atomic  # noqa: E402
from kasparctl.log import configure_logging  # noqa: E402
from kasparctl.sim import simtime  # noqa: E402
from kasparctl.sim.demo import DemoOptions, assemble, demo_config, with_variant  # noqa: E402

# A simulated researcher resumes after every fault, and again when the robot refuses
# (a servo still silent); only after this many tries in one game do they stop it.
PATIENCE = 40
# The robot's own health poll (hal.servos.settings' default), not the demo's relaxed one.
POLL_INTERVAL_S = 1.0
# A game takes 5-15 simulated minutes with its faults; one still going after this has
# stalled. (Far below the demo's 12 hours: each simulated second of a stalled game
# still costs six real health reads.)
STALL_LIMIT_S = 2 * 3600.0


def soak_config(game: int) -> Config:
    """The demo robot, playing the names game or (every other game) the pilot, each game in
    the next uncertainty mode (spoken, body, both, none: the body's thinking, its hesitant
    and quick points and nods in two games of four)."""
    config = with_variant(demo_config(), "pilot" if game % 2 else "names")
    servos = msgspec.structs.replace(config.servos, poll_interval_s=POLL_INTERVAL_S)
    mode = UNCERTAINTY_MODES[game % len(UNCERTAINTY_MODES)]
    plans = tuple(
        msgspec.structs.replace(plan, uncertainty=mode, speak_uncertainty=None)
        for plan in config.sessions
    )
    return msgspec.structs.replace(config, servos=servos, sessions=plans)


def game_seed(seed: int, game: int) -> int:
    return seed * 1_000_003 + game


async def play(game: int, directory: Path, seed: int, faults: int, ledger: Ledger) -> dict:
    loop = asyncio.get_running_loop()
    config = soak_config(game)
    entries = ledger.entries()
    incarnation = sum(e["event"] == "start" for e in entries) - 1
    kills = sum(e.get("kind") == "sigkill" for e in entries)

    def violation(found: Violation) -> None:
        ledger.write(event="violation", joint=found.joint, kind=found.kind, detail=found.detail)

    monitor = MotionMonitor(config.servos, violation)
    ids = [joint.id for joint in config.servos.joints]
    emulator = MonitoredHerkulex(directory / "tty", ids, monitor, loop.time)
    try:
        clock = LoopClock()
        servos = EmulatedServos(emulated_settings(config.servos, emulator.path), emulator, clock)
        sink = HangingSink(clock, config.voice.rate)
        voice = Voice(config.voice, clock, sink=sink)
        options = DemoOptions(
            state_dir=directory / "state", seed=game_seed(seed, game), out=io.StringIO()
        )
        # The configuration's body (the demo robot's: on), streaming on the same emulated bus.
        rig = assemble(config, options, servos, voice, patience=PATIENCE)
        watch = StateWatch()
        watch.resumed.append(lambda: ledger.write(event="resumed", wall=time.time()))
        rig.game.listeners.append(watch)
        rng = np.random.default_rng([seed, game, incarnation])
        injector = Injector(
            rig.game, servos, emulator, rig.keyfob, sink, ledger, directory / "log.jsonl", rng,
            first_kind=KINDS[(game + incarnation) % len(KINDS)],
            faults=faults,
            may_kill=kills < MAX_KILLS_PER_GAME,
            watch=watch,
        )
        task = loop.create_task(injector.run(), name="fault injector")
        running = loop.create_task(rig.run(), name="game")
        try:
            await asyncio.wait({running}, timeout=STALL_LIMIT_S)
        finally:
            task.cancel()
            (injector_outcome,) = await asyncio.gather(task, return_exceptions=True)
        if not running.done():  # stalled: the game is cancelled to report it
            running.cancel()
            await asyncio.gather(running, return_exceptions=True)
            result = None
        else:
            result = running.result()  # an exception here is a crash: it ends the worker
        if injector.kill_armed:
            time.sleep(5.0)  # the armed SIGKILL lands here at the latest
        return {
            "game": game,
            "stalled": result is None,
            "finished": bool(result and result.finished),
            "final_state": result.final_state if result else rig.game.stage,
            "trials": result.trials if result else None,
            "goals_checked": monitor.goals_checked,
            "violations": monitor.violations,
            "bus": vars(servos.driver.bus.stats),
            # A failed injector would quietly inject fewer faults: soak.py reports it.
            "injector_error": (
                repr(injector_outcome) if isinstance(injector_outcome, Exception) else None
            ),
        }
    finally:
        emulator.stop()


def finished_before(directory: Path) -> bool:
    """A session that finished, SIGKILLed before its result was written: nothing to replay."""
    state = directory / "state"
    sessions = state / "sessions"
    return sessions.is_dir() and any(sessions.iterdir()) and find_unfinished(state) is None


def run_game(game: int, root: Path, seed: int, faults: int) -> None:
    directory = root / f"game-{game:04d}"
    result_path = directory / "result.json"
    if result_path.exists():
        return
    directory.mkdir(parents=True, exist_ok=True)
    ledger = Ledger(directory / "ledger.jsonl")
    if finished_before(directory):
        (session,) = (directory / "state" / "sessions").iterdir()
        records = read_json_lines(session / RECORDS_FILE).records
        trials = sum(r["kind"] == "trial" for r in records)
        result = {"game": game, "finished": True, "final_state": "finished", "trials": trials,
                  "stalled": False, "recovered_from_disk": True}
    else:
        ledger.write(event="start", wall=time.time())
        log = (directory / "log.jsonl").open("a", buffering=1)  # line by line: survives SIGKILL
        configure_logging("info", "json", stream=log)
        try:
            result = simtime.run(play(game, directory, seed, faults, ledger), virtual=True)
        finally:
            log.close()
    ledger.write(event="end", **{k: v for k, v in result.items() if k != "bus"})
    write_atomic(result_path, json.dumps(result, sort_keys=True).encode())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--root", type=Path, required=True)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--faults", type=int, default=3, help="faults per game")
    parser.add_argument("games", type=int, nargs="+")
    args = parser.parse_args(argv)
    for game in args.games:
        run_game(game, args.root, args.seed, args.faults)
    return 0


if __name__ == "__main__":
    sys.exit(main())
