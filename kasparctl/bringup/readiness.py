"""Is this robot ready for a session? The configuration, phrases, body and hardware, checked.

Validates the configuration and phrases, the body's behaviours against the
configured joints (as `behaviour check`: a bad file would leave Kaspar still in
front of the children), pings and reads every configured servo (its
temperature, voltage, error bits; an impossible reading fails; nothing moves on
a powered robot), finds the keyfob and the researcher's device (which node, its battery, a press
within N seconds when asked), speaks a test line, and warns when the wall clock is not
synchronised. Each part gives
rows of a table (`kasparctl check` prints it); a configuration or phrase book
that cannot be read raises its own error first.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hal.clock import MonotonicClock
from hal.scheduling import UNIT_POLICY, UNIT_PRIORITY, kernel_grants_realtime
from hal.servos.api import JointStatus
from hal.servos.joints import Joints
from hal.servos.ports import SYSFS, describe
from hal.servos.settings import ServoSettings
from kasparctl.body.behaviours import BehaviourError, load_library
from kasparctl.body.check import absent_joints, problems
from kasparctl.config import Config, load_config, servo_backend_given
from kasparctl.game.language import phrasebook_for
from kasparctl.game.wallclock import ClockSource, clock_source

# The voice check's test line: Kaspar's greeting, in the configured language.
TEST_KEY = "session.greeting"
NO_BACKEND = (
    "no [servos] table with its backend: the servos would be simulated without a word; "
    "say backend = 'real' with the robot's buses and joints (systemd/kaspar-3.toml), "
    "or backend = 'sim'"
)


@dataclass(frozen=True, slots=True)
class Result:
    """One row of the check table: what was checked, whether it is ok, and the detail."""

    part: str
    ok: bool
    detail: str
    # Ok, but the researcher should know (a clock not synchronised does not stop a session).
    warning: bool = False


@dataclass(frozen=True)
class Robot:
    """The configuration to check, read: ConfigError or PhraseError if it cannot be."""

    path: str
    config: Config
    phrases: str  # where the phrase book came from

    @classmethod
    def read(cls, path: str) -> Robot:
        """The configuration at `path` (playable), and its phrase book."""
        config = load_config(path, playable=True)
        return cls(path, config, phrasebook_for(config).source)

    def settings(self) -> list[Result]:
        """The rows of what was read: the configuration, the phrases, the body, the backend."""
        config = self.config
        planned = f"{len(config.sessions)} planned sessions"
        if config.sessions_file is not None:
            planned += f" from {config.sessions_file}"
        return [
            Result("configuration", True, f"{self.path} ({planned})"),
            Result("phrases", True, self.phrases),
            *_body(config),
            *([] if servo_backend_given(self.path) else [Result("servos", False, NO_BACKEND)]),
        ]

    def hardware(self, speak: bool, press_within: float | None = None) -> list[Result]:
        """The rows of the servos, keyfob, researcher's device and voice (the test line said
        aloud if `speak`; a button of each device asked for if `press_within` seconds)."""
        results = asyncio.run(_hardware(self.config, speak))
        from kasparctl.bringup.remotes import device_rows

        devices = [Result(r.part, r.ok, r.detail) for r in device_rows(self.config, press_within)]
        voice = [r for r in results if r.part == "voice"]
        return [*(r for r in results if r.part != "voice"), *devices, *voice]


def _body(config: Config) -> list[Result]:
    if not config.body.enabled:
        return [Result("body", True, "still ([body] enabled = false)")]
    try:
        library = load_library(config.body.behaviours_dir)
    except BehaviourError as error:
        return [Result("body", False, str(error))]
    found = problems(library, config.servos, absent_is_problem=False)
    if found:
        return [Result("body", False, line) for line in found]
    fit = f"behaviours that fit this robot: {len(library)}"
    absent = absent_joints(library, config.servos)
    if absent:
        fit += f" (joints it lacks, skipped when played: {', '.join(absent)})"
    return [Result("body", True, fit)]


async def _hardware(config: Config, speak: bool) -> list[Result]:
    checks: list[Callable[[Config, bool], Any]] = [_servos, _voice, _clock, _scheduling]
    return [result for check in checks for result in await check(config, speak)]


async def _clock(config: Config, speak: bool) -> list[Result]:
    return [clock_row(clock_source())]


async def _scheduling(config: Config, speak: bool) -> list[Result]:
    refused = await asyncio.to_thread(kernel_grants_realtime)
    return [scheduling_row(refused, os.geteuid() == 0)]


def scheduling_row(refused: str | None, as_root: bool) -> Result:
    """Whether the unit's real-time policy would be granted: refused, the service would not
    start (214/SETSCHEDULER); as another user than root the answer means nothing."""
    wanted = f"{UNIT_POLICY} {UNIT_PRIORITY}"
    if refused is None:
        return Result("scheduling", True, f"the kernel grants the unit's {wanted}")
    if not as_root:
        return Result(
            "scheduling", True, f"not checked: only root can ask for {wanted} as systemd "
            "would (run check as root)", warning=True,
        )
    return Result(
        "scheduling", False, f"{refused}: the service would not start (214/SETSCHEDULER); "
        "docs/install.md, real-time scheduling",
    )


def clock_row(source: ClockSource) -> Result:
    """The wall clock's row: synchronised, or a warning that record times may be wrong."""
    if source.synchronised:
        return Result("clock", True, "synchronised (systemd-timesyncd: NTPSynchronized=yes)")
    return Result(
        "clock",
        True,
        "NOT synchronised (no systemd-timesyncd, or it has no time server): the records' "
        "times may be wrong, their order and ages are not; docs/install.md, a good clock",
        warning=True,
    )


