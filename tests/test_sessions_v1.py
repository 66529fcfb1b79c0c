"""Sessions written before the records were typed still load, export, report and resume.

tests/data/sessions-v1 (see its README) was recorded by the code of commit 9c84157.
Today's code must read it exactly as that code did: the same exports byte for byte,
the same report, the same session list, and the interrupted session resumed to the
very same end, in every learner value and every record. What Kaspar says has changed
since (brief, literal lines; kasparctl/game/scripts.py), so the words said and the
times they took are left out of that comparison: the session resumes with the script
it was planned with (none then: the varied one, the same five bands), and every
choice, answer, band and learner value comes out as it did.
"""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path
from typing import Any

import pytest

from kasparctl.cli import main
from kasparctl.game.session import (
    RECORDS_FILE,
    STATE_FILE,
    Session,
    state_from_plain,
    state_to_plain,
)
from kasparctl.game.state import restore
from kasparctl.research.catalogue import load_session
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo

DATA = Path(__file__).resolve().parent / "data" / "sessions-v1"
STATE = DATA / "state"
EXPECTED = DATA / "expected"
SESSIONS = sorted((STATE / "sessions").iterdir())
(INTERRUPTED,) = [d for d in SESSIONS if d.name.endswith("-C13")]


def plain_records(path: Path) -> list[dict[str, Any]]:
    """Each record as JSON, without the wall-clock time that no rerun can repeat."""
    records = [json.loads(line) for line in path.read_text().splitlines()]
    return [{k: v for k, v in record.items() if k != "time"} for record in records]


# What depends on the words Kaspar says and how long they take, not on the game.
SAID_AND_WHEN = ("time", "clock", "spoken", "question_end", "feedback_at", "reaction_time", "at")


