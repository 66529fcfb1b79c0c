"""`kasparctl fit-teacher`: a teacher model of the children, fitted from recorded sessions.

One child per place in the turn order, pooled over the sessions named (every
session by default): how often they gave a green for a wrong guess (over
the wrong guesses they answered) and a red for a right one, how often a
question needed a prompt, and their reaction times (log-normal). Written as
TOML for `kasparctl simulate --teacher FILE`, `kasparctl demo --teacher FILE`
and `kasparctl replicate --teacher FILE`; it can be edited by hand.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from kasparctl.commands.arguments import add_sources, path
from kasparctl.research.cohort import teaching_by_place
from kasparctl.research.output import check_outputs, text_output
from kasparctl.research.source import SourceError, input_files, read_sessions
from kasparctl.sim.fit import fitted_teacher, fitted_teacher_file


def register(subparsers: Any) -> None:
    """Add the `fit-teacher` subcommand."""
    parser = subparsers.add_parser(
        "fit-teacher",
        help="fit a model of the children's answers from recorded sessions",
        description=__doc__,
    )
    add_sources(parser, condition=True)
    parser.add_argument(
        "--out", required=True, type=path, metavar="FILE",
        help="the teacher model (TOML; '-': stdout)",
    )  # fmt: skip
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Fit the model and write it."""
    source, catalogue = read_sessions(arguments)
    sessions = catalogue.sessions
    places = teaching_by_place(sessions)
    if not places:
        raise SourceError("no answers to fit a teacher from (no trials in the sessions)")
    check_outputs(
        [("--out", arguments.out)],
        source.state_dirs,
        [s.directory for s in sessions] + [d.directory for d in catalogue.damaged],
        input_files(arguments),
    )
    model = fitted_teacher(places, len(sessions))
    keyed = sum(1 for s in sessions if s.answer_key)
    with text_output(arguments.out) as stream:
        stream.write(fitted_teacher_file(model, len(sessions), keyed, [s.group for s in sessions]))
    where = "stdout" if arguments.out == "-" else str(Path(arguments.out))
    print(
        f"teacher model of {len(model.children)} children from {len(sessions)} sessions to {where}",
        file=sys.stderr,
    )
    return 0
