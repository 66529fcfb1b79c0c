"""Our Dynamixel drivers and the ROBOTIS SDK, both against the same pty emulators."""

from __future__ import annotations

import dynamixel_sdk as sdk
import pytest
from emulators.dynamixel import Dynamixel1Emulator, Dynamixel2Emulator
from servo_fixtures import eventually, make_driver

from hal.errors import ServoSilent
from hal.servos import dynamixel1 as dx1
from hal.servos import dynamixel2 as dx2
from hal.servos.api import FaultKind


@pytest.fixture
def ax12(tmp_path):
    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2, 3]) as emulator:
        yield emulator


@pytest.fixture
def xl430(tmp_path):
    with Dynamixel2Emulator(tmp_path / "ttyXL", ids=[1, 2, 3]) as emulator:
        yield emulator


def sdk_port(emulator):
    port = sdk.PortHandler(str(emulator.path))
    assert port.setBaudRate(1000000)
    return port


def test_sdk_pings_reads_and_sync_writes_the_protocol1_emulator(ax12):
    port, handler = sdk_port(ax12), sdk.PacketHandler(1.0)
    try:
        model, result, error = handler.ping(port, 2)
        assert (model, result, error) == (12, sdk.COMM_SUCCESS, 0)
        _, result, _ = handler.ping(port, 9)
        assert result == sdk.COMM_RX_TIMEOUT
        handler.write1ByteTxRx(port, 2, 24, 1)
        group = sdk.GroupSyncWrite(port, handler, 30, 2)
        group.addParam(2, [0x00, 0x02])
        group.addParam(3, [0x10, 0x02])
        assert group.txPacket() == sdk.COMM_SUCCESS
        position, result, _ = handler.read2ByteTxRx(port, 3, 30)
        assert (position, result) == (0x210, sdk.COMM_SUCCESS)
    finally:
        port.closePort()


def test_sdk_pings_sync_reads_and_writes_the_protocol2_emulator(xl430):
    port, handler = sdk_port(xl430), sdk.PacketHandler(2.0)
    try:
        model, result, _ = handler.ping(port, 1)
        assert (model, result) == (1060, sdk.COMM_SUCCESS)
        handler.write4ByteTxRx(port, 1, 116, 3000)
        value, result, _ = handler.read4ByteTxRx(port, 1, 116)
        assert (value, result) == (3000, sdk.COMM_SUCCESS)
        group = sdk.GroupSyncRead(port, handler, 132, 4)
        for servo_id in (1, 2, 3):
            group.addParam(servo_id)
        assert group.txRxPacket() == sdk.COMM_SUCCESS
        assert group.getData(2, 132, 4) == 2048
    finally:
        port.closePort()


@pytest.mark.parametrize("protocol", ["dynamixel1", "dynamixel2"])
async def test_driver_pings_moves_and_reads_over_the_pty(tmp_path, protocol):
    emulator_type = Dynamixel1Emulator if protocol == "dynamixel1" else Dynamixel2Emulator
    centre = 512 if protocol == "dynamixel1" else 2048
    with emulator_type(tmp_path / "tty", ids=[1, 2, 3]) as emulator:
        driver = make_driver(protocol, emulator.path)
        await driver.start()
        try:
            assert await driver.ping(2) == (12 if protocol == "dynamixel1" else 1060)
            assert await driver.ping(7) is None
            assert await driver.read_positions([1, 2, 3]) == {1: centre, 2: centre, 3: centre}
            await driver.set_torque([1, 2], True)
            await driver.write_goals({1: (centre + 20, 100.0), 2: (centre - 20, 100.0)}, 0.02)
            codec = dx1 if protocol == "dynamixel1" else dx2
            goal = bytes((30,)) if protocol == "dynamixel1" else dx2.le16(116)

            def goal_writes():
                packets = [codec.decode_instruction(p) for p in emulator.received]
                return [p for p in packets if p.params.startswith(goal)]

            await eventually(goal_writes)
            (write,) = goal_writes()  # one packet for both servos
            assert write.instruction == codec.Instruction.SYNC_WRITE
            expected = {1: centre + 20, 2: centre - 20, 3: centre}

            async def arrived():
                return await driver.read_positions([1, 2, 3]) == expected

            await eventually(arrived)
            health = await driver.read_health(1)
            assert health.kind is None and health.temperature_c is not None
        finally:
            await driver.close()


