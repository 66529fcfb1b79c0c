"""The researcher's commands: where they come from, and where each applies.

Pure rules, no I/O: the game (kasparctl.game.machine) asks them and acts.
Which command applies where comes from the machine's own table
(kasparctl.game.stages) through `may`: a command applies where the trigger it
fires would move the machine. Only what the table cannot know is added here:
the researcher's "next" never skips a step that ends by itself (while Kaspar checks
the buttons at a session's start it skips the check, not the step), undo needs an
answer to take back, a re-open needs a learned name and a target still open
(kasparctl.game.recovery), a resume from a fault needs the keyfob back, and in idle
a stopped session waiting for the researcher's choice is reopened by "next"
and closed by "stop".

The commands come from the researcher's own device (a key per command), from
a keypad's extra keys, or, on a robot with one keyfob, from holds on the
children's keyfob (game.commands: "long green", "long red", "both", held
researcher.hold_s) that count only when begun while Kaspar asks the children
nothing (kasparctl.game.presses.ChildPresses.asking_at).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from hal.keyfob.gestures import Gesture, GestureKind, GestureNeeds, held_gestures
from kasparctl.game.records import Confirmation
from kasparctl.game.stages import PAUSABLE, RESEARCHER_MOVES_ON, Conditions, may
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
# Kaspar confirms these before what they start; the others after what they stop. A
# start has no confirmation of its own: the greeting that begins the session is it.
SPOKEN_FIRST = frozenset({Confirmation.NEXT_STEP, Confirmation.RESUME})
# A re-open is confirmed by the game itself, naming the name it re-opens; a skipped check
# of the buttons by what Kaspar says next.
SILENT = frozenset(
    {
        Confirmation.START,
        Confirmation.REOPEN,
        Confirmation.SKIP_CHECK,
        # The next child is named as Kaspar asks them: nothing else is said.
        Confirmation.AWAY,
        Confirmation.BACK,
        # Before a session nothing is said to the children (a chime, where configured).
        Confirmation.CHOOSE,
        Confirmation.ABSENT,
        Confirmation.PRESENT,
    }
)


@dataclass(frozen=True, slots=True)
class Facts:
    """What, besides the machine's stage, decides whether a command applies."""

    conditions: Conditions  # the transitions' conditions (bags taught, where a resume goes...)
    undo_available: bool  # an answer was recorded since the last undo or step
    hardware_ready: bool  # the keyfob is connected: a resume from a fault can be heard
    # A stopped session waits in idle for the researcher: reopen it or close it.
    stopped_waiting: bool = False
    # A learned name can be re-opened: one is learned, and a target is still open.
    reopen_available: bool = False
    # What the researcher's "away" would do in step 4 (kasparctl.game.rotation): AWAY
    # (the child asked taken out), BACK (the child skipped just now back), or None.
    away: Confirmation | None = None
    # In idle, before a session: planned sessions to choose from (none stopped waits).
    plans_to_choose: bool = False
    # Kaspar is checking the buttons at the start of the session (kasparctl.game.buttons).
    checking_buttons: bool = False


def confirmation(stage: str, command: Command, facts: Facts) -> Confirmation | None:
    """What `command` does in `stage`, as the confirmation Kaspar says; None: it does not apply."""
    conditions = facts.conditions
    if command is Command.STOP:
        if may("stop", stage, conditions):
            return Confirmation.STOP
        return Confirmation.CLOSE if stage == "idle" and facts.stopped_waiting else None
    if command is Command.PAUSE:
        if may("pause", stage, conditions):
            return Confirmation.PAUSE
        if may("resume", stage, conditions) and (stage != "fault" or facts.hardware_ready):
            return Confirmation.RESUME
        return None
    if command is Command.UNDO:
        return Confirmation.UNDO if stage == "guessing" and facts.undo_available else None
    if command is Command.REOPEN:
        return Confirmation.REOPEN if stage == "guessing" and facts.reopen_available else None
    if command is Command.AWAY:
        return facts.away if stage == "guessing" else None
    if command in (Command.CHOOSE, Command.ABSENT):
        if stage != "idle" or not facts.plans_to_choose:
            return None
        return Confirmation.CHOOSE if command is Command.CHOOSE else Confirmation.ABSENT
    if facts.checking_buttons and stage in PAUSABLE:
        return Confirmation.SKIP_CHECK  # "next" skips the check, not the step
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


def gesture_needs(commands: Mapping[str, Command], hold_s: float) -> GestureNeeds:
    """The children's keyfob when it also carries the researcher's commands: presses, and
    holds of `hold_s` for the buttons (and the chord) some command uses; a red press
    waits for its release only if a long red means something."""
    return held_gestures(
        hold_s,
        green="long green" in commands,
        red="long red" in commands,
        both="both" in commands,
    )
