"""A simulated group of children answering Kaspar's guesses.

The pilot's children made 3 mistakes in 202 trials, all of them greens for a
wrong guess; the model lets a simulation add such mistakes, the opposite ones,
and guesses nobody answers. An unanswered guess counts as a trial (Kaspar
pointed and spoke) but gives the learner nothing to update, and it breaks a
streak of greens (see kasparctl.game.problem).

How children press is another matter (Messiness): they hold a button, tap it
twice, squeeze both, press before Kaspar has finished asking. None of it
changes what they mean; the game must take the meaning and nothing more.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hal.errors import KasparError


class TeacherError(KasparError, ValueError):
    """A teacher probability outside [0, 1]; `key` names it."""

    def __init__(self, message: str, key: str) -> None:
        """The message says what is wrong; `key` names the probability."""
        super().__init__(message)
        self.key = key


@dataclass(frozen=True, slots=True)
class Teacher:
    """How often the children give a wrong green, a wrong red, or no answer."""

    p_wrong_green: float = 0.0
    p_wrong_red: float = 0.0
    p_no_answer: float = 0.0

    def __post_init__(self) -> None:
        """Refuse a probability outside [0, 1], naming it."""
        for name in ("p_wrong_green", "p_wrong_red", "p_no_answer"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise TeacherError(f"expected a probability in [0, 1], found {value!r}", name)

    @property
    def honest(self) -> bool:
        """Every guess answered, and answered right."""
        return self.p_wrong_green == 0.0 and self.p_wrong_red == 0.0 and self.p_no_answer == 0.0

    def answer(self, correct: bool, rng: np.random.Generator) -> bool | None:
        """True for green, False for red, None when nobody answers.

        An honest teacher draws nothing, and any other teacher draws exactly two
        numbers per guess: the vectorised simulator (kasparctl.sim.sweep) follows the
        same rule, so the two paths take the same random stream for one problem.
        """
        if self.honest:
            return correct
        no_answer_draw, mistake_draw = rng.random(2)
        if no_answer_draw < self.p_no_answer:
            return None
        p_mistake = self.p_wrong_red if correct else self.p_wrong_green
        return (not correct) if mistake_draw < p_mistake else correct


# -- a teacher per child, fitted from recorded sessions or written by hand ----------

# Reaction times of the demo's children without a model: uniform in this range (s).
DEFAULT_THINK_S = (0.8, 2.5)


@dataclass(frozen=True, slots=True)
class ChildTeacher:
    """One child (a place in the turn order): their mistakes, silences and reaction times.

    `p_prompt` is how often the child needed a prompt before answering: in the
    game an answer always comes (Kaspar asks again), so it changes nothing the
    learner sees; the demo's children use it as their silence before a prompt.
    `p_no_answer` is the simulator's guess nobody ever answers (a trial that
    updates nothing), which a recorded session never has.
    """

    p_wrong_green: float = 0.0
    p_wrong_red: float = 0.0
    p_no_answer: float = 0.0
    p_prompt: float = 0.0
    # Log-normal reaction time: median seconds and the sd of its logarithm.
    reaction_time_median: float | None = None
    reaction_time_log_sd: float | None = None
    # How many answers the rates were fitted from (0: written by hand).
    answers: int = 0

    def __post_init__(self) -> None:
        """Refuse a probability outside [0, 1] or a reaction time that is none, naming it."""
        for name in ("p_wrong_green", "p_wrong_red", "p_no_answer", "p_prompt"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise TeacherError(f"expected a probability in [0, 1], found {value!r}", name)
        for name in ("reaction_time_median", "reaction_time_log_sd"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and 0.0 <= value <= 600.0):
                raise TeacherError(f"expected seconds from 0 to 600, found {value!r}", name)

    @property
    def teacher(self) -> Teacher:
        """The child's answers as the simulator's Teacher."""
        return Teacher(self.p_wrong_green, self.p_wrong_red, self.p_no_answer)

    @classmethod
    def fitted(
        cls,
        answers: int,
        wrong_guesses: int,
        false_greens: int,
        right_guesses: int,
        false_reds: int,
        prompted: int,
        reaction_times: Sequence[float],
    ) -> ChildTeacher:
        """A child's rates from their recorded answers (maximum likelihood: shares).

        False greens over the wrong guesses they answered, false reds over the right
        ones, prompted questions over all; reaction times as a log-normal (median and
        sd of the logarithm) of the positive ones. A rate without any answer to
        estimate it from is 0.
        """
        positive = [t for t in reaction_times if t > 0 and math.isfinite(t)]
        logs = [math.log(t) for t in positive]
        median = math.exp(statistics.fmean(logs)) if logs else None
        spread = statistics.stdev(logs) if len(logs) > 1 else (0.0 if logs else None)
        return cls(
            p_wrong_green=false_greens / wrong_guesses if wrong_guesses else 0.0,
            p_wrong_red=false_reds / right_guesses if right_guesses else 0.0,
            p_prompt=min(prompted / answers, 1.0) if answers else 0.0,
            reaction_time_median=median,
            reaction_time_log_sd=spread,
            answers=answers,
        )


@dataclass(frozen=True, slots=True)
class Rates:
    """Each child's probabilities as arrays, for the vectorised simulators."""

    p_wrong_green: np.ndarray[tuple[int], np.dtype[np.float64]]
    p_wrong_red: np.ndarray[tuple[int], np.dtype[np.float64]]
    p_no_answer: np.ndarray[tuple[int], np.dtype[np.float64]]

    @property
    def children(self) -> int:
        """How many children take turns."""
        return len(self.p_wrong_green)

    @property
    def honest(self) -> bool:
        """Every child always answers, and answers right."""
        return not (self.p_wrong_green.any() or self.p_wrong_red.any() or self.p_no_answer.any())


