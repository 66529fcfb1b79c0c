"""`kasparctl export`: the tidy trials CSV and the events CSV, read back with the csv module."""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
import re
from pathlib import Path

import pytest
from research_fixtures import (
    CHILDREN,
    Study,
    counted_trials,
    documented_columns,
    make_study,
    raw_records,
)

from kasparctl.cli import main

TOYS = ("lion", "elephant", "giraffe", "monkey", "zebra", "crocodile")


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Study:
    return make_study(tmp_path_factory.mktemp("study"))


def read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with path.open(newline="", encoding="utf-8") as stream:
        reader = csv.DictReader(stream)
        rows = list(reader)
        return list(reader.fieldnames or []), rows


def export(study: Study, tmp_path: Path, *extra: str) -> tuple[list[str], list[dict[str, str]]]:
    out = tmp_path / "trials.csv"
    assert main(["export", "--state-dir", str(study.state_dir), "--csv", str(out), *extra]) == 0
    return read_csv(out)


def expand(columns: list[str], attributes: tuple[str, ...] = ()) -> list[str]:
    """Documented names with "<toy>" written out for the demo's toys, "<attribute>" for
    participants.csv's columns (none without --participants)."""
    return [
        name.replace("<toy>", part).replace("<attribute>", part)
        for name in columns
        for part in (TOYS if "<toy>" in name else attributes if "<attribute>" in name else [""])
    ]


def is_type(value: str, kind: str) -> bool:
    if kind == "integer":
        return re.fullmatch(r"-?\d+", value) is not None
    if kind == "number":
        float(value)
        return True
    if kind == "boolean":
        return value in ("TRUE", "FALSE")
    if kind == "timestamp":
        return dt.datetime.fromisoformat(value).utcoffset() == dt.timedelta(0)
    return kind in ("string", "list")


def test_one_row_per_trial_record_and_undone_ones_marked(
    study: Study, tmp_path: Path, capsys
) -> None:
    _, rows = export(study, tmp_path)
    for session in study.planned:
        records = raw_records(study.state_dir / "sessions" / session)
        mine = [r for r in rows if r["session_name"] == session]
        assert len(mine) == sum(1 for r in records if r["kind"] == "trial")
        counted = [r for r in mine if r["undone"] == "FALSE"]
        assert len(counted) == len(counted_trials(records))
        assert [int(r["trial"]) for r in counted] == [t["trial"] for t in counted_trials(records)]
    undone = [r for r in rows if r["undone"] == "TRUE"]
    assert [(r["group"], r["trial"]) for r in undone] == [("G3", "1")]
    assert "line 3: skipped" in capsys.readouterr().err


def test_columns_and_types_are_as_documented(study: Study, tmp_path: Path) -> None:
    documented = documented_columns("## kasparctl export: the trials CSV")
    header, rows = export(study, tmp_path)
    assert header == expand([c.name for c in documented])
    for column in documented:
        for name in expand([column.name]):
            for row in rows:
                value = row[name]
                if value == "NA":
                    assert column.empty_when != "never", (name, row["session_name"], row["trial"])
                    continue
                assert is_type(value, column.type), (name, value)
    # Silent sessions have no band; spoken ones always do.
    assert {r["band"] == "NA" for r in rows if r["speak_uncertainty"] == "FALSE"} == {True}
    assert "NA" not in {r["band"] for r in rows if r["speak_uncertainty"] == "TRUE"}
    assert "" not in {value for row in rows for value in row.values()}


def test_values_are_the_records_own(study: Study, tmp_path: Path) -> None:
    _, rows = export(study, tmp_path)
    by_key = {(r["session_name"], int(r["trial"])): r for r in rows}
    for session, planned in study.planned.items():
        for trial in (
            r for r in raw_records(study.state_dir / "sessions" / session) if r["kind"] == "trial"
        ):
            row = by_key[(session, trial["trial"])]
            assert row["group"] == planned.group and row["variant"] == planned.variant
            # Full precision: the same floats come back, not rounded ones.
            assert [float(row[f"p_{toy}"]) for toy in TOYS] == trial["probabilities"]
            assert [float(row[f"q_after_{toy}"]) for toy in TOYS] == trial["q_after"]
            assert float(row["entropy"]) == trial["entropy"]
            assert row["candidates"].split(";") == trial["candidates"]
            assert (row["choice"], row["feedback"]) == (trial["choice"], trial["feedback"])
            assert row["perseverative"] == ("TRUE" if trial["perseverative"] else "FALSE")
            assert int(row["child_number"]) == trial["child_index"] + 1
            assert "learner_rng" not in row


