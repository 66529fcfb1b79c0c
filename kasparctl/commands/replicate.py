"""`kasparctl replicate`: a cohort's figures (or the paper's) among simulated studies of its size.

--paper places the pilot's published figures (16 groups, 48 problems) among
studies simulated with the chosen learner and game; --readings does so for
each reading of the paper's text (docs/simulation.md: the fit table).
Without --paper, the sessions named (every session by default; one
condition) are the cohort: its game, learner and number of groups are
simulated, with its own children (a teacher model fitted from the sessions;
--teacher FILE or --teacher honest to choose others). Each figure gets the
model's median, its 95 % range, the cohort's percentile and a two-sided p.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import msgspec

from kasparctl.config import BUILTIN_PROFILES, GameSettings, ProfileSettings
from kasparctl.learning.learner import LearnerError, LearnerParams
from kasparctl.research.cohort import Cohort, CohortError, cohort_of, teaching_by_place
from kasparctl.research.output import closed_pipe
from kasparctl.research.source import (
    SourceError,
    add_source_arguments,
    read_sessions,
    resolve_source,
)
from kasparctl.sim.fit import (
    FIGURES,
    PAPER,
    PAPER_GROUPS,
    PILOT_TEACHER,
    Fit,
    fit,
    fit_readings,
    simulate_studies,
)
from kasparctl.sim.simulate import SimulationError, pilot_game, playable
from kasparctl.sim.teacher import ChildTeacher, Teacher, TeacherError, TeacherModel, load_teacher

DEFAULT_STUDIES = 10_000
MAX_STUDIES = 200_000


def register(subparsers: Any) -> None:
    """Add the `replicate` subcommand."""
    parser = subparsers.add_parser(
        "replicate",
        help="place a cohort's (or the paper's) figures among simulated studies of its size",
        description=__doc__,
    )
    add_source_arguments(parser, condition=True)
    parser.add_argument(
        "--paper", action="store_true", help="the cohort is the paper's pilot (section IV)"
    )
    parser.add_argument(
        "--readings",
        action="store_true",
        help="with --paper: the fit of each reading of the paper (the fit table)",
    )
    parser.add_argument("--profile", default=None, help="the learner (default: the cohort's)")
    parser.add_argument(
        "--exclude-learned",
        choices=("names", "always", "never"),
        default=None,
        help="withdraw a learned toy from later targets (default: the config's, else names)",
    )
    parser.add_argument(
        "--teacher",
        default=None,
        metavar="FILE|honest",
        help="the children: a teacher model file, or 'honest' (default: fitted from the "
        "cohort; the paper's 3 wrong greens for --paper)",
    )
    parser.add_argument(
        "--studies",
        type=int,
        default=DEFAULT_STUDIES,
        help=f"simulated studies (default {DEFAULT_STUDIES:,})",
    )
    parser.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    parser.add_argument("--json", action="store_true", help="one JSON object")
    parser.set_defaults(run=run)


class UsageError(Exception):
    """Options that do not fit together; the message names them."""


def run(arguments: argparse.Namespace) -> int:
    """Fit the model (or each reading) to the cohort and print the table."""
    try:
        if not 100 <= arguments.studies <= MAX_STUDIES:
            raise UsageError(
                f"--studies: expected 100 to {MAX_STUDIES:,}, found {arguments.studies:,}"
            )
        if arguments.readings and not arguments.paper:
            raise UsageError("--readings: only with --paper (the readings are of the paper)")
        if arguments.paper and arguments.sessions:
            raise UsageError("--paper: the cohort is the paper's; name no sessions")
        fits = _paper(arguments) if arguments.paper else [_cohort(arguments)]
    except BrokenPipeError:
        return closed_pipe()
    except (
        UsageError,
        SourceError,
        CohortError,
        SimulationError,
        TeacherError,
        LearnerError,
    ) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    try:
        _print(fits, arguments.json)
    except BrokenPipeError:
        return closed_pipe()
    return 0


def _profiles(arguments: argparse.Namespace) -> tuple[dict[str, ProfileSettings], Any]:
    source = resolve_source(arguments, needs_state_dir=False)
    config = source.config
    profiles = config.learner.all_profiles() if config else dict(BUILTIN_PROFILES)
    return profiles, config


def _params(profiles: dict[str, ProfileSettings], name: str) -> LearnerParams:
    if name not in profiles:
        raise UsageError(
            f"--profile: expected one of {', '.join(sorted(profiles))}, found {name!r}"
        )
    return profiles[name].params()


def _teacher(
    arguments: argparse.Namespace, default: Teacher | TeacherModel
) -> Teacher | TeacherModel:
    if arguments.teacher is None:
        return default
    if arguments.teacher == "honest":
        return Teacher()
    return load_teacher(arguments.teacher)


def _paper(arguments: argparse.Namespace) -> list[tuple[str, Fit]]:
    if arguments.readings:
        if arguments.profile or arguments.exclude_learned or arguments.teacher:
            raise UsageError(
                "--readings: each reading sets the learner, game and children; drop --profile, "
                "--exclude-learned and --teacher"
            )
        return [
            (f"{reading.name}: {reading.reason}", result)
            for reading, result in fit_readings(arguments.studies, arguments.seed)
        ]
    profiles, config = _profiles(arguments)
    params = _params(profiles, arguments.profile or "paper")
    rule = arguments.exclude_learned or (config.game.exclude_learned_rule if config else "names")
    game = pilot_game(exclude_learned_rule=rule)
    teacher = _teacher(arguments, PILOT_TEACHER)
    simulated = simulate_studies(
        arguments.studies, PAPER_GROUPS, game, params, teacher, arguments.seed
    )
    label = f"the paper's pilot vs {arguments.profile or 'paper'}, exclude_learned {rule}"
    return [(label, fit("paper", PAPER, simulated, PAPER_GROUPS))]


def _cohort(arguments: argparse.Namespace) -> tuple[str, Fit]:
    source, catalogue = read_sessions(arguments)
    sessions = catalogue.sessions
    if not sessions:
        raise SourceError("no sessions to replicate")
    cohort = cohort_of(sessions, source.params)
    config = source.config
    name = arguments.profile or cohort.profile
    params = source.params(name)
    game = _game(cohort, config.game if config else None, arguments.exclude_learned)
    teacher = _teacher(arguments, _fitted(sessions))
    simulated = simulate_studies(
        arguments.studies, cohort.sessions, game, params, teacher, arguments.seed
    )
    label = (
        f"{cohort.label}: {cohort.sessions} sessions vs {name}, {game.variant}, "
        f"exclude_learned {game.exclude_learned_rule}"
    )
    return label, fit(cohort.label, cohort.figures, simulated, cohort.sessions)


def _game(cohort: Cohort, configured: GameSettings | None, rule: str | None) -> GameSettings:
    """The cohort's game: its variant, toys and targets; the rest from the config."""
    base = configured or GameSettings()
    rule = rule or base.exclude_learned_rule
    if cohort.variant == "pilot":
        locations = tuple(f"location {i + 1}" for i in range(max(cohort.targets, 1)))
        game = msgspec.structs.replace(
            base, variant="pilot", toys=cohort.toys, locations=locations, poses={}
        )
    else:
        game = msgspec.structs.replace(
            base, variant="names", toys=cohort.toys, locations=(), poses={}
        )
    return playable(msgspec.structs.replace(game, exclude_learned_rule=rule))


