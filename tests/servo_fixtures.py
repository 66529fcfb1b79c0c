"""Shared builders for the servo tests: drivers on buses on emulated ptys."""

from __future__ import annotations

from hal.servos.bus import SerialBus
from hal.servos.drivers import DRIVERS

# Generous: a busy 2-core CI machine can stall a thread for tens of milliseconds.
TEST_MARGIN = 0.1


def make_driver(protocol: str, path, baud: int = 1_000_000, retries: int = 2, **options):
    """A driver of `protocol` on `path`; `options` go to the driver (HerkuleX voltage_limits)."""
    bus = SerialBus(protocol, str(path), baud, timeout_margin=TEST_MARGIN, retries=retries,
                    backoff_initial=0.02, backoff_max=0.2)
    return DRIVERS[protocol](bus, **options)


class FakeClock:
    """Virtual time: sleeping jumps ahead at once, so a long move takes no real time."""

    def __init__(self) -> None:
        self.t = 1000.0

    def now(self) -> float:
        return self.t

    async def sleep(self, seconds: float) -> None:
        import asyncio

        self.t += max(0.0, seconds)
        await asyncio.sleep(0)


def servo_settings(safe_action: str = "hold", backend: str = "sim", **overrides):
    """Two buses, an arm of three AX-12s and two HerkuleX head joints."""
    import msgspec

    from hal.servos.settings import BusSettings, JointSettings, ServoSettings

    buses = (
        BusSettings(name="body", port="/dev/kaspar-body", protocol="dynamixel1", baud=1_000_000),
        BusSettings(name="head", port="/dev/kaspar-head", protocol="herkulex", baud=115200),
    )
    joints = (
        JointSettings(name="left_shoulder", bus="body", id=1, model="ax-12a",
                      range_deg=(-90.0, 60.0), max_speed_dps=60.0, rest_deg=-10.0,
                      group="left_arm"),
        JointSettings(name="left_elbow", bus="body", id=2, model="ax-12a", direction=-1,
                      range_deg=(0.0, 90.0), offset_deg=45.0, max_speed_dps=90.0,
                      rest_deg=10.0, group="left_arm"),
        JointSettings(name="torso", bus="body", id=3, model="ax-12a",
                      range_deg=(-30.0, 30.0), max_speed_dps=20.0, group="body"),
        JointSettings(name="head_yaw", bus="head", id=1, model="drs-0101",
                      range_deg=(-60.0, 60.0), max_speed_dps=120.0, group="head"),
        JointSettings(name="head_pitch", bus="head", id=2, model="drs-0101",
                      range_deg=(-20.0, 30.0), max_speed_dps=45.0, group="head"),
    )
    values = dict(backend=backend, safe_action=safe_action, buses=buses, joints=joints)
    values.update(overrides)
    return msgspec.convert(values, ServoSettings, from_attributes=True)


async def eventually(check, timeout: float = 10.0):
    """Poll `check` (returning a truth value, or an awaitable of one) until it holds.

    The emulators run on their own threads: waiting for an effect, rather than
    sleeping a fixed time, keeps the tests right on a loaded machine.
    """
    import asyncio
    import inspect
    import time

    deadline = time.monotonic() + timeout
    while True:
        result = check()
        if inspect.isawaitable(result):
            result = await result
        if result:
            return result
        if time.monotonic() > deadline:
            raise AssertionError(f"condition not met within {timeout} s")
        await asyncio.sleep(0.02)


def soon(check, timeout: float = 10.0):
    """`eventually` for code outside an event loop: a write the servo does not answer
    (HerkuleX's default ACK policy) returns before the emulator's thread has applied it."""
    import time

    deadline = time.monotonic() + timeout
    while not (result := check()):
        if time.monotonic() > deadline:
            raise AssertionError(f"condition not met within {timeout} s")
        time.sleep(0.02)
    return result
