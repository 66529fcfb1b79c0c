"""The bus: deadlines from the baud rate, bounded retries, every injected fault, unplug and return."""

from __future__ import annotations

import asyncio

import pytest
from emulators.dynamixel import Dynamixel1Emulator
from servo_fixtures import make_driver

from hal.errors import BusClosed, InvalidArgument, PortUnavailable, ServoSilent
from hal.servos import dynamixel1 as dx1
from hal.servos.bus import BusState, SerialBus, wire_time


@pytest.fixture
def ax12(tmp_path):
    with Dynamixel1Emulator(tmp_path / "ttyUSB-kaspar", ids=[1, 2]) as emulator:
        yield emulator


@pytest.fixture
async def driver(ax12):
    driver = make_driver("dynamixel1", ax12.path, retries=2)
    await driver.start()
    yield driver
    await driver.close()


def test_deadline_grows_with_packet_length_and_falls_with_baud():
    slow = SerialBus("b", "/dev/null", 57600, timeout_margin=0.005)
    fast = SerialBus("b", "/dev/null", 1_000_000, timeout_margin=0.005)
    assert wire_time(8 + 8, 57600) == pytest.approx(16 * 10 / 57600)
    assert slow.transaction_timeout(8, 8, 1) == pytest.approx(16 * 10 / 57600 + 0.005)
    assert fast.transaction_timeout(8, 8, 1) < slow.transaction_timeout(8, 8, 1)
    assert slow.transaction_timeout(8, 800, 1) > slow.transaction_timeout(8, 8, 1)
    assert slow.transaction_timeout(8, 8, 17) == pytest.approx(16 * 10 / 57600 + 17 * 0.005)


async def test_a_silent_servo_is_retried_then_named(ax12, driver):
    ax12.faults.silent.add(2)
    with pytest.raises(ServoSilent) as caught:
        await driver.read_positions([1, 2])
    assert caught.value.servo_id == 2
    assert driver.bus.stats.retries == 2 and driver.bus.stats.timeouts == 1
    assert await driver.read_positions([1]) == {1: 512}  # the bus is still usable


async def test_a_dropped_reply_is_recovered_by_a_retry(ax12, driver):
    ax12.faults.drop_next = 1
    assert await driver.read_positions([1]) == {1: 512}
    assert driver.bus.stats.retries >= 1


async def test_one_corrupt_reply_is_recovered_by_a_retry(ax12, driver):
    ax12.faults.corrupt_next = 1
    assert await driver.read_positions([2]) == {2: 512}
    assert driver.bus.stats.retries >= 1


async def test_persistent_bad_checksums_end_as_a_silent_servo(ax12, driver):
    ax12.faults.bad_checksum.add(1)
    with pytest.raises(ServoSilent) as caught:
        await driver.read_positions([1])
    assert caught.value.servo_id == 1 and "checksum" in str(caught.value)


async def test_a_reply_from_the_wrong_id_is_not_taken_for_the_right_one(ax12, driver):
    ax12.faults.wrong_id[1] = 2
    with pytest.raises(ServoSilent) as caught:
        await driver.read_positions([1])
    assert caught.value.servo_id == 1 and "id 2" in str(caught.value)


async def test_garbage_before_a_reply_is_survived(ax12, driver):
    ax12.port.write(b"\x00\x13\xff")  # line noise the driver must flush, not parse
    assert await driver.read_positions([1, 2]) == {1: 512, 2: 512}


async def test_unplug_is_reported_and_the_bus_resumes_when_the_port_returns(ax12, driver):
    states = []
    driver.bus.on_state = states.append
    assert await driver.read_positions([1]) == {1: 512}

    ax12.unplug()
    with pytest.raises(PortUnavailable):
        await driver.read_positions([1])
    assert driver.bus.state is BusState.DISCONNECTED
    with pytest.raises(PortUnavailable):  # fails at once while away, does not hang
        await driver.read_positions([1])

    ax12.plug()
    assert await driver.bus.wait_state(BusState.CONNECTED, timeout=10)
    assert await driver.read_positions([1, 2]) == {1: 512, 2: 512}
    assert states == [BusState.DISCONNECTED, BusState.CONNECTED]
    assert driver.bus.stats.disconnects == 1 and driver.bus.stats.reconnects == 1


