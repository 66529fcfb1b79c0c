"""Dynamixel Protocol 1.0 and 2.0 codecs: byte equality with dynamixel-sdk, round trips, fuzzing."""

from __future__ import annotations

import contextlib

import dynamixel_sdk as sdk
import pytest
from emulators.pty_port import PtyPort
from hypothesis import given
from hypothesis import strategies as st

from hal.errors import CodecError
from hal.servos import dynamixel1 as dx1
from hal.servos import dynamixel2 as dx2


@pytest.fixture
def sdk_port(tmp_path):
    """A dynamixel-sdk PortHandler on a pty whose master we read: what the SDK puts on the wire."""
    pty = PtyPort(tmp_path / "ttyDXL")
    port = sdk.PortHandler(str(pty.path))
    assert port.setBaudRate(57600)
    yield port, pty
    port.closePort()
    pty.close()


def wire(pty: PtyPort) -> bytes:
    data = b""
    while chunk := pty.read_available(0.2):
        data += chunk
    return data


@pytest.mark.parametrize("version", [1.0, 2.0])
def test_ping_read_write_sync_write_match_the_sdk_byte_for_byte(sdk_port, version):
    port, pty = sdk_port
    codec = dx1 if version == 1.0 else dx2
    handler = sdk.PacketHandler(version)
    goal = 30 if version == 1.0 else 116
    width = 2 if version == 1.0 else 4

    handler.ping(port, 7)  # no servo answers: only the request goes out
    assert wire(pty) == codec.ping(7)

    handler.readTx(port, 7, goal, width)
    assert wire(pty) == codec.read(7, goal, width)
    port.is_using = False  # readTx leaves the SDK's flag set until a readRx that never comes

    handler.writeTxOnly(port, 7, goal, width, [0x34, 0x12, 0, 0][:width])
    assert wire(pty) == codec.write(7, goal, bytes([0x34, 0x12, 0, 0][:width]))

    group = sdk.GroupSyncWrite(port, handler, goal, width)
    values = {1: 0x0200, 2: 0x03FF, 17: 0x0001}
    for servo_id, value in values.items():
        assert group.addParam(servo_id, list(value.to_bytes(width, "little")))
    group.txPacket()
    expected = codec.sync_write(goal, width, {i: v.to_bytes(width, "little") for i, v in values.items()})
    assert wire(pty) == expected


def test_protocol2_byte_stuffing_follows_the_manual_where_the_sdk_does_not(sdk_port):
    port, pty = sdk_port
    handler = sdk.PacketHandler(2.0)
    # A goal whose bytes hold FF FF FD must be sent as FF FF FD FD (e-manual, Protocol 2.0,
    # byte stuffing). The SDK's addStuffing builds the stuffed packet in a new list that its
    # txPacket never sends, so it puts the unstuffed packet on the wire; we do not copy that.
    handler.writeTxOnly(port, 3, 116, 4, [0xFF, 0xFF, 0xFD, 0x00])
    sent = wire(pty)
    body = bytes((dx2.Instruction.WRITE,)) + dx2.le16(116) + b"\xff\xff\xfd\x00"
    unstuffed = dx2.HEADER + bytes((3,)) + dx2.le16(len(body) + 2) + body
    assert sent == unstuffed + dx2.le16(dx2.crc16(unstuffed))
    ours = dx2.write(3, 116, b"\xff\xff\xfd\x00")
    assert ours[7:-2] == dx2.stuff(body) and b"\xff\xff\xfd\xfd" in ours
    assert dx2.decode_instruction(ours).params == dx2.le16(116) + b"\xff\xff\xfd\x00"


def test_protocol2_packets_without_the_pattern_need_no_stuffing(sdk_port):
    port, pty = sdk_port
    handler = sdk.PacketHandler(2.0)
    handler.writeTxOnly(port, 3, 116, 4, [0xFF, 0xFF, 0x00, 0xFD])
    assert wire(pty) == dx2.write(3, 116, b"\xff\xff\x00\xfd")


def test_protocol2_sync_read_and_reboot_encode_as_the_sdk(sdk_port):
    port, pty = sdk_port
    handler = sdk.PacketHandler(2.0)
    group = sdk.GroupSyncRead(port, handler, 132, 4)
    for servo_id in (1, 2, 3):
        group.addParam(servo_id)
    group.txPacket()
    assert wire(pty) == dx2.sync_read(132, 4, [1, 2, 3])
    port.is_using = False
    handler.reboot(port, 5)
    assert wire(pty) == dx2.reboot(5)


