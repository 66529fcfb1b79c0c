"""The view laid out for a screen: lines of text spans, each with a style's name.

Pure: a WatchView, the time now, and a size in, a list of lines out. The
terminal renderer gives each style a colour (or none: NO_COLOR, a dumb
terminal, a pipe), so the picture is the same in every case and tests read it
as plain text. Colour is never the only sign: answers carry a mark, the
chosen toy an arrow, a pending fault the word.

A screen of 80x24 holds it all with six toys; a smaller one loses the lists
at the bottom first, a wider one gets longer bars.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from kasparctl.view.ages import Now, Stamp, ago, clock_time, next_change
from kasparctl.view.model import (
    Answer,
    CommandSeen,
    DaemonEvent,
    FaultSeen,
    Question,
    SessionView,
    WatchView,
    step_number,
)

# Shown while the session's last clock record says the wall clock is not synchronised.
CLOCK_WARNING = "unsynchronised: the times shown may be wrong (the ages and order are not)"

Style = Literal[
    "",
    "title",
    "dim",
    "good",
    "bad",
    "warn",
    "chosen",
    "trough",
    "badge",
    "badge-good",
    "badge-bad",
    "badge-warn",
]
Span = tuple[str, Style]
Line = tuple[Span, ...]

MIN_WIDTH = 40


@dataclass(frozen=True, slots=True)
class Glyphs:
    """The characters the frame draws with: Unicode, or ASCII for terminals without it."""

    full: str
    eighths: str  # partial blocks, from one eighth to seven
    trough: str
    rule: str
    separator: str  # between pictures printed one after another
    guess: str
    yes: str
    no: str
    arrow: str
    dot: str


UNICODE = Glyphs("█", "▏▎▍▌▋▊▉", "░", "─", "═", "◀", "✓", "✗", "→", "·")
ASCII = Glyphs("#", "", ".", "-", "=", "<", "+", "x", "->", "|")

STAGE_STYLE: dict[str, Style] = {
    "fault": "badge-bad",
    "stopped": "badge-bad",
    "paused": "badge-warn",
    "finished": "badge-good",
}

STEP_HELP = {
    "idle": "Waiting for the researcher's 'next' to start the session.",
    "placing": "The children place the bagged toys; the researcher's 'next' moves on.",
    "revealing": "The children reveal the toys; the researcher's 'next' moves on.",
    "guessing": "Kaspar is about to point and guess.",
    "farewell": "Kaspar thanks the children and says goodbye.",
}


def plain_text(line: Line) -> str:
    """A line without its styles."""
    return "".join(text for text, _ in line)


def shown_times(view: WatchView) -> list[Stamp]:
    """The times the frame shows as "ago": when one changes, the frame must be drawn again."""
    times = [Stamp(event.time) for event in view.daemon[-3:]]
    session = view.session
    if session is not None:
        times += [fault_stamp(fault) for fault in session.faults[-4:]]
        if session.last_time:
            times.append(last_stamp(session))
    return times


def fault_stamp(fault: FaultSeen) -> Stamp:
    """When a fault was recorded, on both clocks."""
    return Stamp(fault.time, fault.clock, fault.run)


def last_stamp(session: SessionView) -> Stamp:
    """When the session's last record was written, on both clocks."""
    return Stamp(session.last_time, session.last_clock, session.run)


def seconds_to_redraw(view: WatchView, now: Now | dt.datetime) -> float | None:
    """How long the frame stays right as time passes; None while nothing on it ages."""
    waits = [w for w in (next_change(t, now) for t in shown_times(view)) if w is not None]
    return min(waits) if waits else None


def _fit(text: str, width: int) -> str:
    """`text` cut to `width` characters, with an ellipsis where it was cut."""
    if len(text) <= width:
        return text
    if width <= 1:
        return text[: max(width, 0)]
    return text[: width - 1] + "…"


class _Row:
    """One line being built, cut at the frame's width."""

    def __init__(self, width: int) -> None:
        self.width = width
        self.spans: list[Span] = []
        self.used = 0

    def add(self, text: str, style: Style = "") -> _Row:
        room = self.width - self.used
        if room <= 0 or not text:
            return self
        piece = _fit(text, room)
        self.spans.append((piece, style))
        self.used += len(piece)
        return self

    def pad_to(self, column: int) -> _Row:
        if column > self.used:
            self.add(" " * (column - self.used))
        return self

    def right(self, text: str, style: Style = "") -> _Row:
        """`text` at the right edge, if it fits after what is there."""
        start = self.width - len(text)
        if start > self.used:
            self.pad_to(start)
            self.add(text, style)
        return self

    def line(self) -> Line:
        return tuple(self.spans)


