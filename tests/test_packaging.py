"""The package installs as the robot will get it: a wheel that carries its phrases."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_wheel_ships_the_phrases_and_every_package(tmp_path: Path) -> None:
    # Built from a copy: setuptools leaves a build/ directory behind, and building
    # in the checkout would both litter it and package stale files from earlier builds.
    source = tmp_path / "source"
    shutil.copytree(
        REPO,
        source,
        ignore=shutil.ignore_patterns(
            ".git", ".venv", "build", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis"
        ),
    )
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(source)],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("kasparctl-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "phrases/en.toml" in names
    # The remotes' profiles, read by every configuration's [keyfob] and [researcher].
    assert {f"hal/keyfob/remotes/{p.name}" for p in (REPO / "hal/keyfob/remotes").glob("*.toml")} <= names
    assert "hal/keyfob/remotes/logitech-r400.toml" in names
    assert {"kasparctl/learning/learner.py", "kasparctl/config/__init__.py", "kasparctl/config/schema.py", "hal/__init__.py"} <= names
    assert not any(name.startswith("tests/") for name in names)
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    assert "kasparctl = kasparctl.cli:main" in zipfile.ZipFile(wheel).read(entry_points).decode()


def test_python_dash_m_runs_the_command_line() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "kasparctl", "--version"], capture_output=True, text=True, check=True
    )
    assert result.stdout.startswith("kasparctl ")
