"""`kasparctl sessions` on sessions the demo recorded."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from research_fixtures import Study, counted_trials, make_study, raw_records

from kasparctl.cli import main


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Study:
    return make_study(tmp_path_factory.mktemp("study"))


def test_json_lists_every_session_with_status_trials_and_condition(study: Study, capsys) -> None:
    assert main(["sessions", "--state-dir", str(study.state_dir), "--json"]) == 0
    out, err = capsys.readouterr()
    listed = {row["session_name"]: row for row in json.loads(out)}
    assert set(listed) == set(study.planned)
    for session, planned in study.planned.items():
        row = listed[session]
        records = raw_records(study.state_dir / "sessions" / session)
        spoken = "spoken" if planned.speak_uncertainty else "silent"
        assert row["group"] == planned.group
        assert row["condition"] == f"{planned.profile}/{spoken}"
        assert row["variant"] == planned.variant
        assert row["status"] == planned.status, session
        assert row["resumed"] == planned.resumed
        assert row["trials"] == len(counted_trials(records))
        assert row["date"] == records[0]["time"][:10]
    assert listed[next(s for s, p in study.planned.items() if p.group == "G3")]["undone"] == 1
    # The damaged session is listed, and its damage is reported, not hidden.
    assert "line 3: skipped" in err and "torn" in err


def test_table_has_one_line_per_session(study: Study, capsys) -> None:
    assert main(["sessions", "--state-dir", str(study.state_dir)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == [
        "session_name",
        "session",
        "robot",
        "group",
        "condition",
        "variant",
        "date",
        "trials",
        "status",
        "resumed",
    ]
    by_group = {line.split()[3]: line.split() for line in lines[1:]}
    assert by_group["G5"][8] == "stopped"
    assert by_group["G6"][8] == "interrupted"
    assert by_group["G4"][8:] == ["finished", "1"]


def test_state_dir_comes_from_the_configuration(study: Study, tmp_path: Path, capsys) -> None:
    config = tmp_path / "kaspar.toml"
    config.write_text(f'state_dir = "{study.state_dir}"\n')
    assert main(["sessions", "--config", str(config), "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == len(study.planned)


def test_without_state_dir_or_configuration_the_error_says_what_to_give(
    tmp_path: Path, monkeypatch, capsys
) -> None:
    monkeypatch.setenv("KASPAR_CONFIG", str(tmp_path / "missing.toml"))
    assert main(["sessions"]) == 1
    err = capsys.readouterr().err
    assert "--state-dir" in err and "missing.toml" in err


def test_a_missing_state_dir_is_named(tmp_path: Path, capsys) -> None:
    assert main(["sessions", "--state-dir", str(tmp_path / "nowhere")]) == 1
    assert "nowhere: no such state directory" in capsys.readouterr().err


def test_an_empty_state_dir_has_no_sessions(tmp_path: Path, capsys) -> None:
    assert main(["sessions", "--state-dir", str(tmp_path)]) == 0
    assert capsys.readouterr().out.startswith("no sessions in")
