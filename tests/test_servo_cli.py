"""`kasparctl servos scan/read` and `kasparctl check` against emulated buses."""

from __future__ import annotations

import json

import pytest
import structlog
from emulators.dynamixel import Dynamixel1Emulator, Dynamixel2Emulator
from emulators.herkulex import HerkulexEmulator

from kasparctl.cli import main


@pytest.fixture(autouse=True)
def _restore_logging():
    # The commands send the log to stderr, here pytest's capture, which closes after the test.
    yield
    structlog.reset_defaults()


@pytest.mark.parametrize(
    ("protocol", "emulator_type", "model", "positions"),
    [
        ("dynamixel1", Dynamixel1Emulator, "ax-12a", (512, 512)),
        ("dynamixel2", Dynamixel2Emulator, "xl430-w250", (2048, 2048)),
        ("herkulex", HerkulexEmulator, "drs-0101", (514, 507)),  # each servo where it is
    ],
)
def test_scan_lists_the_answering_ids_as_json(tmp_path, capsys, protocol, emulator_type, model,
                                              positions):
    with emulator_type(tmp_path / "tty", ids=[2, 5]):
        code = main(["servos", "scan", "--port", str(tmp_path / "tty"), "--protocol", protocol,
                     "--baud", "1000000", "--ids", "1-6", "--margin-ms", "100", "--json"])
    assert code == 0
    found = json.loads(capsys.readouterr().out)
    assert [(s["id"], s["model"], s["position"]) for s in found] == [
        (2, model, positions[0]), (5, model, positions[1]),
    ]


def test_scan_names_a_drs_0201_by_its_model_number(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "tty", ids=[3], models={3: "drs-0201"}, ack_policy=0):
        code = main(["servos", "scan", "--port", str(tmp_path / "tty"), "--protocol",
                     "herkulex", "--baud", "115200", "--ids", "3", "--margin-ms", "100",
                     "--json"])
    assert code == 0
    (found,) = json.loads(capsys.readouterr().out)
    assert (found["model"], found["model_number"]) == ("drs-0201", 0x0102)


def test_scan_of_a_missing_port_fails_with_a_message(tmp_path, capsys):
    code = main(["servos", "scan", "--port", str(tmp_path / "nothing"), "--protocol", "maestro",
                 "--baud", "115200"])
    assert code == 1 and "cannot open" in capsys.readouterr().err


def test_scan_rejects_nonsense_ids(capsys):
    with pytest.raises(SystemExit):
        main(["servos", "scan", "--port", "/dev/null", "--protocol", "herkulex", "--ids", "a-b"])
    assert "expected ids like 1-20" in capsys.readouterr().err


def real_config(tmp_path, port) -> str:
    path = tmp_path / "kaspar.toml"
    path.write_text(f"""
[game]
pointing_group = "left_arm"

[keyfob]
backend = "sim"

[voice]
backend = "sim"

[servos]
backend = "real"

[[servos.buses]]
name = "body"
port = "{port}"
protocol = "dynamixel1"
baud = 1000000
timeout_margin_ms = 100.0

[[servos.joints]]
name = "left_elbow"
bus = "body"
id = 1
model = "ax-12a"
range_deg = [-40.0, 40.0]
group = "left_arm"

[[servos.joints]]
name = "torso_yaw"
bus = "body"
id = 2
model = "ax-12a"
range_deg = [-30.0, 30.0]
offset_deg = 10.0
""")
    return str(path)


def test_read_prints_every_joint_in_degrees_and_names_the_silent_one(tmp_path, capsys):
    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2]) as emulator:
        emulator.faults.silent.add(2)
        code = main(["servos", "read", "--config", real_config(tmp_path, emulator.path), "--json"])
    rows = {row["joint"]: row for row in json.loads(capsys.readouterr().out)}
    assert code == 1
    assert rows["left_elbow"]["position_deg"] == 0.0 and rows["left_elbow"]["status"] == "ok"
    assert rows["left_elbow"]["temperature_c"] == 32.0 and rows["left_elbow"]["voltage_v"] == 12.0
    assert rows["torso_yaw"]["position_deg"] is None
    assert rows["torso_yaw"]["status"].startswith("silent")


def test_read_works_on_the_simulated_servos(tmp_path, capsys):
    path = tmp_path / "kaspar.toml"
    path.write_text(real_config(tmp_path, "/dev/none") and
                    (tmp_path / "kaspar.toml").read_text().replace('"real"', '"sim"'))
    assert main(["servos", "read", "--config", str(path)]) == 0
    out = capsys.readouterr().out
    assert "left_elbow" in out and "torso_yaw" in out and out.count("0.0 deg  35.0 C  13.2 V  ok") == 2  # the simulated battery, full


def test_check_names_each_missing_servo(tmp_path, capsys, monkeypatch):
    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1]) as emulator:
        code = main(["check", "--config", real_config(tmp_path, emulator.path)])
    captured = capsys.readouterr()
    assert code == 1
    assert "servos         FAIL  servo torso_yaw is missing (bus body on" in captured.out
    assert "id 2" in captured.out
    assert "servos         ok    left_elbow: 0.0 deg, 32 C, 12.0 V" in captured.out


