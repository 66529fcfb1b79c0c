"""`kasparctl plan`: the planned sessions of a counterbalanced study, one file per robot.

Groups x conditions x robots, within-group (each group meets every condition, in
the orders of a balanced Latin square) or between-group (each group one
condition), robots crossed with the conditions, one per condition, or one per
group. Each robot's file (DIR/sessions-<robot>.toml) holds its `[[sessions]]`
in running order; the robot's kaspar.toml names it as `sessions_file`. The
seed makes the assignment reproducible (printed, and written in each file).
docs/studies.md.
"""

from __future__ import annotations

import argparse
import secrets
import shlex
from pathlib import Path
from typing import Any

from kasparctl.commands.arguments import UsageError, names, path, seed, usage_of, whole
from kasparctl.config import BUILTIN_PROFILES, load_config
from kasparctl.research.design import (
    DESIGNS,
    MAX_GROUPS,
    MAX_REPEATS,
    ROBOT_PLANS,
    Design,
    DesignError,
    group_codes,
    header,
    parse_condition,
    plan,
    sessions_toml,
    summary,
)
from kasparctl.research.output import check_outputs, private_directory, write_bytes


def register(subparsers: Any) -> None:
    """Add `plan` and its options to the command line."""
    parser = subparsers.add_parser(
        "plan",
        help="write the planned sessions of a counterbalanced study, one file per robot",
        description=__doc__,
    )
    add = parser.add_argument
    add("--groups", type=whole(1, MAX_GROUPS), default=None,
        help="how many groups (codes G01, G02...)")
    add("--group-codes", type=names, default=None, metavar="CODE,CODE,...",
        help="the groups' own codes, instead of --groups")
    add("--conditions", type=names, required=True, metavar="PROFILE[/MODE],...",
        help="the conditions: a learner profile, and optionally an uncertainty mode "
        "(spoken, body, both, none), e.g. fast/spoken,slow/spoken")
    add("--robots", type=names, required=True, metavar="NAME,...",
        help="the robots, by name (each gets its own file)")
    add("--design", choices=DESIGNS, default="within",
        help="within: each group meets every condition (default); between: one each")
    add("--robot-plan", choices=ROBOT_PLANS, default="crossed",
        help="crossed: which robot runs which condition is counterbalanced (default); "
        "condition: condition N always on robot N; group: each group stays on one robot")
    add("--repeats", type=whole(1, MAX_REPEATS), default=1,
        help="sessions of each of a group's conditions, in a row (default 1)")
    add("--seed", type=seed, default=None, help="the assignment's seed (default: fresh, printed)")
    add("--config", type=path, default=None,
        help="a kaspar.toml whose learner profiles the conditions must name")
    add("--out", type=path, required=True, metavar="DIR",
        help="the directory to write sessions-<robot>.toml into")
    parser.set_defaults(run=run)  # fmt: skip


def run(arguments: argparse.Namespace) -> int:
    """Plan the study, write each robot's file and print the design's table."""
    if (arguments.groups is None) == (arguments.group_codes is None):
        raise UsageError("--groups: expected --groups N or --group-codes A,B,... (one of them)")
    codes = tuple(arguments.group_codes or group_codes(arguments.groups))
    chosen = secrets.randbits(63) if arguments.seed is None else arguments.seed
    with usage_of(DesignError):
        conditions = tuple(parse_condition(text) for text in arguments.conditions)
        design = Design(codes, conditions, tuple(arguments.robots),
                        within=arguments.design == "within", robot_plan=arguments.robot_plan,
                        repeats=arguments.repeats, seed=chosen)  # fmt: skip
    _check_profiles(design, arguments.config)
    out = Path(arguments.out)
    targets = {robot: out / f"sessions-{robot}.toml" for robot in design.robots}
    inputs = [("--config", arguments.config)] if arguments.config else []
    check_outputs([("--out", str(t)) for t in targets.values()], [], [], inputs)
    result = plan(design)
    command = _command_line(arguments, chosen)
    private_directory(out)
    for robot, target in targets.items():
        text = sessions_toml(result, robot, header(result, robot, command))
        write_bytes(target, text.encode())
    print(summary(result))
    print()
    for robot, target in targets.items():
        print(f"{robot}: {len(result.of_robot(robot))} sessions in {target}")
    return 0


def _check_profiles(design: Design, config: str | None) -> None:
    """Each condition's profile exists: built in, or in --config's [learner] profiles."""
    known = load_config(config).learner.all_profiles() if config else dict(BUILTIN_PROFILES)
    for condition in design.conditions:
        if condition.profile not in known:
            where = f"in {config}" if config else "built in (give --config for the robot's own)"
            raise UsageError(
                f"--conditions: {condition.label!r}: expected a learner profile {where} "
                f"({', '.join(sorted(known))}), found {condition.profile!r}"
            )


def _command_line(arguments: argparse.Namespace, chosen: int) -> str:
    """The command that makes this plan again, seed included (from the parsed options)."""
    words = ["kasparctl", "plan"]
    if arguments.group_codes is not None:
        words += ["--group-codes", ",".join(arguments.group_codes)]
    else:
        words += ["--groups", str(arguments.groups)]
    words += ["--conditions", ",".join(arguments.conditions)]
    words += ["--robots", ",".join(arguments.robots), "--design", arguments.design]
    words += ["--robot-plan", arguments.robot_plan, "--repeats", str(arguments.repeats)]
    words += ["--seed", str(chosen)]
    if arguments.config:
        words += ["--config", arguments.config]
    return shlex.join([*words, "--out", arguments.out])
