"""The service as systemd sees it: time to READY=1, memory after start, CPU while idle.

Run on demand: .venv/bin/python bench/bench_daemon.py [--idle-seconds 60] [--config FILE]
Runs `kasparctl run --sim` (simulated servos, keyfob, voice) with the example robot's
configuration (systemd/kaspar.toml: body enabled, life on) and NOTIFY_SOCKET pointing
at a socket of this script. Idle CPU is measured twice in one run, as configured and
with `[body] enabled = false`, so the body's own cost reads as the difference.
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
IDLE_CPU_TARGET = 0.3  # percent of one core, with the body alive
TICKS = os.sysconf("SC_CLK_TCK")


def start(
    tmp: Path, listener: socket.socket, config: Path
) -> tuple[subprocess.Popen[bytes], float]:
    env = os.environ | {"NOTIFY_SOCKET": str(tmp / "notify.sock")}
    began = time.monotonic()
    process = subprocess.Popen(
        [sys.executable, "-m", "kasparctl", "run", "--sim", "--config",
         str(config), "--state-dir", str(tmp / "state")],
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


def still_copy(config: Path, tmp: Path) -> Path:
    """`config` with its body disabled (written beside the original: its paths are relative)."""
    text = config.read_text(encoding="utf-8")
    head, _, tail = text.partition("\n[body]\n")
    if not tail or "enabled = true" not in tail.split("\n[", 1)[0]:
        raise SystemExit(f"{config}: no [body] with enabled = true to turn off")
    copy = config.with_name(f".bench-still-{os.getpid()}-{config.name}")
    copy.write_text(head + "\n[body]\n" + tail.replace("enabled = true", "enabled = false", 1),
                    encoding="utf-8")
    return copy


def idle_cpu(tmp: Path, listener: socket.socket, config: Path, seconds: float) -> float:
    process, _ = start(tmp, listener, config)
    time.sleep(1.0)
    before = cpu_seconds(process.pid)
    time.sleep(seconds)
    used = (cpu_seconds(process.pid) - before) / seconds * 100
    stop(process)
    return used


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--idle-seconds", type=float, default=60.0)
    parser.add_argument("--starts", type=int, default=5)
    parser.add_argument("--config", type=Path, default=REPO / "systemd" / "kaspar.toml")
    arguments = parser.parse_args()
    config = arguments.config.resolve()
    with tempfile.TemporaryDirectory() as scratch:
        tmp = Path(scratch)
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        listener.bind(str(tmp / "notify.sock"))
        times = []
        for _ in range(arguments.starts):
            process, took = start(tmp, listener, config)
            times.append(took)
            stop(process)
        ready = statistics.median(times)
        print(f"start to READY=1: {ready:.2f} s median of {arguments.starts} "
              f"(target < {READY_TARGET_S:g} s) {'PASS' if ready < READY_TARGET_S else 'FAIL'}")
        process, _ = start(tmp, listener, config)
        time.sleep(1.0)
        rss = rss_mb(process.pid)
        print(f"resident memory after start: {rss:.1f} MB (target < {RSS_TARGET_MB:g} MB) "
              f"{'PASS' if rss < RSS_TARGET_MB else 'FAIL'}")
        stop(process)
        seconds = arguments.idle_seconds
        used = idle_cpu(tmp, listener, config, seconds)
        still = still_copy(config, tmp)
        try:
            without = idle_cpu(tmp, listener, still, seconds)
        finally:
            still.unlink()
        print(f"CPU while idle over {seconds:g} s, {config.name} (body alive): {used:.2f} % of "
              f"one core (target < {IDLE_CPU_TARGET:g} %) "
              f"{'PASS' if used < IDLE_CPU_TARGET else 'FAIL'}; with the body disabled: "
              f"{without:.2f} %")


if __name__ == "__main__":
    main()