def test_protocol1_known_packet_from_the_manual():
    # AX-12A e-manual example: read the internal temperature of id 1.
    assert dx1.read(1, 0x2B, 1) == bytes.fromhex("ff ff 01 04 02 2b 01 cc")
    status = dx1.decode_status(bytes.fromhex("ff ff 01 03 00 20 db"))
    assert status.servo_id == 1 and status.error == 0 and status.params == b"\x20"


def test_protocol1_error_bits_are_named():
    status = dx1.decode_status(dx1.status(4, 0x24, b""))
    assert status.error == dx1.ErrorBits.OVERHEATING | dx1.ErrorBits.OVERLOAD


def test_protocol2_crc_known_value():
    # e-manual 2.0 example: PING id 1 is FF FF FD 00 01 03 00 01 19 4E.
    assert dx2.ping(1) == bytes.fromhex("ff ff fd 00 01 03 00 01 19 4e")


def test_protocol2_status_alert_and_error_number():
    status = dx2.decode_status(dx2.status(9, 0x80 | 4, b"\x01\x02"))
    assert status.alert and status.error is dx2.ErrorNumber.DATA_RANGE
    assert status.params == b"\x01\x02"


@pytest.mark.parametrize("codec", [dx1, dx2])
def test_corrupt_checksum_is_rejected(codec):
    packet = bytearray(codec.status(1, 0, b"\x10\x20"))
    packet[-1] ^= 0x01
    with pytest.raises(codec.DynamixelError):
        codec.decode_status(bytes(packet))


def test_builders_refuse_values_that_do_not_fit():
    with pytest.raises(dx1.DynamixelError):
        dx1.read(300, 36, 2)
    with pytest.raises(dx1.DynamixelError):
        dx1.sync_write(30, 2, {1: b"\x00"})
    with pytest.raises(dx2.DynamixelError):
        dx2.sync_read(132, 4, [0xFE])


payloads = st.binary(max_size=40)
ids = st.integers(0, 0xFC)


@given(ids, st.integers(0, 0x7F), payloads)
def test_protocol1_status_round_trips(servo_id, error, params):
    status = dx1.decode_status(dx1.status(servo_id, error, params))
    assert (status.servo_id, int(status.error), status.params) == (servo_id, error, params)


@given(ids, st.integers(0, 0xFF), payloads)
def test_protocol1_instruction_round_trips(servo_id, instruction, params):
    packet = dx1.decode_instruction(dx1.instruction(servo_id, instruction, params))
    assert (packet.servo_id, packet.instruction, packet.params) == (servo_id, instruction, params)


@given(ids, st.integers(0, 0xFF), st.binary(max_size=60))
def test_protocol2_instruction_round_trips_through_stuffing(servo_id, instruction, params):
    packet = dx2.decode_instruction(dx2.instruction(servo_id, instruction, params))
    assert (packet.servo_id, packet.instruction, packet.params) == (servo_id, instruction, params)


@given(ids, st.integers(0, 7), st.booleans(), st.binary(max_size=60))
def test_protocol2_status_round_trips(servo_id, error, alert, params):
    raw = dx2.status(servo_id, error | (0x80 if alert else 0), params)
    assert dx2.packet_length(raw[: dx2.HEAD_SIZE]) == len(raw)
    status = dx2.decode_status(raw)
    assert (status.servo_id, status.error, status.alert, status.params) == (
        servo_id, error, alert, params,
    )


@given(st.binary(max_size=80))
def test_unstuff_undoes_stuff(payload):
    assert dx2.unstuff(dx2.stuff(payload)) == payload
    assert b"\xff\xff\xfd" not in dx2.stuff(payload).replace(b"\xff\xff\xfd\xfd", b"")


@pytest.mark.parametrize("codec", [dx1, dx2])
@given(raw=st.binary(max_size=64))
def test_decoders_given_random_bytes_raise_only_their_own_error(codec, raw):
    for decode in (codec.decode_status, codec.decode_instruction, codec.packet_length):
        try:
            decode(raw)
        except codec.DynamixelError:
            pass
        except CodecError as error:  # pragma: no cover - would be a family mix-up
            pytest.fail(f"{decode.__name__} raised {type(error).__name__}")


@pytest.mark.parametrize("codec", [dx1, dx2])
@given(data=st.data())
def test_decoders_given_framed_random_bodies_raise_only_their_own_error(codec, data):
    # Random bytes almost never pass the header check; these do, and reach deeper code.
    body = data.draw(st.binary(max_size=30))
    raw = codec.instruction(data.draw(st.integers(0, 0xFE)), data.draw(st.integers(0, 255)), body)
    with contextlib.suppress(codec.DynamixelError):
        codec.decode_status(raw)
