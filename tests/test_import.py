"""`kasparctl import`: small published-format content directories, written here from the
format descriptions (kaspar-hardware.md, kasparctl/bringup/legacy.py), imported for the
shipped profiles: values converted through the servos' raw positions, timings kept,
out-of-range values named and never clamped, the rest reported."""

from __future__ import annotations

import shutil
import tomllib
import wave
from pathlib import Path

import pytest

from kasparctl.body.behaviours import load_library
from kasparctl.body.check import problems
from kasparctl.bringup.importing import ImportFailed, import_content, write_imported
from kasparctl.cli import main
from kasparctl.config import load_config

SYSTEMD = Path(__file__).resolve().parent.parent / "systemd"
ROBOT_XML_1C = """<?xml version="1.0"?>
<KASPAR version="1C">
    <NAME>Kaspar_1c</NAME>
    <SERVOLIST>
        <SERVO type="AX12" id="2"><NAME>EYELIDS</NAME>
            <LIMITS type="pos"><MIN>305</MIN><MAX>0</MAX></LIMITS></SERVO>
        <SERVO type="AX12" id="7"><NAME>HEAD_VERT</NAME>
            <LIMITS type="pos"><MIN>300</MIN><MAX>556</MAX></LIMITS></SERVO>
    </SERVOLIST>
</KASPAR>
"""


