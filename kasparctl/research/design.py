"""A counterbalanced study as planned sessions: groups x conditions x robots (pure).

`kasparctl plan` asks for a design; this module decides who meets what, where
and when, and renders each robot's `[[sessions]]` file. Nothing here touches
the disk or the clock: the same design and seed give the same plan.

- **Within-group**: every group meets every condition. The orders are the rows
  of a balanced Latin square (Williams): with an even number of conditions k,
  k orders in which each condition is in each position once and follows each
  other condition once; with an odd k, the square and its mirror (2k orders).
- **Between-group**: each group meets one condition.
- **Robots**: `crossed` (a Latin square over the robots: which robot runs which
  condition changes from group to group, so robot and condition are not
  confounded), `condition` (condition j always on robot j: the robot is part of
  the condition, as a fast and a slow robot) or `group` (each group stays on one
  robot).

Groups are shuffled by the seed and dealt in turn to the design's cells (order
x robot mapping), so the design is exactly balanced when the groups divide
evenly among the cells, and within one group of it otherwise (`Balance` says
which). A group's sessions are numbered 1, 2... across the whole study and
robots (`number`, unique per group as `check` requires); `repeats` plays each of
a group's conditions that many times in a row. Each robot's file lists its
sessions in running order: period by period (every group's first session, then
every second...), groups in the shuffled order within a period.
"""

from __future__ import annotations

import random
import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

from hal.errors import KasparError
from kasparctl.config import UNCERTAINTY_MODES

DESIGNS = ("within", "between")
ROBOT_PLANS = ("crossed", "condition", "group")
# The condition label's word for "none" (kasparctl.config.CONDITION_LABELS), taken too.
MODE_ALIASES = {"silent": "none"}
MAX_GROUPS = 999
MAX_REPEATS = 9
# A robot's name becomes part of a file name: letters, digits, "-" and "_".
ROBOT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,39}")
GROUP_CODE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,23}")


class DesignError(KasparError):
    """A design that cannot be planned; the message names the option and what was found."""


@dataclass(frozen=True)
class Condition:
    """A learner profile and, if given, an uncertainty mode (else the robot's default)."""

    profile: str
    uncertainty: str | None = None

    @property
    def label(self) -> str:
        """As given on the command line: "fast/spoken", or "paper" without a mode."""
        return self.profile if self.uncertainty is None else f"{self.profile}/{self.uncertainty}"


def parse_condition(text: str) -> Condition:
    """ "profile[/mode]" into a Condition; DesignError names --conditions and the text."""
    profile, slash, mode = text.strip().partition("/")
    if not re.fullmatch(r"[A-Za-z0-9_-]+", profile):
        raise DesignError(
            f"--conditions: expected profile[/mode] such as fast/spoken, found {text!r}"
        )
    if not slash:
        return Condition(profile)
    mode = MODE_ALIASES.get(mode, mode)
    if mode not in UNCERTAINTY_MODES:
        raise DesignError(
            f"--conditions: {text!r}: expected a mode of {', '.join(UNCERTAINTY_MODES)} "
            f"after the '/', found {mode!r}"
        )
    return Condition(profile, mode)


@dataclass(frozen=True)
class Design:
    """What a study is asked to be."""

    groups: tuple[str, ...]
    conditions: tuple[Condition, ...]
    robots: tuple[str, ...]
    within: bool = True
    robot_plan: str = "crossed"
    repeats: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        """Refuse what cannot be planned, naming the option."""
        if not self.groups:
            raise DesignError("--groups: expected at least one group, found none")
        if len(self.groups) > MAX_GROUPS:
            raise DesignError(f"--groups: expected at most {MAX_GROUPS}, found {len(self.groups)}")
        for code in self.groups:
            if not GROUP_CODE.fullmatch(code):
                raise DesignError(
                    f"--groups: expected group codes of letters, digits, '.', '_' and '-' "
                    f"(at most 24), found {code!r}"
                )
        _distinct(self.groups, "--groups", "group code")
        if len(self.conditions) < 2:
            raise DesignError(
                f"--conditions: expected at least two conditions, found {len(self.conditions)}"
            )
        _distinct([c.label for c in self.conditions], "--conditions", "condition")
        if not self.robots:
            raise DesignError("--robots: expected at least one robot, found none")
        for name in self.robots:
            if not ROBOT_NAME.fullmatch(name):
                raise DesignError(
                    f"--robots: expected names of letters, digits, '_' and '-' (a file is "
                    f"named after each), found {name!r}"
                )
        _distinct([name.lower() for name in self.robots], "--robots", "robot (letter case aside)")
        if self.robot_plan not in ROBOT_PLANS:
            raise DesignError(
                f"--robot-plan: expected one of {', '.join(ROBOT_PLANS)}, found {self.robot_plan!r}"
            )
        if self.robot_plan == "condition" and len(self.robots) != len(self.conditions):
            raise DesignError(
                f"--robot-plan condition: expected one robot per condition "
                f"({len(self.conditions)}), found {len(self.robots)} robots"
            )
        if not 1 <= self.repeats <= MAX_REPEATS:
            raise DesignError(f"--repeats: expected 1 to {MAX_REPEATS}, found {self.repeats}")


