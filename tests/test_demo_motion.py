"""What the body did in a game: `kasparctl demo --motion` and the voice the mouth follows.

The demo robot's live body (the test is marked live_body), the simulated voice's syllables
or espeak-ng's real sound, every goal each joint received read back from the CSV.
"""

from __future__ import annotations

import csv
import itertools
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from hal.voice.envelope import wav_levels
from kasparctl.cli import main
from kasparctl.sim.demo import demo_config

pytestmark = pytest.mark.live_body
CONFIG = demo_config()
MOUTH = CONFIG.body.mouth_joint
ARM = set(CONFIG.servos.groups[CONFIG.game.pointing_group])


@dataclass(frozen=True)
class Row:
    time: float
    joint: str
    degrees: float
    source: str


def demo_with_motion(capsys, tmp_path: Path, *options: str) -> tuple[list[Row], str]:
    motion = tmp_path / "motion.csv"
    assert main(["demo", "--fast", "--seed", "1", "--state-dir", str(tmp_path / "state"),
                 "--motion", str(motion), *options]) == 0
    out = capsys.readouterr().out
    with motion.open(encoding="utf-8", newline="") as file:
        reader = csv.reader(file)
        assert next(reader) == ["time_s", "joint", "position_deg", "source"]
        rows = [Row(float(t), joint, float(d), source) for t, joint, d, source in reader]
    return rows, out


def first_point(rows: list[Row]) -> tuple[float, float]:
    """The first point's first and last goals' times (a plain point: one move)."""
    times = [row.time for row in rows if row.source == "point"]
    begin = times[0]
    return begin, max(t for t in times if t - begin < 2.0)


def line_at(out: str, moment: float) -> str:
    """The line Kaspar began at `moment` (the transcript's clock, to the millisecond)."""
    for stamp, text in re.findall(r"\[\s*([\d.]+)\] Kaspar: (.*)", out):
        if abs(float(stamp) - moment) < 0.002:
            return text
    raise AssertionError(f"no line at {moment}")


def test_the_mouth_says_the_uncertainty_line_while_the_arm_points(capsys, tmp_path):
    rows, out = demo_with_motion(capsys, tmp_path)
    begin, end = first_point(rows)
    # The uncertainty line starts with the point (the plan says it: spoken).
    assert line_at(out, begin) in ("I have no idea.", "I am not sure.", "I think I know.")
    assert f"[{begin:10.3f}]   (Kaspar points at bag" in out
    point = [row for row in rows if begin <= row.time <= end]
    assert {row.joint for row in point if row.source == "point"} == ARM
    mouth = [row.degrees for row in point if row.joint == MOUTH]
    assert {row.source for row in point if row.joint == MOUTH} == {"mouth"}
    assert len(mouth) >= 25  # at 50 Hz, through most of the point's second
    travel = sum(abs(b - a) for a, b in itertools.pairwise(mouth))
    assert travel > 30.0 and max(mouth) - min(mouth) > 5.0  # it opens and closes, syllables
    # The head turned to the bag meanwhile, and the arm's goals are the point's alone.
    assert any(row.joint == "head_yaw" and row.source == "gaze" for row in point)
    assert {row.source for row in point if row.joint in ARM} == {"point"}



def points(rows: list[Row]) -> list[tuple[float, float]]:
    """Every point's first and last goal times (its goals come 20 ms apart)."""
    times = [row.time for row in rows if row.source == "point"]
    spans, begin = [], times[0]
    for before, after in itertools.pairwise(times):
        if after - before > 0.5:
            spans.append((begin, before))
            begin = after
    return [*spans, (begin, times[-1])]


def test_the_eyelids_blink_on_while_the_arm_points_and_the_head_holds_the_bag(capsys, tmp_path):
    rows, _ = demo_with_motion(capsys, tmp_path)
    spans = points(rows)
    assert len(spans) >= 15
    # From the point's first goal on (a body tick at that very moment came before it).
    during = [row for row in rows if any(a < row.time <= b for a, b in spans)]
    blinks = {round(row.time) for row in during if row.source == "blink"}
    assert len(blinks) >= 3  # blinks fall in several points, at the body's own rate
    # No idle movement of the head meanwhile: it holds the bag Kaspar looked at.
    assert not [row for row in during if row.source == "idle"]

def test_every_goal_of_a_game_is_in_range_and_within_the_speed_limits(capsys, tmp_path):
    rows, _ = demo_with_motion(capsys, tmp_path, "--uncertainty", "both")
    joints = {joint.name: joint for joint in CONFIG.servos.joints}
    step = 1.0 / CONFIG.servos.control_hz
    sources = {row.source for row in rows}
    assert {"torque_on", "point", "mouth", "blink", "gaze", "gesture:thinking"} <= sources
    for name, joint in joints.items():
        mine = [row for row in rows if row.joint == name]
        unit = joint.servo.degrees_per_unit
        low, high = joint.range_deg
        assert all(low - unit <= row.degrees <= high + unit for row in mine), name
        # Each goal is reached within its packet's time: a control step for a move's, the
        # time since the last goal for a streamed one (at most one of the body's ticks).
        for before, after in itertools.pairwise(mine):
            allowed = joint.max_speed_dps * max(after.time - before.time, step) + 2 * unit
            assert abs(after.degrees - before.degrees) <= allowed, (name, after)
            if after.source not in ("point", "move", "rest", "into_range", "torque_on"):
                streamed = joint.max_speed_dps * (after.time - before.time) + 2 * unit
                assert abs(after.degrees - before.degrees) <= streamed, (name, after)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="needs espeak-ng")
def test_demo_voice_espeak_ng_writes_every_line_and_the_mouth_follows_its_sound(
    capsys, tmp_path
):
    rows, out = demo_with_motion(capsys, tmp_path, "--voice", "espeak-ng")
    lines = re.findall(r"\[\s*([\d.]+)\] Kaspar: (.*)", out)
    wavs = sorted((tmp_path / "state" / "voice").glob("*.wav"))
    assert len(wavs) == len(lines) and all(w.name.endswith("-espeak-ng.wav") for w in wavs)
    begin, _ = first_point(rows)
    number = next(i for i, (stamp, _) in enumerate(lines) if abs(float(stamp) - begin) < 0.002)
    levels, frame = wav_levels(wavs[number])
    # The mouth against the file's own envelope, on one grid from the line's start (the
    # clock stood still while espeak-ng rendered it): the real sound, not syllables.
    grid = np.arange(0.0, len(levels) * frame, 0.01)
    sound = np.array([levels[min(len(levels) - 1, int(t / frame))] for t in grid])
    mouth_rows = [(row.time - begin, row.degrees) for row in rows
                  if row.joint == MOUTH and begin <= row.time <= begin + grid[-1] + 0.02]
    times = np.array([t for t, _ in mouth_rows])
    values = np.array([d for _, d in mouth_rows])
    index = np.searchsorted(times, grid, side="right") - 1
    mouth = np.where(index >= 0, values[np.clip(index, 0, None)], 0.0)
    assert float(np.corrcoef(sound, mouth)[0, 1]) > 0.7


def test_a_motion_file_that_cannot_be_written_is_a_usage_error(capsys, tmp_path):
    for where, why in ((tmp_path / "none" / "m.csv", "no such directory"),
                       (tmp_path, "is a directory, expected a file")):
        with pytest.raises(SystemExit) as usage:
            main(["demo", "--fast", "--motion", str(where)])
        assert usage.value.code == 2
        assert f"argument --motion: {where}: {why}" in capsys.readouterr().err