def test_first_names_are_exported_only_without_anonymise(study: Study, tmp_path: Path) -> None:
    _, rows = export(study, tmp_path)
    assert {r["child"] for r in rows if r["group"] == "G1"} == set(CHILDREN)
    # A group without first names: the phrase book's names.child.
    assert {r["child"] for r in rows if r["group"] == "G2"} == {"child 1", "child 2", "child 3"}

    events = tmp_path / "events.csv"
    _, rows = export(study, tmp_path, "--anonymise", "--events", str(events))
    assert {r["child"] for r in rows} == {"child 1", "child 2", "child 3"}
    for path in (tmp_path / "trials.csv", events):
        text = path.read_text()
        for name in CHILDREN:
            assert re.search(rf"\b{name}\b", text) is None, (path.name, name)


def test_named_sessions_by_id_or_directory(study: Study, tmp_path: Path) -> None:
    first, second = sorted(study.planned)[:2]
    out = tmp_path / "two.csv"
    arguments = ["export", first, str(study.state_dir / "sessions" / second), "--csv", str(out)]
    assert main([*arguments, "--state-dir", str(study.state_dir)]) == 0
    _, rows = read_csv(out)
    assert {r["session_name"] for r in rows} == {first, second}
    # Given as directories only, sessions need no state directory.
    assert main(["export", str(study.state_dir / "sessions" / second), "--csv", str(out)]) == 0
    assert {r["session_name"] for r in read_csv(out)[1]} == {second}


def test_an_unknown_session_is_named(study: Study, tmp_path: Path, capsys) -> None:
    code = main(
        ["export", "nope", "--state-dir", str(study.state_dir), "--csv", str(tmp_path / "x")]
    )
    assert code == 1
    assert "no session 'nope'" in capsys.readouterr().err


def test_events_hold_every_other_record_as_documented(study: Study, tmp_path: Path) -> None:
    events = tmp_path / "events.csv"
    export(study, tmp_path, "--events", str(events))
    header, rows = read_csv(events)
    documented = documented_columns("## kasparctl export --events")
    assert header == [c.name for c in documented]
    for column in documented:
        for row in rows:
            if row[column.name] == "NA":
                assert column.empty_when != "never", (column.name, row)
            else:
                assert is_type(row[column.name], column.type), (column.name, row[column.name])
    for session in study.planned:
        records = raw_records(study.state_dir / "sessions" / session)
        others = [r for r in records if r["kind"] != "trial"]
        assert [int(r["seq"]) for r in rows if r["session_name"] == session] == [
            r["seq"] for r in others
        ]
    kinds = {(r["kind"], r["name"]) for r in rows}
    assert {("command", "stop"), ("command", "undo"), ("fault", "servo")} <= kinds
    assert {("session", "start"), ("session", "resumed")} <= kinds
    assert any(kind == "prompt" for kind, _ in kinds)
    stop = next(r for r in rows if (r["kind"], r["name"]) == ("command", "stop"))
    assert json.loads(stop["detail"])["applied"] is True


def test_the_csv_can_go_to_stdout(study: Study, capsys) -> None:
    assert main(["export", "--state-dir", str(study.state_dir), "--csv", "-"]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("session,session_name,robot,robot_name,group,session_number,")
    assert "trials from 6 sessions" in captured.err


def test_first_names_are_replaced_as_whole_words_only() -> None:
    from kasparctl.research.anonymise import Pseudonyms

    names = Pseudonyms({"Anna": "child 1", "Anna-Lena": "child 2", "Bo": "child 3"})
    assert names.text("Anna-Lena, then Anna, then Annabel; Bo's turn") == (
        "child 2, then child 1, then Annabel; child 3's turn"
    )
    assert names.value({"text": ["Bo", 3]}) == {"text": ["child 3", 3]}


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_shows_on_a_terminal_only() -> None:
    from kasparctl.research.progress import MINIMUM_ITEMS, progress

    items = list(range(MINIMUM_ITEMS))
    quiet = io.StringIO()
    assert list(progress(items, "reading", stream=quiet)) == items
    assert quiet.getvalue() == ""
    terminal = Terminal()
    assert list(progress(items, "reading", stream=terminal)) == items
    assert "reading:" in terminal.getvalue() and f"/{MINIMUM_ITEMS}" in terminal.getvalue()
