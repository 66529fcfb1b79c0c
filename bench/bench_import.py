"""Import time of the daemon's modules, in a fresh interpreter each run.

Start-up time matters on the robot: systemd starts kasparctl at boot and the
researcher is waiting with the keyfob. Measured as the median over fresh
processes, minus the median of an interpreter that imports nothing.
Run: .venv/bin/python bench/bench_import.py
"""

from __future__ import annotations

import importlib.util
import statistics
import subprocess
import sys
import time

TARGET_MS = 300.0
RUNS = 15
DAEMON_MODULES = (
    "kasparctl.cli",
    "kasparctl.config",
    "kasparctl.learning.learner",
    "kasparctl.game.phrases",
    "kasparctl.log",
    "kasparctl.game.session",
    "kasparctl.game.machine",
    "kasparctl.service.daemon",
    "hal",
)


def median_run_ms(code: str) -> float:
    times = []
    for _ in range(RUNS):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True)
        times.append((time.perf_counter() - start) * 1000.0)
    return statistics.median(times)


def main() -> None:
    present = [name for name in DAEMON_MODULES if importlib.util.find_spec(name) is not None]
    absent = sorted(set(DAEMON_MODULES) - set(present))
    baseline = median_run_ms("pass")
    with_modules = median_run_ms("import " + ", ".join(present))
    cost = with_modules - baseline
    verdict = "PASS" if cost < TARGET_MS else "FAIL"
    print(f"modules measured: {', '.join(present)}")
    if absent:
        print(f"modules not built yet, not measured: {', '.join(absent)}")
    print(
        f"import time of the daemon's modules: {cost:.0f} ms median over {RUNS} fresh "
        f"interpreters (interpreter alone {baseline:.0f} ms) "
        f"(target < {TARGET_MS:.0f} ms) {verdict}"
    )


if __name__ == "__main__":
    main()
