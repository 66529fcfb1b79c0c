"""The export as a data package: the codebook as the one source, NA that R and pandas read
alike, datapackage.json valid for `frictionless validate`, Psych-DS's layout, the sessions
table, and the bundle that leaves the robot (anonymised, re-keyed, checksummed).

R is not installed here: R's side is checked by its documented rules (read.csv:
na.strings = "NA", and a blank field is NA only in logical, integer and numeric columns;
readr: na = c("", "NA")) applied with python's csv module, beside pandas itself.
"""

from __future__ import annotations

import csv
import datetime as dt
import hashlib
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from codebook_table import DOC, block, current
from research_fixtures import CHILDREN, Study, make_study

from kasparctl.cli import main
from kasparctl.config import ConfigError, load_config
from kasparctl.research import codebook
from kasparctl.research.tidy import cell
from kasparctl.vocabulary import MISSING_MARKERS

PY311 = Path(__file__).parent / "data" / "sessions-py311" / "state"


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Study:
    return make_study(tmp_path_factory.mktemp("package-study"))


def rows_of(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as stream:
        return list(csv.DictReader(stream))


# -- the codebook is the one source -----------------------------------------------------


def test_the_docs_tables_are_the_codebooks() -> None:
    doc = DOC.read_text(encoding="utf-8")
    for table in codebook.TABLES:
        assert current(doc, table) == block(table), (
            f"docs/research-data.md's {table} table differs from kasparctl/research/codebook.py:"
            " run .venv/bin/python tests/codebook_table.py"
        )


def test_every_column_is_described_once() -> None:
    for name, columns in codebook.TABLES.items():
        names = [c.name for c in columns]
        assert len(names) == len(set(names)), name
        assert all(c.type in ("string", "integer", "number", "boolean", "timestamp", "list")
                   for c in columns), name
        assert all(c.meaning and c.empty_when for c in columns), name


# -- NA ---------------------------------------------------------------------------------


def r_read_csv(path: Path) -> dict[str, list[Any]]:
    """Base R's read.csv by its documentation: "NA" is NA in every column; a blank field is NA
    only in a column that is logical, integer or numeric, "" in a character one."""
    rows = rows_of(path)
    columns: dict[str, list[Any]] = {}
    for name in rows[0]:
        values = [row[name] for row in rows]
        present = [v for v in values if v not in ("NA", "")]
        numeric = all(re.fullmatch(r"-?[\d.eE+-]+|TRUE|FALSE", v) for v in present)
        columns[name] = [
            None if v == "NA" or (v == "" and numeric) else v for v in values
        ]
    return columns


def readr_read_csv(path: Path) -> dict[str, list[Any]]:
    """readr's read_csv by its documentation: na = c("", "NA")."""
    rows = rows_of(path)
    return {name: [None if row[name] in ("", "NA") else row[name] for row in rows]
            for name in rows[0]}


def test_missing_values_read_the_same_in_base_r_readr_and_pandas(
    study: Study, tmp_path: Path
) -> None:
    pandas = pytest.importorskip("pandas")
    out = tmp_path / "package"
    assert main(["export", "--state-dir", str(study.state_dir), "--out", str(out)]) == 0
    for name in ("trials.csv", "events.csv", "sessions.csv"):
        path = out / name
        frame = pandas.read_csv(path, keep_default_na=True)
        r_side, readr_side = r_read_csv(path), readr_read_csv(path)
        for column in frame.columns:
            in_pandas = frame[column].isna().tolist()
            in_r = [v is None for v in r_side[column]]
            in_readr = [v is None for v in readr_side[column]]
            assert in_pandas == in_r == in_readr, (name, column)
        # Before, an empty cell: read.csv read a text column's as "" (band, participant).
        assert "" not in {v for row in rows_of(path) for v in row.values()}, name


def test_text_a_reader_would_take_for_missing_is_marked() -> None:
    for marker in MISSING_MARKERS - {""}:
        assert cell(marker) == "'" + marker
    assert cell(None) == cell("") == cell(float("nan")) == "NA"
    assert cell("NAB") == "NAB" and cell(-0.5) == "-0.5"


@pytest.mark.parametrize(
    ("key", "value"),
    [("group", '"NA"'), ("participants", '["P1", "null"]'), ("children", '["Ann", "None"]')],
)
def test_check_refuses_codes_and_names_that_read_as_missing(
    tmp_path: Path, key: str, value: str
) -> None:
    config = tmp_path / "kaspar.toml"
    group = value if key == "group" else '"G1"'
    extra = "" if key == "group" else f"{key} = {value}\n"
    if key == "participants":
        extra += 'children = ["Ann", "Bo"]\n'
    elif key == "children":
        extra += 'participants = ["P1", "P2"]\n'
    config.write_text(f'[[sessions]]\ngroup = {group}\n{extra}')
    # `check` reads the configuration with load_config, and says its error as it is.
    with pytest.raises(ConfigError) as refused:
        load_config(config)
    err = str(refused.value)
    assert f"sessions[0].{key}" in err and "read back from a CSV as a missing value" in err, err


# -- the data package -------------------------------------------------------------------


def frictionless_validate(descriptor: Path) -> subprocess.CompletedProcess[str]:
    pytest.importorskip("frictionless")
    tool = Path(sys.executable).parent / "frictionless"
    return subprocess.run(
        [str(tool), "validate", str(descriptor)], capture_output=True, text=True, timeout=300
    )


def test_frictionless_validates_the_package_of_a_demo_study(study: Study, tmp_path: Path) -> None:
    out = tmp_path / "package"
    assert main(["export", "--state-dir", str(study.state_dir), "--out", str(out)]) == 0
    package = json.loads((out / "datapackage.json").read_text())
    assert [r["name"] for r in package["resources"]] == ["trials", "events", "sessions"]
    trials = package["resources"][0]["schema"]
    assert trials["primaryKey"] == ["session", "trial"]
    assert trials["missingValues"] == ["NA"]
    fields = {f["name"]: f for f in trials["fields"]}
    assert list(fields) == next(csv.reader((out / "trials.csv").open()))
    assert fields["reaction_time"]["description"].startswith("seconds from the end")
    assert fields["entropy"]["constraints"] == {"required": True}
    result = frictionless_validate(out / "datapackage.json")
    print(result.stdout)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "INVALID" not in result.stdout and result.stdout.count("VALID") == 3


def test_the_package_catches_a_broken_table(study: Study, tmp_path: Path) -> None:
    out = tmp_path / "package"
    assert main(["export", "--state-dir", str(study.state_dir), "--out", str(out)]) == 0
    # A trial number written twice breaks the primary key: the validation is no rubber stamp.
    lines = (out / "trials.csv").read_text().splitlines(keepends=True)
    (out / "trials.csv").write_text("".join([*lines, lines[1]]))
    result = frictionless_validate(out / "datapackage.json")
    assert result.returncode != 0 and "primary-key" in result.stdout


def test_psych_ds_layout_describes_every_column(study: Study, tmp_path: Path) -> None:
    out = tmp_path / "psych"
    arguments = ["export", "--state-dir", str(study.state_dir), "--out", str(out), "--psych-ds"]
    assert main(arguments) == 0
    description = json.loads((out / "dataset_description.json").read_text())
    assert description["@context"] == "https://schema.org/"
    assert description["@type"] == "Dataset" and description["name"]
    measured = {v["name"] for v in description["variableMeasured"]}
    data = sorted((out / "data").iterdir())
    assert [p.name for p in data] == [
        "study-kaspar_description-events_data.csv",
        "study-kaspar_description-sessions_data.csv",
        "study-kaspar_description-trials_data.csv",
    ]
    headers: set[str] = set()
    for path in data:
        # The Psych-DS validator's Datafile rule: keyword-value pairs, then _data.csv.
        assert re.fullmatch(r"([a-z]+-[a-zA-Z0-9]+)(_[a-z]+-[a-zA-Z0-9]+)*_data\.csv", path.name)
        header = set(next(csv.reader(path.open())))
        assert header <= measured, path.name  # else CSV_COLUMN_MISSING_FROM_METADATA
        headers |= header
    # A variable measured in no CSV is the validator's VARIABLE_MISSING_FROM_CSV_COLUMNS error.
    assert measured == headers
    assert frictionless_validate(out / "datapackage.json").returncode == 0


# -- the sessions table and plan.json's new keys ------------------------------------------

NEW_KEYS = {
    "robot": {"id": "kaspar-lab-2", "name": "Robin"},
    "kasparctl_version": "0.27.0",
    "settings": {
        "variant": "pilot",
        "correct_answers_to_learn": 3,
        "max_trials_per_target": 30,
        "toys": ["lion", "elephant"],
        "prompt_after_s": 8.0,
        "reactions": "none",
        "speed_scale": 0.5,
        "voice": {"engine": "espeak-ng", "voice": "en", "rate": 90, "volume": 0.2, "pitch": 50},
        "learner": {"profile": "paper", "alpha": 0.3, "beta": 3.0},
    },
    "learner": {"profile": "paper", "alpha": 0.3, "beta": 3.0, "gamma": 0.0,
                "reward_green": 1.0, "reward_red": -1.0, "initial_q": 0.0},
}


@pytest.fixture
def new_and_old(tmp_path: Path) -> Path:
    """The three py311 demo sessions, the first given plan.json's new keys by hand."""
    state = shutil.copytree(PY311, tmp_path / "state")
    first = sorted((state / "sessions").iterdir())[0]
    plan = json.loads((first / "plan.json").read_text())
    (first / "plan.json").write_text(json.dumps({**plan, **NEW_KEYS}))
    return state


def test_sessions_table_reads_new_keys_and_old_sessions_as_missing(
    new_and_old: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sessions.csv"
    trials = tmp_path / "trials.csv"
    arguments = ["export", "--state-dir", str(new_and_old), "--csv", str(trials)]
    assert main([*arguments, "--sessions", str(out)]) == 0
    rows = rows_of(out)
    assert list(rows[0]) == [c.name for c in codebook.SESSIONS]
    new, *old = rows
    assert (new["robot"], new["robot_name"], new["kasparctl_version"]) == (
        "kaspar-lab-2", "Robin", "0.27.0")
    assert (new["correct_answers_to_learn"], new["reactions"], new["voice_rate"]) == (
        "3", "none", "90")
    assert (new["learner_alpha"], new["learner_beta"]) == ("0.3", "3.0")
    assert new["session_number"] == "1" and new["status"] == "finished"
    assert new["resumed"] == "0" and json.loads(new["settings"])["speed_scale"] == 0.5
    for row in old:
        assert row["robot"].startswith("robot-") and row["robot_name"] == "NA"
        assert row["kasparctl_version"] == "NA" and row["settings"] == "NA"
        assert row["learner_alpha"] == "0.6"  # frozen in plan.json already
    # The trials carry the join key and what a row needs on its own.
    by_session = {r["session"]: r for r in rows}
    for trial in rows_of(trials):
        session = by_session[trial["session"]]
        assert trial["robot_name"] == session["robot_name"]
        assert trial["learner_beta"] == session["learner_beta"]
        assert trial["session_number"] == session["session_number"]
    capsys.readouterr()
    assert main(["sessions", "--state-dir", str(new_and_old), "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed[0]["robot_name"] == "Robin" and listed[0]["learner_alpha"] == 0.3
    assert listed[1]["kasparctl_version"] is None and listed[1]["session_number"] == 1


# -- the bundle -----------------------------------------------------------------------------


def bundle(study: Study, out: Path, *extra: str) -> None:
    assert main(["export", "--state-dir", str(study.state_dir), "--bundle", str(out), *extra]) == 0


def test_the_bundle_is_anonymised_rekeyed_shifted_and_checksummed(
    study: Study, tmp_path: Path
) -> None:
    secret = tmp_path / "secret"
    secret.write_bytes(b"a secret the researcher keeps off the robot")
    out = tmp_path / "bundle"
    bundle(study, out, "--secret", str(secret), "--shift-dates")
    # Names: nowhere, not in the records, the CSVs or the plan.
    for path in out.rglob("*"):
        if path.is_file():
            text = path.read_text(encoding="utf-8")
            for name in CHILDREN:
                assert re.search(rf"\b{name}\b", text) is None, (path, name)
    # Ids: none of the robot's uids or session names is left.
    old = {json.loads((d / "plan.json").read_text())["uid"]: d.name
           for d in (study.state_dir / "sessions").iterdir() if (d / "plan.json").is_file()}
    everything = "".join(p.read_text() for p in out.rglob("*") if p.is_file())
    for uid, name in old.items():
        assert uid not in everything and name not in everything, name
    # The same new ids in the records, the trials and the sessions table.
    sessions = rows_of(out / "sessions.csv")
    copies = {json.loads((d / "plan.json").read_text())["uid"]
              for d in (out / "records" / "sessions").iterdir()}
    assert {r["session"] for r in sessions} == copies
    assert {r["session"] for r in rows_of(out / "trials.csv")} <= copies
    # Dates: moved back by whole weeks, the same shift everywhere.
    original = sorted(json.loads((d / "plan.json").read_text())["created"]
                      for d in (study.state_dir / "sessions").iterdir()
                      if (d / "plan.json").is_file())
    shifted = sorted(r["created"] for r in sessions)
    shifts = {dt.datetime.fromisoformat(a) - dt.datetime.fromisoformat(b)
              for a, b in zip(original, shifted, strict=True)}
    (shift,) = shifts
    assert shift.days % 7 == 0 and 7 <= shift.days <= 728 and shift.seconds == 0
    # The manifest checks every file.
    manifest = (out / "MANIFEST.sha256").read_text().splitlines()
    listed = {line.split("  ", 1)[1] for line in manifest}
    assert listed == {p.relative_to(out).as_posix() for p in out.rglob("*")
                      if p.is_file() and p.name != "MANIFEST.sha256"}
    for line in manifest:
        digest, name = line.split("  ", 1)
        assert hashlib.sha256((out / name).read_bytes()).hexdigest() == digest
    assert "records/" in "".join(listed) and "datapackage.json" in listed
    assert frictionless_validate(out / "datapackage.json").returncode == 0
    # The same secret re-keys alike: bundles of different days join.
    again = tmp_path / "again"
    bundle(study, again, "--secret", str(secret), "--shift-dates")
    assert {r["session"] for r in rows_of(again / "sessions.csv")} == copies
    assert "secret" not in {p.name for p in out.rglob("*")}


def test_the_bundle_reads_back_as_the_study_did(study: Study, tmp_path: Path) -> None:
    out = tmp_path / "bundle"
    bundle(study, out)
    trials = rows_of(out / "trials.csv")
    plain = tmp_path / "plain.csv"
    assert main(["export", "--state-dir", str(study.state_dir), "--csv", str(plain),
                 "--anonymise"]) == 0
    before = rows_of(plain)
    kept = ("trial", "target", "choice", "feedback", "entropy", "reaction_time", "child")
    assert [[r[k] for k in kept] for r in trials] == [[r[k] for k in kept] for r in before]
    assert [r["time"] for r in trials] == [r["time"] for r in before]  # no shift asked


def test_bundle_options_are_checked(study: Study, tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    short = tmp_path / "short"
    short.write_bytes(b"abc")
    code = main(["export", "--state-dir", str(study.state_dir), "--bundle", str(tmp_path / "b"),
                 "--secret", str(short)])
    assert code == 2 and "at least 16 bytes" in capsys.readouterr().err
    assert main(["export", "--state-dir", str(study.state_dir), "--shift-dates",
                 "--csv", str(tmp_path / "x.csv")]) == 2
    assert main(["export", "--state-dir", str(study.state_dir)]) == 2
