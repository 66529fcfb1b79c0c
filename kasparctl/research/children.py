"""Each child's teaching, measured: answers checked, reaction times, prompts, extra presses, undos.

A child is a participant code where the plan names children by codes (the
same child over every session); without codes, a place in one session's turn
order ("20260302T094107-G1 #2": that session's second child), which links
nothing across sessions. First names never appear here.

Measures, per child:
- false greens (a green for a wrong guess) over the wrong guesses they
  answered, false reds (a red for a right guess) over the right ones, and
  all wrong answers over all checked (only where the plan has an answer key);
- reaction time (end of Kaspar's question to the press), by the uncertainty
  band Kaspar spoke before the guess ("silent" when it did not say): the mean
  and medians are over the answers given after the question; an answer pressed
  in the question's last words (in_question: a negative time, the toy already
  named) is counted apart, as `answers_in_question`, since its time measures
  when the question ended, not how long the child took;
- prompts needed (Kaspar asked again because nobody answered), extra presses
  after their answer, and their answers the researcher undid.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from kasparctl.game.records import TrialRecord
from kasparctl.research.catalogue import SessionData

SILENT = "silent"


def in_question(trial: TrialRecord) -> bool:
    """Answered in the question's last words and taken (a negative reaction time; such
    times recorded before the flag existed count too)."""
    return trial.in_question is True or trial.reaction_time < 0


@dataclass(slots=True)
class Feedback:
    """Answers checked against the answer key, and the wrong ones by kind."""

    answers: int = 0
    checked: int = 0
    right: int = 0
    wrong_guesses: int = 0  # guesses that were wrong (and answered)
    right_guesses: int = 0
    wrong_green: int = 0  # a green for a wrong guess
    wrong_red: int = 0  # a red for a right guess

    def add(self, trial: TrialRecord) -> None:
        """Count one answer."""
        self.answers += 1
        if trial.correct is None:
            return
        self.checked += 1
        self.right += trial.feedback_right is True
        if trial.correct:
            self.right_guesses += 1
            self.wrong_red += not trial.green
        else:
            self.wrong_guesses += 1
            self.wrong_green += trial.green

    def merge(self, other: Feedback) -> None:
        """Add another tally to this one."""
        for name in _FEEDBACK_FIELDS:
            setattr(self, name, getattr(self, name) + getattr(other, name))


_FEEDBACK_FIELDS = tuple(Feedback.__dataclass_fields__)


@dataclass(slots=True)
class ChildMeasures:
    """One child's answers and what happened around them."""

    key: str
    label: str
    participant: str | None
    feedback: Feedback = field(default_factory=Feedback)
    sessions: set[str] = field(default_factory=set)
    groups: set[str] = field(default_factory=set)
    conditions: set[str] = field(default_factory=set)
    prompts: int = 0
    extra_presses: int = 0
    undos: int = 0
    reaction_times: dict[str, list[float]] = field(default_factory=dict)
    answers_in_question: int = 0

    def answer(self, trial: TrialRecord) -> None:
        """Count one answer that counts (not undone)."""
        self.feedback.add(trial)
        if in_question(trial):
            self.answers_in_question += 1
            return
        band = trial.band or SILENT
        self.reaction_times.setdefault(band, []).append(trial.reaction_time)

    def row(self, band_names: list[str]) -> dict[str, Any]:
        """The child as a row of children.csv and summary.json."""
        f = self.feedback
        times = [t for values in self.reaction_times.values() for t in values]
        row: dict[str, Any] = {
            "child": self.label,
            "participant": self.participant,
            "sessions": len(self.sessions),
            "groups": ";".join(sorted(self.groups)),
            "conditions": ";".join(sorted(self.conditions)),
            "answers": f.answers,
            "checked": f.checked,
            "right": f.right,
            "wrong_guesses": f.wrong_guesses,
            "false_greens": f.wrong_green,
            "false_green_rate": _rate(f.wrong_green, f.wrong_guesses),
            "right_guesses": f.right_guesses,
            "false_reds": f.wrong_red,
            "false_red_rate": _rate(f.wrong_red, f.right_guesses),
            "wrong_feedback_rate": _rate(f.checked - f.right, f.checked),
            "reaction_time_mean": statistics.fmean(times) if times else None,
            "reaction_time_median": statistics.median(times) if times else None,
            "answers_in_question": self.answers_in_question,
        }
        for band in band_names:
            values = self.reaction_times.get(band, [])
            row[f"reaction_time_{band}_n"] = len(values)
            row[f"reaction_time_{band}_median"] = statistics.median(values) if values else None
        row.update(
            prompts=self.prompts,
            prompts_per_answer=_rate(self.prompts, f.answers),
            extra_presses=self.extra_presses,
            extra_presses_per_answer=_rate(self.extra_presses, f.answers),
            undos=self.undos,
            undos_per_answer=_rate(self.undos, f.answers),
        )
        return row


def _rate(count: int, total: int) -> float | None:
    return count / total if total else None


class Children:
    """Every child of the sessions read, by participant code or place in a session."""

    def __init__(self) -> None:
        """No children yet."""
        self.by_key: dict[str, ChildMeasures] = {}

    def child(self, session: SessionData, child_index: int, condition: str) -> ChildMeasures:
        """The measures of the child at `child_index` in `session`'s turn order."""
        code = session.participant(child_index)
        key = code if code is not None else f"{session.uid}#{child_index + 1}"
        measures = self.by_key.get(key)
        if measures is None:
            label = code if code is not None else f"{session.name} #{child_index + 1}"
            measures = self.by_key[key] = ChildMeasures(key, label, code)
        measures.sessions.add(session.uid)
        measures.groups.add(session.group)
        measures.conditions.add(condition)
        return measures

    def bands(self) -> list[str]:
        """Every band some child answered after, in the order of uncertainty (silent last)."""
        seen = {band for child in self.by_key.values() for band in child.reaction_times}
        order = ["no_idea", "unsure", "idea_not_sure", "fairly_sure", "sure"]
        known = [band for band in order if band in seen]
        others = sorted(seen - set(order) - {SILENT})
        return known + others + ([SILENT] if SILENT in seen else [])

    def rows(self, coded_only: bool = False) -> Iterator[dict[str, Any]]:
        """One row per child, made as it is asked for: participants by code first, then the
        rest by session and place (`coded_only`: participants only)."""
        bands = self.bands()
        ordered = sorted(
            self.by_key.values(), key=lambda c: (c.participant is None, c.label, c.key)
        )
        for child in ordered:
            if coded_only and child.participant is None:
                break
            yield child.row(bands)
