"""Sessions written before the records were typed still load, export, report and resume.

tests/data/sessions-v1 (see its README) was recorded by the code of commit 9c84157.
Today's code must read it exactly as that code did: the same exports byte for byte
in every column that code wrote (its `session` is today's `session_name`; the
columns added since hold the session's derived uid, an empty robot, no participant,
and the script "varied" version 0), the same statistics in the report, the same
session list, and the interrupted session resumed to the very same end, in every
learner value and every record. What Kaspar says has changed since (brief, literal
lines; kasparctl/game/scripts.py), so the words said and the times they took are
left out of that comparison: the session resumes with the script it was planned with
(none then: the varied one, the same five bands), and every choice, answer, band and
learner value comes out as it did.
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
        lines = (directory / RECORDS_FILE).read_text().splitlines()
        assert session.index.records == len(lines) == len(list(session.records()))


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


# Each old session's uid, derived from its plan.json: the same on every computer, every run.
DERIVED_UIDS = {
    "20261125T165026-demo": "01M89SV7BDY3QJ2WVDWG15QGY6",
    "20261125T165027-demo": "01M89SV8EZCHPXS6BXAD6JHM2N",
    "20261125T165027-C13": "01M89SV8TZF3XFD63AK074D9ZE",
}


def as_written_then(path: Path) -> tuple[str, list[dict[str, str]]]:
    """A CSV of today projected on the columns of commit 9c84157, written as that code did;
    and today's rows, for the columns added since."""
    with path.open(newline="", encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    with (EXPECTED / "trials.csv").open(newline="", encoding="utf-8") as stream:
        old_trials = next(csv.reader(stream))
    with (EXPECTED / "events.csv").open(newline="", encoding="utf-8") as stream:
        old_events = next(csv.reader(stream))
    header = old_trials if "trial" in rows[0] and "detail" not in rows[0] else old_events
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        # Written then: an empty cell for a missing value (NA now), no trial on a prompt
        # (the question it repeated, now), non-ASCII escaped in the detail.
        then = {k: "" if v == "NA" else v for k, v in row.items()}
        then["session"] = row["session_name"]
        if then.get("kind") == "prompt":
            then["trial"] = ""
        if then.get("detail"):
            then["detail"] = json.dumps(json.loads(then["detail"]), sort_keys=True)
        writer.writerow([then[column] for column in header])
    return buffer.getvalue(), rows


@pytest.mark.parametrize("anonymise", [False, True], ids=["named", "anonymised"])
def test_export_is_what_it_was(tmp_path: Path, anonymise: bool) -> None:
    suffix = "-anonymised" if anonymise else ""
    trials, events = tmp_path / "trials.csv", tmp_path / "events.csv"
    arguments = ["export", "--state-dir", str(STATE), "--csv", str(trials), "--events", str(events)]
    assert main([*arguments, *(["--anonymise"] if anonymise else [])]) == 0
    for path, expected in ((trials, "trials"), (events, "events")):
        then, rows = as_written_then(path)
        assert then == (EXPECTED / f"{expected}{suffix}.csv").read_text()
        for row in rows:
            assert row["session"] == DERIVED_UIDS[row["session_name"]]
            assert row["robot"] == "NA" and row["participant"] == "NA"
            # Planned before scripts: the five varied bands, with the words of then.
            assert (row["script"], row["script_version"]) == ("varied", "0")
            assert row["language"] == "en"  # planned before languages were recorded
    _, rows = as_written_then(trials)
    flagged = [r for r in rows if "TRUE" in (r["perseverative"], r["win_shift"])]
    assert flagged and all(r["error_cause"] in ("exploratory", "after_wrong_feedback") for r in flagged)
    assert {r["error_cause"] for r in rows if r not in flagged} == {"NA"}


def test_report_is_what_it_was(tmp_path: Path) -> None:
    assert main(["report", "--state-dir", str(STATE), "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    then = json.loads((EXPECTED / "summary.json").read_text())
    assert summary["session_names"] == then["sessions"]
    assert summary["sessions"] == [DERIVED_UIDS[name] for name in then["sessions"]]
    for now, old in zip(
        [*summary["conditions"], summary["all"]], [*then["conditions"], then["all"]], strict=True
    ):
        for key, value in old.items():
            assert now[key] == value, (old["condition"], key)
    # The Markdown keeps every row it had, with shares now to 0.1 %.
    text = (tmp_path / "summary.md").read_text()
    assert "| Trials | 27 | 15 | 42 |" in text
    assert "| Trials to learn, mean ± sd | 3.14 ± 1.35" in text
    # Labelled now as over all problems, beside the problems with a choice (issue 27).
    assert "| First guess correct, all problems | 3 of 8 (37.5 %)" in text


def test_session_list_is_what_it_was(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sessions", "--state-dir", str(STATE), "--json"]) == 0
    # The list names each directory as given: the expected one was made from the repository root.
    listed = json.loads(capsys.readouterr().out.replace(str(STATE), "tests/data/sessions-v1/state"))
    then = json.loads((EXPECTED / "sessions.json").read_text())
    assert len(listed) == len(then)
    for now, old in zip(listed, then, strict=True):
        assert now["session"] == DERIVED_UIDS[old["session"]]
        assert {**now, "session": now["session_name"]} | old == {
            **now,
            "session": now["session_name"],
        }


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
