"""Messy children and a researcher who interrupts: nothing mistaken for anything else.

Run on demand: .venv/bin/python bench/bench_messy_children.py [--answers N] [--json]

Whole names games (all five steps) on the simulated robot in simulated time, with
children who press as children do, at these rates per answer (a step-2 press that
logs a bag is an answer too):

    hold (0.6-5 s, about half of them past the 3 s of a researcher's hold)   20 %
    double tap                                                              10 %
    both buttons, the meant one first (0.15-4 s)                            10 %
    early: pressed while Kaspar is still asking, again once asked if need be 20 %

and a researcher who, besides their next, resumes and re-opens, interrupts at any
moment, open questions included (kasparctl.sim.children.Interruptions):

    pause, resumed 2-8 s later        15 % of questions and bag requests
    undo                               5 % of answers
    stop                               0.5 % of questions (the game ends stopped)

in each place the researcher's commands can come from: their own device (the
default; the children's keyfob carries answers only), the extra keys of the
children's keypad, and the children's keyfob alone (the researcher's holds of
3 s; one begun during a question is no command and no answer, and is held again a
moment later). Targets, per mode: 0 commands a child's press started, 0 researcher
commands taken as the children's answer (both counted from the records against the
simulated people's own key times), 0 answers not taken as meant, every session
finished or stopped by the researcher. Also reported: holds on one keyfob that were
neither (pressed again), the median time from an answer to the end of Kaspar's next
question, and Kaspar's speech per trial.
"""

from __future__ import annotations

import argparse
import io
import json
import statistics
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

import msgspec

from kasparctl.config import Config
from kasparctl.game.presses import HELD
from kasparctl.game.records import PressRecord
from kasparctl.log import configure_logging
from kasparctl.sim import simtime
from kasparctl.sim.children import Interruptions
from kasparctl.sim.demo import DemoOptions, DemoResult, DemoRig, build, demo_config
from kasparctl.sim.teacher import Messiness

RATES = Messiness(p_hold=0.20, p_double=0.10, p_both=0.10, p_early=0.20)
RESEARCHER = Interruptions(p_pause=0.15, p_undo=0.05, p_stop=0.005)
MODES = ("device", "keypad", "keyfob")
KEYPAD = {"KEY_F1": "next", "KEY_F2": "pause", "KEY_F3": "undo", "KEY_F4": "stop"}


def config_for(mode: str) -> Config:
    """The demo robot with the researcher's commands on their device, a keypad's extra
    keys, or the children's keyfob."""
    config = demo_config()
    keyfob = msgspec.structs.replace(config.keyfob, commands=KEYPAD if mode == "keypad" else {})
    return msgspec.structs.replace(
        config,
        keyfob=keyfob,
        researcher=msgspec.structs.replace(config.researcher, source=mode),
    )


def one_game(
    config: Config, seed: int, root: Path, messiness: Messiness, researcher: Interruptions
) -> tuple[DemoResult, int, Counter[str]]:
    """A whole game; its result, how many answers the children gave (trials + poses) and
    how they and the researcher pressed."""
    options = DemoOptions(
        state_dir=root / str(seed),
        seed=seed,
        messiness=messiness,
        interruptions=researcher,
        out=io.StringIO(),
    )

    async def main() -> tuple[DemoResult, DemoRig[Any]]:
        rig = build(config, options)
        return await rig.run(), rig

    result, rig = simtime.run(main(), virtual=True)
    assert rig.children is not None
    presses = rig.children.presses
    shown = sum(press.bag is not None for press in presses)
    kinds: Counter[str] = Counter()
    for press in presses:
        words = press.action.split()
        kinds[words[0] if len(words) > 1 else "press"] += 1
        kinds["early"] += press.early
        if words[0] in ("hold", "chord") and float(words[2]) >= config.researcher.hold_s:
            kinds[f"{words[0]} past the researcher's hold"] += 1
    for action in rig.researcher_actions:
        kinds[f"researcher {action.command}"] += 1
    assert rig.game.session is not None
    kinds["held, neither answer nor command"] += sum(
        isinstance(r, PressRecord) and r.ignored == HELD for r in rig.game.session.records()
    )
    return result, result.trials + shown, kinds


def run_mode(
    mode: str,
    answers_wanted: int,
    messiness: Messiness = RATES,
    researcher: Interruptions = RESEARCHER,
) -> dict[str, Any]:
    """Games in `mode` until the children have given `answers_wanted` answers."""
    config = config_for(mode)
    totals: dict[str, Any] = {
        "mode": mode,
        "games": 0,
        "answers": 0,
        "trials": 0,
        "accidental_commands": 0,
        "commands_taken_as_answers": 0,
        "answers_lost": 0,
        "stopped_by_researcher": 0,
        "unfinished": 0,
    }
    gaps: list[float] = []
    speech: list[float] = []
    kinds: Counter[str] = Counter()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="kaspar-messy-") as scratch:
        seed = 0
        while totals["answers"] < answers_wanted:
            result, answers, pressed = one_game(
                config, seed, Path(scratch), messiness, researcher
            )
            kinds += pressed
            totals["games"] += 1
            totals["answers"] += answers
            totals["trials"] += result.trials
            totals["accidental_commands"] += result.accidental_commands
            totals["commands_taken_as_answers"] += result.commands_taken_as_answers
            totals["answers_lost"] += result.answers_lost
            stopped = pressed["researcher stop"] > 0 and result.final_state == "stopped"
            totals["stopped_by_researcher"] += stopped
            totals["unfinished"] += not (result.finished or stopped)
            if result.answer_to_next_question_s is not None:
                gaps.append(result.answer_to_next_question_s)
            if result.speech_s_per_trial is not None:
                speech.append(result.speech_s_per_trial)
            seed += 1
    totals["answer_to_next_question_s_median"] = round(statistics.median(gaps), 2)
    totals["speech_s_per_trial_mean"] = round(statistics.mean(speech), 2)
    totals["presses"] = dict(sorted(kinds.items()))
    totals["wall_s"] = round(time.perf_counter() - started, 1)
    return totals


def main() -> int:
    """Run every mode; exit 1 if a target is missed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--answers", type=int, default=10_000, help="answers per mode")
    parser.add_argument("--json", action="store_true", help="one JSON line per mode")
    arguments = parser.parse_args()
    configure_logging("error", "console", stream=io.StringIO())
    missed = False
    for mode in MODES:
        totals = run_mode(mode, arguments.answers)
        ok = (
            totals["accidental_commands"] == 0
            and totals["commands_taken_as_answers"] == 0
            and totals["answers_lost"] == 0
            and totals["unfinished"] == 0
        )
        missed |= not ok
        if arguments.json:
            print(json.dumps(totals))
        else:
            print(
                f"{mode:7} {totals['games']} games ({totals['stopped_by_researcher']} stopped by "
                f"the researcher), {totals['answers']} answers: "
                f"{totals['accidental_commands']} commands a child started, "
                f"{totals['commands_taken_as_answers']} researcher commands taken as answers, "
                f"{totals['answers_lost']} answers lost, {totals['unfinished']} unfinished "
                f"(targets 0, 0, 0, 0: {'met' if ok else 'MISSED'}); answer to next "
                f"question {totals['answer_to_next_question_s_median']} s (median of games), "
                f"speech {totals['speech_s_per_trial_mean']} s a trial; {totals['wall_s']} s\n"
                f"        presses: {totals['presses']}"
            )
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
