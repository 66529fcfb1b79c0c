"""`kasparctl simulate`: replicate the pilot study, sweep the learner, or plan a study's size.

Without --config it plays the paper's pilot (3 locations, 6 toys) with the
built-in profiles; with --config the game and profiles come from kaspar.toml.
--alpha, --beta and --gamma override the chosen profile's values; --teacher
gives the children of a teacher model (`kasparctl fit-teacher` fits one from
recorded sessions). --power compares two arms (--compare NAME=A,B) and gives
the power to detect their difference against the number of groups; with
--paired each group plays both arms (a within-group design). --design
TARGET finds a learner profile (greens to learn, alpha, beta) whose mean guesses
per game is TARGET.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from kasparctl.commands import paired_power
from kasparctl.commands.arguments import (
    PROBABILITY,
    UsageError,
    assignment,
    finite,
    number_range,
    pair,
    path,
    seed,
    usage_of,
    whole,
    wholes,
)
from kasparctl.learning.study_stats import ProblemRecord
from kasparctl.research.output import check_outputs, write_bytes
from kasparctl.research.progress import progress
from kasparctl.sim.design import DEFAULT_DESIGN_GROUPS
from kasparctl.sim.paired import PairedAnswer
from kasparctl.sim.power import DEFAULT_GROUPS, DEFAULT_STUDIES, MAX_SIMULATED_GROUPS
from kasparctl.sim.request import (
    COMPARABLE,
    EXCLUDE_RULES,
    MAX_SWEEP_VALUES,
    SWEEPABLE,
    Design,
    PowerAnswer,
    Request,
    answer,
)
from kasparctl.sim.simulate import OptionError
from kasparctl.sim.studies import GROUP_MEASURES

# Below this many groups the scalar simulation takes about a second; no bar.
PROGRESS_MIN_GROUPS = 2000


def register(subparsers: Any) -> None:
    """Add `simulate` and its options to the command line."""
    parser = subparsers.add_parser(
        "simulate",
        help="simulate groups of children teaching Kaspar (the pilot study), or sweep the learner",
        description=__doc__,
    )
    add = parser.add_argument
    # The room says what to do instead of a run of hours (MAX_GROUPS, MAX_SWEEP_PROBLEMS).
    add("--groups", type=whole(1, None), default=16,
        help="groups of children (default 16, as in the pilot)")
    add("--seed", type=seed, default=None,
        help="random seed (default: the config's game.seed, else fresh)")
    add("--profile", default=None,
        help="learner profile (default: the config's default, else 'paper')")
    add("--alpha", type=finite, default=None, help="learning rate, overrides the profile")
    add("--beta", type=finite, default=None, help="inverse temperature, overrides the profile")
    add("--gamma", type=finite, default=None, help="discount factor, overrides the profile")
    add("--variant", choices=("pilot", "names"), default=None,
        help="game variant (default: the config's, else pilot)")
    add("--p-wrong-green", type=PROBABILITY, default=0.0,
        help="chance of a green for a wrong guess")
    add("--p-wrong-red", type=PROBABILITY, default=0.0, help="chance of a red for a right guess")
    add("--p-no-answer", type=PROBABILITY, default=0.0, help="chance nobody answers a guess")
    add("--teacher", metavar="FILE", type=path, default=None,
        help="a teacher model (TOML; `kasparctl fit-teacher` writes one): each child's rates")
    add("--exclude-learned", choices=EXCLUDE_RULES, default=None,
        help="withdraw a learned toy from later targets (default: the config's, else names)")
    add("--recover", action="store_true",
        help="a researcher re-opens a wrongly learned name when Kaspar is confused "
        "(kasparctl.game.recovery); the scalar simulator only")
    add("--config", type=path, default=None,
        help="kaspar.toml to take the game settings and profiles from")
    add("--json", action="store_true", help="print one JSON object (a list with --sweep)")
    add("--sweep", action="append", default=[], metavar="NAME=START:STOP:STEP",
        type=assignment(number_range(MAX_SWEEP_VALUES), SWEEPABLE, "NAME=START:STOP:STEP"),
        help="sweep alpha or beta over an inclusive range (repeatable; vectorised pilot problems)")
    power = parser.add_argument_group("study design (--power)").add_argument
    power("--power", action="store_true",
          help="the power to detect the --compare difference, against the number of groups")
    power("--compare", type=assignment(pair, COMPARABLE, "NAME=A,B"), metavar="NAME=A,B",
          help=f"the two arms: NAME one of {', '.join(COMPARABLE)} (teacher: two model files)")
    power("--measure", choices=tuple(GROUP_MEASURES), default="trials_mean",
          help="each group's value the arms are compared on (default trials_mean)")
    power("--groups-per-arm", type=wholes(2, MAX_SIMULATED_GROUPS), default=DEFAULT_GROUPS,
          metavar="N,N,...", help=f"designs to try (default {','.join(map(str, DEFAULT_GROUPS))})")
    power("--studies", type=whole(1, MAX_SIMULATED_GROUPS), default=DEFAULT_STUDIES,
          help=f"simulated studies per design (default {DEFAULT_STUDIES})")
    power("--level", type=PROBABILITY, default=0.05, help="the test's level (default 0.05)")
    power("--figure", metavar="FILE", type=path, default=None,
          help="also draw the power curve (.png or .svg)")
    power("--paired", action="store_true",
          help="within-group: each group plays both arms (order counterbalanced), analysed "
          "paired as the report does; --groups-per-arm is then the number of groups")
    power("--order-effect", type=finite, default=0.0, metavar="D",
          help="with --paired: a group's second session is D higher on --measure (default 0)")
    designing = parser.add_argument_group("a learner for a game's length (--design)").add_argument
    designing("--design", type=finite, default=None, metavar="TARGET",
              help="find a profile (greens to learn, alpha, beta) whose mean guesses per game "
              "is TARGET, coherent as the paper's learner; printed as kaspar.toml lines")
    designing("--design-groups", type=whole(100, 100_000), default=DEFAULT_DESIGN_GROUPS,
              help=f"groups simulated per candidate (default {DEFAULT_DESIGN_GROUPS})")
    parser.set_defaults(run=run)  # fmt: skip


def run(arguments: argparse.Namespace) -> int:
    """Simulate, sweep or plan, and print the result (JSON with --json)."""
    request = Request(
        groups=arguments.groups,
        seed=arguments.seed,
        profile=arguments.profile,
        learner={key: getattr(arguments, key) for key in ("alpha", "beta", "gamma")
                 if getattr(arguments, key) is not None},
        variant=arguments.variant,
        rates=(arguments.p_wrong_green, arguments.p_wrong_red, arguments.p_no_answer),
        teacher=arguments.teacher,
        exclude_learned=arguments.exclude_learned,
        recover=arguments.recover,
        config=arguments.config,
        sweep=tuple(arguments.sweep),
        power=arguments.power,
        compare=arguments.compare,
        design=Design(arguments.measure, arguments.groups_per_arm, arguments.studies,
                      arguments.level),
        design_for=arguments.design,
        design_groups=arguments.design_groups,
    )  # fmt: skip
    if arguments.figure is not None and arguments.power:
        check_outputs([("--figure", arguments.figure)], [], [], _inputs(arguments))
    if arguments.order_effect and not arguments.paired:
        raise UsageError("--order-effect: only with --paired")
    with usage_of(OptionError):
        result = (paired_power.answer(request, arguments.order_effect) if arguments.paired
                  else answer(request, _bar))  # fmt: skip
    if isinstance(result, PowerAnswer | PairedAnswer) and arguments.figure is not None:
        kind = "svg" if Path(arguments.figure).suffix.lower() == ".svg" else "png"
        write_bytes(Path(arguments.figure), result.figure(kind))
    print(json.dumps(result.plain(), allow_nan=False) if arguments.json else result.text())
    return 0


def _bar(groups: Iterator[list[ProblemRecord]], total: int) -> Iterable[list[ProblemRecord]]:
    return progress(groups, "simulating", "group", total=total, minimum=PROGRESS_MIN_GROUPS)


def _inputs(arguments: argparse.Namespace) -> list[tuple[str, str]]:
    """The files the run reads, which --figure may not replace."""
    files = [(f"--{name}", getattr(arguments, name)) for name in ("config", "teacher")]
    if arguments.compare is not None and arguments.compare[0] == "teacher":
        files += [("--compare", value) for value in arguments.compare[1]]
    return [(option, file) for option, file in files if file]
