"""The research toolkit: unique ids across robots, participants, errors attributed, inference.

Every expected number here is computed from the raw JSON lines, independently of
kasparctl's readers and statistics.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
import re
import statistics
import types
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest
from research_cohort import DIAGNOSIS, GROUPS, NAMES, Cohort, make_cohort

import kasparctl.game.session as session_module
from kasparctl.cli import main
from kasparctl.config import SessionPlan
from kasparctl.research.children import Feedback
from kasparctl.research.conditions import Condition, Factors, Problem
from kasparctl.research.inference import intervals
from kasparctl.research.participants import ParticipantsError, load_participants
from kasparctl.research.summary import percent
from kasparctl.sim.demo import DemoOptions, demo_config, run_demo


@pytest.fixture(scope="module")
def cohort(tmp_path_factory: pytest.TempPathFactory) -> Cohort:
    return make_cohort(tmp_path_factory.mktemp("cohort"))


@pytest.fixture(scope="module")
def coded_report(cohort: Cohort, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The report of the cohort with its participants.csv: made once for the tests that
    read it (each of them ran this same command into its own directory)."""
    out = tmp_path_factory.mktemp("coded-report")
    arguments = ["report", "--state-dir", str(cohort.state_dir), "--out", str(out)]
    assert main([*arguments, "--participants", str(cohort.participants)]) == 0
    return out


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="", encoding="utf-8") as stream:
        return list(csv.DictReader(stream))


def raw(state_dir: Path) -> dict[str, tuple[dict[str, Any], list[dict[str, Any]]]]:
    """uid -> (plan.json, records) read with the json module."""
    found = {}
    for directory in sorted((state_dir / "sessions").iterdir()):
        plan = json.loads((directory / "plan.json").read_text())
        records = [json.loads(line) for line in (directory / "records.jsonl").read_text().splitlines()]
        found[plan["uid"]] = (plan, records)
    return found


# -- unique ids ------------------------------------------------------------------------


class FrozenClock(dt.datetime):
    """Every session starts at the same second, as ten robots might."""

    @classmethod
    def now(cls, tz: dt.tzinfo | None = None) -> FrozenClock:  # type: ignore[override]
        return cls(2026, 3, 2, 9, 41, 7, 118000, tzinfo=dt.UTC)