def test_check_passes_when_every_servo_answers(tmp_path, capsys):
    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2]) as emulator:
        code = main(["check", "--config", real_config(tmp_path, emulator.path)])
    out = capsys.readouterr().out
    assert code == 0 and "all 2 servos answered" in out
    assert "servos         ok    left_elbow: 0.0 deg, 32 C, 12.0 V" in out
    assert "servos         ok    torso_yaw: 10.0 deg, 32 C, 12.0 V" in out


def test_check_fails_on_an_impossible_reading_and_on_latched_error_bits(tmp_path, capsys):
    from hal.servos import dynamixel1 as dx1

    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2]) as emulator:
        emulator.set_present(1, 7990)
        emulator.faults.error_bits[2] = int(dx1.ErrorBits.ANGLE_LIMIT)
        code = main(["check", "--config", real_config(tmp_path, emulator.path)])
    out = capsys.readouterr().out
    assert code == 1
    assert "servos         FAIL  left_elbow: 32 C, 12.0 V - position reading 7990 is impossible" in out
    assert "torso_yaw: 10.0 deg, 32 C, 12.0 V - error bits ANGLE_LIMIT" in out


def herkulex_config(tmp_path, port) -> str:
    path = tmp_path / "kaspar.toml"
    path.write_text(f"""
[game]
pointing_group = "body"
[keyfob]
backend = "sim"
[voice]
backend = "sim"
[servos]
backend = "real"
max_temperature_c = 60.0
[[servos.buses]]
name = "body"
port = "{port}"
protocol = "herkulex"
baud = 115200
timeout_margin_ms = 100.0
[[servos.joints]]
name = "head_yaw"
bus = "body"
id = 2
model = "drs-0101"
range_deg = [-60.0, 60.0]
[[servos.joints]]
name = "smile"
bus = "body"
id = 6
model = "drs-0201"
range_deg = [-20.0, 20.0]
""")
    return str(path)


def test_read_of_real_herkulex_servos_masks_the_high_bits_and_reports_temperature(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[2, 6], models={6: "drs-0201"}, ack_policy=0,
                          positions={2: 543, 6: 520}) as emulator:  # 543: as captured
        code = main(["servos", "read", "--config", herkulex_config(tmp_path, emulator.path),
                     "--json"])
    rows = {row["joint"]: row for row in json.loads(capsys.readouterr().out)}
    assert code == 0
    assert rows["head_yaw"]["position_deg"] == pytest.approx(10.1, abs=0.05)
    assert rows["smile"]["position_deg"] == pytest.approx(2.6, abs=0.05)
    assert rows["head_yaw"]["raw_position"] == 543 and rows["smile"]["status"] == "ok"
    assert rows["head_yaw"]["temperature_c"] == pytest.approx(26.0, abs=0.6)
    assert rows["head_yaw"]["voltage_v"] == pytest.approx(7.5, abs=0.1)


def test_read_fails_naming_a_hot_servo_and_a_latched_error(tmp_path, capsys):
    from hal.servos import herkulex as hx

    with HerkulexEmulator(tmp_path / "ttyHX", ids=[2, 6], models={6: "drs-0201"},
                          positions={6: 520}) as emulator:
        emulator.set_temperature(2, 62.0)
        emulator.latch(6, int(hx.StatusError.OVERLOAD))
        code = main(["servos", "read", "--config", herkulex_config(tmp_path, emulator.path)])
    out = capsys.readouterr().out
    assert code == 1
    (yaw,) = [line for line in out.splitlines() if line.startswith("head_yaw")]
    assert "62 C" in yaw and "too hot: 62 C >= max_temperature_c 60 C" in yaw
    (smile,) = [line for line in out.splitlines() if line.startswith("smile")]
    assert "overload: OVERLOAD" in smile and "error bits: OVERLOAD" in smile


def test_read_marks_an_impossible_position_and_exits_non_zero(tmp_path, capsys):
    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2]) as emulator:
        emulator.set_present(2, 7990)
        code = main(["servos", "read", "--config", real_config(tmp_path, emulator.path)])
    out = capsys.readouterr().out
    (torso,) = [line for line in out.splitlines() if line.startswith("torso_yaw")]
    assert code == 1 and "!  7990 deg" in torso
    assert "position reading 7990 is impossible for a ax-12a (it reports 0 to 1023)" in torso


def test_check_does_not_touch_servos_with_the_sim_backend(tmp_path, capsys):
    path = tmp_path / "kaspar.toml"
    path.write_text("[game]\nvariant = 'pilot'\nlocations = ['box']\n[servos]\nbackend = 'sim'\n"
                    "[keyfob]\nbackend = 'sim'\n[voice]\nbackend = 'sim'\n")
    assert main(["check", "--config", str(path)]) == 0
    assert "servos answered" not in capsys.readouterr().out


def test_check_names_a_servo_that_answers_pings_but_no_reads(tmp_path, capsys):
    from hal.servos import dynamixel1 as dx1

    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2]) as emulator:
        emulator.tables[2][dx1.AX12.STATUS_RETURN_LEVEL] = 0
        code = main(["check", "--config", real_config(tmp_path, emulator.path)])
    out = capsys.readouterr().out
    assert code == 1 and "servo torso_yaw answers a ping but no read" in out
