"""Opening a new session: its plan.json, its directory, its first state; which plan.

One way to open a session, for the daemon and the demo alike: `open_new` writes
the plan (`planned`: what the session will play, frozen at its start, so a resume
plays it whatever the configuration says then) and makes its first GameState.
`session_script` reads back the script a session was planned with. `PlanQueue`
is which planned session "next" opens, the researcher's choice among them in
idle, and the groups marked absent.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import msgspec

from kasparctl import __version__
from kasparctl.config import Config, SessionPlan, SessionSettings, resolve_session
from kasparctl.game import recovery
from kasparctl.game.jsonl import UNDECODABLE, read_records
from kasparctl.game.records import SessionEvent, SessionRecord
from kasparctl.game.resume import abandoned_reason
from kasparctl.game.scripts import LEGACY_SCRIPT, Script, script
from kasparctl.game.session import (
    PLAN_FILE,
    RECORDS_FILE,
    Session,
    frozen_learner,
    is_finished,
    session_dirs,
)
from kasparctl.game.state import GameState


class OpenedSession(NamedTuple):
    """A session open on disk, the plan it plays, and the state it has reached."""

    session: Session
    plan: SessionPlan
    state: GameState
    # What it plays with (kasparctl.config.session_settings); None: read from its plan.json.
    settings: SessionSettings | None = None


def planned(
    config: Config, plan: SessionPlan, seed: int | None, settings: SessionSettings | None = None
) -> dict[str, Any]:
    """A session's plan.json (less its id and creation time, which Session.create adds).

    The group, its session number, the condition, the variant, the learner's seed,
    the uncertainty script and its version, the language, the plan entry itself, the
    robot (id and name), kasparctl's version and every setting the group experiences
    (`settings`: SessionSettings.block, resolved from `config` unless given).
    """
    settings = settings or resolve_session(config, plan)
    plan = settings.plan
    chosen = script(settings.game.script)
    seats = config.keyfob.children
    seating: dict[str, Any] = {}
    if seats:
        # One keyfob per child: who sat where, and the rule for a press out of turn.
        seating = {
            "seats": [
                {"seat": number, "device": seat.where, "child": seat.child}
                for number, seat in enumerate(seats, start=1)
            ],
            "answer_out_of_turn": plan.answer_out_of_turn or config.game.answer_out_of_turn,
        }
    return {
        **seating,
        "group": plan.group,
        "number": plan.number,
        "condition": plan.condition,
        "variant": settings.game.variant,
        "seed": seed,
        "script": chosen.name,
        "script_version": chosen.version,
        # What Kaspar spoke (sessions planned before languages were recorded spoke "en").
        "language": settings.language,
        # Confusion noticed, names re-opened (kasparctl.game.recovery); absent before.
        "recovery": recovery.RECOVERY_VERSION,
        "uncertainty": plan.uncertainty_mode,
        "plan": msgspec.to_builtins(plan.resolved()),
        # Frozen at the start: a resume uses these, whatever the configuration says then.
        "learner": frozen_learner(plan.profile, settings.learner),
        "robot": settings.robot_block(),
        "kasparctl_version": __version__,
        "settings": settings.block(),
    }


def open_new(state_dir: Path, config: Config, plan: SessionPlan, seed: int) -> OpenedSession:
    """A new session of `plan` in `state_dir`, its learner seeded with `seed`.

    StorageFailed when its directory or plan cannot be written.
    """
    settings = resolve_session(config, plan)
    session = Session.create(state_dir, planned(config, plan, seed, settings))
    state = GameState.new(settings.game, settings.learner, seed)
    return OpenedSession(session, settings.plan, state, settings)


def session_script(session: Session) -> Script:
    """The script a session was planned with; the five varied bands before scripts existed."""
    return script(str(session.plan.get("script", LEGACY_SCRIPT)))


@dataclass(frozen=True, slots=True)
class Offer:
    """A planned session not yet ended, as the researcher chooses among them in idle."""

    plan: SessionPlan
    # Its group is marked absent: "next" does not open it unless it is chosen.
    absent: bool = False

    @property
    def group(self) -> str:
        """The planned group's code."""
        return self.plan.group

    @property
    def number(self) -> int:
        """The group's session number."""
        return self.plan.number

    @property
    def words(self) -> str:
        """The session in words: "group A1, session 2"."""
        return f"group {self.plan.group}, session {self.plan.number}"