def test_ten_sessions_started_together_are_ten_sessions_in_one_pooled_export(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ten demo robots start a session in the same second with the same group code."""
    monkeypatch.setattr(session_module, "dt", types.SimpleNamespace(datetime=FrozenClock, UTC=dt.UTC))
    config = msgspec.structs.replace(demo_config(), sessions=(SessionPlan(group="G1"),))
    state_dirs = [tmp_path / f"robot{index}" for index in range(10)]
    for index, state_dir in enumerate(state_dirs):
        run_demo(config, DemoOptions(state_dir=state_dir, seed=index, out=io.StringIO()), fast=True)
    pooled = [argument for d in state_dirs for argument in ("--state-dir", str(d))]
    out = tmp_path / "trials.csv"
    assert main(["export", *pooled, "--csv", str(out)]) == 0
    rows = read_csv(out)
    # The readable id is the same for all ten: it was never unique.
    assert {r["session_name"] for r in rows} == {"20260302T094107-G1"}
    assert len({r["session"] for r in rows}) == 10
    by_session: dict[str, list[dict[str, str]]] = {}
    for row in rows:
        by_session.setdefault(row["session"], []).append(row)
    for trials in by_session.values():
        # Each session's trials are numbered 1, 2, ... on their own: no two games merged.
        assert [int(r["trial"]) for r in trials] == list(range(1, len(trials) + 1))
    capsys.readouterr()
    assert main(["sessions", *pooled, "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert len({row["session"] for row in listed}) == 10
    report = tmp_path / "report"
    assert main(["report", *pooled, "--out", str(report)]) == 0
    summary = json.loads((report / "summary.json").read_text())
    assert len(set(summary["sessions"])) == 10 == summary["all"]["sessions"]
    # A readable id that is in ten state directories names none of them; the uid does.
    uid = listed[3]["session"]
    assert main(["export", "20260302T094107-G1", *pooled, "--csv", str(out)]) == 1
    assert "is in 10 state directories" in capsys.readouterr().err
    assert main(["export", uid, *pooled, "--csv", str(out)]) == 0
    assert {r["session"] for r in read_csv(out)} == {uid}


def test_the_same_session_in_two_state_directories_counts_once(
    cohort: Cohort, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(cohort.state_dir, copy)
    out = tmp_path / "t.csv"
    assert main(["export", "--state-dir", str(cohort.state_dir), "--state-dir", str(copy), "--csv", str(out)]) == 0
    assert "counted once" in capsys.readouterr().err
    assert len({r["session"] for r in read_csv(out)}) == 8


# -- participants ----------------------------------------------------------------------


def test_every_trial_names_the_participant_who_answered(cohort: Cohort, tmp_path: Path) -> None:
    out = tmp_path / "t.csv"
    arguments = ["export", "--state-dir", str(cohort.state_dir), "--csv", str(out)]
    assert main([*arguments, "--participants", str(cohort.participants)]) == 0
    rows = read_csv(out)
    attributes = {r["code"]: r for r in read_csv(cohort.participants)}
    for uid, (plan, records) in raw(cohort.state_dir).items():
        codes = plan["plan"]["participants"]
        trials = [r for r in records if r["kind"] == "trial"]
        mine = [r for r in rows if r["session"] == uid]
        assert len(mine) == len(trials)
        for row, trial in zip(mine, trials, strict=True):
            code = codes[trial["child_index"]]
            assert row["participant"] == code
            assert row["participant_group"] == attributes[code]["group"]
            assert float(row["participant_age"]) == float(attributes[code]["age"])
            assert row["participant_sex"] == attributes[code]["sex"]
            assert row["participant_group"] == DIAGNOSIS[row["group"]]


def test_anonymised_exports_keep_the_codes_and_lose_the_names(cohort: Cohort, tmp_path: Path) -> None:
    trials, events = tmp_path / "t.csv", tmp_path / "e.csv"
    arguments = ["export", "--state-dir", str(cohort.state_dir), "--csv", str(trials), "--events", str(events)]
    assert main([*arguments, "--anonymise"]) == 0
    assert {r["participant"] for r in read_csv(trials)} == {c for codes in GROUPS.values() for c in codes}
    for path in (trials, events):
        text = path.read_text()
        for name in NAMES:
            assert re.search(rf"\b{name}\b", text) is None


def test_prompts_extra_presses_and_undos_name_their_child(cohort: Cohort, tmp_path: Path) -> None:
    events = tmp_path / "e.csv"
    assert main(["export", "--state-dir", str(cohort.state_dir), "--csv", str(tmp_path / "t.csv"), "--events", str(events)]) == 0
    rows = read_csv(events)
    prompts = [r for r in rows if r["kind"] == "prompt"]
    assert prompts and all(r["participant"] for r in prompts)
    for uid, (plan, records) in raw(cohort.state_dir).items():
        codes = plan["plan"]["participants"]
        mine = [r for r in rows if r["session"] == uid and r["kind"] == "prompt"]
        # The prompt is followed by the answer of the child it prompted.
        expected = []
        for index, record in enumerate(records):
            if record["kind"] == "prompt":
                answer = next(r for r in records[index:] if r["kind"] == "trial")
                expected.append(codes[answer["child_index"]])
        assert [r["participant"] for r in mine] == expected


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "line 1: expected a header with a 'code' column, found nothing"),
        ("id,group\nP01,ASC\n", "line 1: expected a 'code' column (the participants' codes), found id, group"),
        ("code,age (y)\nP01,7\n", "line 1, column 2: expected a column name (a letter, then letters, digits or '_'), found 'age (y)'"),
        ("code,group,group\n", "line 1: expected distinct column names, found 'group' more than once"),
        ("code,group\nP01,ASC\nP02\n", "line 3: expected 2 fields (code, group), found 1"),
        ("code,group\nP01,ASC\n=cmd,TD\n", "line 3, column code: expected a code (1 to 32 letters, digits, '-' or '_', first a letter or digit), found '=cmd'"),
        ("code,group\nP01,ASC\n\nP01,TD\n", "line 4, column code: expected each code once, found 'P01' again (first on line 2)"),
        ("code,age\nP01,7\nP02,seven\n", "line 3, column age: expected a number from 0 to 120, found 'seven'"),
        ("code,age\nP01,700\n", "line 2, column age: expected a number from 0 to 120, found '700'"),
        ("code,score\nP01,12\nP02,high\n", "line 3, column score: expected a number (the column's first value is one), found 'high'"),
        (b"code,group\nP01,A\xffSC\n", "line 2: expected UTF-8 text, found the byte 0xff"),
        ('code,group\nP01,"ASC\n', "line 2: not CSV (unexpected end of data)"),
    ],
)
def test_a_bad_participants_file_is_named_exactly(tmp_path: Path, text: str | bytes, message: str) -> None:
    path = tmp_path / "participants.csv"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ParticipantsError) as caught:
        load_participants(path)
    assert str(caught.value) == f"{path}: {message}"


def test_participants_file_errors_stop_the_command_before_writing(
    cohort: Cohort, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "p.csv"
    bad.write_text("code,group\nP01\n")
    out = tmp_path / "t.csv"
    assert main(["export", "--state-dir", str(cohort.state_dir), "--csv", str(out), "--participants", str(bad)]) == 1
    assert f"error: {bad}: line 2: expected 2 fields" in capsys.readouterr().err
    assert not out.exists()


def test_codes_missing_from_the_participants_file_are_warned(
    cohort: Cohort, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    partial = tmp_path / "p.csv"
    partial.write_text("\n".join(cohort.participants.read_text().splitlines()[:-2]) + "\n")
    out = tmp_path / "t.csv"
    assert main(["export", "--state-dir", str(cohort.state_dir), "--csv", str(out), "--participants", str(partial)]) == 0
    assert "no row for P11, P12" in capsys.readouterr().err
    assert {r["participant_group"] for r in read_csv(out) if r["participant"] == "P12"} == {"NA"}


# -- errors attributed -----------------------------------------------------------------


def expected_causes(records: list[dict[str, Any]]) -> dict[int, str]:
    """Trial number -> cause, from the children's previous counted answer on the target."""
    undone = {r["trial"] for r in records if r["kind"] == "undo"}
    last: dict[int, bool] = {}
    causes = {}
    for record in records:
        if record["kind"] != "trial":
            continue
        if record["perseverative"] or record["win_shift"]:
            right = last.get(record["target_index"])
            causes[record["trial"]] = "exploratory" if right else "after_wrong_feedback"
        if record["trial"] not in undone:
            last[record["target_index"]] = record["feedback_right"]
    return causes


def test_each_perseverative_error_and_win_shift_has_its_cause(cohort: Cohort, tmp_path: Path) -> None:
    out = tmp_path / "t.csv"
    assert main(["export", "--state-dir", str(cohort.state_dir), "--csv", str(out)]) == 0
    rows = read_csv(out)
    seen = set()
    for uid, (_, records) in raw(cohort.state_dir).items():
        causes = expected_causes(records)
        for row in (r for r in rows if r["session"] == uid):
            assert row["error_cause"] == causes.get(int(row["trial"]), "NA")
            seen.add(row["error_cause"])
    # The cohort's children err: both causes occur.
    assert {"exploratory", "after_wrong_feedback"} <= seen


def test_the_summary_counts_errors_by_cause(cohort: Cohort, tmp_path: Path) -> None:
    assert main(["report", "--state-dir", str(cohort.state_dir), "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())["all"]
    counts = {"perseverative": {}, "win_shift": {}}
    for _, records in raw(cohort.state_dir).values():
        causes = expected_causes(records)
        undone = {r["trial"] for r in records if r["kind"] == "undo"}
        for record in records:
            if record["kind"] == "trial" and record["trial"] not in undone:
                for kind in counts:
                    if record[kind]:
                        cause = causes[record["trial"]]
                        counts[kind][cause] = counts[kind].get(cause, 0) + 1
    assert summary["perseverative_after_wrong_feedback"] == counts["perseverative"].get("after_wrong_feedback", 0)
    assert summary["perseverative_exploratory"] == counts["perseverative"].get("exploratory", 0)
    assert summary["win_shifts_after_wrong_feedback"] == counts["win_shift"].get("after_wrong_feedback", 0)
    assert summary["win_shifts_exploratory"] == counts["win_shift"].get("exploratory", 0)
    assert summary["perseverative_errors"] == sum(counts["perseverative"].values())


# -- per-child measures ----------------------------------------------------------------


def test_children_csv_holds_each_participants_teaching(cohort: Cohort, coded_report: Path) -> None:
    children = {row["participant"]: row for row in read_csv(coded_report / "children.csv")}
    expected: dict[str, dict[str, Any]] = {}
    for _, (plan, records) in raw(cohort.state_dir).items():
        codes = plan["plan"]["participants"]
        undone = {r["trial"] for r in records if r["kind"] == "undo"}
        prompted = []
        for index, record in enumerate(records):
            if record["kind"] == "prompt":
                answer = next(r for r in records[index:] if r["kind"] == "trial")
                prompted.append(codes[answer["child_index"]])
        for code in prompted:
            expected.setdefault(code, {}).setdefault("prompts", 0)
            expected[code]["prompts"] += 1
        for record in records:
            if record["kind"] != "trial" or record["trial"] in undone:
                continue
            mine = expected.setdefault(codes[record["child_index"]], {})
            mine.setdefault("times", []).append(record["reaction_time"])
            mine["answers"] = mine.get("answers", 0) + 1
            wrong_green = record["feedback"] == "green" and not record["correct"]
            wrong_red = record["feedback"] == "red" and record["correct"]
            mine["false_greens"] = mine.get("false_greens", 0) + wrong_green
            mine["false_reds"] = mine.get("false_reds", 0) + wrong_red
            mine["wrong_guesses"] = mine.get("wrong_guesses", 0) + (not record["correct"])
    assert set(children) == set(expected)
    for code, numbers in expected.items():
        row = children[code]
        assert int(row["answers"]) == numbers["answers"]
        assert int(row["false_greens"]) == numbers["false_greens"]
        assert int(row["false_reds"]) == numbers["false_reds"]
        assert int(row["prompts"]) == numbers.get("prompts", 0)
        assert float(row["reaction_time_median"]) == pytest.approx(statistics.median(numbers["times"]))
        if numbers["wrong_guesses"]:
            assert float(row["false_green_rate"]) == pytest.approx(numbers["false_greens"] / numbers["wrong_guesses"])
        group = next(g for g, codes in GROUPS.items() if code in codes)
        assert row["participant_group"] == DIAGNOSIS[group]
        assert int(row["sessions"]) == 2  # every group played twice


# -- inference -------------------------------------------------------------------------


def test_intervals_rest_on_the_groups_and_cover_the_estimate(coded_report: Path) -> None:
    summary = json.loads((coded_report / "summary.json").read_text())
    assert summary["intervals"]["unit"] == "group"
    for condition in summary["conditions"]:
        assert condition["clusters"] == 4
        for name, estimate in condition["intervals"].items():
            if estimate["value"] is None or estimate["low"] is None:
                continue
            assert estimate["low"] <= estimate["value"] + 1e-12, name
            assert estimate["value"] <= estimate["high"] + 1e-12, name
            assert estimate["clusters"] == 4
        lows, highs = condition["entropy_by_trial_low"], condition["entropy_by_trial_high"]
        assert len(lows) == len(highs) == len(condition["entropy_by_trial"])


def test_contrasts_compare_the_uncertainty_modes_and_the_participants_groups(
    coded_report: Path,
) -> None:
    summary = json.loads((coded_report / "summary.json").read_text())
    factors = {(c["factor"], c["a"], c["b"]) for c in summary["contrasts"]}
    assert ("uncertainty mode", "paper/spoken", "paper/silent") in factors
    assert ("participant group", "ASC", "TD") in factors
    assert ("participant sex", "F", "M") in factors
    spoken = {c["condition"]: c for c in summary["conditions"]}
    for contrast in summary["contrasts"]:
        if contrast["factor"] == "uncertainty mode" and contrast["measure"] == "trials_mean":
            a = spoken["paper/spoken"]["trials_mean"]
            b = spoken["paper/silent"]["trials_mean"]
            assert contrast["difference"] == pytest.approx(a - b)
            assert contrast["difference_low"] <= contrast["difference"] <= contrast["difference_high"]
            assert contrast["hedges_g"] is not None and contrast["hedges_g_low"] is not None
        if contrast["factor"] == "participant group":
            # Children are nested in groups: two groups a side, so no interval (below MIN_CLUSTERS).
            assert (contrast["clusters_a"], contrast["clusters_b"], contrast["unit"]) == (2, 2, "group")
            assert contrast["difference_low"] is None and contrast["p"] is None
    text = (coded_report / "summary.md").read_text()
    assert "## Contrasts" in text and "| uncertainty mode | paper/spoken - paper/silent |" in text
    assert "contrasts" in summary["figures"]


def problem(cluster: str, trials: int) -> Problem:
    from kasparctl.learning.study_stats import ProblemRecord, TrialRecord

    guesses = tuple(TrialRecord(0, t == trials - 1, 1.0, None) for t in range(trials))
    return Problem(("a", "b"), ProblemRecord(0, 0, None, guesses, 0, (0.0, 0.0), 0.0, 2), cluster)


def condition_of(problems: list[Problem]) -> Condition:
    condition = Condition("c", Factors("paper", "spoken", "pilot"), problems=problems)
    condition.feedback_by_cluster = {p.cluster: Feedback() for p in problems}
    return condition


def test_the_unit_of_an_interval_is_the_cluster_not_the_trial() -> None:
    """Copying every problem of each group ten times adds no information about groups:
    a trial- or problem-level bootstrap would narrow the interval, the cluster bootstrap
    gives the very same one."""
    lengths = {"g1": [2, 3, 6], "g2": [4, 4, 5], "g3": [2, 7, 3], "g4": [5, 2, 2]}
    once = [problem(c, n) for c, ns in lengths.items() for n in ns]
    tenfold = [problem(c, n) for c, ns in lengths.items() for n in ns for _ in range(10)]
    a = intervals(condition_of(once), 2000, 0).measures["trials_mean"]
    b = intervals(condition_of(tenfold), 2000, 0).measures["trials_mean"]
    assert (a.value, a.low, a.high) == pytest.approx((b.value, b.low, b.high))
    assert a.clusters == b.clusters == 4
    # One cluster: an estimate, no interval.
    single = intervals(condition_of([problem("g1", n) for n in (2, 3, 6)]), 500, 0)
    assert single.measures["trials_mean"].low is None


def test_rates_are_shown_to_a_tenth_of_a_percent() -> None:
    assert percent(1 / 440) == "0.2 %"
    assert percent(0.0) == "0.0 %"
    assert percent(37.5 / 100) == "37.5 %"


def test_the_report_is_reproducible(cohort: Cohort, tmp_path: Path) -> None:
    for name in ("a", "b"):
        # SVG on request: its text is the figure's, so equal bytes mean an equal figure.
        assert main(["report", "--state-dir", str(cohort.state_dir), "--out", str(tmp_path / name), "--svg"]) == 0
    for file in ("summary.json", "summary.md", "children.csv", "entropy_by_trial.svg"):
        assert (tmp_path / "a" / file).read_bytes() == (tmp_path / "b" / file).read_bytes(), file
    assert main(["report", "--state-dir", str(cohort.state_dir), "--out", str(tmp_path / "c"), "--seed", "5"]) == 0
    assert (tmp_path / "a" / "summary.json").read_bytes() != (tmp_path / "c" / "summary.json").read_bytes()


def test_a_cluster_bootstrap_interval_covers_the_truth_about_95_percent_of_the_time() -> None:
    """Simulated groups with a known mean: the interval's coverage is near its level."""
    rng = np.random.default_rng(3)
    covered = 0
    runs = 300
    for _ in range(runs):
        problems = []
        for g in range(12):
            offset = int(rng.integers(0, 3))  # groups differ: trials within a group correlate
            problems += [problem(f"g{g}", 2 + offset + int(rng.integers(0, 3))) for _ in range(3)]
        estimate = intervals(condition_of(problems), 400, int(rng.integers(1 << 30))).measures["trials_mean"]
        # The true mean: 2 + E[offset] (1) + E[extra] (1).
        covered += estimate.low <= 4.0 <= estimate.high
    # A percentile interval over 12 clusters covers a little less than its 95 %.
    assert 0.85 <= covered / runs <= 0.99