def _fitted(sessions: Any) -> TeacherModel:
    places = teaching_by_place(sessions)
    if not places:
        return TeacherModel.of(Teacher())
    children = tuple(
        ChildTeacher.fitted(
            p.answers,
            p.wrong_guesses,
            p.false_greens,
            p.right_guesses,
            p.false_reds,
            p.prompted,
            p.reaction_times,
        )
        for p in places
    )
    return TeacherModel(children, f"fitted from {len(sessions)} sessions")


def _p(p: float, studies: int) -> str:
    """A Monte Carlo p-value, or how rare when no simulated study was as extreme."""
    if round(p * (studies + 1)) <= 1:
        return f"p < {1 / studies:.1g} (none of {studies:,} simulated studies)"
    return f"p = {p:.4f}"


def _print(fits: list[tuple[str, Fit]], as_json: bool) -> None:
    if as_json:
        print(
            json.dumps(
                [{"label": label, **result.plain()} for label, result in fits], allow_nan=False
            )
        )
        return
    for label, result in fits:
        print(label)
        print(
            f"  {result.studies:,} simulated studies of {result.groups_per_study} groups; "
            "percentile: share of simulated studies below the cohort (ties half); p two-sided"
        )
        print(
            f"  {'figure':38} {'cohort':>8} {'model median':>13} {'95 % range':>17} "
            f"{'percentile':>11} {'p':>7}"
        )
        for placed in result.placed:
            spread = f"{placed.low:.2f}-{placed.high:.2f}"
            print(
                f"  {FIGURES[placed.figure]:38} {placed.cohort:>8.2f} {placed.median:>13.2f} "
                f"{spread:>17} {placed.percentile:>10.1f}% {placed.p:>7.3f}"
            )
        if result.joint_trials_p is not None:
            print(
                "  trials to learn, mean and sd together: "
                + _p(result.joint_trials_p, result.studies)
            )
        if result.entropy_with_win_shifts_p is not None:
            print(
                "  final entropy at least the cohort's with at most its win-shifts: "
                + _p(result.entropy_with_win_shifts_p, result.studies)
            )
        print()
