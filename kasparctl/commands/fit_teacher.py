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

from kasparctl.research.cohort import teaching_by_place
from kasparctl.research.output import OutputError, check_outputs, closed_pipe, text_output
from kasparctl.research.source import SourceError, add_source_arguments, input_files, read_sessions
from kasparctl.sim.teacher import ChildTeacher, TeacherError, TeacherModel, teacher_toml


def register(subparsers: Any) -> None:
    """Add the `fit-teacher` subcommand."""
    parser = subparsers.add_parser(
        "fit-teacher",
        help="fit a model of the children's answers from recorded sessions",
        description=__doc__,
    )
    add_source_arguments(parser, condition=True)
    parser.add_argument(
        "--out", required=True, metavar="FILE", help="the teacher model (TOML; '-': stdout)"
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Fit the model and write it."""
    try:
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
        keyed = sum(1 for s in sessions if s.answer_key)
        model = TeacherModel(children, f"fitted from {len(sessions)} sessions")
        comment = "\n".join(
            [
                "kasparctl teacher model, written by `kasparctl fit-teacher`.",
                f"From {len(sessions)} sessions ({keyed} with an answer key); groups: "
                + ", ".join(sorted({s.group for s in sessions})),
                "One [[children]] table per place in the turn order (the first child first).",
                "p_wrong_green: greens for a wrong guess / wrong guesses answered;",
                "p_wrong_red: reds for a right guess / right guesses answered;",
                "p_prompt: questions that needed a prompt / questions;",
                "reaction_time_median (s) and reaction_time_log_sd: a log-normal;",
                "answers: how many answers each child's rates rest on.",
            ]
        )
        with text_output(arguments.out) as stream:
            stream.write(teacher_toml(model, comment))
    except BrokenPipeError:
        return closed_pipe()
    except (SourceError, OutputError, TeacherError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"error: cannot write {arguments.out}: {error.strerror or error}", file=sys.stderr)
        return 1
    where = "stdout" if arguments.out == "-" else str(Path(arguments.out))
    print(
        f"teacher model of {len(children)} children from {len(sessions)} sessions to {where}",
        file=sys.stderr,
    )
    return 0