async def _servos(config: Config, speak: bool) -> list[Result]:
    del speak
    if config.servos.backend != "real":
        return [Result("servos", True, "simulated (servos.backend = 'sim')")]
    if not config.servos.joints:
        return [Result("servos", False, "no joints configured in [servos]")]
    found, statuses, unavailable = await _inspect_servos(config.servos)
    results = _ports(config.servos)
    answered = 0
    for bus_name, why in unavailable.items():
        # One line per adapter, not one per servo behind it.
        behind = [j.name for j in config.servos.joints if j.bus == bus_name]
        results.append(Result("servos", False, f"{why}; its {len(behind)} joints not checked"))
    for joint in config.servos.joints:
        if joint.bus in unavailable:
            continue
        bus = config.servos.bus(joint.bus)
        where = f"bus {bus.name} on {bus.port}, id {joint.id}"
        model_number = found[joint.name]
        expected = joint.servo.model_number
        if model_number is None:
            results.append(Result("servos", False, f"servo {joint.name} is missing ({where})"))
            continue
        answered += 1
        if expected is not None and model_number == 0:
            results.append(Result(
                "servos", False,
                f"servo {joint.name} answers a ping but no read ({where}): its status return "
                "level (Dynamixel) or ACK policy (HerkuleX) does not let it answer reads",
            ))
            continue
        if expected is not None and model_number != expected:
            results.append(Result(
                "servos", False,
                f"servo {joint.name} is not a {joint.model} (model number {model_number}, {where})",
            ))
            continue
        results.append(_servo_row(statuses[joint.name]))
    if answered == len(config.servos.joints):
        results.insert(0, Result("servos", True, f"all {answered} servos answered"))
    return results


def _ports(settings: ServoSettings, sysfs: Path = SYSFS) -> list[Result]:
    """One row per bus: the device its port is (node, vendor:product, interface, driver)."""
    rows = []
    for bus in settings.buses:
        info = describe(bus.port, sysfs)
        rows.append(Result("ports", info.node is not None, f"bus {bus.name}: {info}"))
    return rows


async def _inspect_servos(
    settings: ServoSettings,
) -> tuple[dict[str, int | None], dict[str, Any], dict[str, str]]:
    joints = Joints.from_settings(settings, MonotonicClock())
    # Pings and reads only: nothing moves. (A HerkuleX bus gets its ACK policy set, and
    # packet error bits are cleared once reported.)
    await joints.start(poll=False, read=False)
    try:
        unavailable = joints.unavailable_buses()
        found = await joints.ping_all()
        statuses = {s.joint: s for s in await joints.survey()}
    finally:
        await joints.close()
    return found, statuses, unavailable


def _servo_row(status: JointStatus) -> Result:
    """One servo: where it is, how hot, its supply, and what is wrong (error bits, impossible)."""
    readings = []
    if status.position_deg is not None:
        readings.append(f"{status.position_deg:.1f} deg")
    if status.temperature_c is not None:
        readings.append(f"{status.temperature_c:.0f} C")
    if status.voltage_v is not None:
        readings.append(f"{status.voltage_v:.1f} V")
    wrong = list(status.problems)
    if status.fault is not None:
        wrong.insert(0, f"{status.fault.kind.value}: {status.fault.detail}")
    if status.flags:
        wrong.append("error bits " + ", ".join(status.flags))
    detail = f"{status.joint}: {', '.join(readings) or 'no readings'}"
    if wrong:
        detail += " - " + "; ".join(wrong)
    return Result("servos", status.healthy, detail)


async def _voice(config: Config, speak: bool) -> list[Result]:
    if config.voice.backend != "real":
        return [Result("voice", True, "simulated (voice.backend = 'sim')")]
    import tempfile

    import msgspec

    from hal.voice.speaker import Voice

    with tempfile.TemporaryDirectory(prefix="kaspar-check-") as scratch:
        settings = config.voice
        if not speak:
            # Render the line with the real engines into a file nobody plays.
            settings = msgspec.structs.replace(settings, wav_dir=scratch)
        voice = Voice(settings, MonotonicClock())
        try:
            book = phrasebook_for(config)
            spoken = await voice.say(book.render(TEST_KEY, 0, robot=config.robot_settings.name))
        finally:
            await voice.close()
    if not spoken.finished:
        return [Result("voice", False, f"{spoken.status.value}: {spoken.error or 'no detail'}")]
    done = "spoke the test line" if speak else "rendered the test line silently"
    said = f"language {config.language!r}, voice {config.voice.voice!r}"
    return [Result("voice", True, f"{done} via {spoken.via} ({said})")]


