"""`kasparctl demo`: a whole simulated group, narrated, reproducible from its seed."""

from __future__ import annotations

import json

import pytest

from kasparctl.cli import main


def run_demo(capsys: pytest.CaptureFixture[str], *options: str) -> tuple[list[str], dict[str, object]]:
    assert main(["demo", *options, "--json"]) == 0
    lines = capsys.readouterr().out.splitlines()
    return lines, json.loads(lines[-1])


@pytest.mark.parametrize("variant", ["names", "pilot"])
def test_demo_finishes_the_game_and_summarises_it(capsys, variant: str) -> None:
    lines, summary = run_demo(capsys, "--seed", "11", "--variant", variant)
    targets = 6 if variant == "names" else 3
    assert summary == {
        "session": "demo-11",
        "finished": True,
        "trials": summary["trials"],
        "learned": targets,
        "resumed": False,
    }
    presses = [line for line in lines if line.strip() in ("[green]", "[red]")]
    assert len(presses) == summary["trials"]
    # Every guess is preceded by the spoken uncertainty, with its entropy.
    assert sum(" bits: " in line for line in lines) == summary["trials"]
    assert summary["trials"] >= 2 * targets  # at least two correct answers per toy


def test_same_seed_same_game(capsys) -> None:
    first, _ = run_demo(capsys, "--seed", "5")
    second, _ = run_demo(capsys, "--seed", "5")
    third, _ = run_demo(capsys, "--seed", "6")
    assert first == second
    assert first != third


def test_silent_condition_says_no_uncertainty(capsys) -> None:
    lines, summary = run_demo(capsys, "--seed", "5", "--silent")
    assert summary["finished"] is True
    assert not any(" bits: " in line for line in lines)


def test_unknown_profile_is_named(capsys) -> None:
    assert main(["demo", "--profile", "turbo"]) == 1
    assert "--profile: unknown profile 'turbo'" in capsys.readouterr().err
