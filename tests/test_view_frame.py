"""The picture laid out for a screen, read as plain text; the screens that show it."""

from __future__ import annotations

import datetime as dt
import io
import os
import re

import pytest
from view_records import PLAN, TOYS, Stamper, question, trial

from kasparctl.game.records import FaultRecord, FaultSource, QuestionRecord, StepRecord
from kasparctl.view.ages import ago, next_change
from kasparctl.view.fold import session_view
from kasparctl.view.frame import ASCII, frame, plain_text, seconds_to_redraw
from kasparctl.view.model import WatchView
from kasparctl.view.screen import PlainScreen, RichScreen, parse_keys


def picture(*records, width=80, height=24, glyphs=None, now_seq=None):
    stamp = Stamper()
    session = session_view(PLAN, [stamp(r) for r in records])
    view = WatchView("/var/lib/kaspar", session=session, sessions=1, footer="q quits")
    now = stamp.time_of(now_seq if now_seq is not None else stamp.seq)
    lines = frame(view, now, width, height, **({"glyphs": glyphs} if glyphs else {}))
    return [plain_text(line) for line in lines], view, now


def test_an_open_question_on_80_by_24() -> None:
    asked = question(3, target=2, choice="zebra", child="child two", problem_trial=2)
    lines, _, _ = picture(StepRecord(to="guessing"), asked)
    assert len(lines) == 24 and all(len(line) <= 80 for line in lines)
    text = "\n".join(lines)
    assert "STEP 4 GUESSING" in lines[0] and "G7" in lines[0] and "paper/spoken" in lines[0]
    assert "turn: child two" in lines[1]
    assert "bag 3 · try 2 · trial 3 · child two  asking" in text
    for toy, p in zip(TOYS, asked.probabilities, strict=True):
        (row,) = [line for line in lines if line.startswith(f"  {toy} ")]
        assert f" {p:.3f}" in row
    assert "◀ guess" in next(line for line in lines if line.startswith("  zebra "))
    assert f"entropy {asked.entropy:.2f} of {asked.entropy:.2f} bits" in text
    assert 'band "no idea" (to say)' in text


def test_the_answers_read_without_colour() -> None:
    first, second = question(1), question(2, choice="monkey")
    lines, _, _ = picture(
        first,
        trial(first, "green"),
        second,
        trial(second, "red", correct=True, feedback_right=False),
    )
    text = "\n".join(lines)
    assert "✓ green" in text and "✗ red" in text and "wrong red" in text
    assert "ANSWERS (2)" in text


def test_a_pending_fault_says_what_why_and_how_long_ago() -> None:
    fault = FaultRecord(
        fault=FaultSource.SERVO,
        detail="no reply from servo 15",
        joint="right_elbow",
        state="guessing",
    )
    lines, _, _ = picture(StepRecord(to="guessing"), fault, now_seq=14)
    assert "FAULT servo right_elbow 12 s ago: no reply from servo 15" in lines[3]
    assert "robot servo right_elbow" in lines[2]
    assert "Stopped by a fault in guessing" in "\n".join(lines)


def test_many_toys_and_small_screens_still_fit() -> None:
    lines, _, _ = picture(StepRecord(to="guessing"), question(1), width=40, height=12)
    assert len(lines) == 12 and all(len(line) <= 40 for line in lines)
    lines, _, _ = picture(StepRecord(to="guessing"), question(1), width=200, height=60)
    assert len(lines) == 60 and all(len(line) <= 200 for line in lines)


def test_ascii_for_terminals_without_unicode() -> None:
    first = question(1)
    lines, _, _ = picture(first, trial(first, "red"), glyphs=ASCII)
    text = "\n".join(lines).replace("…", "")
    assert text.isascii() and "x red" in text and "< guess" in text


def test_no_session_yet_and_no_state_directory_yet() -> None:
    now = dt.datetime(2026, 3, 2, tzinfo=dt.UTC)
    lines = [plain_text(x) for x in frame(WatchView("/srv/k", exists=False), now)]
    assert "does not exist yet" in lines[1] and len(lines) == 24
    lines = [plain_text(x) for x in frame(WatchView("/srv/k", sessions=3), now)]
    assert "No session yet (3 in the directory)" in lines[1]


