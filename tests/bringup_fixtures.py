"""Robots for the bring-up commands' tests: configurations on simulated or emulated servos."""

from __future__ import annotations

from pathlib import Path

ROBOT = """\
# A test robot: one arm joint and the face.
poses_file = "poses.toml"

[keyfob]
backend = "sim"

[voice]
backend = "sim"

[game]
{game}

[servos]
backend = "{backend}"
control_hz = 50.0
poll_interval_s = 0.5

[[servos.buses]]
name = "body"
port = "{port}"
protocol = "herkulex"
baud = 115200
timeout_margin_ms = 100.0

[[servos.joints]]
name = "left_elbow"   # mirrored on the real robot; found by calibration
bus = "body"
id = 10
model = "drs-0101"
range_deg = [-5.0, 90.0]
rest_deg = 5.0
max_speed_dps = 60.0
group = "left_arm"

[[servos.joints]]
name = "smile"
bus = "body"
id = 6
model = "drs-0101"
range_deg = [-20.0, 20.0]
max_speed_dps = 60.0
group = "face"

[[servos.joints]]
name = "mouth_open"
bus = "body"
id = 5
model = "drs-0101"
range_deg = [-15.0, 15.0]
max_speed_dps = 30.0
group = "face"
"""


def robot(tmp_path: Path, backend: str = "sim", port: str = "/dev/kaspar-test",
          game: str = 'variant = "names"', poses: str | None = None) -> Path:
    """Write kaspar.toml (and poses.toml when given) in tmp_path; return the config's path."""
    path = tmp_path / "kaspar.toml"
    path.write_text(ROBOT.format(backend=backend, port=port, game=game))
    if poses is not None:
        (tmp_path / "poses.toml").write_text(poses)
    return path
