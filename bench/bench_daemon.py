"""The service as systemd sees it: time to READY=1, memory after start, CPU while idle.

Run on demand: .venv/bin/python bench/bench_daemon.py [--idle-seconds 60]
Runs `kasparctl run --sim` (the demo robot's simulated servos, keyfob, voice)
with NOTIFY_SOCKET pointing at a socket of this script.
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
READY_TARGET_S = 1.0
RSS_TARGET_MB = 60.0
IDLE_CPU_TARGET = 1.0  # percent of one core
TICKS = os.sysconf("SC_CLK_TCK")


def start(tmp: Path, listener: socket.socket) -> tuple[subprocess.Popen[bytes], float]:
    env = os.environ | {"NOTIFY_SOCKET": str(tmp / "notify.sock")}
    began = time.monotonic()
    process = subprocess.Popen(
        [sys.executable, "-m", "kasparctl", "run", "--sim", "--config",
         str(REPO / "kasparctl" / "sim" / "demo.toml"), "--state-dir", str(tmp / "state")],
        stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
    )
    listener.settimeout(30)
    while b"READY=1" not in listener.recv(4096):
        pass
    return process, time.monotonic() - began


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime + stime


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def stop(process: subprocess.Popen[bytes]) -> None:
    process.send_signal(signal.SIGTERM)
    process.wait(timeout=30)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--idle-seconds", type=float, default=60.0)
    parser.add_argument("--starts", type=int, default=5)
    arguments = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        tmp = Path(scratch)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        listener.bind(str(tmp / "notify.sock"))
        times = []
        for _ in range(arguments.starts):
            process, took = start(tmp, listener)
            times.append(took)
            stop(process)
        ready = statistics.median(times)
        print(f"start to READY=1: {ready:.2f} s median of {arguments.starts} "
              f"(target < {READY_TARGET_S:g} s) {'PASS' if ready < READY_TARGET_S else 'FAIL'}")
        process, _ = start(tmp, listener)
        time.sleep(1.0)
        rss = rss_mb(process.pid)
        print(f"resident memory after start: {rss:.1f} MB (target < {RSS_TARGET_MB:g} MB) "
              f"{'PASS' if rss < RSS_TARGET_MB else 'FAIL'}")
        before = cpu_seconds(process.pid)
        time.sleep(arguments.idle_seconds)
        used = (cpu_seconds(process.pid) - before) / arguments.idle_seconds * 100
        print(f"CPU while idle over {arguments.idle_seconds:g} s: {used:.2f} % of one core "
              f"(target < {IDLE_CPU_TARGET:g} %) {'PASS' if used < IDLE_CPU_TARGET else 'FAIL'}")
        stop(process)


if __name__ == "__main__":
    main()
