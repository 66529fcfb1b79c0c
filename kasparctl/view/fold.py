"""The live view's picture of a session: a pure function of its typed records.

`session_view(plan, records)` folds the records of one session, in order, into
a SessionView: the stage the game is in, the open question (or the last one
answered) with the learner's probability of each toy, the answers so far, the
toys learned, the researcher's commands and the faults. `daemon_events`
reads the daemon's own log (events.jsonl) as plain data, since the daemon
may write kinds this code does not know. No clock, no I/O: the renderer
decides what "how long ago" means.

The stage follows the machine as the records tell it: a step record moves it,
an applied pause or resume, a fault the game stopped for, a shutdown of the
daemon and a resume of the session; where the records cannot tell (a record
written by newer code, a session cut short), the last known stage stands.

What is learned, given up and re-opened, whether Kaspar is confused, and each
answer's flags are read as the game, STATUS= and the research read them
(kasparctl.game.fold.Reading). The view is not told the session's limit of
guesses unless it is given it: it then sees a bag given up when the game asks
about the next one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from msgspec import UNSET

from kasparctl.game.fold import Confusion, Facts, Guess, Reading
from kasparctl.game.records import (
    AlertRecord,
    AnyRecord,
    ClockRecord,
    CommandRecord,
    Confirmation,
    FaultRecord,
    HalEvent,
    HalRecord,
    PoseRecord,
    PressRecord,
    PromptRecord,
    QuestionRecord,
    ReopenRecord,
    SessionEvent,
    SessionRecord,
    StepRecord,
    TrialRecord,
    UndoRecord,
)
from kasparctl.game.stages import ENDS, STEPS
from kasparctl.view.model import (
    Answer,
    Bar,
    CommandSeen,
    DaemonEvent,
    FaultSeen,
    Learned,
    Question,
    SessionView,
)


def _text(plain: Mapping[str, Any], *keys: str) -> str:
    for key in keys:
        value = plain.get(key)
        if value not in (None, ""):
            return str(value)
    return ""


def daemon_events(lines: Sequence[Mapping[str, Any]]) -> tuple[DaemonEvent, ...]:
    """The daemon's own events (faults outside a session among them), from events.jsonl.

    Read as plain JSON objects so a kind this code does not know still shows:
    its time, its name (`event`, else `kind`) and its detail (`detail`, `reason`
    or `error`). An event is a fault when its kind or name says "fault".
    """
    events = []
    for plain in lines:
        name = _text(plain, "event", "kind") or "event"
        kind = _text(plain, "kind")
        detail = _text(plain, "detail", "reason", "error", "message")
        fault = "fault" in name or "fault" in kind
        if fault and _text(plain, "fault"):
            name = _text(plain, "fault")
        chosen = ""
        if kind == "command" and plain.get("applied") and _text(plain, "group"):
            # The researcher's choice in idle (kasparctl.game.opening.PlanQueue).
            name = _text(plain, "confirm", "command")
            chosen = f"group {_text(plain, 'group')}, session {_text(plain, 'number') or '1'}"
            if name == "absent":
                chosen += ", marked absent"
            detail = detail or chosen
        events.append(DaemonEvent(_text(plain, "time"), name, detail, fault, chosen))
    return tuple(events)


def session_view(
    plan: Mapping[str, Any] | None,
    records: Sequence[AnyRecord],
    warnings: Sequence[str] = (),
    limit: int | None = None,
) -> SessionView:
    """The view of a session from its plan.json (None if unreadable) and its records in order;
    `limit` its max_trials_per_target, if known."""
    fold = SessionFold(plan, limit)
    for record in records:
        fold.apply(record)
    return replace(fold.view, warnings=tuple(warnings))


def _identity(meta: Mapping[str, Any]) -> SessionView:
    plan = meta.get("plan") if isinstance(meta.get("plan"), Mapping) else {}
    assert isinstance(plan, Mapping)
    speak = plan.get("speak_uncertainty")
    profile = str(plan.get("profile") or "")
    condition = meta.get("condition")
    if not condition and profile:
        condition = f"{profile}/{'spoken' if speak is not False else 'silent'}"
    return SessionView(
        session=str(meta.get("session") or ""),
        group=str(meta.get("group") or plan.get("group") or ""),
        condition=str(condition or ""),
        variant=str(meta.get("variant") or ""),
        profile=profile,
        speak_uncertainty=speak if isinstance(speak, bool) else None,
        answer_key=bool(plan.get("answer_key")),
    )


class SessionFold:
    """The view so far, moved on one record at a time (a replay steps forward with it)."""

    def __init__(self, plan: Mapping[str, Any] | None, limit: int | None = None) -> None:
        """The view of a session with `plan` (its plan.json) and no records yet; `limit` its
        max_trials_per_target, if known (the records do not say it)."""
        self.view = _identity(plan or {})
        self.reading = Reading(limit)
        self._runs = 0

    def apply(self, record: AnyRecord) -> None:
        """Move the view on by the next record."""
        guess = self.reading.apply(record)
        view = self.view
        if isinstance(record, SessionRecord) and record.event in _NEW_RUN:
            # A new run of the daemon: its monotonic clock is another's.
            self._runs += 1
            view = replace(view, run=f"run {self._runs}", boot="")
        view = replace(
            view,
            records=view.records + 1,
            last_seq=max(view.last_seq, record.seq),
            last_time=record.time or view.last_time,
            last_clock=record.clock,
            # Anything recorded after a shutdown means the daemon is back.
            shutdown=None,
        )
        if isinstance(record, TrialRecord) and guess is not None:
            view = _on_trial(view, record, guess)
        else:
            handler = _HANDLERS.get(type(record))
            view = handler(view, record) if handler is not None else view
        self.view = _as_read(view, self.reading.facts)


def _as_read(view: SessionView, facts: Facts) -> SessionView:
    """The view with what the records read: learned (in the order learned), given up,
    re-opened, and whether Kaspar is confused."""
    learned = tuple(
        Learned(target.name, item.name, item.problem_trial, item.trial)
        for target in (facts.target(index) for index in facts.learned_order)
        if (item := target.learned) is not None
    )
    given_up = tuple(target.name for target in facts.targets if target.given_up)
    confused = _confused_line(facts.confused)
    if (learned, given_up, confused, facts.reopens) == (
        view.learned,
        view.given_up,
        view.confused,
        view.reopens,
    ):
        return view
    return replace(
        view, learned=learned, given_up=given_up, confused=confused, reopens=facts.reopens
    )


def _confused_line(confusion: Confusion | None) -> str | None:
    """What the researcher is told while Kaspar is confused: about what, why, and what
    their re-open would re-open."""
    if confusion is None:
        return None
    if confusion.reason == "learned_elsewhere" and confusion.name is not None:
        why = f"{confusion.name} was answered green here, learned for {confusion.learned_for}"
    else:
        why = "every name left was answered red"
    ask = ""
    if confusion.reopen_name is not None:
        ask = f"; reopen makes {confusion.reopen_name} ({confusion.reopen_target}) unlearned"
    return f"{confusion.target_name}: {why}{ask}"


def _on_session(view: SessionView, record: SessionRecord) -> SessionView:
    if record.event is SessionEvent.START:
        plan = record.plan if isinstance(record.plan, dict) else None
        fresh = _identity(plan) if plan else view
        return replace(
            view,
            session=view.session or fresh.session,
            group=view.group or fresh.group,
            condition=view.condition or fresh.condition,
            variant=view.variant or fresh.variant,
            profile=view.profile or fresh.profile,
            speak_uncertainty=(
                view.speak_uncertainty
                if view.speak_uncertainty is not None
                else fresh.speak_uncertainty
            ),
            answer_key=view.answer_key or fresh.answer_key,
        )
    if record.event is SessionEvent.RESUMED:
        # The daemon started again: the hardware is opened anew, so nothing is pending.
        stage = record.step if isinstance(record.step, str) else view.stage
        return replace(
            view,
            stage=stage,
            resumes=view.resumes + 1,
            keyfob_lost=False,
            faults=_settled(view.faults),
            question=_interrupted(view.question),
        )
    reason = record.reason if isinstance(record.reason, str) else "stopped"
    return replace(view, shutdown=reason, question=_interrupted(view.question))


def _interrupted(question: Question | None) -> Question | None:
    """An open question the daemon stopped in (or was killed in) no longer stands."""
    if question is not None and question.open:
        return replace(question, interrupted=True)
    return question


def _on_step(view: SessionView, record: StepRecord) -> SessionView:
    step = record.to if record.to in STEPS else view.step
    return replace(view, stage=record.to, step=step, faults=_settled(view.faults))


def _settled(faults: tuple[FaultSeen, ...]) -> tuple[FaultSeen, ...]:
    """The faults with none pending: the game left the fault stage."""
    if not any(fault.pending for fault in faults):
        return faults
    return tuple(replace(fault, pending=False) for fault in faults)


def _on_command(view: SessionView, record: CommandRecord) -> SessionView:
    outcome = str(record.confirm) if record.applied and record.confirm is not UNSET else ""
    if not record.applied:
        outcome = record.ignored if isinstance(record.ignored, str) else "ignored"
    seen = CommandSeen(
        record.time, record.gesture, str(record.command), record.applied, outcome, record.state
    )
    view = replace(view, commands=(*view.commands, seen))
    if not record.applied:
        return view
    if record.confirm == Confirmation.PAUSE:
        return replace(view, stage="paused")
    if record.confirm == Confirmation.RESUME:
        # Back to the step left (idle when a fault came before the first step).
        stage = view.step if view.step is not None and view.stage in ("paused", "fault") else None
        return replace(view, stage=stage or "idle", faults=_settled(view.faults))
    return view


def _on_fault(view: SessionView, record: FaultRecord) -> SessionView:
    # Written with its joint (null for parts that have none) only when the game stopped for it.
    stops = record.joint is not UNSET and record.state not in ENDS
    joint = record.joint if isinstance(record.joint, str) else None
    seen = FaultSeen(
        record.time, str(record.fault), record.detail, joint, stops, stops, record.clock, view.run
    )
    stage = "fault" if stops else view.stage
    return replace(view, faults=(*view.faults, seen), stage=stage)


def _on_hal(view: SessionView, record: HalRecord) -> SessionView:
    if record.event is HalEvent.KEYFOB_BACK:
        return replace(view, keyfob_lost=False)
    if record.event is HalEvent.KEYFOB_LOST:
        # The fault record that follows says it stopped the game; this says the keyfob is gone.
        return replace(view, keyfob_lost=True)
    if record.event in (HalEvent.RESEARCHER_BACK, HalEvent.KEYFOB_HEARD):
        return view
    if record.event in (HalEvent.BATTERY_LOW, HalEvent.BATTERY_OK):
        return _on_battery(view, record)
    if record.event is HalEvent.KEYFOB_SILENT:
        # Nothing stops for it: Kaspar tells the grown-up (the battery, suspected).
        reason = record.reason if isinstance(record.reason, str) else "silent"
        return replace(view, faults=(*view.faults, FaultSeen(record.time, "keyfob", reason)))
    if record.event is HalEvent.RESEARCHER_LOST:
        # Nothing stops for it: the researcher's holds on the children's keyfob meanwhile.
        reason = record.reason if isinstance(record.reason, str) else "lost"
        seen = FaultSeen(record.time, "researcher", reason, clock=record.clock, run=view.run)
        return replace(view, faults=(*view.faults, seen))
    status = record.status if isinstance(record.status, str) else "failed"
    said = record.text if isinstance(record.text, str) else ""
    detail = f"line not heard ({status}): {said}" if said else f"line not heard ({status})"
    if isinstance(record.error, str):
        detail += f"; {record.error}"
    seen = FaultSeen(record.time, "voice", detail, clock=record.clock, run=view.run)
    return replace(view, faults=(*view.faults, seen))


def _on_battery(view: SessionView, record: HalRecord) -> SessionView:
    volts = f"{record.voltage_v:.1f} V" if isinstance(record.voltage_v, float) else "? V"
    line = record.warn_below_v if isinstance(record.warn_below_v, float) else None
    if record.event is HalEvent.BATTERY_LOW:
        below = f" (below {line:.1f} V)" if line is not None else ""
        return replace(view, battery=f"LOW {volts}{below}", battery_low=True)
    return replace(view, battery=f"ok {volts}", battery_low=False)


def _on_pose(view: SessionView, record: PoseRecord) -> SessionView:
    teaching = view.teaching
    return replace(
        view,
        teaching=replace(
            teaching, poses=teaching.poses + 1, round=record.round, bag=record.bag + 1
        ),
    )


def _on_press(view: SessionView, record: PressRecord) -> SessionView:
    if record.teach_retry is not UNSET:
        teaching = view.teaching
        return replace(view, teaching=replace(teaching, retries=teaching.retries + 1))
    question = view.question
    early = isinstance(record.ignored, str) and record.ignored.startswith("before the question")
    if question is not None and question.open and early:
        return replace(view, question=replace(question, early_presses=question.early_presses + 1))
    return view


def _on_prompt(view: SessionView, record: PromptRecord) -> SessionView:
    question = view.question
    if question is not None and question.open:
        return replace(view, question=replace(question, prompts=question.prompts + 1))
    return view


def _toys(
    view: SessionView, candidates: Sequence[str], probabilities: Sequence[float]
) -> tuple[str, ...]:
    """Every toy in the game's order: the first question offers them all."""
    if view.toys and len(view.toys) == len(probabilities):
        return view.toys
    if len(candidates) == len(probabilities):
        return tuple(candidates)
    # Joined a session whose first questions are unreadable: the offered toys have a
    # probability above 0, in order; the others are named by their place.
    names = iter(candidates)
    return tuple(
        (next(names, f"toy {i + 1}") if p > 0 else f"toy {i + 1}")
        for i, p in enumerate(probabilities)
    )