def _badge(stage: str) -> Span:
    number = step_number(stage)
    label = f" STEP {number} {stage.upper()} " if number else f" {stage.upper()} "
    return label, STAGE_STYLE.get(stage, "badge")


def _bar(fraction: float, width: int, glyphs: Glyphs) -> tuple[str, str]:
    """A bar of `width` cells filled to `fraction`: the filled part and the trough."""
    fraction = min(max(fraction, 0.0), 1.0)
    cells = fraction * width
    whole = int(cells)
    filled = glyphs.full * whole
    rest = cells - whole
    if glyphs.eighths and whole < width and rest >= 1 / 8:
        filled += glyphs.eighths[min(int(rest * 8), 7) - 1]
    return filled, glyphs.trough * (width - len(filled))


def _header(view: WatchView, now: Now | dt.datetime, width: int, glyphs: Glyphs) -> list[Line]:
    session = view.session
    first = _Row(width).add("Kaspar ", "title")
    if session is None:
        first.add(f"{glyphs.dot} {view.state_dir}", "dim")
        second = _Row(width)
        if view.problem:
            second.add(view.problem, "bad")
        elif not view.exists:
            second.add("The state directory does not exist yet: waiting for it.", "warn")
        else:
            second.add(f"No session yet ({view.sessions} in the directory): waiting for one.")
        lines = [first.line(), second.line(), _daemon_row(view, None, now, width).line()]
        return lines + _chosen_rows(view, width)
    badge = _badge(session.stage)
    first.add(f"{session.group or '?'}", "title").add(
        f"  {session.condition}  {session.variant}  {session.session}", "dim"
    )
    first.right(badge[0], badge[1])
    second = _Row(width)
    step = step_number(session.step or "")
    if step is not None and session.stage != session.step:
        second.add(f"step {step} {session.step} {glyphs.dot} ", "dim")
    second.add(f"{session.trials} trial{'' if session.trials == 1 else 's'}")
    if session.undone:
        second.add(f" ({session.undone} undone)", "dim")
    targets = _targets(session)
    total = f" of {targets}" if targets else ""
    second.add(f"  {glyphs.dot}  learned {len(session.learned)}{total}")
    turn = session.whose_turn
    if turn:
        second.add(f"  {glyphs.dot}  turn: ").add(turn, "title")
    if session.resumes:
        second.add(f"  {glyphs.dot}  resumed {session.resumes}x", "dim")
    lines = [first.line(), second.line(), _daemon_row(view, session, now, width).line()]
    for fault in session.pending_faults[-2:]:
        what = f"{fault.source} {fault.joint}" if fault.joint else fault.source
        row = _Row(width).add(f"FAULT {what}", "bad").add(f" {ago(fault_stamp(fault), now)}", "dim")
        lines.append(row.add(f": {fault.detail}").line())
    if session.clock_synchronised is False:
        lines.append(_Row(width).add("CLOCK ", "warn").add(CLOCK_WARNING).line())
    if session.confused is not None and not session.ended:
        lines.append(_Row(width).add("CONFUSED ", "warn").add(session.confused).line())
    for alert in session.alerts[-2:]:
        lines.append(_Row(width).add("ALERT ", "warn").add(alert).line())
    return lines + _chosen_rows(view, width)


def _chosen_rows(view: WatchView, width: int) -> list[Line]:
    """The session the researcher chose in idle (the children hear nothing of it)."""
    chosen = view.chosen
    if chosen is None:
        return []
    words = chosen if chosen.endswith("marked absent") else f"{chosen}: 'next' starts it"
    return [_Row(width).add("CHOSEN ", "title").add(words).line()]


def _targets(session: SessionView) -> int | None:
    """How many targets there are to learn, where the records tell: in the names game a
    bag per toy; the pilot's locations are known only as they come up."""
    return len(session.toys) if session.variant == "names" and session.toys else None


