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


# --- the driver over a pty, against the emulator ------------------------------------------

from emulators.herkulex import HerkulexEmulator  # noqa: E402
from servo_fixtures import eventually, make_driver  # noqa: E402

from hal.errors import ServoSilent  # noqa: E402
from hal.servos.api import FaultKind  # noqa: E402


@pytest.fixture
def drs(tmp_path):
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2, 3]) as emulator:
        yield emulator


async def test_driver_pings_jogs_and_reads_positions(drs):
    driver = make_driver("herkulex", drs.path, baud=115200)
    await driver.start()
    try:
        assert await driver.ping(1) == 0x0101
        assert await driver.ping(9) is None
        await driver.set_torque([1, 2], True)
        await driver.write_goals({1: (600, 60.0), 2: (400, 60.0)}, 0.02)
        await eventually(lambda: [p for p in drs.received if p[4] == hx.Command.S_JOG])
        jogs = [p for p in drs.received if p[4] == hx.Command.S_JOG]

        async def arrived():
            return await driver.read_positions([1, 2, 3]) == {1: 600, 2: 400, 3: 512}

        await eventually(arrived)
        jog = hx.decode_packet(jogs[0])
        assert jog.command == hx.Command.S_JOG and jog.data[0] == 2  # 20 ms ~ 2 x 11.2 ms
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
async def test_status_error_bits_become_fault_kinds(drs, bits, kind):
    drs.faults.error_bits[2] = int(bits)
    driver = make_driver("herkulex", drs.path, baud=115200)
    await driver.start()
    try:
        health = await driver.read_health(2)
        assert health.kind is kind and bits.name in health.flags
    finally:
        await driver.close()


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
