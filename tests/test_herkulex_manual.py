"""HerkuleX as its manual says: the thermistor table, the EEP limits, the battery's voltage.

Against the strict emulator over a pty (tests/emulators/herkulex.py): a servo on a
13 V LiFePO4 battery with its factory limits (6.7-10.1 V) latches the voltage error
bit at power-up; the bus's min_voltage_v/max_voltage_v go to RAM at start and the
stale bit is cleared once, while a real under-voltage stays a fault.
"""

from __future__ import annotations

import itertools
import json

import pytest
from emulators.herkulex import HerkulexEmulator
from servo_fixtures import eventually, make_driver

from hal.servos import herkulex as hx
from hal.servos.api import FaultKind, ServoLimits
from kasparctl.cli import main

BATTERY = (10.0, 13.5)  # LiFePO4, as Kaspar 3 runs on


# --- the table ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("raw", "celsius"),
    [(0x00, -79.47), (66, 0.05), (128, 25.2), (160, 39.13), (200, 62.63), (204, 65.78),
     (205, 66.61), (206, 67.46), (0xDE, 84.11), (0xDF, 85.42), (0xF0, 119.49), (0xFE, 300.91)],
)
def test_the_manuals_thermistor_table_gives_its_printed_points(raw, celsius):
    assert hx.temperature_c(raw) == celsius


def test_the_table_has_one_rising_entry_per_raw_value_and_none_for_0xff():
    table = hx.TEMPERATURE_CENTI_C
    assert len(table) == 255  # 0x00-0xFE
    # 205 printed as 68.61 in one copy would break this: it is out of sequence.
    assert all(a < b for a, b in itertools.pairwise(table))
    with pytest.raises(hx.HerkulexError, match="0xff is not a reading"):
        hx.temperature_c(0xFF)
    assert hx.raw_temperature(25.2) == 128 and hx.raw_temperature(62.63) == 200
    assert hx.raw_temperature(-200) == 0 and hx.raw_temperature(400) == 0xFE


def test_voltage_registers_hold_what_the_manual_says():
    assert hx.raw_voltage(13.0) == 176 and hx.voltage_v(176) == pytest.approx(13.02, abs=0.01)
    assert hx.voltage_limits_write(hx.BROADCAST_ID, *BATTERY) == hx.ram_write(
        hx.BROADCAST_ID, hx.Ram.MIN_VOLTAGE, bytes((135, 182)))
    with pytest.raises(hx.HerkulexError, match="does not fit"):
        hx.raw_voltage(19.0)


# --- the driver over a pty ---------------------------------------------------------------


async def _driver(emulator, **options):
    driver = make_driver("herkulex", emulator.path, baud=115200, **options)
    await driver.start()
    return driver


async def test_temperatures_come_from_the_table_and_0xff_is_a_named_impossible_reading(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2]) as emulator:
        driver = await _driver(emulator)
        try:
            emulator.pin_raw_temperature(1, 128)
            emulator.pin_raw_temperature(2, 200)
            assert (await driver.read_health(1)).temperature_c == 25.2
            assert (await driver.read_health(2)).temperature_c == 62.63
            emulator.pin_raw_temperature(2, 0xFF)
            health = await driver.read_health(2)
            assert health.temperature_c is None and health.kind is FaultKind.IMPOSSIBLE
            assert "TEMPERATURE_READING_0XFF" in health.flags and "0xff" in health.detail
        finally:
            await driver.close()


async def test_the_eep_limits_11_to_13_are_read_and_reported(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[3]) as emulator:
        emulator.servos[3].eep[hx.Eep.MAX_TEMPERATURE] = 0xC8  # an engineer's own limit
        driver = await _driver(emulator)
        try:
            health = await driver.read_health(3)
            assert health.stored_limits == ServoLimits(62.63, 0x5B * 0.074, 0x89 * 0.074)
            # RAM holds what the servo copied at power-up (this one was set before it).
            assert health.active_limits == ServoLimits(84.11, 0x5B * 0.074, 0x89 * 0.074)
            await driver.read_health(3)
            eep_reads = [p for p in emulator.received if p[4] == hx.Command.EEP_READ
                         and p[7] == hx.Eep.MAX_TEMPERATURE]
            assert len(eep_reads) == 1  # once per servo
        finally:
            await driver.close()


