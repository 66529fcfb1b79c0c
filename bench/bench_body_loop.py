"""The body's control loop with every layer on: 22 joints at 50 Hz, on the real clock.

Kaspar 3's 22 joints (systemd/kaspar-3.toml, with the demo's gaze directions) on the
simulated servos behind the real joints layer; gaze moving between seats, blinks and
idle movements at short intervals, the mouth following a continuous envelope, and a
gesture always playing. Reports the CPU time of this process
per second of wall time (% of one core; target < 5 %) and the
tick lateness p99 against the loop's absolute schedule (target < 2 ms), quiet machine.
Before the body, the same timer waits with nothing else to do for a third of the
time: that floor is what this machine's scheduler gives (a shared virtual machine
may miss 2 ms on an empty loop); the body's figure is read against it.
Run: .venv/bin/python bench/bench_body_loop.py [seconds]
"""

from __future__ import annotations

import asyncio
import random
import statistics
import sys
import time
from pathlib import Path

import msgspec

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT)]

from hal import scheduling  # noqa: E402
from hal.clock import Alarm, MonotonicClock  # noqa: E402
from hal.servos.sim import SimServos  # noqa: E402
from kasparctl.body.api import Gaze, GazeKind  # noqa: E402
from kasparctl.body.behaviours import load_library  # noqa: E402
from kasparctl.body.engine import LiveBody  # noqa: E402
from kasparctl.config import load_config  # noqa: E402
from kasparctl.log import configure_logging  # noqa: E402
from kasparctl.sim.demo import demo_config  # noqa: E402

TARGET_CPU_PERCENT = 5.0
TARGET_JITTER_P99_MS = 2.0
GESTURES = ["thinking", "nod", "happy", "shake", "sad", "wave", "greeting"]


def row(name: str, value: str, target: str, ok: bool) -> None:
    print(f"  {name:<52} {value:>12}   target {target:<10} {'ok' if ok else 'MISSED'}")


async def empty_loop_lateness(seconds: float, period: float) -> list[float]:
    """Each tick's lateness of a loop that only waits, on the alarm the body uses."""
    clock = MonotonicClock()
    alarm = Alarm(clock)
    late = []
    begin = clock.now()
    for tick in range(1, int(seconds / period)):
        due = begin + tick * period
        await alarm.sleep_until(due)
        late.append(clock.now() - due)
    alarm.close()
    return late


def p99_ms(lateness: list[float]) -> float:
    ordered = sorted(lateness)
    return ordered[int(0.99 * (len(ordered) - 1))] * 1000


async def main(seconds: float) -> None:
    floor = await empty_loop_lateness(seconds / 3, 0.02)
    configure_logging("warning", "console", stream=sys.stderr)
    config = load_config(ROOT / "systemd" / "kaspar-3.toml", poses=False)
    servo_settings = msgspec.structs.replace(config.servos, backend="sim", control_hz=50.0)
    settings = msgspec.structs.replace(demo_config().body, rate_hz=50.0,
                                       blink_interval_s=(0.5, 1.0),
                                       idle_interval_s=(0.5, 1.0))
    clock = MonotonicClock()
    servos = SimServos(servo_settings, clock)
    await servos.start(poll=False)
    for group in servos.groups:
        await servos.set_compliant(group, False)
    body = LiveBody(servos, settings, servo_settings, load_library(), clock, rng=random.Random(1))
    body.lateness = []
    await body.start()
    body.set_alive(True)
    rng = random.Random(2)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    end = clock.now() + seconds
    turn = 0
    while clock.now() < end:
        body.look_at(Gaze(GazeKind.CHILD, turn % 3))
        levels = [abs(rng.gauss(0.1, 0.08)) for _ in range(300)]  # 3 s of speech
        body.mouth.on_envelope(clock.now(), 0.01, levels)
        await body.perform(GESTURES[turn % len(GESTURES)], rng.random())
        turn += 1
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    await body.close()
    await servos.close()
    late = body.lateness[10:]  # the first ticks include the loop's start
    p99 = p99_ms(late)
    sent = sum(len(d.writes) for d in servos.drivers.values())
    print(f"scheduling: {scheduling.current()}")
    print(f"body control loop: {len(servos.joints)} joints, {settings.rate_hz:g} Hz, every layer "
          f"on, {wall:.1f} s wall, {len(late)} ticks, {sent} goal packets")
    row("CPU (% of one core)", f"{100 * cpu / wall:.2f} %", f"< {TARGET_CPU_PERCENT:g} %",
        100 * cpu / wall < TARGET_CPU_PERCENT)
    row("tick lateness p99", f"{p99:.2f} ms", f"< {TARGET_JITTER_P99_MS:g} ms",
        p99 < TARGET_JITTER_P99_MS)
    print(f"  (lateness median {statistics.median(late) * 1000:.2f} ms, "
          f"max {max(late) * 1000:.2f} ms; this machine's floor, the same timer on an empty "
          f"loop just before: p99 {p99_ms(floor):.2f} ms, median "
          f"{statistics.median(floor) * 1000:.2f} ms)")


if __name__ == "__main__":
    asyncio.run(main(float(sys.argv[1]) if len(sys.argv) > 1 else 20.0))
