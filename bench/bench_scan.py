"""`servos scan` of a whole HerkuleX bus (ids 0-253) over a pty, beside its target.

Kaspar 3's 16 servos (1-6, 16-20, 32-36) and a factory-new one at 253 answer;
every other id costs one timeout: the wire time of a STAT and its reply at 115200
baud plus the scan's margin (SCAN_MARGIN_MS). The emulator runs in its own
process, so the figure is the scan's alone. A pty does not pace bytes at the baud
rate: the "wire-time floor" is computed from the packet lengths.
Run: .venv/bin/python bench/bench_scan.py
"""

from __future__ import annotations

import asyncio
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from hal.servos.bus import wire_time  # noqa: E402
from kasparctl.bringup.servos import DEFAULT_IDS, SCAN_MARGIN_MS, scan  # noqa: E402

# The emulator in its own process, as bench_servos runs it (its timing is not ours).
sys.path.insert(0, str(ROOT / "bench"))
from bench_servos import start_emulator  # noqa: E402

BAUD = 115200
KASPAR_3 = [*range(1, 7), *range(16, 21), *range(32, 37)]
FACTORY_NEW = 253
TARGET_S = 5.0  # a full scan while the engineer waits, at the default margin
ROUNDS = 3


def main() -> None:
    low, high = DEFAULT_IDS["herkulex"]
    ids = list(range(low, high + 1))
    answering = [*KASPAR_3, FACTORY_NEW]
    stat = wire_time(7 + 9, BAUD)  # a STAT and its reply
    floor = (len(ids) - len(answering)) * (stat + SCAN_MARGIN_MS / 1000) + len(answering) * stat
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ttyHX"
        emulator = start_emulator("HerkulexEmulator", path, "herkulex", answering)
        try:
            times, found = [], []
            for _ in range(ROUNDS):
                started = time.monotonic()
                found = asyncio.run(scan(str(path), "herkulex", BAUD, ids, SCAN_MARGIN_MS / 1000))
                times.append(time.monotonic() - started)
        finally:
            assert emulator.stdin is not None
            emulator.stdin.close()
            emulator.wait(10)
    answered = [servo["id"] for servo in found]
    best = min(times)
    print(f"servos scan of HerkuleX ids {low}-{high} ({len(ids)} ids) at {BAUD} baud, "
          f"margin {SCAN_MARGIN_MS:g} ms, best of {ROUNDS}")
    print(f"  found {len(answered)}: {answered}")
    print(f"  wire-time floor (timeouts of the missing ids)  {floor:8.2f} s")
    verdict = "ok" if best <= TARGET_S and answered == answering else "MISSED"
    print(f"  full scan                                       {best:8.2f} s   "
          f"target <= {TARGET_S:g} s   {verdict}")


if __name__ == "__main__":
    main()