@dataclass(frozen=True, slots=True)
class TeacherModel:
    """A group of children answering in turn, each with their own rates (one child: a Teacher)."""

    children: tuple[ChildTeacher, ...]
    # Where it came from ("fitted from 12 sessions..."), for the record.
    source: str = ""

    def __post_init__(self) -> None:
        """A group has at least one child."""
        if not self.children:
            raise TeacherError("expected at least one child, found none", "children")

    @classmethod
    def of(cls, teacher: Teacher) -> TeacherModel:
        """Every child answering as `teacher` does."""
        return cls((ChildTeacher(teacher.p_wrong_green, teacher.p_wrong_red, teacher.p_no_answer),))

    def rates(self) -> Rates:
        """The children's probabilities as arrays."""

        def column(name: str) -> np.ndarray[tuple[int], np.dtype[np.float64]]:
            return np.array([getattr(child, name) for child in self.children], dtype=np.float64)

        return Rates(column("p_wrong_green"), column("p_wrong_red"), column("p_no_answer"))

    def answer(self, correct: bool, rng: np.random.Generator, turn: int) -> bool | None:
        """The answer of the child whose turn it is (turn modulo the children)."""
        return self.children[turn % len(self.children)].teacher.answer(correct, rng)

    def pooled(self, prompts_as_silence: bool = True) -> Teacher:
        """One Teacher for the whole group: each rate averaged, weighted by answers if fitted.

        The demo's children share one set of rates; their silence before a prompt is
        the model's prompt rate (`prompts_as_silence`), else its p_no_answer.
        """
        weights = np.array([max(child.answers, 0) for child in self.children], dtype=np.float64)
        if weights.sum() == 0:
            weights = np.ones(len(self.children))
        weights /= weights.sum()

        def mean(name: str) -> float:
            return float(
                sum(w * getattr(c, name) for w, c in zip(weights, self.children, strict=True))
            )

        silence = max(mean("p_prompt"), mean("p_no_answer")) if prompts_as_silence else None
        return Teacher(
            min(mean("p_wrong_green"), 1.0),
            min(mean("p_wrong_red"), 1.0),
            min(mean("p_no_answer") if silence is None else silence, 1.0),
        )

    def think_s(self) -> tuple[float, float]:
        """The demo children's thinking time range: the 10th to 90th percentile of the model's."""
        fitted = [c for c in self.children if c.reaction_time_median is not None]
        if not fitted:
            return DEFAULT_THINK_S
        z = 1.2815515655446004  # the 90th percentile of the standard normal
        lows, highs = [], []
        for child in fitted:
            median = float(child.reaction_time_median or 0.0)
            spread = float(child.reaction_time_log_sd or 0.0)
            lows.append(median * math.exp(-z * spread))
            highs.append(median * math.exp(z * spread))
        low, high = min(lows), max(highs)
        return (max(low, 0.05), max(high, low + 0.05))


_TEACHER_KEYS = {f for f in ChildTeacher.__dataclass_fields__}


