"""The keyfob reader over evdev's real parsing (a pipe-backed device) and real inotify."""

from __future__ import annotations

import asyncio
import os
from pathlib import Path

import pytest
from evdev import ecodes
from evdev_pipe import ManualClock, PipeBank, pack

from hal.clock import MonotonicClock
from hal.errors import KeyfobError, SettingsError
from hal.keyfob.api import KeyfobBack, KeyfobLost
from hal.keyfob.gestures import ANSWERS_ONLY, RESEARCHER_GESTURES, Gesture, GestureKind
from hal.keyfob.reader import Keyfob
from hal.keyfob.settings import KeyfobSettings, key_code

GREEN, RED, PAUSE = ecodes.KEY_PAGEDOWN, ecodes.KEY_PAGEUP, ecodes.KEY_P
NODE = "kaspar-keyfob"
WAIT = 10.0  # generous: a busy CI machine must never fail these


@pytest.fixture
def bank(tmp_path: Path):
    bank = PipeBank(tmp_path)
    yield bank
    bank.dispose()


def settings_for(directory: Path, **overrides) -> KeyfobSettings:
    values = {"device": str(directory / NODE), "commands": {"KEY_P": "pause"}, **overrides}
    return KeyfobSettings(**values)


async def started(bank: PipeBank, clock=None, needs=RESEARCHER_GESTURES, **overrides) -> Keyfob:
    keyfob = Keyfob(
        settings_for(bank.directory, **overrides),
        clock or MonotonicClock(),
        needs=needs,
        opener=bank.open,
        input_dir=str(bank.directory),
        retry_every=0.5,
    )
    await keyfob.start()
    return keyfob


async def next_event(keyfob: Keyfob, timeout: float = WAIT):
    return await asyncio.wait_for(keyfob.next_event(), timeout)


async def assert_quiet(keyfob: Keyfob, for_seconds: float = 0.2) -> None:
    with pytest.raises(TimeoutError):
        event = await asyncio.wait_for(keyfob.next_event(), for_seconds)
        pytest.fail(f"unexpected {event}")


def kinds(*events) -> list[tuple[str, str]]:
    return [(e.kind.value, e.button) for e in events]


def registered_readers(callback) -> list[int]:
    selector = asyncio.get_running_loop()._selector  # type: ignore[attr-defined]
    found = []
    for key in selector.get_map().values():
        reader = key.data[0]
        if reader is not None and getattr(reader, "_callback", None) == callback:
            found.append(key.fd)
    return found


async def test_press_is_read_through_evdev_and_delivered_at_key_down(bank):
    device = bank.plug(NODE)
    keyfob = await started(bank, needs=ANSWERS_ONLY)
    try:
        assert keyfob.connected and device.grabbed
        device.down(GREEN)
        gesture = await next_event(keyfob)
        assert isinstance(gesture, Gesture)
        assert kinds(gesture) == [("press", "green")]
        assert gesture.decided == gesture.at
        device.up(GREEN, 0.1)
        await assert_quiet(keyfob)
    finally:
        await keyfob.close()


async def test_autorepeat_is_ignored(bank):
    device = bank.plug(NODE)
    keyfob = await started(bank, needs=ANSWERS_ONLY)
    try:
        device.events((RED, 1, 0.0), *[(RED, 2, 0.033)] * 10, (RED, 0, 0.033))
        assert kinds(await next_event(keyfob)) == [("press", "red")]
        await assert_quiet(keyfob)
    finally:
        await keyfob.close()


async def test_bounce_in_one_batch_is_one_press(bank):
    device = bank.plug(NODE)
    keyfob = await started(bank, needs=ANSWERS_ONLY)
    try:
        # Down, then a 3 ms flicker, all read as one batch: the kernel's spacing decides.
        device.events((GREEN, 1, 0.0), (GREEN, 0, 0.003), (GREEN, 1, 0.003), (GREEN, 0, 0.12))
        assert kinds(await next_event(keyfob)) == [("press", "green")]
        await assert_quiet(keyfob)
        # The same pattern with a real gap is two presses.
        device.events((GREEN, 1, 0.5), (GREEN, 0, 0.1), (GREEN, 1, 0.1), (GREEN, 0, 0.1))
        assert kinds(await next_event(keyfob), await next_event(keyfob)) == [
            ("press", "green"),
            ("press", "green"),
        ]
    finally:
        await keyfob.close()