def _wav(path: Path) -> None:
    with wave.open(str(path), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(8000)
        out.writeframes(b"\0\0" * 80)


def kaspar_1c_content(root: Path) -> Path:
    (root / "pos").mkdir(parents=True)
    (root / "seqs").mkdir()
    (root / "keyMaps").mkdir()
    (root / "sounds").mkdir()
    (root / "robot.xml").write_text(ROBOT_XML_1C)
    crlf = "\r\n"
    (root / "pos" / "Eye Shut.pose").write_text(crlf.join(
        ["Eye Shut", "1", "EYELIDS,349,300,false", ""]))
    (root / "pos" / "Eye Open.pose").write_text(crlf.join(
        ["Eye Open", "2", "EYELIDS,920,300,false", "WINGS,500,100,false", ""]))
    # Scaled 0 is raw 300 of this lab's robot.xml: below the profile's 381.
    (root / "pos" / "Look up.pose").write_text(crlf.join(["Look up", "1", "HEAD_VERT,0,80,false"]))
    (root / "seqs" / "blink.seq").write_text(crlf.join(
        ["Blink", "2", "Eye Shut,Eye Shut.pose,300", "Eye Open,Eye Open.pose,0", "tada.wav"]))
    (root / "seqs" / "up.seq").write_text(crlf.join(["Up", "1", "Look up,Look up.pose,500"]))
    (root / "keyMaps" / "game.skm").write_text(crlf.join(["Blink,2", "Up,P,ENTeR", "Res", ""]))
    _wav(root / "sounds" / "tada.wav")
    (root / "sounds" / "notes.docx").write_bytes(b"PK\3\4 not a sound")
    return root


def kaspar_3_content(root: Path) -> Path:
    (root / "pos").mkdir(parents=True)
    (root / "seq").mkdir()
    (root / "pos" / "Eye Shut.pose").write_text("Eye Shut\nEYELIDS,60,100\n\n")
    (root / "pos" / "Eye Open.pose").write_text("Eye Open\nEYELIDS,0,100\n\n")
    (root / "pos" / "Nod.pose").write_text("Nod\nHEAD_PITCH,13,100\nMOUTH_SMILE,5,100\n")
    # The eyes 15 down take each lid past open (it follows its eyeball), the mouth past its end.
    (root / "pos" / "Sad.pose").write_text("Sad\nEYELIDS,8,100\nEYES_PITCH,15,100\n"
                                           "MOUTH_OPEN,-8,100\n")
    (root / "seq" / "Blink.seq").write_text("Blink\nEye Shut\nEye Open\n")
    (root / "seq" / "Sulk.seq").write_text("Sulk\nSad\nEye Open\n")
    return root


def _import(content: Path, robot: str, profile: str, out: Path) -> tuple[str, Path]:
    config = load_config(SYSTEMD / profile)
    imported = import_content(content, robot, config, str(SYSTEMD / profile))
    return write_imported(imported, out, config), out


def test_a_kaspar_1c_directory_is_converted_timed_and_reported(tmp_path):
    report, out = _import(kaspar_1c_content(tmp_path / "lab"), "kaspar-1c", "kaspar-1c.toml",
                          tmp_path / "out")
    poses = tomllib.loads((out / "poses.toml").read_text())
    # EYELIDS 349 of 305..0 is raw 198.6; the profile's eyelids: centre raw 61, 300/1024 deg.
    assert poses["eye_shut"]["eyelids"] == pytest.approx((305 - 305 * 0.349 - 61) * 300 / 1024,
                                                         abs=1e-3)
    assert poses["eye_open"] == {"eyelids": pytest.approx((305 - 305 * 0.92 - 61) * 300 / 1024,
                                                          abs=1e-3)}
    assert "look_up" not in poses
    assert ("pose 'Look up' (pos/Look up.pose): not imported (never clamped): HEAD_VERT 0 "
            "(raw 300) puts head_pitch at -45.70 deg, outside its safe range [-21.973, 29.297]") in report
    assert "pose 'Eye Open' (pos/Eye Open.pose): WINGS: not a joint of this profile" in report
    (blink,) = tomllib.loads((out / "behaviours" / "imported.toml").read_text()).values()
    times = [frame["time"] for frame in blink["keyframes"]]
    shut = (305 - 305 * 0.349 - 61) * 300 / 1024 - 11.719  # from the rest, raw 101
    # Step 1 at 300 x 0.666 deg/s would take 0.143 s; the minimum-jerk curve needs 1.875 x
    # the distance over the 333 deg/s limit: 0.161 s. Then the published 300 ms delay.
    assert times[0] == pytest.approx(1.875 * shut / 333.0, abs=0.002)
    assert times[1] == pytest.approx(times[0] + 0.3, abs=0.002)
    assert blink["keyframes"][1]["pose"] == blink["keyframes"][0]["pose"]  # held meanwhile
    assert "step 1 takes 0.16 s, not the published 0.14 s" in report
    assert "sequence 'Up' (seqs/up.seq): step 1 is pose 'Look up'" in report
    assert "sound 'tada.wav' not attached: a behaviour carries no sound" in report
    assert (out / "sounds" / "tada.wav").read_bytes() == (tmp_path / "lab/sounds/tada.wav"
                                                         ).read_bytes()
    assert "sounds/notes.docx: not a WAV file" in report
    assert "keymap keyMaps/game.skm, line 2: 'Up' on keypad ENTER, touch sensor P" in report
    assert "keymap keyMaps/game.skm, line 3: 'Res' is bound to no key" in report
    assert (out / "report.md").read_text() == report


def test_the_written_files_are_a_poses_file_and_behaviours_the_profile_takes(tmp_path):
    _, out = _import(kaspar_1c_content(tmp_path / "lab"), "kaspar-1c", "kaspar-1c.toml",
                     tmp_path / "out")
    assert problems(load_library(out / "behaviours"), load_config(SYSTEMD / "kaspar-1c.toml")
                    .servos) == []
    profile = tmp_path / "kaspar.toml"
    text = (SYSTEMD / "kaspar-1c.toml").read_text()
    profile.write_text(text.replace('poses_file = "kaspar-1c-poses.toml"',
                                    f'poses_file = "{out / "poses.toml"}"'))
    assert load_config(profile).servos.joints  # every pose checked against the ranges


def test_a_kaspar_3_directory_goes_through_the_virtual_joints_and_the_centres(tmp_path):
    report, out = _import(kaspar_3_content(tmp_path / "lab"), "kaspar-3", "kaspar-3.toml",
                          tmp_path / "out")
    poses = tomllib.loads((out / "poses.toml").read_text())
    assert poses["eye_shut"] == {"eyelids": pytest.approx(30.0)}  # 60 x 0.18 / 0.09 / 4 * 4
    # HEAD_PITCH 13 is raw 548.9 (0.352 deg a count), -12.0 of this profile's degrees (down is +).
    assert poses["nod"]["head_pitch"] == pytest.approx(-(13 / 0.352) * 0.325, abs=1e-3)
    assert poses["nod"]["smile"] == pytest.approx(4.55)  # raw 526.2: the smile's end, that end
    assert "sad" not in poses
    assert ("pose 'Sad' (pos/Sad.pose): not imported (never clamped): EYELIDS 8 (raw 6178 = "
            "1544 us), EYES_PITCH 15 (raw 6333 = 1583 us) puts right_eyelid at -3.50 deg, "
            "outside its safe range [0, 30]") in report
    assert "MOUTH_OPEN -8 (raw 597) puts mouth_open at -7.39 deg" in report
    assert "sequence 'Sulk' (seq/Sulk.seq): step 1 is pose 'Sad'" in report
    (blink,) = tomllib.loads((out / "behaviours" / "imported.toml").read_text()).values()
    # No published timing: each step at the lids' 300 deg/s limit, minimum jerk.
    assert [f["pose"] for f in blink["keyframes"]] == [{"eyelids": 30.0}, {"eyelids": 0.0}]
    assert blink["keyframes"][0]["time"] == pytest.approx(1.875 * 30 / 300, abs=0.002)


def test_a_robot_s_own_centres_file_moves_what_its_imported_poses_send(tmp_path):
    robots = SYSTEMD / "kaspar-3-robots"
    for name in ("kaspar-3.toml", "kaspar-3-poses.toml"):
        shutil.copy(SYSTEMD / name, tmp_path / name)
    profile = tmp_path / "kaspar-3.toml"
    profile.write_text(f'centres_file = "{robots / "kaspar3-8.toml"}"\n' + profile.read_text())
    config = load_config(profile)
    imported = import_content(kaspar_3_content(tmp_path / "lab"), "kaspar-3", config,
                              str(profile))
    # Degrees from the robot's own centre: the same pose, whatever its centres.
    assert imported.poses["eye_shut"][1] == {"eyelids": pytest.approx(30.0)}


def test_content_of_the_other_robot_or_an_unusable_directory_is_refused(tmp_path):
    config = load_config(SYSTEMD / "kaspar-3.toml")
    with pytest.raises(ImportFailed, match=r"the profile.s \w+ is a drs-0101, not a kaspar-1c.s"):
        import_content(kaspar_1c_content(tmp_path / "lab"), "kaspar-1c", config, "k3")
    with pytest.raises(ImportFailed, match="not a directory of published Kaspar content"):
        import_content(tmp_path / "nowhere", "kaspar-3", config, "k3")
    lab = kaspar_1c_content(tmp_path / "lab2")
    (lab / "robot.xml").unlink()
    with pytest.raises(ImportFailed, match=r"robot.xml: missing: a Kaspar-1c pose's scaled"):
        import_content(lab, "kaspar-1c", load_config(SYSTEMD / "kaspar-1c.toml"), "k1c")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "mine.toml").write_text("")
    imported = import_content(kaspar_3_content(tmp_path / "lab3"), "kaspar-3", config, "k3")
    with pytest.raises(ImportFailed, match="already holds files"):
        write_imported(imported, tmp_path / "full", config)
    assert (tmp_path / "full" / "mine.toml").read_text() == ""


def test_the_command_writes_and_prints_the_report(tmp_path, capsys):
    lab = kaspar_3_content(tmp_path / "lab")
    code = main(["import", str(lab), "--robot", "kaspar-3", "--out", str(tmp_path / "out"),
                 "--config", str(SYSTEMD / "kaspar-3.toml")])
    out = capsys.readouterr().out
    assert code == 0
    assert out == (tmp_path / "out" / "report.md").read_text()
    assert "## Not carried over, and why" in out
