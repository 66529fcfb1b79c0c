"""The scheduling the unit gives the body loop's thread: read back, logged, and probed.

systemd starts the daemon SCHED_FIFO at priority 10 with SCHED_RESET_ON_FORK
(systemd/kasparctl.service says why): the event loop's thread, which runs the body loop,
keeps it; every later thread and child process starts at the normal policy. The daemon
logs what it got once at the start, so the journal shows whether the unit's request
held; `check` asks the kernel beforehand whether it grants such a policy at all, since a
kernel that refuses keeps the unit from starting (214/SETSCHEDULER).
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass

import structlog

log = structlog.get_logger("hal.scheduling")

# What systemd/kasparctl.service asks for (tests/test_systemd_unit.py holds them equal).
UNIT_POLICY = "fifo"
UNIT_PRIORITY = 10


@dataclass(frozen=True, slots=True)
class Scheduling:
    """A thread's scheduling policy, as chrt and systemd.exec name it, and its priority."""

    policy: str
    priority: int
    reset_on_fork: bool = False

    def __str__(self) -> str:
        """As chrt says it: "fifo 10, reset on fork", "other"."""
        words = f"{self.policy} {self.priority}" if self.priority else self.policy
        return words + (", reset on fork" if self.reset_on_fork else "")


def policy_name(policy: int) -> str:
    """The policy's word ("other", "fifo", "rr", "batch", "idle"), the reset flag ignored."""
    names = {os.SCHED_OTHER: "other", os.SCHED_FIFO: "fifo", os.SCHED_RR: "rr",
             os.SCHED_BATCH: "batch", os.SCHED_IDLE: "idle"}
    return names.get(policy & ~os.SCHED_RESET_ON_FORK, str(policy))


def current() -> Scheduling:
    """The calling thread's scheduling."""
    policy = os.sched_getscheduler(0)
    return Scheduling(
        policy_name(policy),
        os.sched_getparam(0).sched_priority,
        bool(policy & os.SCHED_RESET_ON_FORK),
    )


def log_scheduling() -> Scheduling:
    """The event loop's scheduling, logged once at the start (a warning when the service
    systemd started runs without the unit's real-time policy: its ticks may be late)."""
    got = current()
    under_systemd = bool(os.environ.get("INVOCATION_ID"))
    if under_systemd and (got.policy, got.priority) != (UNIT_POLICY, UNIT_PRIORITY):
        log.warning(
            "scheduling",
            policy=str(got),
            expected=f"{UNIT_POLICY} {UNIT_PRIORITY}, reset on fork",
            hint="the unit's CPUSchedulingPolicy= did not hold; the body's ticks may be late",
        )
    else:
        log.info("scheduling", policy=str(got))
    return got


def kernel_grants_realtime() -> str | None:
    """Why this kernel (and this process's privileges) would refuse the unit's policy to a
    new process, or None when it grants it. Asked in a child, so nothing here changes."""
    probe = (
        "import os; os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, "
        f"os.sched_param({UNIT_PRIORITY}))"
    )
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=False, timeout=30
    )
    if result.returncode == 0:
        return None
    last = (result.stderr.strip().splitlines() or ["no reason given"])[-1]
    return f"sched_setscheduler(SCHED_FIFO, {UNIT_PRIORITY}) refused: {last}"