async def test_on_a_13_v_battery_without_limits_every_servo_reports_a_voltage_fault(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1], supply_v=13.0) as emulator:
        driver = await _driver(emulator)
        try:
            health = await driver.read_health(1)
            assert health.kind is FaultKind.VOLTAGE and not health.cleared
            assert "13.0 V" in health.detail and "6.7-10.1 V" in health.detail
            assert "min_voltage_v" in health.detail  # what the engineer is to set
        finally:
            await driver.close()


async def test_the_buses_voltage_limits_go_to_ram_at_start_and_a_13_v_battery_is_no_error(
    tmp_path,
):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], supply_v=13.0) as emulator:
        assert all(s.latched & hx.StatusError.EXCEED_INPUT_VOLTAGE
                   for s in emulator.servos.values())  # latched at power-up
        driver = await _driver(emulator, voltage_limits=BATTERY)
        try:
            await eventually(lambda: all(s.ram[hx.Ram.MIN_VOLTAGE:hx.Ram.MAX_VOLTAGE + 1]
                                         == bytes((135, 182)) for s in emulator.servos.values()))
            assert all(s.eep[hx.Eep.MIN_VOLTAGE] == 0x5B for s in emulator.servos.values())
            health = await driver.read_health(1)
            assert health.kind is None and health.cleared == ("EXCEED_INPUT_VOLTAGE",)
            assert health.voltage_v == pytest.approx(13.0, abs=0.05)
            assert health.active_limits == ServoLimits(84.11, 135 * 0.074, 182 * 0.074)
            await eventually(lambda: emulator.servos[1].latched == 0)
            await driver.set_torque([1], True)
            await eventually(lambda: emulator.torque_on(1))  # the torque policy let it go
            assert (await driver.read_health(1)).flags == ()
        finally:
            await driver.close()


async def test_a_real_under_voltage_is_a_fault_never_cleared_while_it_lasts(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1], supply_v=12.0) as emulator:
        driver = await _driver(emulator, voltage_limits=BATTERY)
        try:
            assert (await driver.read_health(1)).kind is None
            emulator.set_supply(9.5)  # the battery sags below 10 V
            health = await driver.read_health(1)
            assert health.kind is FaultKind.VOLTAGE and not health.cleared
            assert "9.5 V" in health.detail and "10.0-13.5 V" in health.detail
            await driver.reset_errors([1])  # asked to clear while it lasts: kept
            await driver.read_health(1)
            assert emulator.servos[1].latched & hx.StatusError.EXCEED_INPUT_VOLTAGE
            # Moves do not clear it either (the published driver cleared every bit first).
            await driver.write_goals({1: (520, 30.0)}, 0.02)
            await driver.set_torque([1], True)
            assert (await driver.read_health(1)).kind is FaultKind.VOLTAGE
            emulator.set_supply(12.5)  # charged
            assert (await driver.read_health(1)).kind is FaultKind.VOLTAGE  # still latched
            await driver.reset_errors([1])
            await eventually(lambda: emulator.servos[1].latched == 0)
            writes = [p for p in emulator.received if p[4] == hx.Command.RAM_WRITE
                      and p[3] == 1 and p[7] == hx.Ram.STATUS_ERROR]
            # The power-up bit at the first reading, and the one reset once the voltage was good.
            assert len(writes) == 2
        finally:
            await driver.close()


async def test_a_servo_power_cycled_behind_a_live_adapter_gets_its_limits_again(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[4], supply_v=13.2) as emulator:
        driver = await _driver(emulator, voltage_limits=BATTERY)
        try:
            assert (await driver.read_health(4)).kind is None
            await driver.bus.transact(hx.reboot(4))  # as a battery swap would
            await eventually(lambda: emulator.servos[4].ram[hx.Ram.MAX_VOLTAGE] == 0x89)
            health = await driver.read_health(4)
            assert health.kind is None and "EXCEED_INPUT_VOLTAGE" in health.cleared
            await eventually(lambda: emulator.servos[4].ram[hx.Ram.MAX_VOLTAGE] == 182)
            await eventually(lambda: emulator.servos[4].latched == 0)
        finally:
            await driver.close()


