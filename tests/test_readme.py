"""The README shows the machine that runs, and the commands that work."""

from __future__ import annotations

import re
from pathlib import Path

from kasparctl.game.diagram import mermaid

README = (Path(__file__).resolve().parents[1] / "README.md").read_text()


def test_readme_diagram_is_the_machines() -> None:
    assert f"```mermaid\n{mermaid()}```" in README


def test_readme_starts_with_the_two_commands() -> None:
    first_block = README.split("```sh", 1)[1].split("```", 1)[0]
    assert "kasparctl demo" in first_block
    assert "pytest" in first_block


def test_ci_installs_what_the_readmes_test_command_does() -> None:
    """CI tests the machine the README promises: each package of its test command."""
    first_block = README.split("```sh", 1)[1].split("```", 1)[0]
    (test_line,) = [line for line in first_block.splitlines() if "pytest" in line]
    readme = set(re.search(r"apt-get install -y ([\w .-]+?) &&", test_line).group(1).split())  # type: ignore[union-attr]
    run = (Path(__file__).resolve().parents[1] / ".ci" / "run").read_text()
    ci = set(re.search(r"^needed=\((.*?)\)", run, re.M | re.S).group(1).split())  # type: ignore[union-attr]
    ci |= set(re.findall(r"needed\+=\(([\w.-]+)\)", run))  # what the Python in use lacks
    assert {"man-db", "tmux", "systemd"} <= readme
    assert readme <= ci, readme - ci