async def test_unknown_keys_and_other_events_change_nothing(bank):
    device = bank.plug(NODE)
    keyfob = await started(bank, needs=ANSWERS_ONLY)
    try:
        device.write_raw(pack(1.0, ecodes.EV_REL, ecodes.REL_X, 5) + pack(1.0, ecodes.EV_SYN, 0, 0))
        device.events((ecodes.KEY_A, 1, 0.0), (GREEN, 1, 0.01), (ecodes.KEY_A, 0, 0.01))
        assert kinds(await next_event(keyfob)) == [("press", "green")]
        device.events((ecodes.KEY_A, 1, 0.1), (ecodes.KEY_A, 0, 0.1))
        await assert_quiet(keyfob)
    finally:
        await keyfob.close()


async def test_command_key_is_a_command(bank):
    device = bank.plug(NODE)
    keyfob = await started(bank)
    try:
        device.down(PAUSE)
        assert kinds(await next_event(keyfob)) == [("command", "pause")]
    finally:
        await keyfob.close()


async def test_long_press_is_delivered_by_the_clock_at_the_threshold(bank):
    device = bank.plug(NODE)
    clock = ManualClock()
    keyfob = await started(bank, clock=clock)
    try:
        device.down(GREEN)
        await asyncio.sleep(0.05)  # let the reader run; the clock does not move
        await clock.advance(0.99)
        await assert_quiet(keyfob, 0.1)
        await clock.advance(0.02)
        gesture = await next_event(keyfob)
        assert kinds(gesture) == [("long", "green")]
        assert gesture.at == pytest.approx(100.0)
        assert gesture.decided == pytest.approx(101.0)
        device.up(GREEN, 1.5)
        await clock.advance(5.0)
        await assert_quiet(keyfob, 0.1)
    finally:
        await keyfob.close()


async def test_double_red_and_both_held(bank):
    device = bank.plug(NODE)
    clock = ManualClock()
    keyfob = await started(bank, clock=clock)
    try:
        device.events((RED, 1, 0.0), (RED, 0, 0.1), (RED, 1, 0.15), (RED, 0, 0.1))
        double = await next_event(keyfob)
        assert kinds(double) == [("double", "red")]
        await clock.advance(2.0)  # the manual clock moves only when told
        device.events((GREEN, 1, 2.0), (RED, 1, 0.1))
        await asyncio.sleep(0.05)
        await clock.advance(1.0)
        assert kinds(await next_event(keyfob)) == [("both", "both")]
        device.events((GREEN, 0, 0.1), (RED, 0, 0.0))
        await clock.advance(5.0)
        await assert_quiet(keyfob, 0.1)
    finally:
        await keyfob.close()


async def test_unplug_reports_lost_removes_the_reader_and_reopens_on_return(bank):
    device = bank.plug(NODE)
    keyfob = await started(bank, needs=ANSWERS_ONLY)
    try:
        assert registered_readers(keyfob._on_readable) == [device.fd]
        # A complete press and a key still held when the plug is pulled.
        device.events((GREEN, 1, 0.0), (GREEN, 0, 0.1), (RED, 1, 0.1))
        bank.unplug(NODE)
        events = [await next_event(keyfob) for _ in range(3)]
        assert kinds(*events[:2]) == [("press", "green"), ("press", "red")]
        lost = events[2]
        assert isinstance(lost, KeyfobLost) and "ENODEV" in lost.reason
        assert not keyfob.connected and device.closed
        assert registered_readers(keyfob._on_readable) == []

        again = bank.plug(NODE)
        back = await next_event(keyfob)
        assert isinstance(back, KeyfobBack) and back.device.endswith(NODE)
        assert keyfob.connected and again.grabbed
        assert registered_readers(keyfob._on_readable) == [again.fd]
        again.down(RED)
        assert kinds(await next_event(keyfob)) == [("press", "red")]
    finally:
        await keyfob.close()
    assert registered_readers(keyfob._on_readable) == []


