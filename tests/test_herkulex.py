"""HerkuleX codec: manual examples, checksums, round trips, fuzzing."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hal.errors import CodecError
from hal.servos import herkulex as hx


def test_torque_on_packet_matches_the_manual_layout():
    packet = hx.ram_write(0xFD, hx.Ram.TORQUE_CONTROL, bytes((hx.TorqueControl.ON,)))
    assert packet[:5] == bytes((0xFF, 0xFF, 0x0A, 0xFD, 0x03))
    assert packet[7:] == bytes((52, 1, 0x60))
    cs1 = (0x0A ^ 0xFD ^ 0x03 ^ 52 ^ 1 ^ 0x60) & 0xFE
    assert packet[5:7] == bytes((cs1, ~cs1 & 0xFE))


def test_manual_stat_example():
    # Manual, STAT example: FF FF 07 FD 07 FC 02 asks id 253 for its status.
    assert hx.stat(0xFD) == bytes.fromhex("ff ff 07 fd 07 fc 02")


def test_s_jog_carries_one_play_time_and_four_bytes_per_servo():
    packet = hx.decode_packet(hx.s_jog(60, [(1, 512, 0), (2, 0x3FF, hx.JogSet.GREEN)]))
    assert packet.command == hx.Command.S_JOG and packet.servo_id == hx.BROADCAST_ID
    assert packet.data == bytes((60, 0x00, 0x02, 0, 1, 0xFF, 0x03, 0x04, 2))


def test_i_jog_carries_a_play_time_per_servo():
    packet = hx.decode_packet(hx.i_jog([(3, 100, 0, 10), (4, 200, 0, 20)]))
    assert packet.data == bytes((100, 0, 0, 3, 10, 200, 0, 0, 4, 20))


def test_read_reply_decodes_with_named_status_bits():
    raw = hx.ack(5, hx.Command.RAM_READ, bytes((58, 2, 0x00, 0x02)), 0x14, 0x41)
    reply = hx.decode_ack(raw)
    assert reply.servo_id == 5 and reply.command is hx.Command.RAM_READ
    assert reply.read_value() == (58, b"\x00\x02")
    assert reply.status_error == hx.StatusError.EXCEED_TEMPERATURE | hx.StatusError.OVERLOAD
    assert hx.StatusDetail.MOTOR_ON in reply.status_detail


def test_bad_checksum_and_request_as_reply_are_rejected():
    raw = bytearray(hx.ack(5, hx.Command.STAT, b"", 0, 0))
    raw[5] ^= 0x02
    with pytest.raises(hx.HerkulexError):
        hx.decode_ack(bytes(raw))
    with pytest.raises(hx.HerkulexError):
        hx.decode_ack(hx.stat(5))


def test_builders_refuse_out_of_range_values():
    with pytest.raises(hx.HerkulexError):
        hx.s_jog(256, [(1, 0, 0)])
    with pytest.raises(hx.HerkulexError):
        hx.s_jog(10, [(1, 0x8000, 0)])
    with pytest.raises(hx.HerkulexError):
        hx.ram_write(1, 0, bytes(300))


@given(st.integers(0, 0xFE), st.integers(0, 0xFF), st.binary(max_size=200))
def test_packets_round_trip(servo_id, command, data):
    raw = hx.packet(servo_id, command, data)
    assert hx.packet_length(raw[: hx.HEAD_SIZE]) == len(raw)
    assert hx.decode_packet(raw) == hx.Packet(servo_id, command, data)


@given(st.integers(0, 0xFD), st.sampled_from(list(hx.Command)), st.binary(max_size=100),
       st.integers(0, 0x7F), st.integers(0, 0x7F))
def test_acks_round_trip(servo_id, command, data, error, detail):
    reply = hx.decode_ack(hx.ack(servo_id, command, data, error, detail))
    assert (reply.servo_id, reply.command, reply.data) == (servo_id, command, data)
    assert (int(reply.status_error), int(reply.status_detail)) == (error, detail)


@given(st.binary(max_size=64))
def test_decoders_given_random_bytes_raise_only_their_own_error(raw):
    for decode in (hx.decode_ack, hx.decode_packet, hx.packet_length):
        try:
            decode(raw)
        except hx.HerkulexError:
            pass
        except CodecError as error:  # pragma: no cover
            pytest.fail(f"{decode.__name__} raised {type(error).__name__}")


@given(st.integers(0, 0xFE), st.integers(0, 0xFF), st.binary(max_size=40))
def test_decoders_given_well_framed_random_packets_raise_only_their_own_error(sid, cmd, data):
    raw = hx.packet(sid, cmd, data)
    with contextlib.suppress(hx.HerkulexError):
        hx.decode_ack(raw).read_value()


# --- register values, as the manual and a capture of a real servo give them ----------------


def test_a_captured_position_reply_with_flags_in_its_high_byte_reads_10_bits():
    # A public capture of a DRS servo answering RAM_READ 58 after "move to 10 degrees"
    # and "move to 90 degrees": 0x60 is set in the high byte of each position.
    for capture, degrees in (("ff ff 0d fd 44 b2 4c 3a 02 1f 62 00 42", 10.0),
                             ("ff ff 0d fd 44 be 40 3a 02 13 63 00 42", 90.0)):
        reply = hx.decode_ack(bytes.fromhex(capture))
        address, value = reply.read_value()
        assert address == hx.Ram.CALIBRATED_POSITION and value[1] & 0x60
        assert (hx.position(value) - 512) * 0.325 == pytest.approx(degrees, abs=0.7)
        assert (hx.u16(value) & 0x7FFF) > 1023  # what a 15-bit mask made of it


def test_model_numbers_follow_the_manual_bytes():
    assert hx.model_number(bytes((0x01, 0x01))) == hx.MODEL_DRS_0101
    assert hx.model_number(bytes((0x02, 0x01))) == hx.MODEL_DRS_0201  # Model No1 0x02
    from hal.servos.settings import model_named

    assert model_named(hx.MODEL_DRS_0201, "herkulex") == "drs-0201"
    assert model_named(hx.MODEL_DRS_0101, "herkulex") == "drs-0101"


def test_voltage_and_temperature_conversions_meet_the_manuals_points():
    assert hx.voltage_v(0x5B) == pytest.approx(6.714, abs=0.03)  # Min. Voltage default
    assert hx.voltage_v(0x89) == pytest.approx(10.0, abs=0.2)  # Max. Voltage default
    # The manual's table (tests/test_herkulex_manual.py checks it point by point).
    assert hx.temperature_c(0xDF) == 85.42  # Max. Temperature, as the manual's text gives it
    for celsius in (20.0, 45.0, 65.0, 85.0):
        assert hx.temperature_c(hx.raw_temperature(celsius)) == pytest.approx(celsius, abs=0.7)


# --- the driver over a pty, against the strict emulator -------------------------------------

from emulators.herkulex import HerkulexEmulator, default_position  # noqa: E402
from servo_fixtures import FakeClock, eventually, make_driver  # noqa: E402

from hal.errors import ServoSilent  # noqa: E402
from hal.servos.api import FaultKind  # noqa: E402


@pytest.fixture
def drs(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2, 3]) as emulator:
        yield emulator


@pytest.fixture
async def driver(drs):
    bus_driver = make_driver("herkulex", drs.path, baud=115200)
    await bus_driver.start()
    yield bus_driver
    await bus_driver.close()


async def test_servos_start_at_their_own_positions_read_through_the_high_byte_flags(drs, driver):
    positions = await driver.read_positions([1, 2, 3])
    assert positions == {i: default_position(i) for i in (1, 2, 3)}
    assert len(set(positions.values())) == 3
    assert drs.ram[1][hx.Ram.CALIBRATED_POSITION + 1] & 0x60  # the emulator sends the flags


async def test_ping_is_stat_and_names_the_model(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], models={2: "drs-0201"},
                          ack_policy=0) as emulator:
        driver = make_driver("herkulex", emulator.path, baud=115200)
        await driver.start()
        try:
            assert await driver.ping(1) == hx.MODEL_DRS_0101
            assert await driver.ping(2) == hx.MODEL_DRS_0201
            assert await driver.ping(9) is None
            stats = [p for p in emulator.received if p[4] == hx.Command.STAT]
            assert list(dict.fromkeys(p[3] for p in stats)) == [1, 2, 9]  # 9: with retries
        finally:
            await driver.close()


async def test_the_ack_policy_is_written_to_register_1_by_broadcast_at_start(drs, driver):
    # A broadcast has no reply: start() returns once it is written, maybe before the
    # emulator's thread has read it.
    await eventually(lambda: drs.received)
    (first, *_) = drs.received
    request = hx.decode_packet(first)
    assert request.servo_id == hx.BROADCAST_ID and request.command == hx.Command.RAM_WRITE
    assert request.data == bytes((hx.Ram.ACK_POLICY, 1, hx.AckPolicy.READS_ONLY))
    assert all(s.policy == hx.AckPolicy.READS_ONLY for s in drs.servos.values())
    assert all(s.ram[hx.Ram.TORQUE_CONTROL] == hx.TorqueControl.FREE for s in drs.servos.values())


async def test_servos_left_at_ack_policy_0_answer_after_start(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], ack_policy=0) as emulator:
        driver = make_driver("herkulex", emulator.path, baud=115200, retries=0)
        await driver.start()
        try:
            assert await driver.read_positions([1, 2]) == {1: 511, 2: 514}
            health = await driver.read_health(2)
            assert health.kind is None and health.voltage_v == pytest.approx(7.6, abs=0.1)
        finally:
            await driver.close()


async def test_a_servo_power_cycled_back_to_policy_0_is_told_again_when_it_goes_quiet(drs, driver):
    assert await driver.read_positions([1]) == {1: 511}
    drs.servos[1].ram[hx.Ram.ACK_POLICY] = hx.AckPolicy.NEVER  # its EEP said 0, say
    assert await driver.read_positions([1, 2]) == {1: 511, 2: 514}
    assert drs.servos[1].policy == hx.AckPolicy.READS_ONLY


async def test_servos_left_at_ack_policy_2_cause_no_retries(tmp_path):
    async def exercise(driver):
        for _ in range(5):
            await driver.set_torque([1, 2], True)
            await driver.write_goals({1: (600, 60.0), 2: (400, 60.0)}, 0.02)
            await driver.read_positions([1, 2])
            await driver.set_torque([1, 2], False)
        return driver.retried()

    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], ack_policy=2) as emulator:
        emulator.reply_delay = 0.003
        driver = make_driver("herkulex", emulator.path, baud=115200)
        await driver.start()
        try:
            await exercise(driver)
            # No stale answer read in place of a reply (a late reply on a loaded machine
            # may still be retried: that is the machine, not the protocol).
            assert driver.bus.stats.bad_replies == 0
        finally:
            await driver.close()
    # The same without the policy written: the emulator answers every write, and the
    # answers, arriving a little later as on a real bus, make reads retry (what the
    # driver used to do at start).
    with HerkulexEmulator(tmp_path / "ttyHX2", ids=[1, 2], ack_policy=2) as emulator:
        emulator.reply_delay = 0.003
        careless = make_driver("herkulex", emulator.path, baud=115200)
        careless.bus.greeting = b""  # a driver that never writes the policy
        await careless.bus.start()
        try:
            try:
                troubled = await exercise(careless) > 0
            except ServoSilent:  # the stale answers can even exhaust the retries
                troubled = True
            assert troubled
        finally:
            await careless.close()


async def test_the_ack_policy_is_written_again_after_the_adapter_comes_back(drs, driver):
    await driver.read_positions([1])
    drs.unplug()
    with pytest.raises(Exception):  # noqa: B017 - PortUnavailable or silent, while it is away
        await driver.read_positions([1])
    for servo in drs.servos.values():  # the servos lost power with it
        servo.ram[hx.Ram.ACK_POLICY] = hx.AckPolicy.NEVER
    drs.received.clear()
    drs.plug()

    async def back():
        try:
            return await driver.read_positions([1, 2]) == {1: 511, 2: 514}
        except Exception:
            return False

    await eventually(back)
    first = hx.decode_packet(drs.received[0])
    assert (first.servo_id, first.data[:1]) == (hx.BROADCAST_ID, bytes((hx.Ram.ACK_POLICY,)))


async def test_a_jog_takes_its_play_time_and_the_stop_bit_halts_the_servo(tmp_path):
    clock = FakeClock()
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1], positions={1: 500},
                          clock=clock.now) as emulator:
        driver = make_driver("herkulex", emulator.path, baud=115200)
        await driver.start()
        try:
            await driver.set_torque([1], True)
            playtime = 100  # 1.12 s for 100 units
            await driver.bus.transact(hx.s_jog(playtime, [(1, 600, 0)]))
            assert (await driver.read_positions([1]))[1] == 500
            clock.t += 0.56  # half the play time: half the way
            assert (await driver.read_positions([1]))[1] == pytest.approx(550, abs=1)
            health = await driver.read_health(1)
            assert "MOVING" not in health.flags  # a status, not an error
            await driver.bus.transact(hx.s_jog(playtime, [(1, 600, hx.JogSet.STOP)]))
            await driver.read_positions([1])  # a read behind the jog: the servo has taken it
            clock.t += 2.0
            assert (await driver.read_positions([1]))[1] == pytest.approx(550, abs=1)
            detail = hx.StatusDetail(emulator.ram[1][hx.Ram.STATUS_DETAIL])
            assert hx.StatusDetail.INPOSITION in detail and hx.StatusDetail.MOTOR_ON in detail
        finally:
            await driver.close()


@pytest.mark.parametrize(
    ("bits", "kind"),
    [
        (hx.StatusError.EXCEED_TEMPERATURE, FaultKind.OVERHEATING),
        (hx.StatusError.OVERLOAD, FaultKind.OVERLOAD),
        (hx.StatusError.EXCEED_INPUT_VOLTAGE, FaultKind.VOLTAGE),
        (hx.StatusError.DRIVER_FAULT, FaultKind.HARDWARE),
    ],
)
async def test_status_error_bits_become_fault_kinds_and_release_torque_by_policy(
    drs, driver, bits, kind
):
    await driver.set_torque([2], True)
    await eventually(lambda: drs.torque_on(2))
    drs.latch(2, int(bits))
    health = await driver.read_health(2)
    assert health.kind is kind and bits.name in health.flags and not health.cleared
    assert not drs.torque_on(2)  # the servo's own torque policy (0x35) released it
    await driver.set_torque([2], True)
    assert (await driver.read_health(2)).kind is kind
    assert not drs.torque_on(2)  # and it will not come back on until the error is reset
    await driver.reset_errors([2])
    await driver.set_torque([2], True)
    await eventually(lambda: drs.torque_on(2))


async def test_packet_and_limit_errors_are_cleared_at_once_and_reported(drs, driver):
    drs.latch(3, int(hx.StatusError.INVALID_PACKET))
    health = await driver.read_health(3)
    assert health.kind is None and health.cleared == ("INVALID_PACKET",)
    await eventually(lambda: drs.servos[3].latched == 0)  # the LED stops blinking


async def test_an_eep_read_beyond_the_map_latches_an_invalid_packet(drs, driver):
    await driver.bus.transact(hx.eep_read(1, 50, 10))  # 50..59: the map ends at 53
    health = await driver.read_health(1)
    assert "INVALID_PACKET" in health.flags and "EXCEED_REG_RANGE" in health.flags
    model = await driver.bus.transact(
        hx.eep_read(1, hx.Eep.MAX_TEMPERATURE, 1), 1, driver.framing,
        lambda packets: hx.decode_ack(packets[0]).read_value(), 14)
    assert model == (hx.Eep.MAX_TEMPERATURE, bytes((0xDE,)))  # the default column's


async def test_temperature_and_the_servos_own_limit_are_read_in_degrees(drs, driver):
    drs.set_temperature(1, 52.0)
    health = await driver.read_health(1)
    assert health.temperature_c == pytest.approx(52.0, abs=0.5)
    assert health.temperature_limit_c == 84.11  # RAM 5, copied from EEP 11 (0xDE)


@pytest.mark.parametrize("fault", ["silent", "bad_checksum", "wrong_id"])
async def test_faulty_replies_end_as_a_named_silent_servo(drs, fault):
    if fault == "wrong_id":
        drs.faults.wrong_id[3] = 1
    else:
        getattr(drs.faults, fault).add(3)
    driver = make_driver("herkulex", drs.path, baud=115200, retries=1)
    await driver.start()
    try:
        with pytest.raises(ServoSilent) as caught:
            await driver.read_positions([1, 3])
        assert caught.value.servo_id == 3
    finally:
        await driver.close()


async def test_replies_the_bus_had_to_retry_are_logged_once_per_poll_with_their_count(drs):
    # Found by the soak: a corrupt reply that a retry absorbed left no trace at all,
    # so a failing cable would go unnoticed until it stopped a session.
    import structlog

    from hal.clock import MonotonicClock
    from hal.servos.joints import Joints
    from hal.servos.settings import BusSettings, JointSettings, ServoSettings

    settings = ServoSettings(
        buses=(BusSettings(name="head", port=str(drs.path), protocol="herkulex", baud=115200),),
        joints=(
            JointSettings(name="head_yaw", bus="head", id=1, model="drs-0101",
                          range_deg=(-60.0, 60.0), max_speed_dps=60.0, group="head"),
        ),
    )
    driver = make_driver("herkulex", drs.path, baud=115200)
    joints = Joints(settings, {"head": driver}, MonotonicClock())
    await joints.start(poll=False)
    try:
        with structlog.testing.capture_logs() as logs:
            await joints.poll_health()
            drs.faults.corrupt_next = 2  # both absorbed: the bus retries twice
            await joints.poll_health()
            await joints.poll_health()
        retried = [entry for entry in logs if entry["event"] == "bus replies retried"]
        assert [(r["bus"], r["count"]) for r in retried] == [("head", 2)]
        assert joints.faults == ()  # absorbed: the game never saw it
    finally:
        await joints.close()