def _daemon_row(
    view: WatchView, session: SessionView | None, now: Now | dt.datetime, width: int
) -> _Row:
    row = _Row(width).add("daemon ", "dim")
    if view.writer is not None:
        row.add(f"running (pid {view.writer})", "good")
    elif session is not None and session.shutdown is not None:
        row.add(f"stopped ({session.shutdown}); the session resumes at its start", "warn")
    elif session is not None and session.ended:
        row.add("session over")
    else:
        row.add("unknown", "dim")
    row.add("  robot ", "dim")
    problems = _robot_problems(view, session)
    if problems:
        row.add(", ".join(problems), "bad")
    else:
        row.add("ok", "good")
    if session is not None and session.battery is not None:
        row.add("  battery ", "dim").add(session.battery, "warn" if session.battery_low else "good")
    if session is not None and session.last_time:
        row.right(
            f"last record {clock_time(session.last_time)}, {ago(last_stamp(session), now)}",
            "dim",
        )
    return row


def _robot_problems(view: WatchView, session: SessionView | None) -> list[str]:
    problems = []
    if session is not None:
        for fault in session.pending_faults:
            what = f"{fault.source} {fault.joint}" if fault.joint else fault.source
            if what not in problems:
                problems.append(what)
        if session.keyfob_lost and "keyfob" not in problems:
            problems.append("keyfob lost")
    if view.daemon and view.daemon[-1].fault and session is None:
        problems.append(view.daemon[-1].name)
    return problems


