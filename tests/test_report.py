"""`kasparctl report`: figures that load, and the paper's numbers computed independently."""

from __future__ import annotations

import json
import statistics
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
from matplotlib.image import imread
from research_fixtures import Study, counted_trials, make_study, raw_records

from kasparctl.cli import main

FIGURES = ("entropy_by_trial", "final_q", "trials_to_learn", "feedback_by_child")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Study:
    return make_study(tmp_path_factory.mktemp("study"))


@pytest.fixture(scope="module")
def report(study: Study, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("report")
    assert main(["report", "--state-dir", str(study.state_dir), "--out", str(out)]) == 0
    return out


def expected_by_condition(study: Study) -> dict[str, dict[str, Any]]:
    """The paper's figures straight from the JSON lines, without kasparctl's statistics."""
    trials_by_label: dict[str, list[list[dict[str, Any]]]] = {}
    pairs_by_label: dict[str, list[tuple[dict[str, Any], dict[str, Any]]]] = {}
    sessions: dict[str, int] = {}
    for session_id, planned in study.planned.items():
        spoken = "spoken" if planned.speak_uncertainty else "silent"
        # The fixture mixes variants, so the variant is part of each label.
        label = f"{planned.profile}/{spoken} ({planned.variant})"
        sessions[label] = sessions.get(label, 0) + 1
        records = raw_records(study.state_dir / "sessions" / session_id)
        trials = counted_trials(records)
        problems: dict[int, list[dict[str, Any]]] = {}
        for trial in trials:
            problems.setdefault(trial["target_index"], []).append(trial)
        trials_by_label.setdefault(label, []).extend(problems.values())
        pairs_by_label.setdefault(label, []).extend(followed(records, trials))
    expected = {}
    for label, problems in trials_by_label.items():
        learned = [p for p in problems if p[-1]["learned"]]
        lengths = [len(p) for p in learned]
        pairs = pairs_by_label[label]
        trials = [t for p in problems for t in p]
        longest = max(len(p) for p in problems)
        expected[label] = {
            "sessions": sessions[label],
            "problems": len(problems),
            "problems_learned": len(learned),
            "trials_total": len(trials),
            "trials_mean": statistics.mean(lengths) if lengths else None,
            "trials_sd": statistics.stdev(lengths)
            if len(lengths) > 1
            else (0.0 if lengths else None),
            "trials_min": min(lengths, default=None),
            "trials_max": max(lengths, default=None),
            "first_guess_correct": sum(1 for p in problems if p[0]["correct"]),
            "perseverative_errors": sum(
                1 for a, b in pairs if a["feedback"] == "red" and b["choice"] == a["choice"]
            ),
            "win_shifts": sum(
                1 for a, b in pairs if a["feedback"] == "green" and b["choice"] != a["choice"]
            ),
            "initial_entropy": statistics.mean(p[0]["entropy"] for p in problems),
            "final_entropy_mean": (
                statistics.mean(p[-1]["entropy"] for p in learned) if learned else None
            ),
            "wrong_green": sum(1 for t in trials if t["feedback"] == "green" and not t["correct"]),
            "wrong_red": sum(1 for t in trials if t["feedback"] == "red" and t["correct"]),
            "entropy_by_trial": [
                statistics.mean(p[k]["entropy"] for p in problems if len(p) > k)
                for k in range(longest)
            ],
        }
    return expected


def followed(
    records: list[dict[str, Any]], counted: list[dict[str, Any]]
) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """Each counted trial with the one before it on its target, but the first after the
    researcher re-opened the target's name: the green that had taught it was taken back."""
    kept = {id(trial) for trial in counted}
    last: dict[int, dict[str, Any]] = {}
    pairs = []
    for record in records:
        if record["kind"] == "reopen" and not record.get("taken_back"):
            last.pop(record["target_index"], None)
        elif id(record) in kept:
            before = last.get(record["target_index"])
            if before is not None:
                pairs.append((before, record))
            last[record["target_index"]] = record
    return pairs


def test_summary_numbers_equal_those_computed_from_the_raw_records(
    study: Study, report: Path
) -> None:
    summary = json.loads((report / "summary.json").read_text())
    expected = expected_by_condition(study)
    found = {c["condition"]: c for c in summary["conditions"]}
    assert set(found) == set(expected)
    for label, numbers in expected.items():
        for key, value in numbers.items():
            assert found[label][key] == pytest.approx(value), (label, key)
    everything = summary["all"]
    assert everything["trials_total"] == sum(e["trials_total"] for e in expected.values())
    assert everything["problems"] == sum(e["problems"] for e in expected.values())
    assert everything["wrong_green"] == sum(e["wrong_green"] for e in expected.values()) > 0
    # The session stopped mid-problem and the one interrupted count in their conditions.
    assert everything["stopped"] == 1 and everything["interrupted"] == 1
    assert everything["undone"] == 1


def test_markdown_shows_the_conditions_side_by_side(study: Study, report: Path) -> None:
    text = (report / "summary.md").read_text()
    header = next(line for line in text.splitlines() if line.startswith("|  |"))
    labels = [cell.strip() for cell in header.strip("|").split("|")][1:]
    summary = json.loads((report / "summary.json").read_text())
    assert labels == [c["condition"] for c in summary["conditions"]] + ["all"]
    trials_row = next(line for line in text.splitlines() if line.startswith("| Trials |"))
    cells = [cell.strip() for cell in trials_row.strip("|").split("|")][1:]
    assert cells == [str(c["trials_total"]) for c in summary["conditions"]] + [
        str(summary["all"]["trials_total"])
    ]


def test_every_figure_is_written_and_loads(report: Path) -> None:
    for name in FIGURES:
        png = report / f"{name}.png"
        assert png.read_bytes()[:8] == PNG_SIGNATURE
        pixels = imread(png)
        assert pixels.ndim == 3 and pixels.shape[0] > 300 and pixels.shape[1] > 500, name
        # Not a blank canvas: something was drawn.
        assert pixels[..., :3].std() > 0.05, name
        assert (report / f"{name}.pdf").read_bytes().startswith(b"%PDF"), name
        # SVG only with --svg: the issue asks for PDF and PNG, and SVG cost a fifth of the time.
        assert not (report / f"{name}.svg").exists(), name
    summary = json.loads((report / "summary.json").read_text())
    assert summary["figures"] == list(FIGURES)
    # summary.md links the files that were written, and no others.
    text = (report / "summary.md").read_text()
    assert f"- [{FIGURES[0]}]({FIGURES[0]}.pdf) ([PNG]({FIGURES[0]}.png))\n" in text
    assert ".svg" not in text
    # No two conditions of the fixture differ in one factor with two groups each.
    assert [note.split(":")[0] for note in summary["notes"]] == ["contrasts"]


def test_svg_is_written_on_request_and_linked(study: Study, tmp_path: Path) -> None:
    out = tmp_path / "with-svg"
    assert main(["report", "--state-dir", str(study.state_dir), "--out", str(out), "--svg"]) == 0
    text = (out / "summary.md").read_text()
    for name in FIGURES:
        root = ET.parse(out / f"{name}.svg").getroot()
        assert root.tag == "{http://www.w3.org/2000/svg}svg"
        assert f"- [{name}]({name}.pdf) ([PNG]({name}.png)) ([SVG]({name}.svg))\n" in text


def test_one_condition_gets_one_column_and_one_panel(
    study: Study, report: Path, tmp_path: Path
) -> None:
    g1 = next(s for s, p in study.planned.items() if p.group == "G1")
    assert main(["report", g1, "--state-dir", str(study.state_dir), "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [c["condition"] for c in summary["conditions"]] == ["paper/spoken"]
    assert "| all |" not in (tmp_path / "summary.md").read_text()
    # The heat maps are side by side: five conditions make a wider figure than one, and
    # both stay within a page's 7.5 inches at 300 dpi.
    one = imread(tmp_path / "final_q.png").shape[1]
    five = imread(report / "final_q.png").shape[1]
    assert 1.5 * one < five <= 7.5 * 300


def test_without_matplotlib_the_error_names_the_extra(
    study: Study, tmp_path: Path, monkeypatch, capsys
) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    code = main(["report", "--state-dir", str(study.state_dir), "--out", str(tmp_path / "r")])
    assert code == 1
    assert "pip install 'kasparctl[report]'" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_the_robots_modules_do_not_import_matplotlib() -> None:
    import subprocess

    code = (
        "import sys, kasparctl.cli, kasparctl.commands.report, kasparctl.research.figures;"
        "kasparctl.cli.build_parser(); print('matplotlib' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
