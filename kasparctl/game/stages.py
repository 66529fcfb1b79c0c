"""The game's stages and the transitions between them, as data.

The live machine (kasparctl.game.machine), the researcher's commands
(kasparctl.game.researcher) and the README's diagram (kasparctl.game.diagram)
all read this one table. A stage is a state of the machine: idle, one of the
paper's five steps, finished, paused, fault or stopped.

Conditions are named in the table and answered by `Conditions.holds`, the
one place that knows what each name means: the live machine asks it through
its model, `may` asks it without any machine.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

# The game's steps in order; the pilot variant starts at "guessing".
STEPS = ("placing", "teaching", "revealing", "guessing", "farewell")
PAUSABLE = ("placing", "teaching", "revealing", "guessing")
# A fault can stop these; farewell too, since it moves the robot to rest (found by the soak:
# a servo fault during farewell left the game in farewell for good).
FAULTABLE = (*PAUSABLE, "farewell")
STATES = ("idle", *STEPS, "finished", "paused", "fault", "stopped")
# Where the game is over: run() returns.
ENDS = ("finished", "stopped")
# Steps that wait for the researcher's "next" to move on (teaching once every bag is
# taught); guessing and farewell end by themselves, and no command skips them.
RESEARCHER_MOVES_ON = ("placing", "teaching", "revealing")
# Stages a resume can return to: a paused or faulted step, or idle (a fault before the start).
RESUMABLE = ("idle", *FAULTABLE)

RETURNS_TO = "returns_to_"


@dataclass(frozen=True, slots=True)
class Conditions:
    """The answers to the table's conditions at one moment of a game."""

    plays_names: bool  # the names variant (steps 1-5), not the pilot (step 4 only)
    bags_taught: bool  # every bag's pose is known
    all_done: bool  # every target is learned or given up
    # Where a resume returns to: the step left for a pause or a fault (or, for a stopped
    # session reopened, the step it was stopped in).
    resume_step: str

    def holds(self, name: str) -> bool:
        """The value of the condition `name` (a "conditions"/"unless" entry of TRANSITIONS)."""
        if name.startswith(RETURNS_TO):
            return self.resume_step == name.removeprefix(RETURNS_TO)
        values = {
            "plays_names": self.plays_names,
            "bags_taught": self.bags_taught,
            "all_done": self.all_done,
        }
        return values[name]


def _transitions() -> list[dict[str, Any]]:
    """The machine's transitions as data: the live machine and the diagram share them."""
    table: list[dict[str, Any]] = [
        {"trigger": "start", "source": "idle", "dest": "placing", "conditions": "plays_names"},
        {"trigger": "start", "source": "idle", "dest": "guessing", "unless": "plays_names"},
        {"trigger": "advance", "source": "placing", "dest": "teaching"},
        {
            "trigger": "advance",
            "source": "teaching",
            "dest": "revealing",
            "conditions": "bags_taught",
        },
        {"trigger": "advance", "source": "revealing", "dest": "guessing"},
        {"trigger": "advance", "source": "guessing", "dest": "farewell", "conditions": "all_done"},
        {"trigger": "advance", "source": "farewell", "dest": "finished"},
        {"trigger": "pause", "source": list(PAUSABLE), "dest": "paused"},
        {"trigger": "fail", "source": ["idle", *FAULTABLE, "paused"], "dest": "fault"},
        {"trigger": "stop", "source": [*STEPS, "paused", "fault"], "dest": "stopped"},
    ]
    for step in FAULTABLE:
        table.append(
            {
                "trigger": "resume",
                "source": ["paused", "fault"] if step in PAUSABLE else "fault",
                "dest": step,
                "conditions": f"{RETURNS_TO}{step}",
            }
        )
    table.append(
        {"trigger": "resume", "source": "fault", "dest": "idle", "conditions": f"{RETURNS_TO}idle"}
    )
    # A stopped session reopened later (the researcher's "next" in idle): back to its step.
    for step in STEPS:
        table.append(
            {
                "trigger": "reopen",
                "source": "idle",
                "dest": step,
                "conditions": f"{RETURNS_TO}{step}",
            }
        )
    return table


TRANSITIONS = _transitions()


def _names(entry: str | list[str] | None) -> list[str]:
    if entry is None:
        return []
    return [entry] if isinstance(entry, str) else list(entry)


def may(trigger: str, stage: str, conditions: Conditions) -> str | None:
    """Where `trigger` would take the machine from `stage`, or None if no transition applies.

    The first transition in table order whose source matches and whose
    conditions hold, as transitions itself picks one.
    """
    for transition in TRANSITIONS:
        if transition["trigger"] != trigger or stage not in _names(transition["source"]):
            continue
        if all(conditions.holds(name) for name in _names(transition.get("conditions"))) and not any(
            conditions.holds(name) for name in _names(transition.get("unless"))
        ):
            return str(transition["dest"])
    return None


def bound_transitions(holds: Callable[[str], bool]) -> list[dict[str, Any]]:
    """TRANSITIONS for a live machine: each named condition asked of `holds(name)`."""
    bound = []
    for transition in TRANSITIONS:
        live = dict(transition)
        for key in ("conditions", "unless"):
            if key in live:
                live[key] = functools.partial(holds, live[key])
        bound.append(live)
    return bound
