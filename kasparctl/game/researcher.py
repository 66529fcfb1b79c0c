"""The researcher's side of the keyfob: gestures to commands, and where each command applies.

Pure rules, no I/O: the game (kasparctl.game.machine) asks them and acts.
Which command applies where comes from the machine's own table
(kasparctl.game.stages) through `may`: a command applies where the trigger it
fires would move the machine. Only what the table cannot know is added here:
the researcher's "next" never skips a step that ends by itself, undo needs an
answer to take back, and a resume from a fault needs the keyfob back.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from hal.keyfob.gestures import Gesture, GestureKind, GestureNeeds
from kasparctl.game.records import Confirmation
from kasparctl.game.stages import RESEARCHER_MOVES_ON, Conditions, may
from kasparctl.vocabulary import Command

# The machine's trigger each confirmation fires; an undo is no transition (the game
# takes the answer back and asks again, staying in guessing).
TRIGGERS: Mapping[Confirmation, str] = {
    Confirmation.START: "start",
    Confirmation.NEXT_STEP: "advance",
    Confirmation.PAUSE: "pause",
    Confirmation.RESUME: "resume",
    Confirmation.STOP: "stop",
}
# Kaspar confirms these before what they start; the others after what they stop.
SPOKEN_FIRST = frozenset({Confirmation.START, Confirmation.NEXT_STEP, Confirmation.RESUME})

_MODIFIERS = {"long": GestureKind.LONG, "double": GestureKind.DOUBLE}


@dataclass(frozen=True, slots=True)
class Facts:
    """What, besides the machine's stage, decides whether a command applies."""

    conditions: Conditions  # the transitions' conditions (bags taught, where a resume goes...)
    undo_available: bool  # an answer was recorded since the last undo or step
    hardware_ready: bool  # the keyfob is connected: a resume from a fault can be heard


def confirmation(stage: str, command: Command, facts: Facts) -> Confirmation | None:
    """What `command` does in `stage`, as the confirmation Kaspar says; None: it does not apply."""
    conditions = facts.conditions
    if command is Command.STOP:
        return Confirmation.STOP if may("stop", stage, conditions) else None
    if command is Command.PAUSE:
        if may("pause", stage, conditions):
            return Confirmation.PAUSE
        if may("resume", stage, conditions) and (stage != "fault" or facts.hardware_ready):
            return Confirmation.RESUME
        return None
    if command is Command.UNDO:
        return Confirmation.UNDO if stage == "guessing" and facts.undo_available else None
    if may("start", stage, conditions):
        return Confirmation.START
    if stage in RESEARCHER_MOVES_ON and may("advance", stage, conditions):
        return Confirmation.NEXT_STEP
    return None


def commands_by_gesture(commands: Mapping[str, str]) -> dict[str, Command]:
    """game.commands (gesture name -> command name, validated by the configuration) typed."""
    return {gesture: Command(name) for gesture, name in commands.items()}


def gesture_name(gesture: Gesture) -> str:
    """The name game.commands gives a researcher gesture: "long green", "double red", "both"."""
    if gesture.kind is GestureKind.COMMAND:
        return gesture.button
    if gesture.kind is GestureKind.BOTH:
        return "both"
    return f"{gesture.kind.value} {gesture.button}"


def gesture_needs(commands: Mapping[str, Command]) -> GestureNeeds:
    """Only the gestures some command uses: a red press need not wait for a double
    unless a double red means something."""
    needs: dict[str, set[GestureKind]] = {
        "green": {GestureKind.PRESS},
        "red": {GestureKind.PRESS},
    }
    for gesture in commands:
        words = gesture.split()
        if len(words) == 2:
            needs[words[1]].add(_MODIFIERS[words[0]])
    return GestureNeeds(
        green=frozenset(needs["green"]),
        red=frozenset(needs["red"]),
        both="both" in commands,
    )