def _question(
    view: SessionView, record: QuestionRecord | TrialRecord
) -> tuple[tuple[str, ...], Question]:
    toys = _toys(view, record.candidates, record.probabilities)
    offered = set(record.candidates)
    bars = tuple(
        Bar(toy, probability, toy in offered, toy == record.choice)
        for toy, probability in zip(toys, record.probabilities, strict=False)
    )
    question = Question(
        trial=record.trial,
        problem_trial=record.problem_trial,
        target=record.target,
        child=record.child,
        bars=bars,
        entropy=record.entropy,
        max_entropy=math.log2(len(record.candidates)) if record.candidates else 0.0,
        band=record.band,
        choice=record.choice,
        asked_at=record.time,
    )
    return toys, question


def _with_target(targets: tuple[str, ...], target: str) -> tuple[str, ...]:
    return targets if target in targets else (*targets, target)


def _on_question(view: SessionView, record: QuestionRecord) -> SessionView:
    toys, question = _question(view, record)
    return replace(
        view, question=question, toys=toys, targets=_with_target(view.targets, record.target)
    )


def _on_trial(view: SessionView, record: TrialRecord, guess: Guess) -> SessionView:
    asked = view.question
    if asked is not None and asked.trial == record.trial:
        question = asked
        toys = view.toys
    else:
        # Recorded before question records existed: the trial says what was asked.
        toys, question = _question(view, record)
    question = replace(question, answer=record.feedback, reaction_time=record.reaction_time)
    answer = Answer(
        trial=record.trial,
        problem_trial=record.problem_trial,
        target=record.target,
        child=record.child,
        choice=record.choice,
        feedback=record.feedback,
        reaction_time=record.reaction_time,
        correct=record.correct,
        feedback_right=record.feedback_right,
        learned=record.learned,
        perseverative=guess.perseverative,
        win_shift=guess.win_shift,
        time=record.time,
    )
    return replace(
        view,
        question=question,
        toys=toys,
        answers=(*view.answers, answer),
        targets=_with_target(view.targets, record.target),
    )