# --- `kasparctl servos read` ------------------------------------------------------------------


def _battery_robot(tmp_path, port, limits: bool = True) -> str:
    voltage = "min_voltage_v = 10.0\nmax_voltage_v = 13.5\n" if limits else ""
    battery = '[servos.battery]\njoint = "torso_yaw"\nwarn_below_v = 11.8\n' if limits else ""
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
{battery}
[[servos.buses]]
name = "body"
port = "{port}"
protocol = "herkulex"
baud = 115200
timeout_margin_ms = 100.0
{voltage}
[[servos.joints]]
name = "torso_yaw"
bus = "body"
id = 1
model = "drs-0101"
range_deg = [-30.0, 30.0]
[[servos.joints]]
name = "head_yaw"
bus = "body"
id = 2
model = "drs-0101"
range_deg = [-60.0, 60.0]
""")
    return str(path)


def test_servos_read_shows_the_tables_temperatures_the_battery_and_the_limits(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], supply_v=13.0) as emulator:
        emulator.pin_raw_temperature(1, 128)
        emulator.pin_raw_temperature(2, 200)
        config = _battery_robot(tmp_path, emulator.path)
        code = main(["servos", "read", "--config", config])
        text = capsys.readouterr().out
        assert main(["servos", "read", "--config", config, "--json"]) == 0
        rows = {row["joint"]: row for row in json.loads(capsys.readouterr().out)}
    print(text)  # the figures, for the report (pytest -s)
    assert code == 0, text
    torso, head, battery = text.splitlines()
    assert " 25.2 C " in torso and " 13.0 V " in torso and "  ok  " in torso
    assert " 62.6 C " in head and " 13.0 V " in head
    assert "[EEP 11-13: 84 C, 6.7-10.1 V; RAM 5-7: 84 C, 10.0-13.5 V]" in torso
    assert battery == "battery 13.0 V (read by torso_yaw; warning below 11.8 V)"
    assert rows["torso_yaw"]["temperature_c"] == 25.2 and rows["head_yaw"]["temperature_c"] == 62.6
    assert rows["torso_yaw"]["battery"] == {"voltage_v": 13.0, "warn_below_v": 11.8, "low": False}
    assert rows["torso_yaw"]["limits_eep"] == {
        "max_temperature_c": 84.11, "min_voltage_v": 6.73, "max_voltage_v": 10.14}


def test_servos_read_without_the_limits_names_the_voltage_fault(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], supply_v=13.0) as emulator:
        code = main(["servos", "read", "--config", _battery_robot(tmp_path, emulator.path, False)])
    out = capsys.readouterr().out
    assert code == 1
    assert "voltage: voltage 13.0 V, the servo's limits 6.7-10.1 V" in out


def test_set_voltage_writes_the_limits_to_eep_only_when_asked(tmp_path, capsys):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], supply_v=13.0) as emulator:
        config = _battery_robot(tmp_path, emulator.path)
        assert main(["servos", "read", "--config", config]) == 0
        capsys.readouterr()
        assert all(s.eep[hx.Eep.MIN_VOLTAGE:hx.Eep.MAX_VOLTAGE + 1] == bytes((0x5B, 0x89))
                   for s in emulator.servos.values())  # read wrote RAM only
        code = main(["servos", "set-voltage", "--config", config])
        out = capsys.readouterr().out
        assert code == 0, out
        assert all(s.eep[hx.Eep.MIN_VOLTAGE:hx.Eep.MAX_VOLTAGE + 1] == bytes((135, 182))
                   for s in emulator.servos.values())
        emulator.servos[1].latched = 0
        emulator.handle(hx.reboot(1))  # powered again: RAM copied from the new EEP
        assert emulator.servos[1].latched == 0  # 13 V is inside the servo's own limits now
    assert out.splitlines()[0] == ("torso_yaw            body   id   1  EEP 12-13: 9.99-13.47 V  ok")
