"""`kasparctl demo` from the command line: the whole game, reproducible, summarised in JSON."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from kasparctl.cli import main


def demo(capsys: pytest.CaptureFixture[str], tmp_path: Path, *options: str) -> tuple[str, dict]:
    assert main(["demo", "--fast", "--json", "--state-dir", str(tmp_path), *options]) == 0
    out = capsys.readouterr().out
    return out, json.loads(out.strip().splitlines()[-1])


def test_demo_plays_a_whole_game_and_summarises_it(capsys, tmp_path: Path) -> None:
    out, summary = demo(capsys, tmp_path, "--seed", "3")
    assert summary["finished"] is True and summary["resumed"] is False
    assert summary["learned"] == 6 and summary["trials"] >= 12
    assert summary["state_dir"] == str(tmp_path)
    assert (tmp_path / "sessions" / summary["session"] / "records.jsonl").is_file()
    assert "Kaspar: " in out and "presses GREEN" in out and "Kaspar points at bag 1" in out


def test_same_seed_same_dialogue(capsys, tmp_path: Path) -> None:
    first, _ = demo(capsys, tmp_path / "a", "--seed", "8", "--variant", "pilot")
    second, _ = demo(capsys, tmp_path / "b", "--seed", "8", "--variant", "pilot")
    third, _ = demo(capsys, tmp_path / "c", "--seed", "9", "--variant", "pilot")
    dialogue = lambda text: [line for line in text.splitlines() if "Kaspar:" in line]  # noqa: E731
    assert dialogue(first) == dialogue(second)
    assert dialogue(first) != dialogue(third)


def test_children_who_make_mistakes_still_teach_kaspar(capsys, tmp_path: Path) -> None:
    _, summary = demo(
        capsys, tmp_path, "--seed", "2", "--variant", "pilot", "--p-wrong-green", "0.2"
    )
    assert summary["finished"] is True


def test_default_state_dir_is_new_and_named(capsys) -> None:
    assert main(["demo", "--fast", "--seed", "1", "--variant", "pilot"]) == 0
    out = capsys.readouterr().out
    named = re.search(r"Records: (\S+)", out)
    assert named and Path(named.group(1)).is_dir()


def test_bad_options_are_named(capsys, tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as usage:
        main(["demo", "--speed", "0"])
    assert usage.value.code == 2  # a usage error, as argparse's own
    assert "argument --speed: expected a number from 0.001 to 1e+06, found 0" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("[game]\nvariant = 'maze'\n")
    assert main(["demo", "--config", str(bad)]) == 1
    assert "game.variant: expected one of" in capsys.readouterr().err


def test_messy_children_give_no_command_and_the_summary_says_so(capsys, tmp_path: Path) -> None:
    _, summary = demo(
        capsys, tmp_path, "--seed", "4",
        "--p-hold", "0.3", "--p-double", "0.2", "--p-both", "0.2", "--p-early", "0.3",
    )  # fmt: skip
    assert summary["finished"] is True
    assert summary["accidental_commands"] == 0 and summary["answers_lost"] == 0
    assert 0 < summary["answer_to_next_question_s"] <= 10
    assert 0 < summary["speech_s_per_trial"] < 10


def test_a_messy_probability_outside_zero_to_one_is_refused(capsys) -> None:
    # A usage error, as every bad argument is: exit 2 with argparse's message.
    with pytest.raises(SystemExit) as exited:
        main(["demo", "--fast", "--p-double", "1.5"])
    assert exited.value.code == 2
    assert "argument --p-double: expected a number from 0 to 1, found 1.5" in capsys.readouterr().err
