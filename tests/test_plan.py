"""`kasparctl plan`: counterbalanced designs as each robot's planned sessions, checked."""

from __future__ import annotations

import json
from collections import Counter
from itertools import pairwise
from pathlib import Path

import pytest

from kasparctl.cli import main
from kasparctl.config import ConfigError, load_config
from kasparctl.research.design import (
    Condition,
    Design,
    DesignError,
    balance,
    balanced_latin_square,
    group_codes,
    parse_condition,
    plan,
    sessions_toml,
)

FAST, SLOW = Condition("fast", "spoken"), Condition("slow", "spoken")
ROBOT = """sessions_file = "{file}"
[game]
variant = 'pilot'
locations = ['box']
[servos]
backend = 'sim'
[keyfob]
backend = 'sim'
[voice]
backend = 'sim'
"""


@pytest.mark.parametrize("k", [2, 3, 4, 5, 6])
def test_the_balanced_latin_square_puts_each_condition_in_each_position_and_after_each_other(
    k: int,
) -> None:
    rows = balanced_latin_square(k)
    assert len(rows) == (k if k % 2 == 0 else 2 * k)
    assert all(sorted(row) == list(range(k)) for row in rows)
    for position in range(k):
        assert Counter(row[position] for row in rows) == {c: len(rows) // k for c in range(k)}
    # Carry-over balance: each condition immediately follows each other equally often.
    follows = Counter(pair for row in rows for pair in pairwise(row))
    assert set(follows) == {(a, b) for a in range(k) for b in range(k) if a != b}
    assert set(follows.values()) == {1 if k % 2 == 0 else 2}


def test_twelve_groups_two_conditions_two_robots_within_is_balanced_every_way() -> None:
    result = plan(Design(group_codes(12), (FAST, SLOW), ("KasparA", "KasparB"), seed=26))
    for group in group_codes(12):
        mine = result.of_group(group)
        # Every group meets both conditions, once each, numbered 1 and 2, on both robots.
        assert [s.number for s in mine] == [1, 2]
        assert {s.condition for s in mine} == {FAST, SLOW}
        assert {s.robot for s in mine} == {"KasparA", "KasparB"}
    counts = balance(result)
    assert counts.by_position == {
        ("fast/spoken", 1): 6, ("fast/spoken", 2): 6, ("slow/spoken", 1): 6, ("slow/spoken", 2): 6
    }
    assert counts.by_robot == {
        ("fast/spoken", "KasparA"): 6, ("fast/spoken", "KasparB"): 6,
        ("slow/spoken", "KasparA"): 6, ("slow/spoken", "KasparB"): 6,
    }
    # Order and robot are crossed, not confounded: each (first condition, its robot) 3 times.
    firsts = Counter((s.condition, s.robot) for s in result.sessions if s.number == 1)
    assert set(firsts.values()) == {3} and len(firsts) == 4
    # Each robot's running order: every group's first session before any second one.
    for robot in ("KasparA", "KasparB"):
        numbers = [s.number for s in result.of_robot(robot)]
        assert numbers == sorted(numbers) and Counter(numbers) == {1: 6, 2: 6}


def test_three_conditions_use_six_orders_and_repeats_come_in_a_row() -> None:
    modes = (Condition("paper", "spoken"), Condition("paper", "none"), Condition("paper", "body"))
    result = plan(Design(group_codes(12), modes, ("K",), repeats=2, seed=3))
    counts = balance(result)
    assert set(counts.by_position.values()) == {4} and len(counts.by_position) == 9
    assert len(set(result.cells.values())) == 6
    for group in group_codes(12):
        mine = result.of_group(group)
        assert [s.number for s in mine] == [1, 2, 3, 4, 5, 6]
        conditions = [s.condition for s in mine]
        assert conditions[0::2] == conditions[1::2]  # each condition twice in a row
        assert set(conditions) == set(modes)


def test_between_groups_deals_each_group_one_condition_balanced_over_robots() -> None:
    result = plan(Design(group_codes(12), (FAST, SLOW), ("A", "B"), within=False, seed=1))
    assert all(len(result.of_group(g)) == 1 for g in group_codes(12))
    counts = balance(result)
    assert set(counts.by_robot.values()) == {3} and len(counts.by_robot) == 4
    assert counts.groups_by_robot == {"A": 6, "B": 6}


def test_robot_per_condition_and_robot_per_group() -> None:
    by_condition = plan(Design(group_codes(8), (FAST, SLOW), ("Fast", "Slow"),
                               robot_plan="condition", seed=5))  # fmt: skip
    assert all(s.robot == ("Fast" if s.condition == FAST else "Slow")
               for s in by_condition.sessions)  # fmt: skip
    by_group = plan(Design(group_codes(8), (FAST, SLOW), ("A", "B"), robot_plan="group", seed=5))
    for group in group_codes(8):
        assert len({s.robot for s in by_group.of_group(group)}) == 1
    assert balance(by_group).groups_by_robot == {"A": 4, "B": 4}
    assert set(balance(by_group).by_position.values()) == {4}


def test_the_seed_reproduces_the_plan_and_another_seed_deals_differently() -> None:
    def text(seed: int) -> str:
        result = plan(Design(group_codes(12), (FAST, SLOW), ("A", "B"), seed=seed))
        return sessions_toml(result, "A", [])

    assert text(7) == text(7)
    assert text(7) != text(8)


def test_a_design_that_cannot_be_planned_names_the_option() -> None:
    with pytest.raises(DesignError, match="--conditions: 'fast/loud': expected a mode"):
        parse_condition("fast/loud")
    assert parse_condition("paper/silent") == Condition("paper", "none")
    assert parse_condition("slow") == Condition("slow", None)
    with pytest.raises(DesignError, match="--robot-plan condition: expected one robot per"):
        Design(group_codes(4), (FAST, SLOW), ("A",), robot_plan="condition")
    with pytest.raises(DesignError, match="--conditions: expected at least two"):
        Design(group_codes(4), (FAST,), ("A",))
    with pytest.raises(DesignError, match=r"--robots: expected each robot .* 'a' twice"):
        Design(group_codes(4), (FAST, SLOW), ("A", "a"))
    with pytest.raises(DesignError, match="--robots: expected names"):
        Design(group_codes(4), (FAST, SLOW), ("../x",))


def _plan(tmp_path: Path, *extra: str) -> Path:
    out = tmp_path / "plan"
    argv = ["plan", "--groups", "12", "--conditions", "fast/spoken,slow/spoken",
            "--robots", "KasparA,KasparB", "--seed", "26", "--out", str(out), *extra]  # fmt: skip
    assert main(argv) == 0
    return out


def test_each_robots_file_is_its_sessions_and_check_accepts_the_robot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = _plan(tmp_path)
    printed = capsys.readouterr().out
    assert "Balanced: 12 groups, 3 in each of 4 cells" in printed
    assert f"KasparA: 12 sessions in {out / 'sessions-KasparA.toml'}" in printed
    planned: dict[str, set[tuple[str, int]]] = {}
    for robot in ("KasparA", "KasparB"):
        kaspar = tmp_path / f"{robot}.toml"
        kaspar.write_text(ROBOT.format(file=f"plan/sessions-{robot}.toml"))
        config = load_config(kaspar, playable=True)
        assert len(config.sessions) == 12
        assert Counter(p.condition for p in config.sessions) == {"fast/spoken": 6, "slow/spoken": 6}
        planned[robot] = {(p.group, p.number) for p in config.sessions}
        assert main(["check", "--config", str(kaspar), "--quiet"]) == 0
        expected = f"{kaspar} (12 planned sessions from {out / f'sessions-{robot}.toml'})"
        assert expected in capsys.readouterr().out
    # Together the two robots run each group's two sessions once each.
    assert not planned["KasparA"] & planned["KasparB"]
    assert planned["KasparA"] | planned["KasparB"] == {
        (g, n) for g in group_codes(12) for n in (1, 2)
    }
    # The seed is in the file: the command it names makes the same file.
    first = (out / "sessions-KasparA.toml").read_text()
    assert "--seed 26" in first
    _plan(tmp_path)
    assert (out / "sessions-KasparA.toml").read_text() == first


def test_a_sessions_file_is_held_to_kaspar_tomls_rules_naming_itself(tmp_path: Path) -> None:
    sessions = tmp_path / "s.toml"
    kaspar = tmp_path / "kaspar.toml"
    kaspar.write_text(ROBOT.format(file="s.toml"))
    sessions.write_text('[[sessions]]\ngroup = "G1"\nprofile = "quick"\n')
    with pytest.raises(ConfigError) as error:
        load_config(kaspar)
    assert error.value.source == str(sessions) and error.value.key == "sessions[0].profile"
    sessions.write_text('[[sessions]]\ngroup = "G1"\n[[sessions]]\ngroup = "G1"\n')
    with pytest.raises(ConfigError, match=r"s.toml: sessions\[1\].group: group code 'G1'"):
        load_config(kaspar)
    sessions.write_text('[[sessions]]\ngroup = "G1"\nnumbr = 2\n')
    with pytest.raises(ConfigError, match=r"s.toml: sessions\[0\].numbr"):
        load_config(kaspar)
    sessions.write_text('[game]\nseed = 3\n')
    with pytest.raises(ConfigError, match=r"s.toml: game: expected only \[\[sessions\]\] tables"):
        load_config(kaspar)
    sessions.write_text('[[sessions]]\ngroup = "G1"\n')
    kaspar.write_text(ROBOT.format(file="s.toml") + '[[sessions]]\ngroup = "G2"\n')
    with pytest.raises(ConfigError, match=r"kaspar.toml: sessions_file: expected the planned "
                       r"sessions in .* not both: found 1"):
        load_config(kaspar)
    kaspar.write_text(ROBOT.format(file="none.toml"))
    with pytest.raises(ConfigError, match=r"none.toml: \(file\): cannot read it"):
        load_config(kaspar)


def test_an_unknown_profile_or_no_groups_is_a_usage_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = str(tmp_path / "o")
    code = main(["plan", "--groups", "4", "--conditions", "quick,slow", "--robots", "A",
                 "--out", out])  # fmt: skip
    assert code == 2
    assert "--conditions: 'quick': expected a learner profile built in" in capsys.readouterr().err
    code = main(["plan", "--conditions", "fast,slow", "--robots", "A", "--out", out])
    assert code == 2 and "--groups: expected --groups N or --group-codes" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_groups_that_do_not_divide_into_the_cells_are_said_to(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = str(tmp_path / "o")
    assert main(["plan", "--group-codes", "a1,a2,a3", "--conditions", "paper/spoken,paper/none",
                 "--robots", "K", "--seed", "1", "--out", out]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    assert "Not exactly balanced: 3 groups over 2 cells" in printed
    assert "paper/none @ K" in printed
    text = (tmp_path / "o" / "sessions-K.toml").read_text()
    assert text.count("[[sessions]]") == 6 and 'uncertainty = "none"' in text


def test_the_demo_robot_plays_the_first_session_of_its_planned_file(tmp_path: Path) -> None:
    out = _plan(tmp_path)
    demo = (Path(__file__).resolve().parent.parent / "kasparctl" / "sim" / "demo.toml").read_text()
    own = '[[sessions]]\ngroup = "demo"\nprofile = "paper"\nspeak_uncertainty = true\n'
    assert own in demo
    kaspar = tmp_path / "demo-B.toml"
    kaspar.write_text('sessions_file = "plan/sessions-KasparB.toml"\n' + demo.replace(own, ""))
    first = load_config(kaspar).sessions[0]
    state = tmp_path / "state"
    assert main(["demo", "--config", str(kaspar), "--fast", "--seed", "1",
                 "--state-dir", str(state)]) == 0  # fmt: skip
    (plan_file,) = state.glob("sessions/*/plan.json")
    recorded = json.loads(plan_file.read_text())
    assert (recorded["group"], recorded["number"], recorded["condition"]) == (
        first.group, first.number, first.condition
    )
    # The one the file lists first: a group's first session, as the running order says.
    assert first.number == 1 and out.is_dir()


def test_the_robots_own_profiles_are_taken_with_config(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    kaspar = tmp_path / "kaspar.toml"
    kaspar.write_text("[learner.profiles.careful]\nalpha = 0.4\nbeta = 6.0\n")
    out = tmp_path / "o"
    argv = ["plan", "--groups", "4", "--conditions", "careful/spoken,paper/spoken", "--robots",
            "K", "--seed", "2", "--out", str(out)]  # fmt: skip
    assert main(argv) == 2
    assert "expected a learner profile built in" in capsys.readouterr().err
    assert main([*argv, "--config", str(kaspar)]) == 0
    assert 'profile = "careful"' in (out / "sessions-K.toml").read_text()
    assert f"--config {kaspar}" in (out / "sessions-K.toml").read_text()


def test_docs_studies_shows_what_the_command_prints(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = (Path(__file__).resolve().parent.parent / "docs" / "studies.md").read_text()
    shown = doc.split("The command above prints:\n\n```\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    assert main(["plan", "--groups", "12", "--conditions", "fast/spoken,slow/spoken",
                 "--robots", "KasparA,KasparB", "--seed", "26", "--out", "plan"]) == 0  # fmt: skip
    assert capsys.readouterr().out == shown
    head = doc.split("`plan/sessions-KasparA.toml` begins:\n\n```toml\n", 1)[1].split("...\n", 1)[0]
    assert (tmp_path / "plan" / "sessions-KasparA.toml").read_text().startswith(head)