def _distinct(values: Sequence[str], option: str, what: str) -> None:
    seen: set[str] = set()
    for value in values:
        if value in seen:
            raise DesignError(f"{option}: expected each {what} once, found {value!r} twice")
        seen.add(value)


@dataclass(frozen=True)
class Session:
    """One planned session: who, which session of theirs, what, on which robot."""

    group: str
    number: int  # the group's session, 1, 2... across the study
    condition: Condition
    robot: str
    period: int  # 0-based: the round of the study it belongs to


@dataclass(frozen=True)
class Plan:
    """The design, every session, and each group's cell."""

    design: Design
    sessions: tuple[Session, ...]
    # Per group (in the shuffled order): the index of its order and of its robot mapping.
    cells: dict[str, tuple[int, int]]
    orders: tuple[tuple[int, ...], ...]

    def of_robot(self, robot: str) -> list[Session]:
        """A robot's sessions in running order: period by period, groups in dealt order."""
        dealt = {group: i for i, group in enumerate(self.cells)}
        mine = [s for s in self.sessions if s.robot == robot]
        return sorted(mine, key=lambda s: (s.period, dealt[s.group]))

    def of_group(self, group: str) -> list[Session]:
        """A group's sessions, first to last."""
        return sorted((s for s in self.sessions if s.group == group), key=lambda s: s.number)


def balanced_latin_square(k: int) -> list[list[int]]:
    """Williams' orders of k conditions: each in each position equally often, and each
    immediately after each other equally often (k rows for even k, 2k for odd)."""
    if k < 1:
        raise DesignError(f"a Latin square needs at least one condition, found {k}")
    first = [0]
    low, high = 1, k - 1
    for index in range(1, k):
        if index % 2:
            first.append(low)
            low += 1
        else:
            first.append(high)
            high -= 1
    rows = [[(c + shift) % k for c in first] for shift in range(k)]
    if k % 2:
        rows += [list(reversed(row)) for row in rows]
    return rows