def _question_block(session: SessionView, height: int, width: int, glyphs: Glyphs) -> list[Line]:
    question = session.question
    if question is None:
        return _step_block(session, width)
    rows: list[Line] = [_question_title(session, question, width, glyphs).line()]
    offered = [bar for bar in question.bars if bar.offered]
    others = [bar for bar in question.bars if not bar.offered]
    room = max(height - 2 - (1 if others else 0), 1)
    shown = offered
    if len(offered) > room:
        # When not all fit: Kaspar's guess and the most likely, in the game's order.
        keep = set(sorted(offered, key=lambda bar: (not bar.chosen, -bar.probability))[: room - 1])
        shown = [bar for bar in offered if bar in keep]
    name_width = max([len(bar.toy) for bar in shown] + [6])
    name_width = min(name_width, max(width // 4, 8))
    bar_width = max(width - name_width - 24, 10)
    for bar in shown:
        row = _Row(width).add("  ")
        row.add(f"{_fit(bar.toy, name_width):<{name_width}} ", "chosen" if bar.chosen else "")
        filled, trough = _bar(bar.probability, bar_width, glyphs)
        row.add(filled, "chosen" if bar.chosen else "").add(trough, "trough")
        row.add(f" {bar.probability:.3f}")
        if bar.chosen:
            row.add(f" {glyphs.guess} guess", "chosen")
        rows.append(row.line())
    if len(shown) < len(offered):
        rows.append(_Row(width).add(f"  +{len(offered) - len(shown)} less likely", "dim").line())
    if others:
        learned = {item.toy: item.target for item in session.learned}
        names = ", ".join(
            f"{bar.toy} ({learned[bar.toy]})" if bar.toy in learned else bar.toy for bar in others
        )
        rows.append(_Row(width).add(f"  no longer offered: {names}", "dim").line())
    rows.append(_entropy_row(session, question, width, glyphs).line())
    return rows


def _question_title(session: SessionView, question: Question, width: int, glyphs: Glyphs) -> _Row:
    row = _Row(width)
    row.add(f"{question.target}", "title").add(f" {glyphs.dot} try {question.problem_trial}")
    row.add(f" {glyphs.dot} trial {question.trial} {glyphs.dot} ").add(question.child, "title")
    if question.undone:
        row.add("  answer undone", "warn")
    elif question.interrupted:
        row.add("  interrupted, to be asked again", "warn")
    elif question.open:
        asking = "asking" if session.stage == "guessing" else f"asked, {session.stage}"
        row.add(f"  {asking}", "warn" if session.stage != "guessing" else "")
        if question.prompts:
            row.add(f" {glyphs.dot} prompted {question.prompts}x", "warn")
        if question.early_presses:
            row.add(f" {glyphs.dot} {question.early_presses} early", "dim")
    else:
        row.add("  ")
        _answer_mark(row, question.answer or "", glyphs)
        if question.reaction_time is not None:
            row.add(f" in {question.reaction_time:.1f} s")
        wrong = _wrong(session, question.trial)
        if wrong:
            row.add(f"  {wrong}", "bad")
    return row


def _wrong(session: SessionView, trial: int) -> str | None:
    for answer in reversed(session.answers):
        if answer.trial == trial:
            return answer.wrong
    return None


def _answer_mark(row: _Row, feedback: str, glyphs: Glyphs) -> None:
    if feedback == "green":
        row.add(f"{glyphs.yes} green", "good")
    elif feedback == "red":
        row.add(f"{glyphs.no} red", "bad")
    else:
        row.add(feedback or "?", "dim")


def _entropy_row(session: SessionView, question: Question, width: int, glyphs: Glyphs) -> _Row:
    row = _Row(width).add("  entropy ", "dim")
    row.add(f"{question.entropy:.2f}", "title").add(f" of {question.max_entropy:.2f} bits")
    fraction = question.entropy / question.max_entropy if question.max_entropy > 0 else 0.0
    filled, trough = _bar(fraction, 10, glyphs)
    row.add(" ").add(filled).add(trough, "trough")
    if question.band is not None:
        row.add("  band ", "dim").add(f'"{question.band.replace("_", " ")}"', "title")
        row.add(" (said)" if not question.open else " (to say)", "dim")
    elif session.speak_uncertainty is False:
        # "silent", or "body" where Kaspar shows it with its body instead.
        mode = session.condition.rsplit("/", 1)[-1] or "silent"
        row.add(f"  {mode} condition: no band said", "dim")
    return row


def _step_block(session: SessionView, width: int) -> list[Line]:
    stage = session.stage
    if stage == "teaching":
        teaching = session.teaching
        text = (
            f"The children teach Kaspar to point at each bag: {teaching.poses} poses logged,"
            f" round {teaching.round + 1} at bag {teaching.bag}"
            if teaching.poses
            else "The children teach Kaspar to point at each bag."
        )
        if teaching.retries:
            text += f", {teaching.retries} asked again"
        return [_Row(width).add(text).line()]
    if stage == "finished":
        text = f"Session finished: {session.trials} trials, {len(session.learned)} toys learned."
        return [_Row(width).add(text, "good").line()]
    if stage == "stopped":
        return [_Row(width).add("The researcher stopped the session.", "warn").line()]
    if stage in ("paused", "fault"):
        left = session.step or "idle"
        style: Style = "warn" if stage == "paused" else "bad"
        text = (
            f"The game is paused in {left}; the researcher's 'pause' resumes it."
            if stage == "paused"
            else f"Stopped by a fault in {left}; 'pause' resumes once the hardware is back."
        )
        return [_Row(width).add(text, style).line()]
    return [_Row(width).add(STEP_HELP.get(stage, stage)).line()]


def _answer_row(answer: Answer, widths: tuple[int, int], width: int, glyphs: Glyphs) -> _Row:
    row = _Row(width)
    style: Style = "dim" if answer.undone else ""
    target_width, choice_width = widths
    row.add(f"#{answer.trial:<3} ", "dim").add(
        f"{_fit(answer.target, target_width):<{target_width}} ", style
    )
    row.add(
        f"{_fit(answer.choice, choice_width):<{choice_width}} ", "dim" if answer.undone else "title"
    )
    _answer_mark(row, answer.feedback, glyphs)
    row.add(" " if answer.feedback == "green" else "   ")
    row.add(f"{answer.reaction_time:4.1f}s", style)
    if answer.undone:
        row.add(" undone", "warn")
    elif answer.wrong:
        row.add(f" {answer.wrong}", "bad")
    elif answer.learned:
        row.add(" learned", "good")
    elif answer.perseverative:
        row.add(" persev.", "dim")
    return row


def _answer_widths(answers: Sequence[Answer]) -> tuple[int, int]:
    """Columns as wide as the longest target and toy shown, within reason."""
    targets = max((len(a.target) for a in answers), default=5)
    choices = max((len(a.choice) for a in answers), default=5)
    return min(targets, 10), min(choices, 10)


def _command_row(command: CommandSeen, width: int, glyphs: Glyphs) -> _Row:
    row = _Row(width).add(f"{clock_time(command.time)} ", "dim").add(command.gesture, "title")
    row.add(f" {glyphs.arrow} ")
    if command.applied:
        row.add(command.outcome.replace("_", " "), "good")
    else:
        row.add(f"{command.command} ignored", "warn").add(f": {command.outcome}", "dim")
    return row


def _fault_row(fault: FaultSeen, now: Now | dt.datetime, width: int) -> _Row:
    """When, what and why; a pending one (the game waits for a resume) marked "now"."""
    row = _Row(width).add(f"{ago(fault_stamp(fault), now)} ", "dim")
    what = f"{fault.source} {fault.joint}" if fault.joint else fault.source
    row.add(what, "bad" if fault.pending else "warn")
    if fault.pending:
        row.add(" (now)", "bad")
    return row.add(f": {fault.detail}")


def _daemon_event_row(event: DaemonEvent, now: Now | dt.datetime, width: int) -> _Row:
    """An event of the daemon's own log, in the faults' form."""
    row = _Row(width).add(f"{ago(event.time, now)} ", "dim").add("daemon ", "dim")
    row.add(event.name, "bad" if event.fault else "")
    return row.add(f": {event.detail}") if event.detail else row


def _columns(left: list[Line], right: list[Line], width: int, split: int) -> list[Line]:
    rows = []
    for index in range(max(len(left), len(right))):
        row = _Row(width)
        for span in left[index] if index < len(left) else ():
            row.add(*span)
        row.pad_to(split)
        for span in right[index] if index < len(right) else ():
            row.add(*span)
        rows.append(row.line())
    return rows


def _lists(
    view: WatchView,
    session: SessionView,
    now: Now | dt.datetime,
    height: int,
    width: int,
    glyphs: Glyphs,
) -> list[Line]:
    """Answers and learned toys side by side, then commands and faults; as many as fit."""
    if height < 2:
        return []
    split = min(max(width * 3 // 5, 40), width)
    left_width, right_width = split - 1, width - split
    two_columns = right_width >= 24
    faults = [_fault_row(f, now, right_width if two_columns else width) for f in session.faults]
    faults += [
        _daemon_event_row(e, now, right_width if two_columns else width)
        for e in view.daemon
        if e.fault
    ]
    half = max(height // 2, 1)
    top_height = min(half, 1 + max(len(session.answers), len(session.learned), 1))
    bottom_height = height - top_height
    rows_top = top_height - 1
    recent = session.answers[-rows_top:]
    widths = _answer_widths(recent)
    answers = [_answer_row(a, widths, left_width, glyphs).line() for a in recent]
    targets = _targets(session)
    learned_total = f" {len(session.learned)}" + (f" of {targets}" if targets else "")
    learned = [
        _Row(right_width)
        .add(f"{item.target} {glyphs.arrow} ")
        .add(item.toy, "good")
        .add(f" in {item.trials} tries", "dim")
        .line()
        for item in session.learned[-rows_top:]
    ]
    rows: list[Line] = []
    if two_columns:
        rows += _columns(
            [((f"ANSWERS ({session.trials})", "dim"),), *answers],
            [((f"LEARNED{learned_total}", "dim"),), *learned],
            width,
            split,
        )
    else:
        rows += [((f"ANSWERS ({session.trials})", "dim"),), *answers]
    rows_bottom = bottom_height - 1
    if rows_bottom <= 0:
        return rows[:height]
    commands = [_command_row(c, left_width, glyphs).line() for c in session.commands[-rows_bottom:]]
    fault_lines = [row.line() for row in faults[-rows_bottom:]]
    fault_title = f"FAULTS ({len(faults)})" if faults else "FAULTS none"
    if two_columns:
        rows += _columns(
            [(("RESEARCHER", "dim"),), *commands],
            [((fault_title, "dim"),), *fault_lines],
            width,
            split,
        )
    else:
        rows += [((fault_title, "dim"),), *fault_lines]
    return rows[:height]


def frame(
    view: WatchView,
    now: Now | dt.datetime,
    width: int = 80,
    height: int = 24,
    glyphs: Glyphs = UNICODE,
) -> list[Line]:
    """The whole screen: header, the question or the step, the lists, and a footer line."""
    width = max(width, MIN_WIDTH)
    rule: Line = ((glyphs.rule * width, "dim"),)
    lines = _header(view, now, width, glyphs)
    session = view.session
    body_height = max(height - len(lines) - 1, 0)
    body: list[Line] = []
    if session is not None:
        body.append(rule)
        question = _question_block(session, min(body_height - 2, 12), width, glyphs)
        body += question
        body.append(rule)
        body += _lists(view, session, now, body_height - len(body), width, glyphs)
    else:
        events = [
            _daemon_event_row(e, now, width).line() for e in view.daemon[-(body_height - 1) :]
        ]
        if events:
            body += [rule, *events]
    lines += body[:body_height]
    lines += [()] * (height - 1 - len(lines))
    footer = _Row(width)
    warnings = session.warnings if session is not None else ()
    if view.problem and session is not None:
        footer.add(view.problem, "bad").add("  ")
    if warnings:
        # First: a line of the records not read is data the researcher may be missing.
        footer.add(f"{len(warnings)} line(s) not read", "warn").add("  ")
    lines.append(footer.add(view.footer, "dim").line())
    return lines[:height]