async def test_unplug_during_writes_is_reported_too(ax12, driver):
    ax12.unplug()
    with pytest.raises(PortUnavailable):
        for _ in range(5):  # the first write may still land in the tty buffer
            await driver.set_torque([1], True)
            await driver.read_positions([1])
    ax12.plug()
    assert await driver.bus.wait_state(BusState.CONNECTED, timeout=10)
    await driver.set_torque([1], True)


async def test_a_bus_whose_port_is_missing_at_start_connects_when_it_appears(tmp_path):
    path = tmp_path / "ttyLATE"
    bus = SerialBus("late", str(path), 1_000_000, timeout_margin=0.1, backoff_initial=0.02,
                    backoff_max=0.1)
    await bus.start()
    try:
        assert bus.state is BusState.DISCONNECTED
        with pytest.raises(PortUnavailable):
            await bus.transact(dx1.ping(1))
        with Dynamixel1Emulator(path, ids=[1]):
            assert await bus.wait_state(BusState.CONNECTED, timeout=10)
            packets = await bus.transact(dx1.ping(1), 1, make_driver("dynamixel1", path).framing)
            assert dx1.decode_status(packets[0]).servo_id == 1
    finally:
        await bus.close()


async def test_the_port_is_opened_exclusively(ax12, driver):
    other = make_driver("dynamixel1", ax12.path)
    await other.start()
    try:
        assert other.bus.state is BusState.DISCONNECTED  # the first bus holds the port
    finally:
        await other.close()


async def test_closed_bus_refuses_work(ax12):
    driver = make_driver("dynamixel1", ax12.path)
    await driver.start()
    await driver.close()
    with pytest.raises(BusClosed):
        await driver.read_positions([1])


async def test_replies_without_a_framing_are_refused_before_anything_is_sent(ax12, driver):
    with pytest.raises(InvalidArgument, match="replies need a framing"):
        await driver.bus.transact(dx1.ping(1), replies=1)
    assert driver.bus.stats.transactions == 0


async def test_the_loop_is_never_blocked_by_a_slow_transaction(ax12, driver):
    ax12.faults.silent.add(1)
    ticks = 0

    async def ticker():
        nonlocal ticks
        while True:
            await asyncio.sleep(0.01)
            ticks += 1

    task = asyncio.create_task(ticker())
    with pytest.raises(ServoSilent):
        await driver.read_positions([1])  # about 3 x 0.1 s of waiting, all on the bus thread
    task.cancel()
    assert ticks >= 5


async def test_a_cancellation_that_lands_with_the_reply_still_cancels(ax12, driver, monkeypatch):
    # Found by the soak: with asyncio.wait_for on Python 3.11, a pause arriving in the
    # same loop turn as a servo's reply was dropped, the game step carried on, and the
    # game waited for ever for that step to end.
    from hal.servos import bus as bus_module

    loop = asyncio.get_running_loop()
    reader: asyncio.Task | None = None
    settle = bus_module._Job.resolve

    def settle_then_cancel(self, result=None, error=None) -> None:
        def on_loop() -> None:
            # Both queued from the loop in one callback, so nothing runs between them:
            # the reply, then the cancellation, in the same loop turn.
            settle(self, result, error)
            loop.call_soon(reader.cancel)

        loop.call_soon_threadsafe(on_loop)

    monkeypatch.setattr(bus_module._Job, "resolve", settle_then_cancel)
    reader = asyncio.create_task(driver.read_positions([1]))
    with pytest.raises(asyncio.CancelledError):
        await reader
    monkeypatch.undo()
    assert 1 in await driver.read_positions([1])  # the bus is still fine