def load_teacher(path: str) -> TeacherModel:
    """A teacher model from its TOML file (`kasparctl fit-teacher` writes one).

    The file has `[[children]]` tables, one per place in the turn order, with any
    of ChildTeacher's keys. TeacherError names the file, the key, what was
    expected and what was found.
    """
    import tomllib

    def fail(key: str, message: str) -> TeacherError:
        return TeacherError(f"{path}: {key}: {message}", key)

    try:
        with open(path, "rb") as stream:
            raw = tomllib.load(stream)
    except OSError as error:
        raise fail("(file)", f"cannot read it: {error.strerror or error}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise fail("(syntax)", f"not valid TOML: {error}") from None
    unknown = sorted(set(raw) - {"source", "children"})
    if unknown:
        raise fail(unknown[0], "unknown key; expected one of: source, children")
    entries = raw.get("children")
    if (
        not isinstance(entries, list)
        or not entries
        or not all(isinstance(e, dict) for e in entries)
    ):
        raise fail("children", f"expected one or more [[children]] tables, found {entries!r}")
    children = []
    for index, entry in enumerate(entries):
        where = f"children[{index}]"
        for key, value in entry.items():
            if key not in _TEACHER_KEYS:
                raise fail(
                    f"{where}.{key}",
                    f"unknown key; expected one of: {', '.join(sorted(_TEACHER_KEYS))}",
                )
            expected_int = key == "answers"
            ok = isinstance(value, int) if expected_int else isinstance(value, int | float)
            if isinstance(value, bool) or not ok:
                kind = "an integer" if expected_int else "a number"
                raise fail(f"{where}.{key}", f"expected {kind}, found {value!r}")
        try:
            children.append(ChildTeacher(**entry))
        except TeacherError as error:
            raise fail(f"{where}.{error.key}", str(error)) from None
    source = raw.get("source", "")
    return TeacherModel(tuple(children), str(source) if source else path)


def teacher_toml(model: TeacherModel, comment: str = "") -> str:
    """The model as a TOML file load_teacher reads back."""
    lines = [f"# {line}" for line in comment.splitlines()] if comment else []
    lines.append(f"source = {_toml_string(model.source)}")
    for child in model.children:
        lines += ["", "[[children]]"]
        for name in ChildTeacher.__dataclass_fields__:
            value = getattr(child, name)
            if value is not None:
                lines.append(f"{name} = {value!r}")
    return "\n".join(lines) + "\n"


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", " ") + '"'


# A messy hold lasts this long (s): often past the 3 s of a researcher's hold.
HOLD_S = (0.6, 5.0)
# A squeeze of both buttons lasts this long (s).
SQUEEZE_S = (0.15, 4.0)
# An early press comes this long (s) after Kaspar starts asking.
EARLY_S = (0.2, 3.0)


@dataclass(frozen=True, slots=True)
class Messiness:
    """How often, per answer, children press in ways a keyfob must survive.

    p_hold: the button held (HOLD_S); p_double: pressed twice quickly; p_both: both
    buttons squeezed, the meant one first (SQUEEZE_S); p_early: pressed while Kaspar
    is still asking (EARLY_S after it starts), then again once asked if need be.
    """

    p_hold: float = 0.0
    p_double: float = 0.0
    p_both: float = 0.0
    p_early: float = 0.0

    def __post_init__(self) -> None:
        """Refuse a probability outside [0, 1], naming it."""
        for name in ("p_hold", "p_double", "p_both", "p_early"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise TeacherError(f"expected a probability in [0, 1], found {value!r}", name)

    @property
    def tidy(self) -> bool:
        """Every press a clean, single press after the question."""
        return not (self.p_hold or self.p_double or self.p_both or self.p_early)

    def action(self, button: str, rng: np.random.Generator) -> str:
        """The keyfob action for an answer `button`: a press, a hold, a double or a squeeze.

        A tidy group draws nothing (the children's random stream is as it was).
        """
        if self.tidy:
            return button
        kind, length = rng.random(2)
        if kind < self.p_both:
            return f"chord {button} {SQUEEZE_S[0] + length * (SQUEEZE_S[1] - SQUEEZE_S[0]):.3f}"
        if kind < self.p_both + self.p_double:
            return f"double {button}"
        if kind < self.p_both + self.p_double + self.p_hold:
            return f"hold {button} {HOLD_S[0] + length * (HOLD_S[1] - HOLD_S[0]):.3f}"
        return button

    def early(self, rng: np.random.Generator) -> float | None:
        """Seconds after Kaspar starts asking that an eager child presses, or None."""
        if self.tidy or self.p_early == 0.0:
            return None
        when, draw = (float(value) for value in rng.random(2))
        return EARLY_S[0] + when * (EARLY_S[1] - EARLY_S[0]) if draw < self.p_early else None