async def test_held_key_is_forgotten_when_the_keyfob_is_lost(bank):
    device = bank.plug(NODE)
    keyfob = await started(bank)
    try:
        device.down(GREEN)
        await asyncio.sleep(0.05)
        device.end_of_file()
        lost = await next_event(keyfob)
        assert isinstance(lost, KeyfobLost) and lost.reason == "end of file"
        await assert_quiet(keyfob, 1.3)  # no long press from a key nobody is holding
    finally:
        await keyfob.close()


async def test_permissions_arriving_after_the_node(bank):
    keyfob = await started(bank, needs=ANSWERS_ONLY, reopen_grace=30.0)
    try:
        lost = await next_event(keyfob)
        assert isinstance(lost, KeyfobLost) and "not available at start" in lost.reason
        device = bank.plug(NODE, mode=0o600)  # udev has not set the group yet
        await assert_quiet(keyfob, 0.4)
        os.chmod(device.path, 0o660)
        assert isinstance(await next_event(keyfob), KeyfobBack)
        device.down(GREEN)
        assert kinds(await next_event(keyfob)) == [("press", "green")]
    finally:
        await keyfob.close()


async def test_open_by_name_among_other_devices(bank):
    bank.plug("event0", name="AT Translated Set 2 keyboard")
    device = bank.plug("event3", name="Kaspar keyfob")
    keyfob = Keyfob(
        KeyfobSettings(name="Kaspar keyfob"),
        MonotonicClock(),
        needs=ANSWERS_ONLY,
        opener=bank.open,
        input_dir=str(bank.directory),
    )
    await keyfob.start()
    try:
        assert keyfob.connected and device.grabbed
        device.down(RED)
        assert kinds(await next_event(keyfob)) == [("press", "red")]
    finally:
        await keyfob.close()


def test_probe_names_a_keyfob_that_cannot_be_opened(bank):
    missing = Keyfob(settings_for(bank.directory), MonotonicClock(), opener=bank.open)
    with pytest.raises(KeyfobError, match="No such file") as caught:
        missing.probe()
    assert isinstance(caught.value.__cause__, OSError)
    by_name = Keyfob(
        KeyfobSettings(name="Kaspar keyfob"), MonotonicClock(), input_dir=str(bank.directory)
    )
    with pytest.raises(KeyfobError, match="no input device named 'Kaspar keyfob'"):
        by_name.probe()
    bank.plug(NODE)
    assert Keyfob(settings_for(bank.directory), MonotonicClock(), opener=bank.open).probe() == (
        f"{bank.directory / NODE} (Kaspar keyfob)"
    )


@pytest.mark.parametrize(
    ("key", "message"),
    [
        (0, "expected a key code between 1 and 767, found 0"),
        ("pageup", "expected a key name such as 'KEY_PAGEDOWN' or a number, found 'pageup'"),
        ("KEY_NOPE", "expected a key name known to evdev, found 'KEY_NOPE'"),
    ],
)
def test_a_key_that_is_not_one_is_a_settings_error(key, message):
    with pytest.raises(SettingsError, match=message) as caught:
        key_code(key)
    assert isinstance(caught.value, ValueError)


async def test_kernel_overflow_forgets_holds(bank):
    device = bank.plug(NODE)
    clock = ManualClock()
    keyfob = await started(bank, clock=clock)
    try:
        device.down(GREEN)
        device.write_raw(pack(1001.0, ecodes.EV_SYN, ecodes.SYN_DROPPED, 0))
        device.write_raw(pack(1001.0, ecodes.EV_KEY, GREEN, 0) + pack(1001.0, 0, 0, 0))
        await asyncio.sleep(0.05)
        await clock.advance(2.0)
        await assert_quiet(keyfob, 0.1)
        device.events((GREEN, 1, 0.1), (GREEN, 0, 0.1))
        await asyncio.sleep(0.05)
        await clock.advance(0.1)
        assert kinds(await next_event(keyfob)) == [("press", "green")]
    finally:
        await keyfob.close()


def test_gesture_kinds_cover_the_design():
    assert {kind.value for kind in GestureKind} == {"press", "long", "double", "both", "command"}
