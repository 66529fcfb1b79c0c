"""Whose turn it is in step 4, who pressed, and the children out of the rotation.

The children answer in turn: child (turn mod group size). A child is out of the
rotation when the researcher took them out ("away", for a child who left the
table) or when their seat's keyfob is not connected ([[keyfob.children]]): their
turn is passed over, recorded as a `rotation` record ("skipped") that moves the
turn on, so a resume replays the same rotation and the others keep their order.

The researcher's one key "away", during a question of step 4:
- asked right after a child's skipped turn (the rotation's previous place is a
  child out), it brings that child back and asks them instead: on every later
  cycle that is the moment their place comes round, and pressed twice in a row
  it takes a mistaken "away" back at once;
- otherwise it takes the child asked out, and the question goes to the next child.
The last child in the rotation cannot be taken out. Why the last one taken out,
and not everybody: children come back one by one, and "everybody back" would
put a child who is still away back into the turns.

With one keyfob per child, a press is credited to its seat's child. A press
from a child whose turn it is not is recorded and not taken, or taken and
credited to the presser (`answer_out_of_turn`, per session: "ignore" by default).

Pure rules on what they are given; the game (kasparctl.game.machine, guess)
writes the records.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from typing import Literal

import msgspec
from msgspec import UNSET

from kasparctl.game.records import PressRecord, RotationRecord
from kasparctl.game.state import GameState

OutOfTurn = Literal["ignore", "take"]
OUT_OF_TURN = "out of turn"
NO_CHILD_HERE = "no child of this group at this seat"
KEYFOB_ABSENT = "keyfob absent"


def away(state: GameState) -> frozenset[int]:
    """The children the researcher took out of the rotation."""
    return frozenset(() if state.away is UNSET else state.away)


def skips(
    state: GameState,
    group_size: int,
    absent: Collection[int],
    name: Callable[[int], str],
    seat_of: Callable[[int], int | None] = lambda _child: None,
) -> list[RotationRecord]:
    """The turns to pass over before the next question: each child out of the rotation
    (away, or in `absent`: their seat's keyfob not connected) whose turn comes first.

    None when every child is out: the question is asked all the same.
    """
    taken_out = away(state)
    out = {child for child in range(group_size) if child in taken_out or child in absent}
    if group_size < 2 or len(out) >= group_size:
        return []
    records = []
    turn = state.turn
    while (child := turn % group_size) in out:
        turn += 1
        seat = seat_of(child)
        records.append(
            RotationRecord(
                event="skipped",
                child=name(child),
                child_index=child,
                turn=turn,
                reason="away" if child in taken_out else KEYFOB_ABSENT,
                seat=UNSET if seat is None else seat + 1,
            )
        )
    return records


def away_command(
    state: GameState, group_size: int, name: Callable[[int], str]
) -> RotationRecord | None:
    """What the researcher's "away" does now (the module's rule); None when it cannot."""
    if group_size < 2:
        return None
    taken_out = away(state)
    turn = state.turn
    previous = (turn - 1) % group_size
    if turn > 0 and previous in taken_out:
        back = name(previous)
        return RotationRecord(event="back", child=back, child_index=previous, turn=turn - 1)
    asked = turn % group_size
    present = [child for child in range(group_size) if child not in taken_out]
    if asked in taken_out or len(present) < 2:
        return None
    return RotationRecord(event="away", child=name(asked), child_index=asked, turn=turn)


@dataclass(frozen=True, slots=True)
class Seat:
    """A seat of [[keyfob.children]]: its child's place (from 0) and its device."""

    child: int
    device: str


@dataclass
class Turn:
    """The live picture a guess and the run loop share: whose turn the open question is,
    and which seat's press answered it."""

    seats: Sequence[Seat] = ()
    # The child (from 0) the open question asks; None while none is open.
    asking: int | None = None
    # The seat (from 0) whose press answered the last question; None: no seat (or one keyfob).
    answered_by: int | None = None
    # Seats whose keyfob is not connected.
    absent_seats: set[int] = field(default_factory=set)

    def seat_of(self, child: int) -> int | None:
        """The seat of child `child`, if they have one."""
        return next((i for i, seat in enumerate(self.seats) if seat.child == child), None)

    def absent_children(self) -> frozenset[int]:
        """The children whose seat's keyfob is not connected."""
        return frozenset(self.seats[i].child for i in self.absent_seats if i < len(self.seats))

    def out_of_turn(self, seat: int) -> bool:
        """Whether a press of `seat` now is from a child whose turn it is not."""
        return self.asking is not None and self.seats[seat].child != self.asking

    def refused(self, seat: int, group_size: int, rule: OutOfTurn) -> str | None:
        """Why a press of `seat` during the open question is not taken (recorded instead):
        no child of this group sits there, or it is out of turn and the rule ignores it;
        None: it is a press like any other (the answer, if one is awaited)."""
        if self.asking is None:
            return None
        if not (0 <= seat < len(self.seats) and self.seats[seat].child < group_size):
            return NO_CHILD_HERE
        if self.out_of_turn(seat) and rule == "ignore":
            return OUT_OF_TURN
        return None

    def pressed(
        self,
        record: PressRecord,
        seat: int | None,
        group_size: int,
        name: Callable[[int], str],
        turn_of: int | None = None,
    ) -> PressRecord:
        """`record` saying which seat, device and child pressed (unchanged without a seat)."""
        if seat is None or not 0 <= seat < len(self.seats):
            return record
        child = self.seats[seat].child
        return msgspec.structs.replace(
            record,
            seat=seat + 1,
            device=self.seats[seat].device,
            pressed_by=name(child) if child < group_size else UNSET,
            pressed_by_index=child,
            turn_of_index=UNSET if turn_of is None else turn_of,
        )
