"""What the simulated robot received: the goals of every joint that moved, as a CSV.

Shared by `say --motion` and `behaviour play --motion`. The simulated servos keep
every goal packet (hal.servos.sim.SimDriver.writes); each goal is turned back into
degrees and written as (time_s, joint, position_deg), time from a chosen origin: the
first columns of `demo --motion`'s record (kasparctl.sim.recording).
"""

from __future__ import annotations

import asyncio
import random
import tempfile
import wave
from collections.abc import Iterator, Sequence
from pathlib import Path

import msgspec

from hal.clock import LoopClock
from hal.servos.sim import SimServos
from hal.voice.api import Spoken
from hal.voice.settings import VoiceSettings
from hal.voice.sinks import WavSink
from hal.voice.speaker import Voice
from kasparctl.body.behaviours import load_library
from kasparctl.body.engine import LiveBody
from kasparctl.config import Config
from kasparctl.sim import simtime
from kasparctl.sim.recording import write_csv

__all__ = ["powered_sim", "render", "say_with_motion", "trajectory", "wav_seconds", "write_csv"]

# After the line's last sample, the body keeps running this long (the mouth closes).
TAIL_S = 0.6


def trajectory(servos: SimServos, origin: float) -> Iterator[tuple[float, str, float]]:
    """Every goal sent to a joint that moved: (seconds from `origin`, joint, degrees)."""
    names = {(j.bus, j.id): j for j in servos.settings.joints}
    rows: list[tuple[float, str, float]] = []
    for bus, driver in servos.drivers.items():
        for write in driver.writes:
            for servo_id, raw in write.goals.items():
                joint = names[(bus, servo_id)]
                degrees = joint.servo.to_degrees(raw, joint.direction, joint.offset_deg)
                rows.append((write.time - origin, joint.name, degrees))
    moved = {
        name for name in {row[1] for row in rows}
        if len({round(row[2], 3) for row in rows if row[1] == name}) > 1
    }
    rows.sort(key=lambda row: (row[0], row[1]))
    return (row for row in rows if row[1] in moved)


async def powered_sim(config: Config) -> SimServos:
    """The configured joints as simulated servos on the running loop's clock, all holding."""
    servos = SimServos(config.servos, LoopClock())
    await servos.start(poll=False)
    for group in servos.groups:
        await servos.set_compliant(group, False)
    for driver in servos.drivers.values():
        driver.writes.clear()  # torque-on goals are where each joint already was
    return servos


async def render(voice: VoiceSettings, text: str, key: str | None, wav: Path) -> Spoken:
    """Say `text` (or play its clip) into the WAV file `wav`, in real time."""
    spoken_voice = Voice(voice, sink=WavSink(file=wav))
    try:
        return await spoken_voice.say(text, key)
    finally:
        await spoken_voice.close()


async def _mouth_on(config: Config, wav: Path) -> tuple[SimServos, float]:
    """In simulated time: the body's mouth hears `wav` through the voice's envelope hook
    (as a WAV sink announces each line it writes); the servos and the first sample's time."""
    servos = await powered_sim(config)
    clock = LoopClock()
    body = LiveBody(servos, config.body, config.servos, load_library(config.body.behaviours_dir),
                    clock, latency_s=0.0, rng=random.Random(0))
    origin: list[float] = []

    class Stamp:
        """Passes the envelope to the mouth and keeps the first sample's time."""

        def on_envelope(self, start: float, frame_s: float, levels: Sequence[float]) -> None:
            origin.append(start)
            body.mouth.on_envelope(start, frame_s, levels)

        def on_end(self, cut: bool) -> None:
            body.mouth.on_end(cut)

    sink = WavSink(file=wav)
    sink.listen(Stamp(), clock)
    await body.start()
    try:
        await clock.sleep(0.2)  # the mouth at rest before the line, as on the robot
        await sink.written(wav)
        await clock.sleep(wav_seconds(wav) + TAIL_S)
    finally:
        await body.close()
    return servos, origin[0]


def wav_seconds(path: Path) -> float:
    """The duration of a WAV file in seconds."""
    with wave.open(str(path), "rb") as audio:
        return audio.getnframes() / audio.getframerate()


def say_with_motion(
    config: Config, voice: VoiceSettings, text: str, key: str | None,
    wav: str | None, motion: Path,
) -> tuple[Spoken, int]:
    """Render `text` to `wav` (a temporary file if None), then let the simulated body's
    mouth follow it in simulated time; write the trajectory to `motion`. (spoken, rows)."""
    body = msgspec.structs.replace(config.body, enabled=True)
    config = msgspec.structs.replace(config, body=body)
    with tempfile.TemporaryDirectory(prefix="kaspar-say-") as scratch:
        target = Path(wav) if wav else Path(scratch) / "line.wav"
        spoken = asyncio.run(render(voice, text, key, target))
        if not spoken.finished:
            return spoken, 0
        servos, origin = simtime.run(_mouth_on(config, target), virtual=True)
        rows = write_csv(trajectory(servos, origin), Path(motion))
    return spoken, rows

