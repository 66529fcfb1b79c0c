"""Servo bus benchmarks: 17 emulated Dynamixels at 1,000,000 baud and Kaspar 3's 16 HerkuleX at
115200, each figure beside its target.

The emulator runs in its own process on a pty, so the CPU figures are ours
alone. A pty does not pace bytes at the baud rate: the "wire-time limit" is
computed from the packet lengths, and reading within 2x of it means our
overhead (thread hand-off, select, decoding) is no larger than the wire itself.
Run: .venv/bin/python bench/bench_servos.py
"""

from __future__ import annotations

import asyncio
import itertools
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import dynamixel_sdk as sdk  # noqa: E402
import msgspec  # noqa: E402

from hal.clock import MonotonicClock  # noqa: E402
from hal.servos import dynamixel1 as dx1  # noqa: E402
from hal.servos import dynamixel2 as dx2  # noqa: E402
from hal.servos import herkulex as hx  # noqa: E402
from hal.servos.bus import SerialBus, wire_time  # noqa: E402
from hal.servos.drivers import Dynamixel1Driver, Dynamixel2Driver, HerkulexDriver  # noqa: E402
from hal.servos.joints import Joints  # noqa: E402
from hal.servos.settings import ServoSettings  # noqa: E402

BAUD = 1_000_000
IDS = list(range(1, 18))
CONTROL_HZ = 50.0
TARGET_JITTER_P99_MS = 2.0
TARGET_READ_RATIO = 2.0
TARGET_IDLE_CPU_PERCENT = 0.5
READ_ROUNDS = 200


HERKULEX_BAUD = 115200  # Kaspar 3's body bus
HERKULEX_IDS = list(range(1, 17))


def start_emulator(kind: str, path: Path, module: str = "dynamixel",
                   ids: list[int] = IDS) -> subprocess.Popen[str]:
    script = f"""
import sys
sys.path[:0] = [{str(ROOT)!r}, {str(ROOT / "tests")!r}]
from pathlib import Path
from emulators.{module} import {kind}
emulator = {kind}(Path({str(path)!r}), ids={ids!r}, rate=1e6)
print("ready", flush=True)
sys.stdin.read()
emulator.stop()
"""
    process = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, text=True)
    assert process.stdout is not None and process.stdout.readline().strip() == "ready"
    return process


def make_bus(path: Path) -> SerialBus:
    # Margin of 5 ms: a pty on a busy laptop is slower to answer than a servo at 1 Mbps.
    return SerialBus("bench", str(path), BAUD, timeout_margin=0.005, retries=2)


def row(name: str, value: str, target: str, ok: bool | None) -> None:
    verdict = "" if ok is None else ("ok" if ok else "MISSED")
    print(f"  {name:<52} {value:>16}   target {target:<14} {verdict}")


def bytes_per_step() -> None:
    goals = {i: dx1.le16(512) + dx1.le16(100) for i in IDS}
    sync = len(dx1.sync_write(dx1.AX12.GOAL_POSITION, 4, goals))
    # One WRITE per servo, each answered by a 6-byte status packet (status return level 2).
    single = sum(len(dx1.write(i, dx1.AX12.GOAL_POSITION, goals[i])) + 6 for i in IDS)
    print("bytes on the wire for one control step (goal + speed of 17 AX-12A)")
    row("SYNC_WRITE (one packet, no replies)", f"{sync} B", "", None)
    row("one WRITE per servo (+ status replies)", f"{single} B", "", None)
    row("ratio", f"{single / sync:.1f}x fewer", "> 1x", single > sync)
    row("wire time per step at 1 Mbps, SYNC_WRITE", f"{wire_time(sync, BAUD) * 1e3:.2f} ms",
        "", None)