class PlanQueue:
    """The planned sessions, what "next" opens, and the researcher's choice among them.

    "next" opens the first planned (group, number) that has not ended and whose group is
    not marked absent (sessions recorded before plans were numbered are number 1; an
    abandoned session did not end: it is played again); with every plan ended, the last
    again. In idle the researcher's "choose" steps through the planned sessions not
    ended, those marked absent included, and "next" opens the one chosen; "absent"
    marks the chosen one's group absent without opening it, or takes the mark back.

    An absence is durable: a session directory of its own whose plan.json says
    "absent" and whose only records are `session` `absent` (and `present` when the mark
    is taken back), finished: `kasparctl sessions` and the exports show it as absent,
    never as a session stopped with no trials, and it is never resumed. The choice
    itself is not: after a restart "next" opens the first again.
    """

    def __init__(self, state_dir: Path, config: Callable[[], Config]) -> None:
        """The plans of `config()` (read again at each use: a reload changes them) against
        the sessions of `state_dir`."""
        self.state_dir = state_dir
        self._config = config
        self._chosen: tuple[str, int] | None = None

    def offered(self) -> list[Offer]:
        """The planned sessions not yet ended, in plan order, absent ones marked."""
        ended, absent = self._read()
        return [
            Offer(plan, (plan.group, plan.number) in absent)
            for plan in self._config().sessions
            if (plan.group, plan.number) not in ended
        ]

    def chosen(self) -> Offer | None:
        """What "next" opens now: the researcher's choice, else the first not absent."""
        offered = self.offered()
        picked = [offer for offer in offered if (offer.group, offer.number) == self._chosen]
        if picked:
            return picked[0]
        return next((offer for offer in offered if not offer.absent), None)

    def choose(self) -> Offer:
        """The researcher steps on to the next planned session (after the last, the first).

        ValueError when nothing is offered (the command does not apply then)."""
        offered = self.offered()
        if not offered:
            raise ValueError("no planned session to choose")
        current = self.chosen()
        index = offered.index(current) + 1 if current in offered else 0
        offer = offered[index % len(offered)]
        self._chosen = (offer.group, offer.number)
        return offer

    def toggle_absent(self, clock: float) -> Offer:
        """The chosen session's group marked absent, or (already marked) the mark taken back;
        the session as it now stands. Once marked, the choice goes back to what "next"
        would open. StorageFailed when the mark cannot be written."""
        offer = self.chosen()
        if offer is None:
            raise ValueError("no planned session to mark absent")
        if offer.absent:
            self._mark(offer.plan, SessionEvent.PRESENT, clock)
            self._chosen = (offer.group, offer.number)
            return Offer(offer.plan, absent=False)
        self._mark(offer.plan, SessionEvent.ABSENT, clock)
        self._chosen = None
        return Offer(offer.plan, absent=True)

    def take(self, clock: Callable[[], float]) -> SessionPlan:
        """The plan "next" opens now (an absent group chosen is marked present first, its
        record stamped with `clock()`); the researcher's choice is used up."""
        plans = self._config().sessions
        if not plans:
            return SessionPlan(group="unplanned")
        offer = self.chosen()
        self._chosen = None
        if offer is None:
            return plans[-1]
        if offer.absent:
            self._mark(offer.plan, SessionEvent.PRESENT, clock())
        return offer.plan

    def words(self) -> str:
        """What idle's STATUS= says "next" would do."""
        offer = self.chosen()
        if offer is None:
            return "waiting: 'next' starts the session"
        if offer.absent:
            return (
                f"waiting: chosen {offer.words}, marked absent: 'next' starts it all the same, "
                "'absent' takes the mark back, 'choose' chooses another"
            )
        return f"waiting: 'next' starts {offer.words}"

    # -- the state directory ------------------------------------------------------------

    def _read(self) -> tuple[set[tuple[str, int]], set[tuple[str, int]]]:
        """The (group, number)s ended, and those marked absent, as the sessions on disk say."""
        ended: set[tuple[str, int]] = set()
        absent: set[tuple[str, int]] = set()
        for directory in session_dirs(self.state_dir):
            with contextlib.suppress(OSError, *UNDECODABLE, KeyError, TypeError, ValueError):
                meta = msgspec.json.decode((directory / PLAN_FILE).read_bytes())
                key = (meta["group"], int(meta.get("number", 1)))
                if meta.get("absent") is True:
                    if _absence_stands(directory):
                        absent.add(key)
                elif is_finished(directory) and abandoned_reason(directory) is None:
                    ended.add(key)
        return ended, absent - ended

    def _absence_of(self, plan: SessionPlan) -> Path | None:
        for directory in session_dirs(self.state_dir):
            with contextlib.suppress(OSError, *UNDECODABLE, KeyError, TypeError, ValueError):
                meta = msgspec.json.decode((directory / PLAN_FILE).read_bytes())
                if meta.get("absent") is True and (meta["group"], int(meta.get("number", 1))) == (
                    plan.group,
                    plan.number,
                ):
                    return directory
        return None

    def _mark(self, plan: SessionPlan, event: SessionEvent, clock: float) -> None:
        """The group's absence written (its own session directory), or taken back there."""
        config = self._config()
        directory = self._absence_of(plan)
        if directory is not None:
            session, _ = Session.open(directory)
            try:
                session.record(SessionRecord(event=event, state="idle"), clock)
            finally:
                session.close()
            return
        if event is SessionEvent.PRESENT:
            return  # never marked: nothing to take back
        session = Session.create(
            self.state_dir, {**planned(config, plan, None), "absent": True}
        )
        try:
            session.record(SessionRecord(event=event, state="idle"), clock)
            settings = resolve_session(config, plan)
            state = GameState.new(settings.game, settings.learner, None)
            session.save_state(state, finished=True)
        finally:
            session.close()


def is_absence(directory: Path) -> bool:
    """Whether a session directory is a group's absence (never opened, never waiting)."""
    with contextlib.suppress(OSError, *UNDECODABLE, AttributeError):
        return msgspec.json.decode((directory / PLAN_FILE).read_bytes()).get("absent") is True
    return False


def _absence_stands(directory: Path) -> bool:
    """Whether an absence's last word is "absent" (not taken back)."""
    events = [
        record.event
        for record in read_records(directory / RECORDS_FILE).records
        if isinstance(record, SessionRecord)
        and record.event in (SessionEvent.ABSENT, SessionEvent.PRESENT)
    ]
    return bool(events) and events[-1] is SessionEvent.ABSENT
