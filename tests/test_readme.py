"""The README shows the machine that runs, and the commands that work."""

from __future__ import annotations

from pathlib import Path

from kasparctl.game.diagram import mermaid

README = (Path(__file__).resolve().parents[1] / "README.md").read_text()


def test_readme_diagram_is_the_machines() -> None:
    assert f"```mermaid\n{mermaid()}```" in README


def test_readme_starts_with_the_two_commands() -> None:
    first_block = README.split("```sh", 1)[1].split("```", 1)[0]
    assert "kasparctl demo" in first_block
    assert "pytest" in first_block
