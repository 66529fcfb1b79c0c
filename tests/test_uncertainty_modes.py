"""The session plan's uncertainty mode: read from old and new configurations, recorded in
plan.json and on every exported row, and compared side by side in the report."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from kasparctl.cli import main
from kasparctl.config import ConfigError, parse_config
from kasparctl.research.catalogue import load_session

V1_STATE = Path(__file__).resolve().parent / "data" / "sessions-v1" / "state"


def plans(text: str) -> list[tuple[str, str, bool]]:
    config = parse_config(text, "kaspar.toml")
    return [(p.uncertainty_mode, p.condition, p.says_uncertainty) for p in config.sessions]


def test_speak_uncertainty_maps_onto_spoken_and_none() -> None:
    text = """
[[sessions]]
group = "A"
speak_uncertainty = true
[[sessions]]
group = "B"
speak_uncertainty = false
[[sessions]]
group = "C"
"""
    assert plans(text) == [
        ("spoken", "paper/spoken", True),
        ("none", "paper/silent", False),  # "silent" as before modes: old and new pool
        ("spoken", "paper/spoken", True),
    ]


def test_each_mode_by_its_own_key_and_the_old_key_beside_it_when_they_agree() -> None:
    text = "".join(
        f'[[sessions]]\ngroup = "G{i}"\nuncertainty = "{mode}"\n{extra}'
        for i, (mode, extra) in enumerate(
            [
                ("spoken", ""),
                ("body", ""),
                ("both", "speak_uncertainty = true\n"),
                ("none", "speak_uncertainty = false\n"),
                ("body", "speak_uncertainty = false\n"),
            ]
        )
    )
    assert plans(text) == [
        ("spoken", "paper/spoken", True),
        ("body", "paper/body", False),
        ("both", "paper/both", True),
        ("none", "paper/silent", False),
        ("body", "paper/body", False),
    ]


@pytest.mark.parametrize(
    ("mode", "spoken", "agreeing"),
    [("body", "true", "false"), ("none", "true", "false"), ("spoken", "false", "true"),
     ("both", "false", "true")],
)
def test_the_old_key_that_disagrees_is_an_exact_error(mode: str, spoken: str, agreeing: str) -> None:
    text = f'[[sessions]]\ngroup = "A"\nuncertainty = "{mode}"\nspeak_uncertainty = {spoken}\n'
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "kaspar.toml")
    assert str(caught.value) == (
        f"kaspar.toml: sessions[0].speak_uncertainty: expected {agreeing} to agree with "
        f"uncertainty = '{mode}' (or leave it out: uncertainty says it all), found {spoken}"
    )


def test_an_unknown_mode_names_the_modes() -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config('[[sessions]]\ngroup = "A"\nuncertainty = "loud"\n', "kaspar.toml")
    assert str(caught.value) == (
        "kaspar.toml: sessions[0].uncertainty: expected one of 'spoken', 'body', 'both', "
        "'none', found 'loud'"
    )
    with pytest.raises(ConfigError) as caught:
        parse_config('[[sessions]]\ngroup = "A"\nspeak_uncertainty = "yes"\n', "kaspar.toml")
    assert str(caught.value) == (
        "kaspar.toml: sessions[0].speak_uncertainty: expected bool, found str"
    )


def test_old_sessions_read_with_the_mapping() -> None:
    for directory in sorted((V1_STATE / "sessions").iterdir()):
        session = load_session(directory)
        assert session.uncertainty == "spoken" and session.speak_uncertainty
        assert session.condition == "paper/spoken"


# -- a demo session in each mode, exported and reported side by side -------------------

MODES = ("spoken", "body", "both", "none")


@pytest.mark.live_body  # the must-show: each mode with the body as configured
def test_a_demo_in_each_mode_exported_and_reported_side_by_side(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    state = tmp_path / "state"
    for mode in MODES:
        assert main(["demo", "--fast", "--seed", "5", "--uncertainty", mode,
                     "--state-dir", str(state)]) == 0
    out = capsys.readouterr().out
    assert "(Kaspar tilts its head, thinking" in out and "(Kaspar nods)" in out
    sessions = sorted((state / "sessions").iterdir())
    planned = [json.loads((s / "plan.json").read_text()) for s in sessions]
    assert [p["uncertainty"] for p in planned] == list(MODES)
    assert [p["plan"]["uncertainty"] for p in planned] == list(MODES)
    assert [p["plan"]["speak_uncertainty"] for p in planned] == [True, False, True, False]

    trials, events = tmp_path / "trials.csv", tmp_path / "events.csv"
    assert main(["export", "--state-dir", str(state), "--csv", str(trials),
                 "--events", str(events)]) == 0
    for path in (trials, events):
        with path.open(newline="") as stream:
            rows = list(csv.DictReader(stream))
        by_session = {row["session_name"]: row["uncertainty"] for row in rows}
        assert sorted(by_session.values()) == sorted(MODES)
        assert all(row["uncertainty"] in MODES for row in rows)  # on every row
    with trials.open(newline="") as stream:
        rows = list(csv.DictReader(stream))
    for row in rows:
        assert row["condition"] == {
            "spoken": "paper/spoken", "body": "paper/body", "both": "paper/both",
            "none": "paper/silent",
        }[row["uncertainty"]]
        # The line is said only where the mode says it.
        assert (row["band"] != "NA") == (row["uncertainty"] in ("spoken", "both"))

    report = tmp_path / "report"
    assert main(["report", "--state-dir", str(state), "--out", str(report),
                 "--bootstrap", "200"]) == 0
    summary = json.loads((report / "summary.json").read_text())
    modes = summary["uncertainty_modes"]
    assert [m["uncertainty"] for m in modes] == list(MODES)
    per_mode_trials = {m["uncertainty"]: m["trials_total"] for m in modes}
    assert per_mode_trials == {
        mode: sum(1 for row in rows if row["uncertainty"] == mode and row["undone"] == "FALSE")
        for mode in MODES
    }
    text = (report / "summary.md").read_text()
    table = text[text.index("## Uncertainty modes"):].split("\n\n")[2].splitlines()
    assert table[0] == "|  | spoken | body | both | none |"
    assert table[2] == "| Conditions | paper/spoken | paper/body | paper/both | paper/silent |"
    assert any(line.startswith("| Trials to learn, mean ± sd |") for line in table)
    assert any(line.startswith("| Reaction time, median (s) |") for line in table)
    contrasts = {(c["factor"], c["a"], c["b"]) for c in summary["contrasts"]}
    assert ("uncertainty mode", "paper/spoken", "paper/silent") in contrasts
    assert ("uncertainty mode", "paper/both", "paper/body") in contrasts