async def test_protocol2_reads_all_positions_with_one_sync_read(xl430):
    driver = make_driver("dynamixel2", xl430.path)
    await driver.start()
    try:
        before = len(xl430.received)
        await driver.read_positions([1, 2, 3])
        assert len(xl430.received) == before + 1
        assert xl430.received[-1][7] == dx2.Instruction.SYNC_READ
    finally:
        await driver.close()


async def test_protocol2_names_the_silent_servo_of_a_sync_read(xl430):
    xl430.faults.silent.add(2)
    driver = make_driver("dynamixel2", xl430.path, retries=1)
    await driver.start()
    try:
        with pytest.raises(ServoSilent) as caught:
            await driver.read_positions([1, 2, 3])
        assert caught.value.servo_id == 2
    finally:
        await driver.close()


async def test_protocol1_goal_write_carries_a_nonzero_speed_limit(ax12):
    driver = make_driver("dynamixel1", ax12.path)
    await driver.start()
    try:
        await driver.write_goals({1: (600, 0.01)}, 0.02)
        await eventually(lambda: ax12.received)
        packet = dx1.decode_instruction(ax12.received[-1])
        assert packet.instruction == dx1.Instruction.SYNC_WRITE
        assert packet.params == bytes((30, 4, 1)) + dx1.le16(600) + dx1.le16(1)
    finally:
        await driver.close()


@pytest.mark.parametrize(
    ("bits", "kind"),
    [
        (dx1.ErrorBits.OVERHEATING, FaultKind.OVERHEATING),
        (dx1.ErrorBits.OVERLOAD, FaultKind.OVERLOAD),
        (dx1.ErrorBits.INPUT_VOLTAGE, FaultKind.VOLTAGE),
    ],
)
async def test_protocol1_error_bits_become_named_fault_kinds(ax12, bits, kind):
    ax12.faults.error_bits[3] = int(bits)
    driver = make_driver("dynamixel1", ax12.path)
    await driver.start()
    try:
        health = await driver.read_health(3)
        assert health.kind is kind and bits.name in health.flags
    finally:
        await driver.close()


async def test_protocol2_alert_reads_the_hardware_error_status(xl430):
    xl430.faults.error_bits[1] = int(dx2.HardwareError.OVERLOAD)
    driver = make_driver("dynamixel2", xl430.path)
    await driver.start()
    try:
        health = await driver.read_health(1)
        assert health.kind is FaultKind.OVERLOAD and health.flags == ("OVERLOAD",)
    finally:
        await driver.close()


async def test_protocol2_reset_reboots_the_servo_and_clears_its_hardware_error(xl430):
    xl430.faults.error_bits[2] = int(dx2.HardwareError.OVERHEATING)
    driver = make_driver("dynamixel2", xl430.path)
    await driver.start()
    try:
        assert (await driver.read_health(2)).kind is FaultKind.OVERHEATING
        await driver.reset_errors([2])
        assert xl430.received[-1] == dx2.reboot(2)
        assert (await driver.read_health(2)).kind is None
    finally:
        await driver.close()


async def test_an_ax12_at_status_return_level_0_is_named_not_missing(tmp_path):
    from emulators.dynamixel import Dynamixel1Emulator
    from servo_fixtures import make_driver

    from hal.servos import dynamixel1 as dx1

    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1]) as emulator:
        emulator.tables[1][dx1.AX12.STATUS_RETURN_LEVEL] = 0  # answers PING only
        driver = make_driver("dynamixel1", emulator.path, retries=0)
        await driver.start()
        try:
            assert await driver.ping(1) == 0
            assert await driver.ping(2) is None
        finally:
            await driver.close()
