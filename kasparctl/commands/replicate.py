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
from typing import Any

from kasparctl.commands.arguments import UsageError, add_sources, path, seed, usage_of, whole
from kasparctl.config import BUILTIN_PROFILES
from kasparctl.research.cohort import cohort_of, teaching_by_place
from kasparctl.research.source import (
    SourceError,
    read_sessions,
    resolve_source,
)
from kasparctl.sim import tables
from kasparctl.sim.fit import (
    Fit,
    chosen_teacher,
    cohort_game,
    fit_cohort,
    fit_paper,
    fit_readings,
    fitted_teacher,
)
from kasparctl.sim.request import EXCLUDE_RULES, learner
from kasparctl.sim.simulate import OptionError

DEFAULT_STUDIES = 10_000
MAX_STUDIES = 200_000


def register(subparsers: Any) -> None:
    """Add the `replicate` subcommand."""
    parser = subparsers.add_parser(
        "replicate",
        help="place a cohort's (or the paper's) figures among simulated studies of its size",
        description=__doc__,
    )
    add_sources(parser, condition=True)
    add = parser.add_argument
    add("--paper", action="store_true", help="the cohort is the paper's pilot (section IV)")
    add("--readings", action="store_true",
        help="with --paper: the fit of each reading of the paper (the fit table)")
    add("--profile", default=None, help="the learner (default: the cohort's)")
    add("--exclude-learned", choices=EXCLUDE_RULES, default=None,
        help="withdraw a learned toy from later targets (default: the config's, else names)")
    add("--teacher", default=None, type=path, metavar="FILE|honest",
        help="the children: a teacher model file, or 'honest' (default: fitted from the "
        "cohort; the paper's 3 wrong greens for --paper)")
    add("--studies", type=whole(100, MAX_STUDIES), default=DEFAULT_STUDIES,
        help=f"simulated studies (default {DEFAULT_STUDIES:,})")
    add("--seed", type=seed, default=1, help="random seed (default 1)")
    add("--json", action="store_true", help="one JSON object")
    parser.set_defaults(run=run)  # fmt: skip


def run(arguments: argparse.Namespace) -> int:
    """Fit the model (or each reading) to the cohort and print the table."""
    if arguments.readings and not arguments.paper:
        raise UsageError("--readings: only with --paper (the readings are of the paper)")
    if arguments.paper and arguments.sessions:
        raise UsageError("--paper: the cohort is the paper's; name no sessions")
    if arguments.readings and (arguments.profile or arguments.exclude_learned or arguments.teacher):
        raise UsageError(
            "--readings: each reading sets the learner, game and children; drop --profile, "
            "--exclude-learned and --teacher"
        )
    fits = _paper(arguments) if arguments.paper else [_cohort(arguments)]
    if arguments.json:
        print(json.dumps([{"label": label, **fit.plain()} for label, fit in fits], allow_nan=False))
    else:
        print(tables.fits(fits))
    return 0


def _paper(arguments: argparse.Namespace) -> list[tuple[str, Fit]]:
    if arguments.readings:
        return [
            (f"{reading.name}: {reading.reason}", result)
            for reading, result in fit_readings(arguments.studies, arguments.seed)
        ]
    config = resolve_source(arguments, needs_state_dir=False).config
    profiles = config.learner.all_profiles() if config else dict(BUILTIN_PROFILES)
    profile = arguments.profile or "paper"
    with usage_of(OptionError):
        params = learner(profiles, profile)
    rule = arguments.exclude_learned or (config.game.exclude_learned_rule if config else "names")
    teacher = chosen_teacher(arguments.teacher)
    return [fit_paper(profile, params, rule, teacher, arguments.studies, arguments.seed)]


def _cohort(arguments: argparse.Namespace) -> tuple[str, Fit]:
    source, catalogue = read_sessions(arguments)
    sessions = catalogue.sessions
    if not sessions:
        raise SourceError("no sessions to replicate")
    cohort = cohort_of(sessions, source.params)
    profile = arguments.profile or cohort.profile
    params = source.params(profile)
    game = cohort_game(
        cohort, source.config.game if source.config else None, arguments.exclude_learned
    )
    teacher = chosen_teacher(arguments.teacher)
    if teacher is None:
        teacher = fitted_teacher(teaching_by_place(sessions), len(sessions))
    return fit_cohort(cohort, game, profile, params, teacher, arguments.studies, arguments.seed)