def _on_reopen(view: SessionView, record: ReopenRecord) -> SessionView:
    if record.taken_back is True:
        return view
    alerts = tuple(alert for alert in view.alerts if not alert.startswith(f"{record.name} "))
    return replace(view, alerts=alerts)


def _on_alert(view: SessionView, record: AlertRecord) -> SessionView:
    line = (
        f"{record.toy} (right for {record.target}) no longer offered: "
        f"learned for {record.learned_for}"
    )
    return replace(view, alerts=(*view.alerts, line))


def _on_clock(view: SessionView, record: ClockRecord) -> SessionView:
    return replace(view, boot=record.boot, clock_synchronised=record.synchronised)


def _on_undo(view: SessionView, record: UndoRecord) -> SessionView:
    answers = tuple(
        replace(answer, undone=True) if answer.trial == record.trial else answer
        for answer in view.answers
    )
    question = view.question
    if question is not None and question.trial == record.trial:
        question = replace(question, undone=True)
    return replace(view, answers=answers, question=question)


_HANDLERS: dict[type, Any] = {
    SessionRecord: _on_session,
    StepRecord: _on_step,
    CommandRecord: _on_command,
    FaultRecord: _on_fault,
    HalRecord: _on_hal,
    PoseRecord: _on_pose,
    PressRecord: _on_press,
    PromptRecord: _on_prompt,
    QuestionRecord: _on_question,
    UndoRecord: _on_undo,
    ReopenRecord: _on_reopen,
    AlertRecord: _on_alert,
    ClockRecord: _on_clock,
}
# The records that begin a run of the daemon in a session.
_NEW_RUN = (SessionEvent.START, SessionEvent.RESUMED)