def without_words(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records without what the words and their durations decide."""
    return [{k: v for k, v in record.items() if k not in SAID_AND_WHEN} for record in records]


def without_questions(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records as that code wrote them: today's game also records each question
    before asking it (history only, for the live view), so those are left out and the
    others numbered again in their order."""
    kept = [record for record in records if record["kind"] != "question"]
    return [{**record, "seq": seq} for seq, record in enumerate(kept, start=1)]


def test_every_session_loads_whole() -> None:
    assert len(SESSIONS) == 3
    for directory in SESSIONS:
        session = load_session(directory)
        assert session.warnings == []
        assert len(session.records) == len((directory / RECORDS_FILE).read_text().splitlines())


@pytest.mark.parametrize("directory", SESSIONS, ids=lambda d: d.name)
def test_replaying_the_records_gives_the_snapshot(directory: Path, tmp_path: Path) -> None:
    """The records alone rebuild the state the snapshot holds, field for field."""
    config = demo_config()
    plan = json.loads((directory / "plan.json").read_text())
    snapshot = json.loads((directory / STATE_FILE).read_text())["state"]
    session, warnings = Session.open(shutil.copytree(directory, tmp_path / directory.name))
    assert warnings == []
    settings = config.game if plan["variant"] == "names" else _pilot_game()
    params = config.profile(plan["plan"]["profile"])
    replayed = restore(None, session.records(), settings, params, plan["seed"])
    assert json.loads(json.dumps(state_to_plain(replayed))) == snapshot
    # And the snapshot itself reads back as that very state.
    from_snapshot, later = session.load_state()
    session.close()
    assert from_snapshot is not None and later == []
    assert state_to_plain(from_snapshot) == state_to_plain(replayed)


def _pilot_game() -> Any:
    from kasparctl.sim.demo import with_variant

    return with_variant(demo_config(), "pilot").game


@pytest.mark.parametrize("snapshot", sorted((DATA / "snapshots").iterdir()), ids=lambda p: p.stem)
def test_old_snapshots_load_and_save_unchanged(snapshot: Path) -> None:
    state = json.loads(snapshot.read_text())["state"]
    assert json.loads(json.dumps(state_to_plain(state_from_plain(state)))) == state


# Columns added since: the uncertainty script and its version, on every row.
ADDED_COLUMNS = ("script", "script_version")


def without_added_columns(text: str) -> tuple[str, set[tuple[str, ...]]]:
    """A CSV without ADDED_COLUMNS, and the values those held."""
    rows = list(csv.reader(io.StringIO(text)))
    dropped = [rows[0].index(name) for name in ADDED_COLUMNS]
    kept = [[cell for i, cell in enumerate(row) if i not in dropped] for row in rows]
    values = {tuple(row[i] for i in dropped) for row in rows[1:]}
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows(kept)
    return out.getvalue(), values


@pytest.mark.parametrize("anonymise", [False, True], ids=["named", "anonymised"])
def test_export_is_what_it_was(tmp_path: Path, anonymise: bool) -> None:
    suffix = "-anonymised" if anonymise else ""
    trials, events = tmp_path / "trials.csv", tmp_path / "events.csv"
    arguments = ["export", "--state-dir", str(STATE), "--csv", str(trials), "--events", str(events)]
    assert main([*arguments, *(["--anonymise"] if anonymise else [])]) == 0
    for path, expected in ((trials, "trials"), (events, "events")):
        text, values = without_added_columns(path.read_text())
        assert text == (EXPECTED / f"{expected}{suffix}.csv").read_text()
        # Planned before scripts: the five varied bands, with the words of then.
        assert values == {("varied", "0")}


def test_report_is_what_it_was(tmp_path: Path) -> None:
    assert main(["report", "--state-dir", str(STATE), "--out", str(tmp_path)]) == 0
    for name in ("summary.json", "summary.md"):
        assert (tmp_path / name).read_text() == (EXPECTED / name).read_text(), name


def test_session_list_is_what_it_was(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sessions", "--state-dir", str(STATE), "--json"]) == 0
    # The list names each directory as given: the expected one was made from the repository root.
    listed = capsys.readouterr().out.replace(str(STATE), "tests/data/sessions-v1/state")
    assert listed == (EXPECTED / "sessions.json").read_text()


@pytest.mark.parametrize("from_records", [False, True], ids=["from-snapshot", "from-records"])
def test_the_interrupted_session_resumes_to_the_same_end(tmp_path: Path, from_records: bool) -> None:
    copy = tmp_path / "sessions" / INTERRUPTED.name
    shutil.copytree(INTERRUPTED, copy)
    if from_records:
        (copy / STATE_FILE).unlink()
    options = DemoOptions(state_dir=tmp_path, seed=13, out=io.StringIO())
    result = run_demo(demo_config(), options, fast=True)
    assert result.resumed and result.finished
    expected = "resumed-from-records" if from_records else "resumed"
    got = without_questions(plain_records(copy / RECORDS_FILE))
    want = plain_records(EXPECTED / f"{expected}.records.jsonl")
    assert len(got) == len(want)
    for mine, theirs in zip(without_words(got), without_words(want), strict=True):
        assert mine == theirs
    # Resumed with the bands it was planned with, and with today's words.
    trials = [r for r in got if r["kind"] == "trial"][-1]
    assert trials["band"] in ("no_idea", "unsure", "idea_not_sure", "fairly_sure", "sure")
    # The records written before the crash are untouched.
    assert (copy / RECORDS_FILE).read_text().startswith((INTERRUPTED / RECORDS_FILE).read_text())


def test_a_line_that_is_no_record_is_reported_never_a_crash(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A readable JSON line that no record type accepts: each reader names its file and
    line on stderr, and goes on with the records it can read."""
    copy = shutil.copytree(INTERRUPTED, tmp_path / "sessions" / INTERRUPTED.name)
    records = copy / RECORDS_FILE
    lines = records.read_text().splitlines(keepends=True)
    lines.insert(4, '{"kind": "trial", "seq": 5, "trial": "five"}\n')
    lines.insert(7, '{"kind": "hug", "seq": 8}\n')
    records.write_text("".join(lines))
    trials = tmp_path / "trials.csv"
    assert main(["export", "--state-dir", str(tmp_path), "--csv", str(trials)]) == 0
    assert main(["sessions", "--state-dir", str(tmp_path)]) == 0
    assert main(["report", "--state-dir", str(tmp_path), "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    for line in (5, 8):
        assert f"{records}: line {line}: skipped, not a valid record" in err
    assert len(trials.read_text().splitlines()) == 1 + 8  # header and the eight trials
