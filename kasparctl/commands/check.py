"""`kasparctl check`: is this robot ready for a session? A table, and an exit code.

Validates the configuration and phrases, the body's behaviours against the
configured joints (as `behaviour check`: a bad file would leave Kaspar still in
front of the children), pings and reads every configured servo (its
temperature, voltage, error bits; an impossible reading fails; nothing moves on
a powered robot), finds the keyfob, and speaks a test line. Usable
over ssh by an engineer; exit 1 when anything is wrong.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hal.clock import MonotonicClock
from hal.servos.api import JointStatus
from hal.servos.bus import open_failure
from hal.servos.joints import Joints
from hal.servos.settings import ServoSettings
from kasparctl.body.behaviours import BehaviourError, load_library
from kasparctl.body.check import absent_joints, problems
from kasparctl.config import (
    Config,
    ConfigError,
    default_config_path,
    load_config,
    servo_backend_given,
)
from kasparctl.game.language import phrasebook_for
from kasparctl.game.phrases import PhraseError
from kasparctl.log import configure_logging

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


def register(subparsers: Any) -> None:
    """Add the `check` subcommand."""
    parser = subparsers.add_parser("check", help="check the configuration and the hardware")
    parser.add_argument(
        "--config",
        default=None,
        help="kaspar.toml (default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)",
    )
    parser.add_argument(
        "--quiet", action="store_true", help="do not speak the test line (check the voice silently)"
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Check the configuration, phrases, servos, keyfob and voice; exit 1 if any fails."""
    path = arguments.config or default_config_path()
    try:
        config = load_config(path, playable=True)
        phrasebook = phrasebook_for(config)
    except (ConfigError, PhraseError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    # Errors only: the table says what is wrong, once per part (a bus's retries would
    # repeat its adapter's row).
    configure_logging("error", "console", stream=sys.stderr)
    results = [
        Result("configuration", True, f"{path} ({len(config.sessions)} planned sessions)"),
        Result("phrases", True, phrasebook.source),
        *_body(config),
        *([] if servo_backend_given(path) else [Result("servos", False, NO_BACKEND)]),
        *asyncio.run(_hardware(config, speak=not arguments.quiet)),
    ]
    _print_table(results)
    return 0 if all(result.ok for result in results) else 1


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
    checks: list[Callable[[Config, bool], Any]] = [_servos, _keyfob, _voice]
    return [result for check in checks for result in await check(config, speak)]


async def _servos(config: Config, speak: bool) -> list[Result]:
    del speak
    if config.servos.backend != "real":
        return [Result("servos", True, "simulated (servos.backend = 'sim')")]
    if not config.servos.joints:
        return [Result("servos", False, "no joints configured in [servos]")]
    found, statuses, unavailable = await _inspect_servos(config.servos)
    results = []
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


async def _keyfob(config: Config, speak: bool) -> list[Result]:
    del speak
    if config.keyfob.backend != "real":
        return [Result("keyfob", True, "simulated (keyfob.backend = 'sim')")]
    from hal.errors import HalError
    from hal.keyfob.reader import Keyfob

    try:
        found = Keyfob(config.keyfob, MonotonicClock()).probe()
    except (HalError, OSError) as error:
        cause = error if isinstance(error, OSError) else error.__cause__
        if isinstance(cause, OSError) and cause.filename:
            found = f"cannot open {cause.filename}: {open_failure(cause)}"
            return [Result("keyfob", False, found)]
        return [Result("keyfob", False, f"not found: {error}")]
    return [Result("keyfob", True, found)]


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
            spoken = await voice.say(phrasebook_for(config).render(TEST_KEY, 0))
        finally:
            await voice.close()
    if not spoken.finished:
        return [Result("voice", False, f"{spoken.status.value}: {spoken.error or 'no detail'}")]
    done = "spoke the test line" if speak else "rendered the test line silently"
    said = f"language {config.language!r}, voice {config.voice.voice!r}"
    return [Result("voice", True, f"{done} via {spoken.via} ({said})")]


def _print_table(results: list[Result]) -> None:
    width = max(len(result.part) for result in results)
    for result in results:
        verdict = "ok" if result.ok else "FAIL"
        print(f"{result.part:<{width}}  {verdict:<4}  {result.detail}")
