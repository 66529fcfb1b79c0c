"""Whose a gesture is: a child's answer, or the researcher's command, and from which source.

The researcher's commands come from their own device (a key per command, the
default), from the extra keys of the children's keypad, or, on a robot with one
keyfob (and while their own device is away), from holds on the children's keyfob
that count only when begun while Kaspar asks the children nothing
(kasparctl.game.presses.ChildPresses.asking_at). A child's green or red press is
always a child's; a key that means no command is recorded as such.

Pure decisions on what it is given: the game acts on what `Router` returns
(kasparctl.game.machine), and sets the children's keyfob to wait for what
`keyfob_needs` says.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from hal.keyfob.api import KeyfobInput
from hal.keyfob.gestures import ANSWERS_ONLY, Gesture, GestureKind, GestureNeeds
from hal.keyfob.settings import ResearcherSettings
from kasparctl.game.records import PressRecord
from kasparctl.game.researcher import commands_by_gesture, gesture_name, gesture_needs
from kasparctl.vocabulary import Command


@dataclass(frozen=True, slots=True)
class ChildPress:
    """A child's green or red: the answer, if one is awaited (kasparctl.game.presses)."""

    button: str
    at: float


@dataclass(frozen=True, slots=True)
class ChildGesture:
    """A child's hold, squeeze or double: its first key-down is a press like any other, and
    what it went on to be (`name`) is recorded, never acted on."""

    button: str
    name: str
    at: float


@dataclass(frozen=True, slots=True)
class HeldPress:
    """A hold that reached the researcher's hold and is no command (begun while the
    children were asked, or with no command for it): neither an answer nor a command,
    recorded as what it was (kasparctl.game.presses.ChildPresses.held)."""

    button: str
    name: str
    at: float


@dataclass(frozen=True, slots=True)
class ResearcherCommand:
    """The researcher's `command`, given by `gesture` at `at` on `source` (researcher,
    keypad or keyfob)."""

    command: Command
    gesture: str
    at: float
    source: str


@dataclass(frozen=True, slots=True)
class NoCommand:
    """A command key that means no command: recorded, nothing else."""

    record: PressRecord


Routed = ChildPress | ChildGesture | HeldPress | ResearcherCommand | NoCommand


class Router:
    """Where the researcher's commands come from, and whose each gesture is."""

    def __init__(
        self,
        researcher: ResearcherSettings,
        commands: Mapping[str, str],
        device: KeyfobInput | None,
    ) -> None:
        """The researcher's settings, game.commands (their holds on the children's keyfob),
        and their own device (None: there is none)."""
        self.researcher = researcher
        self.commands = commands_by_gesture(commands)
        self.device = device

    @property
    def reads_device(self) -> bool:
        """Whether the researcher's own device is to be read."""
        return self.device is not None and self.researcher.source == "device"

    def commands_on_keyfob(self) -> bool:
        """The researcher's commands are holds on the children's keyfob: there is no
        device of their own, or it is away."""
        source = self.researcher.source
        if source == "keyfob":
            return True
        if source == "keypad":
            return False
        return self.device is None or not self.device.connected

    def keyfob_needs(self) -> GestureNeeds:
        """What the children's keyfob waits for before it says what a key-down was."""
        if self.commands_on_keyfob():
            return gesture_needs(self.commands, self.researcher.hold_s)
        # Nothing the children do is a command: every key-down is a press, at once.
        return ANSWERS_ONLY

    def from_keyfob(self, gesture: Gesture, asking_at: Callable[[float], bool]) -> Routed:
        """A gesture of the children's keyfob: their answer, or (a hold, on one keyfob only,
        begun while nobody is asked: not `asking_at` its start) the researcher's command;
        any other hold is neither (HeldPress)."""
        if gesture.kind is GestureKind.PRESS and gesture.button in ("green", "red"):
            return ChildPress(gesture.button, gesture.at)
        name = gesture_name(gesture)
        if gesture.kind is GestureKind.COMMAND:
            # An extra key of the children's keypad ([keyfob.commands]).
            if self.researcher.source == "keypad" and gesture.button in tuple(Command):
                return ResearcherCommand(Command(gesture.button), name, gesture.at, "keypad")
            return _no_command(gesture)
        # A hold, a chord or a double: the children's, or the researcher's on one keyfob.
        button = gesture.first if gesture.kind is GestureKind.BOTH else gesture.button
        command = self.commands.get(name) if self.commands_on_keyfob() else None
        if command is not None and not asking_at(gesture.at):
            return ResearcherCommand(command, name, gesture.at, "keyfob")
        if gesture.kind in (GestureKind.LONG, GestureKind.BOTH):
            # It reached the researcher's hold: whoever held it, it answers nothing.
            return HeldPress(button or "green", name, gesture.at)
        return ChildGesture(button or "green", name, gesture.at)

    def from_device(self, gesture: Gesture) -> ResearcherCommand | NoCommand:
        """A key of the researcher's own device: its command, or none."""
        if gesture.kind is GestureKind.COMMAND and gesture.button in tuple(Command):
            command = Command(gesture.button)
            return ResearcherCommand(command, gesture.button, gesture.at, "researcher")
        return _no_command(gesture)


def _no_command(gesture: Gesture) -> NoCommand:
    name = gesture_name(gesture)
    return NoCommand(
        PressRecord(button=gesture.button, gesture=name, at=gesture.at, ignored="no command")
    )
