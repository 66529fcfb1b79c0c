"""`kasparctl demo`: a simulated group of children teaches Kaspar, narrated.

For now the demo narrates the learner and the phrase book: one group of
simulated children (the simulator's honest teachers) plays the game's guessing
step, and every line Kaspar would say is printed with the entropy behind it.
The five-step game on the simulated hardware replaces this once it exists.
"""

from __future__ import annotations

import argparse
import json
import secrets
import sys
from typing import Any, TextIO

import numpy as np

from kasparctl.config import Config, ConfigError, GameSettings, load_config
from kasparctl.learner import LearnerError
from kasparctl.phrases import PhraseError, PhrasePicker, load_phrasebook
from kasparctl.simulate import playable, simulate_group
from kasparctl.study_stats import ProblemRecord
from kasparctl.teacher import Teacher

CHILD_WORDS = ("child one", "child two", "child three", "child four", "child five", "child six")


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "demo", help="watch a simulated group of children teach Kaspar", description=__doc__
    )
    parser.add_argument("--seed", type=int, default=None, help="reproduce a game exactly")
    parser.add_argument("--variant", choices=("names", "pilot"), default=None)
    parser.add_argument("--profile", default=None, help="learner profile (default: paper)")
    parser.add_argument("--config", default=None, help="kaspar.toml (default: built-in settings)")
    parser.add_argument(
        "--silent", action="store_true", help="Kaspar does not say how sure it is"
    )
    parser.add_argument(
        "--json", action="store_true", help="end with one JSON line summarising the game"
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    try:
        config = load_config(arguments.config) if arguments.config else Config()
        game = config.game
        if arguments.variant:
            game = GameSettings(variant=arguments.variant, toys=game.toys, locations=game.locations)
        game = playable(game)
        params = config.profile(arguments.profile)
        book = load_phrasebook(config.language, config.phrases_dir)
    except KeyError:
        print(f"error: --profile: unknown profile {arguments.profile!r}", file=sys.stderr)
        return 1
    except (ConfigError, PhraseError, LearnerError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    seed = arguments.seed if arguments.seed is not None else secrets.randbelow(2**31)
    rng = np.random.default_rng(seed)
    problems = simulate_group(game, params, Teacher(), rng)
    speaker = Narrator(sys.stdout, PhrasePicker(book, np.random.default_rng(seed + 1)))
    speaker.play(game, problems, speak_uncertainty=not arguments.silent)
    trials = sum(len(problem.trials) for problem in problems)
    learned = sum(problem.learned is not None for problem in problems)
    print(f"\n{trials} guesses, {learned} of {len(problems)} toys learned (seed {seed}).")
    if arguments.json:
        summary = {
            "session": f"demo-{seed}",
            "finished": learned == len(problems),
            "trials": trials,
            "learned": learned,
            "resumed": False,
        }
        print(json.dumps(summary))
    return 0


class Narrator:
    """Prints what Kaspar says and does, and what the children press."""

    def __init__(self, out: TextIO, picker: PhrasePicker) -> None:
        self.out = out
        self.picker = picker

    def say(self, key: str, note: str = "", **values: str) -> None:
        line = self.picker.line(key, **values)
        self.out.write(f"Kaspar: {line}{f'   ({note})' if note else ''}\n")

    def act(self, text: str) -> None:
        self.out.write(f"        [{text}]\n")

    def play(
        self, game: GameSettings, problems: list[ProblemRecord], speak_uncertainty: bool
    ) -> None:
        pilot = game.variant == "pilot"
        self.say("session.intro_pilot" if pilot else "session.greeting")
        if not pilot:
            self.say("steps.guessing")
        n_candidates = len(game.toys)
        turn = 0
        for problem in problems:
            target = game.targets[problem.target]
            answer = game.toys[problem.answer or 0]
            self.out.write(f"\n-- {target}: the right toy is the {answer}\n")
            for trial in problem.trials:
                self.say("turn.child", child=CHILD_WORDS[turn % game.children_per_group])
                turn += 1
                self.act(f"points at {target}")
                if speak_uncertainty:
                    band, line = self.picker.uncertainty(trial.entropy, n_candidates)
                    self.out.write(f"Kaspar: {line}   ({trial.entropy:.3f} bits: {band})\n")
                toy = game.toys[trial.choice]
                if pilot:
                    self.say("guess.pilot", toy=toy, location=target)
                else:
                    self.say("guess.names", toy=toy)
                self.act({True: "green", False: "red", None: "nobody answers"}[trial.feedback])
                if trial.feedback is not None:
                    self.say("react.happy" if trial.feedback else "react.sad")
            if problem.learned is not None:
                toy = game.toys[problem.learned]
                if pilot:
                    self.say("react.learned_pilot", toy=toy, location=target)
                else:
                    self.say("react.learned", toy=toy)
                    n_candidates -= 1
        self.say("react.all_learned")
        self.say("session.farewell")
