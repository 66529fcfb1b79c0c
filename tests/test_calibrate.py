"""`kasparctl servos calibrate`: ranges, rest and direction from a joint moved by hand."""

from __future__ import annotations

import itertools
import json
import tomllib

import pytest
from bringup_fixtures import robot
from emulators.herkulex import HerkulexEmulator

from hal.servos import herkulex as hx
from hal.servos.settings import JointSettings
from kasparctl.bringup.calibration import Sweep, propose
from kasparctl.cli import main
from kasparctl.config import load_config


def elbow(**overrides) -> JointSettings:
    values = dict(name="left_elbow", bus="body", id=10, model="drs-0101", range_deg=(-5.0, 90.0),
                  rest_deg=5.0, max_speed_dps=60.0, group="left_arm")
    values.update(overrides)
    return JointSettings(**values)


def swept(*positions: float) -> Sweep:
    sweep = Sweep("left_elbow", positions[0])
    for degrees in positions:
        sweep.see(degrees)
    return sweep


def test_the_range_is_what_was_seen_brought_in_by_the_margin():
    proposal = propose(swept(5.0, 40.0, 97.0, -12.0, 6.0), elbow(), margin=2.0)
    assert proposal.proposed == {"range_deg": (-10.0, 95.0), "rest_deg": 6.0}
    assert proposal.seen == (-12.0, 97.0)


def test_a_range_never_goes_beyond_what_the_servo_reaches():
    proposal = propose(swept(0.0, 170.0, -170.0, 0.0), elbow(), margin=2.0)
    low, high = proposal.proposed["range_deg"]
    assert (low, high) == (-159.5, 159.2)  # raw 21..1002 at 0.325 deg per unit, rounded inward
    assert any("can reach" in note for note in proposal.notes)


def test_a_first_movement_the_wrong_way_flips_the_direction():
    # Asked to move it first the way its angle grows, the engineer moved it to -85: the
    # servo is mounted the other way round. Range and rest are given in the new sign.
    proposal = propose(swept(5.0, -20.0, -85.0, 9.0, 5.0), elbow(), margin=2.0)
    assert proposal.proposed == {"range_deg": (-7.0, 83.0), "rest_deg": -5.0, "direction": -1}


def test_a_joint_hardly_moved_keeps_its_configuration():
    proposal = propose(swept(5.0, 6.0, 7.0), elbow(), margin=2.0)
    assert proposal.proposed == {} and "moved only 2.0 deg" in proposal.notes[0]


def test_simulated_calibration_proposes_a_diff_and_writes_it_keeping_comments(tmp_path, capsys):
    path = robot(tmp_path)
    before = path.read_text()
    code = main(["servos", "calibrate", "--config", str(path), "--group", "left_arm",
                 "--seconds", "1.0", "--sim-sweep", "10", "--json", "--write"])
    result = json.loads(capsys.readouterr().out)
    assert code == 0 and result["written"] and result["ending"] == "done"
    (joint,) = result["joints"]
    low, high = joint["proposed"]["range_deg"]
    assert low == pytest.approx(-15.0 + 2.0, abs=0.5) and high == pytest.approx(100.0 - 2.0, abs=0.5)
    assert joint["proposed"]["rest_deg"] == pytest.approx(5.0, abs=0.5)
    after = path.read_text()
    assert "# mirrored on the real robot; found by calibration" in after
    changed = [(a, b) for a, b in zip(before.splitlines(), after.splitlines(), strict=True) if a != b]
    assert [a.split(" =")[0] for a, _ in changed] == ["range_deg", "rest_deg"]
    assert load_config(path, poses=False).servos.joints[0].range_deg == (low, high)
    assert "-range_deg = [-5.0, 90.0]" in result["diff"]


def test_without_write_nothing_changes(tmp_path, capsys):
    path = robot(tmp_path)
    before = path.read_text()
    assert main(["servos", "calibrate", "--config", str(path), "--joints", "left_elbow",
                 "--seconds", "0.5", "--sim-sweep", "5"]) == 0
    out = capsys.readouterr().out
    assert "not written (add --write)" in out and "+range_deg" in out
    assert path.read_text() == before


def test_a_joint_moved_by_hand_on_the_emulated_bus_is_calibrated_while_the_rest_hold(
    tmp_path, capsys
):
    import time

    # The hand holds left_elbow (id 10) from rest, first down to -85 deg, up to +9, back
    # to rest: on the real robot the elbow is mirrored, so its direction must flip.
    begin = time.monotonic()
    marks = [(0.0, 527), (0.3, 250), (0.5, 250), (0.8, 540), (1.0, 540), (1.2, 527)]

    def hand(now: float) -> float:
        t = now - begin
        for (t0, r0), (t1, r1) in itertools.pairwise(marks):
            if t <= t1:
                return r0 + (r1 - r0) * max(0.0, t - t0) / (t1 - t0)
        return marks[-1][1]

    with HerkulexEmulator(tmp_path / "ttyHX", ids=[5, 6, 10], ack_policy=0,
                          positions={10: 527}) as emulator:
        emulator.hand(10, hand)
        path = robot(tmp_path, backend="real", port=str(emulator.path))
        code = main(["servos", "calibrate", "--config", str(path), "--joints", "left_elbow",
                     "--seconds", "1.5", "--json", "--write"])
        assert not emulator.torque_on(10)  # the calibrated joint is left limp
        assert emulator.torque_on(6) and emulator.torque_on(5)  # the others held throughout
        jogs = [hx.decode_packet(p) for p in emulator.received if p[4] == hx.Command.S_JOG]
        assert all(10 not in p.data[4::4] for p in jogs)  # never a goal for the limp joint
    result = json.loads(capsys.readouterr().out)
    assert code == 0, result
    (joint,) = result["joints"]
    assert joint["proposed"]["direction"] == -1
    low, high = joint["proposed"]["range_deg"]
    assert low == pytest.approx(-(540 - 512) * 0.325 + 2.0, abs=0.7)
    assert high == pytest.approx((512 - 250) * 0.325 - 2.0, abs=0.7)
    written = tomllib.loads(path.read_text())["servos"]["joints"][0]
    assert written["direction"] == -1 and written["range_deg"] == [low, high]


def test_hobby_servos_cannot_be_calibrated_by_hand(tmp_path, capsys):
    path = tmp_path / "kaspar.toml"
    path.write_text("""
[servos]
backend = "sim"
[[servos.buses]]
name = "eyes"
port = "/dev/eyes"
protocol = "maestro"
[[servos.joints]]
name = "left_eyelid"
bus = "eyes"
id = 0
model = "hs-82mg"
range_deg = [-15.0, 15.0]
""")
    assert main(["servos", "calibrate", "--config", str(path), "--seconds", "0.1"]) == 1
    assert "has no position feedback" in capsys.readouterr().err


def test_an_interactive_calibration_with_no_way_to_end_says_what_to_do(tmp_path, capsys,
                                                                        monkeypatch):
    import io

    monkeypatch.setattr("sys.stdin", io.StringIO(""))  # no terminal, no keyfob configured
    path = robot(tmp_path)
    assert main(["servos", "calibrate", "--config", str(path), "--group", "face"]) == 1
    assert "give --seconds N" in capsys.readouterr().err
