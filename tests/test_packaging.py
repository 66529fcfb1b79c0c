"""The package installs as the robot will get it: a wheel that carries its phrases."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_wheel_ships_the_phrases_and_every_package(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(REPO)],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("kasparctl-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "phrases/en.toml" in names
    assert {"kasparctl/learner.py", "kasparctl/config.py", "hal/__init__.py"} <= names
    assert not any(name.startswith("tests/") for name in names)
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    assert "kasparctl = kasparctl.cli:main" in zipfile.ZipFile(wheel).read(entry_points).decode()


def test_python_dash_m_runs_the_command_line() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "kasparctl", "--version"], capture_output=True, text=True, check=True
    )
    assert result.stdout.startswith("kasparctl ")