async def control_jitter(path: Path) -> None:
    settings = msgspec.convert(
        {
            "backend": "real",
            "control_hz": CONTROL_HZ,
            "buses": [{"name": "body", "port": str(path), "protocol": "dynamixel1", "baud": BAUD}],
            "joints": [
                {"name": f"j{i}", "bus": "body", "id": i, "model": "ax-12a",
                 "range_deg": [-100.0, 100.0], "max_speed_dps": 100.0}
                for i in IDS
            ],
        },
        ServoSettings,
    )
    driver = Dynamixel1Driver(make_bus(path))
    stamps: list[float] = []
    write_goals = driver.write_goals

    async def stamped(goals, step):  # type: ignore[no-untyped-def]
        stamps.append(time.perf_counter())
        await write_goals(goals, step)

    driver.write_goals = stamped  # type: ignore[method-assign]
    joints = Joints(settings, {"body": driver}, MonotonicClock())
    await joints.start(poll=False)
    for group in joints.groups:
        await joints.set_compliant(group, False)
    stamps.clear()
    await joints.move({f"j{i}": 60.0 for i in IDS}, duration=5.0)
    await joints.close()
    period = 1.0 / CONTROL_HZ
    deviations = sorted(abs(b - a - period) * 1e3 for a, b in itertools.pairwise(stamps))
    p99 = deviations[int(0.99 * (len(deviations) - 1))]
    baseline = await bare_loop_jitter(len(stamps))
    print(f"50 Hz control loop ({len(stamps)} steps of a 5 s move of 17 joints, real clock)")
    row("asyncio.sleep alone, same schedule: p99 (the floor)", f"{baseline:.3f} ms", "", None)
    row("step-interval jitter p50", f"{statistics.median(deviations):.3f} ms", "", None)
    row("step-interval jitter p99", f"{p99:.3f} ms", f"< {TARGET_JITTER_P99_MS} ms",
        p99 < TARGET_JITTER_P99_MS)
    row("worst step", f"{deviations[-1]:.3f} ms", "", None)


async def bare_loop_jitter(steps: int) -> float:
    """p99 interval error of an empty loop on the same schedule: the OS and asyncio floor."""
    period, stamps = 1.0 / CONTROL_HZ, []
    begin = time.perf_counter()
    for k in range(1, steps + 1):
        stamps.append(time.perf_counter())
        await asyncio.sleep(max(0.0, begin + k * period - time.perf_counter()))
    deviations = sorted(abs(b - a - period) * 1e3 for a, b in itertools.pairwise(stamps))
    return deviations[int(0.99 * (len(deviations) - 1))]


async def read_all(driver, rounds: int, ids: list[int] = IDS) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    await driver.read_positions(ids)  # warm up
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(rounds):
        positions = await driver.read_positions(ids)
        assert len(positions) == len(ids)
    return (time.perf_counter() - wall) / rounds, (time.process_time() - cpu) / rounds


def sdk_read_all(path: Path, version: float, rounds: int) -> tuple[float, float]:
    port = sdk.PortHandler(str(path))
    assert port.setBaudRate(BAUD)
    handler = sdk.PacketHandler(version)
    try:
        if version == 1.0:
            def once() -> None:
                for i in IDS:
                    _, result, _ = handler.read2ByteTxRx(port, i, 36)
                    assert result == sdk.COMM_SUCCESS
        else:
            group = sdk.GroupSyncRead(port, handler, 132, 4)
            for i in IDS:
                group.addParam(i)

            def once() -> None:
                assert group.txRxPacket() == sdk.COMM_SUCCESS
        once()
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(rounds):
            once()
        return (time.perf_counter() - wall) / rounds, (time.process_time() - cpu) / rounds
    finally:
        port.closePort()


