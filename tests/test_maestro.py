"""Pololu Maestro codec: the user's guide's byte layouts, round trips, fuzzing."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hal.errors import CodecError
from hal.servos import maestro as mo


def test_set_target_splits_into_seven_bit_bytes():
    # User's guide: 1500 us = 6000 quarter-us on channel 2 is 0x84 0x02 0x70 0x2E.
    assert mo.set_target(2, 6000) == bytes((0x84, 0x02, 0x70, 0x2E))


def test_pololu_form_addresses_a_device():
    assert mo.pololu(12, mo.set_target(0, 6000)) == bytes((0xAA, 12, 0x04, 0, 0x70, 0x2E))


def test_set_multiple_targets_layout():
    assert mo.set_multiple_targets(3, [0, 6000]) == bytes((0x9F, 2, 3, 0, 0, 0x70, 0x2E))


def test_replies_decode():
    assert mo.decode_position(bytes((0x70, 0x17))) == 6000
    assert mo.decode_errors(bytes((0x11, 0x01))) == (
        mo.Errors.SERIAL_SIGNAL | mo.Errors.SERIAL_PROTOCOL | mo.Errors.SCRIPT_PROGRAM_COUNTER
    )
    assert mo.decode_moving_state(b"\x01") is True


def test_builders_refuse_out_of_range_values():
    with pytest.raises(mo.MaestroError):
        mo.set_target(24, 6000)
    with pytest.raises(mo.MaestroError):
        mo.set_target(0, 0x4000)
    with pytest.raises(mo.MaestroError):
        mo.set_multiple_targets(22, [1, 2, 3])


@given(st.integers(0, 23), st.integers(0, mo.MAX_VALUE))
def test_set_target_round_trips(channel, target):
    raw = mo.set_target(channel, target)
    assert mo.command_length(raw[:2]) == len(raw)
    assert mo.decode_command(raw) == (mo.Command.SET_TARGET, (channel, target))


@given(st.integers(0, 23), st.lists(st.integers(0, mo.MAX_VALUE), min_size=1, max_size=24))
def test_set_multiple_targets_round_trips(first, targets):
    if first + len(targets) > mo.MAX_CHANNELS:
        with pytest.raises(mo.MaestroError):
            mo.set_multiple_targets(first, targets)
        return
    raw = mo.set_multiple_targets(first, targets)
    assert mo.decode_command(raw) == (mo.Command.SET_MULTIPLE_TARGETS, (first, *targets))


@given(st.binary(max_size=60))
def test_decoders_given_random_bytes_raise_only_their_own_error(raw):
    for decode in (mo.decode_command, mo.command_length, mo.decode_position,
                   mo.decode_errors, mo.decode_moving_state):
        try:
            decode(raw)
        except mo.MaestroError:
            pass
        except CodecError as error:  # pragma: no cover
            pytest.fail(f"{decode.__name__} raised {type(error).__name__}")


@given(st.binary(min_size=1, max_size=60))
def test_pololu_form_rejects_or_builds(raw):
    with contextlib.suppress(mo.MaestroError):
        assert mo.pololu(1, raw)[2] == raw[0] & 0x7F


# --- the driver over a pty, against the emulator ------------------------------------------

from emulators.maestro import MaestroEmulator  # noqa: E402
from servo_fixtures import eventually, make_driver  # noqa: E402

from hal.errors import ServoSilent  # noqa: E402


@pytest.fixture
def maestro(tmp_path):
    with MaestroEmulator(tmp_path / "ttyACM", channels=12) as emulator:
        yield emulator


async def test_driver_sets_targets_in_one_write_and_reads_them_back(maestro):
    driver = make_driver("maestro", maestro.path, baud=115200)
    await driver.start()
    try:
        assert await driver.ping(0) == 0
        await driver.write_goals({0: (5000, 90.0), 1: (7000, 90.0), 5: (6400, 90.0)}, 0.02)
        await eventually(lambda: len(maestro.received) >= 3)
        assert maestro.received[-2][0] == mo.Command.SET_MULTIPLE_TARGETS  # channels 0-1
        assert maestro.received[-1] == mo.set_target(5, 6400)

        async def arrived():
            return await driver.read_positions([0, 1, 5]) == {0: 5000, 1: 7000, 5: 6400}

        await eventually(arrived)
        await driver.set_torque([0], False)
        await eventually(lambda: maestro.targets[0] == 0)  # pulses off: the servo is limp
        assert (await driver.read_positions([0, 1]))[0] == 0  # and its position is unknown
    finally:
        await driver.close()


async def test_channels_start_off_and_read_0_as_a_real_maestro_does(maestro):
    driver = make_driver("maestro", maestro.path, baud=115200)
    await driver.start()
    try:
        assert await driver.read_positions([0, 3]) == {0: 0, 3: 0}
    finally:
        await driver.close()


async def test_eye_joints_without_feedback_start_from_rest_and_come_back_where_they_were(
    tmp_path, maestro
):
    from servo_fixtures import FakeClock

    from hal.servos.joints import Joints
    from hal.servos.settings import BusSettings, JointSettings, ServoSettings

    settings = ServoSettings(
        backend="real",
        buses=(BusSettings(name="eyes", port=str(maestro.path), protocol="maestro",
                           baud=115200),),
        joints=(
            JointSettings(name="left_eyelid", bus="eyes", id=0, model="hs-82mg",
                          range_deg=(-15.0, 15.0), rest_deg=5.0, max_speed_dps=90.0,
                          group="eyes"),
            JointSettings(name="right_eyelid", bus="eyes", id=1, model="hs-82mg",
                          range_deg=(-15.0, 15.0), rest_deg=-5.0, max_speed_dps=90.0,
                          group="eyes"),
        ),
    )
    joints = Joints(settings, {"eyes": make_driver("maestro", maestro.path, baud=115200)},
                    FakeClock())
    await joints.start(poll=False)
    try:
        assert joints.faults == ()  # 0 is "no pulses", not an impossible position
        assert await joints.read_positions("eyes") == {}
        await joints.set_compliant("eyes", False)  # no feedback: each starts from its rest
        assert await joints.read_positions("eyes") == pytest.approx(
            {"left_eyelid": 5.0, "right_eyelid": -5.0}, abs=0.05)
        await joints.move({"left_eyelid": 10.0})
        await joints.set_compliant("left_eyelid", True)
        await joints.set_compliant("left_eyelid", False)  # back where it was last sent
        assert (await joints.read_positions("left_eyelid"))["left_eyelid"] == pytest.approx(
            10.0, abs=0.05)
        statuses = {s.joint: s for s in await joints.survey()}
        assert all(s.healthy for s in statuses.values())
    finally:
        await joints.close()


async def test_a_silent_maestro_is_reported(maestro):
    maestro.faults.all_silent = True
    driver = make_driver("maestro", maestro.path, baud=115200, retries=1)
    await driver.start()
    try:
        assert await driver.ping(0) is None
        with pytest.raises(ServoSilent):
            await driver.read_positions([0, 1])
    finally:
        await driver.close()


async def test_maestro_errors_are_reported_as_flags_not_faults(maestro):
    maestro.faults.error_bits[0] = int(mo.Errors.SERIAL_PROTOCOL)
    driver = make_driver("maestro", maestro.path, baud=115200)
    await driver.start()
    try:
        health = await driver.read_health(0)
        assert health.flags == ("SERIAL_PROTOCOL",) and health.kind is None
    finally:
        await driver.close()