def plan(design: Design) -> Plan:
    """Every session of the design, dealt by its seed."""
    rng = random.Random(design.seed)
    k, r = len(design.conditions), len(design.robots)
    groups = list(design.groups)
    rng.shuffle(groups)
    # Which condition is which symbol of the square: by the seed, so no condition is
    # always the one met first in the square's first row.
    symbols = list(range(k))
    rng.shuffle(symbols)
    if design.within:
        orders = [tuple(symbols[c] for c in row) for row in balanced_latin_square(k)]
    else:
        orders = [(c,) for c in range(k)]
    mappings = r if design.robot_plan in ("crossed", "group") else 1
    cells: dict[str, tuple[int, int]] = {}
    sessions: list[Session] = []
    for index, group in enumerate(groups):
        order = index % len(orders)
        mapping = (index // len(orders)) % mappings
        cells[group] = (order, mapping)
        period = 0
        for condition_index in orders[order]:
            robot = design.robots[_robot_index(design.robot_plan, condition_index, mapping, r)]
            for _ in range(design.repeats):
                sessions.append(
                    Session(group, period + 1, design.conditions[condition_index], robot, period)
                )
                period += 1
    return Plan(design, tuple(sessions), cells, tuple(orders))


def _robot_index(robot_plan: str, condition: int, mapping: int, robots: int) -> int:
    if robot_plan == "crossed":
        return (condition + mapping) % robots
    if robot_plan == "condition":
        return condition
    return mapping  # "group": the group's one robot


@dataclass(frozen=True)
class Balance:
    """How evenly the plan spreads conditions over positions and robots, groups over robots."""

    # (condition label, position) -> groups; position 1 is a group's first condition.
    by_position: dict[tuple[str, int], int]
    by_robot: dict[tuple[str, str], int]  # (condition label, robot) -> sessions
    groups_by_robot: dict[str, int]  # robot -> groups that meet it
    cells: int  # the design's cells (orders x robot mappings)

    @property
    def positions_even(self) -> bool:
        """Whether each condition is in each position equally often."""
        return len(set(self.by_position.values())) <= 1

    @property
    def robots_even(self) -> bool:
        """Whether each condition runs on each robot it is planned for equally often."""
        return len(set(self.by_robot.values())) <= 1


def balance(result: Plan) -> Balance:
    """The plan's counts: condition x position, condition x robot, groups per robot."""
    design = result.design
    by_position: Counter[tuple[str, int]] = Counter()
    by_robot: Counter[tuple[str, str]] = Counter()
    meets: dict[str, set[str]] = {robot: set() for robot in design.robots}
    for session in result.sessions:
        if session.period % design.repeats == 0:  # a group's repeats count once
            position = session.period // design.repeats + 1
            by_position[(session.condition.label, position)] += 1
        by_robot[(session.condition.label, session.robot)] += 1
        meets[session.robot].add(session.group)
    positions = len(result.orders[0])
    for condition in design.conditions:
        for position in range(1, positions + 1):
            by_position.setdefault((condition.label, position), 0)
    mappings = len({mapping for _, mapping in result.cells.values()})
    return Balance(
        dict(by_position),
        dict(by_robot),
        {robot: len(groups) for robot, groups in meets.items()},
        len(result.orders) * mappings,
    )


def group_codes(count: int, prefix: str = "G") -> tuple[str, ...]:
    """`count` group codes, G01, G02... (as wide as the largest needs)."""
    width = max(2, len(str(count)))
    return tuple(f"{prefix}{i:0{width}d}" for i in range(1, count + 1))


def sessions_toml(result: Plan, robot: str, header: Sequence[str]) -> str:
    """A robot's `[[sessions]]` file: comment lines, then its sessions in running order."""
    lines = [f"# {line}" if line else "#" for line in header]
    for session in result.of_robot(robot):
        lines += [
            "",
            "[[sessions]]",
            f'group = "{session.group}"',
            f"number = {session.number}",
            f'profile = "{session.condition.profile}"',
        ]
        if session.condition.uncertainty is not None:
            lines.append(f'uncertainty = "{session.condition.uncertainty}"')
    return "\n".join(lines) + "\n"


def summary(result: Plan) -> str:
    """The design as a table a researcher reads: each group's sessions, then the balance."""
    design = result.design
    counts = balance(result)
    slots = len(design.conditions if design.within else (0,)) * design.repeats
    width = max(len("group"), *(len(g) for g in design.groups))
    cell = max(
        len(f"{c.label} @ {robot}") for c in design.conditions for robot in design.robots
    )
    head = f"{'group':<{width}}  " + "  ".join(
        f"{f'session {n}':<{cell}}" for n in range(1, slots + 1)
    )
    lines = [_title(design), "", head.rstrip(), "-" * len(head.rstrip())]
    for group in sorted(result.cells):
        row = [f"{s.condition.label} @ {s.robot}" for s in result.of_group(group)]
        lines.append((f"{group:<{width}}  " + "  ".join(f"{c:<{cell}}" for c in row)).rstrip())
    lines.append("")
    if design.within:
        positions = len(result.orders[0])
        lines.append("Each condition by position (a group's first condition, second...):")
        for condition in design.conditions:
            found = [counts.by_position[(condition.label, p)] for p in range(1, positions + 1)]
            lines.append(f"  {condition.label:<{cell}}  " + "  ".join(f"{n:>3}" for n in found))
    lines.append("Sessions of each condition on each robot:")
    column = max(10, *(len(robot) for robot in design.robots))
    lines.append(f"  {'':<{cell}}  " + "  ".join(f"{robot:>{column}}" for robot in design.robots))
    for condition in design.conditions:
        found = [counts.by_robot.get((condition.label, robot), 0) for robot in design.robots]
        lines.append(f"  {condition.label:<{cell}}  " + "  ".join(f"{n:>{column}}" for n in found))
    lines.append(
        "Groups meeting each robot: "
        + ", ".join(f"{robot} {n}" for robot, n in counts.groups_by_robot.items())
    )
    spare = len(design.groups) % counts.cells
    if spare:
        lines.append(
            f"Not exactly balanced: {len(design.groups)} groups over {counts.cells} cells "
            f"(orders x robot mappings) leave {spare} over; a multiple of {counts.cells} "
            "balances it."
        )
    else:
        lines.append(
            f"Balanced: {len(design.groups)} groups, {len(design.groups) // counts.cells} in each "
            f"of {counts.cells} cells (orders x robot mappings)."
        )
    return "\n".join(lines)


def _title(design: Design) -> str:
    kind = "within-group" if design.within else "between-group"
    repeats = f", each condition {design.repeats} times in a row" if design.repeats > 1 else ""
    return (
        f"{kind} design: {len(design.groups)} groups x {len(design.conditions)} conditions "
        f"({', '.join(c.label for c in design.conditions)}) x {len(design.robots)} robots "
        f"({', '.join(design.robots)}), robots {design.robot_plan}{repeats}; seed {design.seed}"
    )


def header(result: Plan, robot: str, command: str) -> list[str]:
    """The comment lines of a robot's file: what it is, how it was made, how to use it."""
    sessions = len(result.of_robot(robot))
    return [
        f"Planned sessions of robot {robot}: {sessions}, in running order.",
        _title(result.design) + ".",
        f"Written by: {command}",
        "Name this file in the robot's kaspar.toml as sessions_file = \"<this file>\"",
        "(relative to kaspar.toml), then run `kasparctl check`. Make the plan again",
        "with the same command and seed rather than editing it by hand.",
    ]