@pytest.mark.parametrize(
    ("seconds", "reads", "changes_in"),
    [
        (0.4, "just now", 0.6),
        (12.25, "12 s ago", 0.75),
        (125, "2 min ago", 55),
        (7300, "2 h ago", 3500),
    ],
)
def test_ages_and_when_they_change(seconds: float, reads: str, changes_in: float) -> None:
    then = dt.datetime(2026, 3, 2, 9, tzinfo=dt.UTC)
    now = then + dt.timedelta(seconds=seconds)
    assert ago(then.isoformat(), now) == reads
    assert next_change(then.isoformat(), now) == pytest.approx(changes_in)


def test_the_frame_is_drawn_again_only_when_something_on_it_ages() -> None:
    now = dt.datetime(2026, 3, 2, tzinfo=dt.UTC)
    assert seconds_to_redraw(WatchView("/srv/k"), now) is None
    _, view, now = picture(question(1))
    assert seconds_to_redraw(view, now) == pytest.approx(1.0)


def test_plain_screen_prints_a_picture_only_when_it_changes() -> None:
    out = io.StringIO()
    screen = PlainScreen(out)
    lines = frame(WatchView("/srv/k"), dt.datetime(2026, 3, 2, tzinfo=dt.UTC))
    screen.draw(lines)
    screen.draw(lines)
    assert out.getvalue().count("No session yet") == 1


def test_plain_screen_in_ascii_when_the_output_cannot_take_unicode() -> None:
    raw = io.BytesIO()
    out = io.TextIOWrapper(raw, encoding="ascii")
    screen = PlainScreen(out)
    assert screen.glyphs is ASCII
    _, view, now = picture(question(1), glyphs=ASCII)
    screen.draw(frame(view, now, glyphs=screen.glyphs))
    out.flush()
    assert raw.getvalue().isascii() and b"entropy" in raw.getvalue()


def _rich_output(monkeypatch: pytest.MonkeyPatch, no_color: bool) -> str:
    if no_color:
        monkeypatch.setenv("NO_COLOR", "1")
    else:
        monkeypatch.delenv("NO_COLOR", raising=False)
    monkeypatch.setenv("TERM", "xterm-256color")
    master, slave = os.openpty()
    os.set_blocking(master, False)
    out = open(slave, "w", encoding="utf-8", closefd=True)  # noqa: SIM115
    try:
        screen = RichScreen(out)
        first = question(1)
        _, view, now = picture(first, trial(first, "red"))
        screen.draw(frame(view, now, *screen.size()))
        screen.close()
        out.flush()
        chunks = []
        while True:
            try:
                chunks.append(os.read(master, 65536))
            except BlockingIOError:
                break
        return b"".join(chunks).decode()
    finally:
        out.close()
        os.close(master)


# SGR parameters that set a colour: 30-37, 40-47, 90-97, 100-107, 38;..., 48;...
_COLOUR = re.compile(r"\x1b\[[0-9;]*?(?<![0-9])(3[0-8]|4[0-8]|9[0-7]|10[0-7])(;[0-9;]*)?m")


def test_rich_screen_colours_and_respects_no_color(monkeypatch: pytest.MonkeyPatch) -> None:
    coloured = _rich_output(monkeypatch, no_color=False)
    assert "\x1b[?1049h" in coloured and "\x1b[?1049l" in coloured  # alternate screen, and back
    assert _COLOUR.search(coloured)
    plain = _rich_output(monkeypatch, no_color=True)
    assert "✗ red" in plain and not _COLOUR.search(plain)


def test_keys_as_terminals_send_them() -> None:
    assert parse_keys(b"q \x1b[C\x1b[D\x1bOH+") == ["q", " ", "right", "left", "home", "+"]


def test_with_more_toys_than_rows_the_guess_and_the_most_likely_are_shown() -> None:
    toys = [f"toy{i}" for i in range(12)]
    weights = [i + 1.0 for i in range(12)]
    asked = QuestionRecord(
        trial=1,
        problem_trial=1,
        target="bag 1",
        target_index=0,
        child="child one",
        child_index=0,
        candidates=toys,
        probabilities=[w / sum(weights) for w in weights],
        entropy=3.4,
        band="unsure",
        choice="toy0",
        choice_index=0,
    )
    lines, _, _ = picture(StepRecord(to="guessing"), asked)
    shown = [line.split()[0] for line in lines if line.startswith("  toy")]
    assert len(lines) == 24 and shown[0] == "toy0" and shown[-1] == "toy11"
    assert "  +3 less likely" in lines