async def reads(path1: Path, path2: Path) -> None:
    limit1 = len(IDS) * wire_time(len(dx1.read(1, 36, 2)) + 8, BAUD)
    limit2 = wire_time(len(dx2.sync_read(132, 4, IDS)) + len(IDS) * 15, BAUD)
    print(f"reading all 17 positions ({READ_ROUNDS} rounds, mean per read)")
    for label, path, driver_type, limit, version in (
        ("Protocol 1.0, 17 READs (AX-12A has no SYNC_READ)", path1, Dynamixel1Driver, limit1, 1.0),
        ("Protocol 2.0, one SYNC_READ", path2, Dynamixel2Driver, limit2, 2.0),
    ):
        driver = driver_type(make_bus(path))
        await driver.start()
        ours_wall, ours_cpu = await read_all(driver, READ_ROUNDS)
        await driver.close()
        theirs_wall, theirs_cpu = await asyncio.to_thread(sdk_read_all, path, version, READ_ROUNDS)
        print(f"  {label}")
        row("  wire-time limit", f"{limit * 1e3:.2f} ms", "", None)
        row("  kasparctl wall time", f"{ours_wall * 1e3:.2f} ms",
            f"< {TARGET_READ_RATIO:.0f}x limit", ours_wall < TARGET_READ_RATIO * limit)
        row("  kasparctl / wire-time limit", f"{ours_wall / limit:.2f}x", "", None)
        row("  dynamixel-sdk wall time", f"{theirs_wall * 1e3:.2f} ms", "", None)
        row("  kasparctl CPU time", f"{ours_cpu * 1e3:.2f} ms", "", None)
        row("  dynamixel-sdk CPU time", f"{theirs_cpu * 1e3:.2f} ms", "", None)


async def herkulex_reads(path: Path) -> None:
    """16 DRS-0101 at 115200 baud (Kaspar 3): one RAM_READ each, handed over at once."""
    per_servo = len(hx.ram_read(1, hx.Ram.CALIBRATED_POSITION, 2)) + 13
    limit = len(HERKULEX_IDS) * wire_time(per_servo, HERKULEX_BAUD)
    driver = HerkulexDriver(SerialBus("bench", str(path), HERKULEX_BAUD, timeout_margin=0.005))
    await driver.start()
    wall, cpu = await read_all(driver, READ_ROUNDS // 4, HERKULEX_IDS)
    await driver.close()
    print(f"reading all 16 positions of Kaspar 3's HerkuleX bus at {HERKULEX_BAUD} baud "
          f"({READ_ROUNDS // 4} rounds)")
    row("wire-time limit (16 RAM_READs and replies)", f"{limit * 1e3:.2f} ms", "", None)
    row("kasparctl wall time (pty: our overhead only)", f"{wall * 1e3:.2f} ms",
        f"< {TARGET_READ_RATIO:.0f}x limit", wall < TARGET_READ_RATIO * limit)
    row("kasparctl CPU time", f"{cpu * 1e3:.2f} ms", "", None)


async def idle_cpu(path: Path) -> None:
    bus = make_bus(path)
    await bus.start()
    await asyncio.sleep(0.5)
    seconds = 5.0
    cpu = time.process_time()
    await asyncio.sleep(seconds)
    used = (time.process_time() - cpu) / seconds * 100
    await bus.close()
    print(f"idle bus ({seconds:.0f} s with the port open and nothing to do)")
    row("CPU of one core", f"{used:.3f} %", f"< {TARGET_IDLE_CPU_PERCENT} %",
        used < TARGET_IDLE_CPU_PERCENT)


async def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path1, path2 = Path(tmp) / "ttyAX", Path(tmp) / "ttyXL"
        path3 = Path(tmp) / "ttyHX"
        emulators = [start_emulator("Dynamixel1Emulator", path1),
                     start_emulator("Dynamixel2Emulator", path2),
                     start_emulator("HerkulexEmulator", path3, "herkulex", HERKULEX_IDS)]
        try:
            print(f"kasparctl servo bench: 17 emulated servos at {BAUD} baud on a pty\n")
            bytes_per_step()
            print()
            await control_jitter(path1)
            print()
            await reads(path1, path2)
            print()
            await herkulex_reads(path3)
            print()
            await idle_cpu(path1)
        finally:
            for process in emulators:
                assert process.stdin is not None
                process.stdin.close()
                process.wait(10)


if __name__ == "__main__":
    asyncio.run(main())
