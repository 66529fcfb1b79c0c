"""The unit's real-time policy as the kernel applies it: SCHED_FIFO for the thread systemd
starts, never passed on to a later thread or a child (espeak-ng); logged; probed by check."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from hal import scheduling as realtime
from kasparctl.bringup.readiness import scheduling_row

UNIT = Path(__file__).resolve().parents[1] / "systemd" / "kasparctl.service"

# What a process started as the unit starts it sees: its own thread, a thread it starts
# (a serial bus's), and a child process it runs (espeak-ng).
SEEN = textwrap.dedent(
    """
    import json, subprocess, sys, threading
    from hal.scheduling import current
    seen = {"main": str(current())}
    def in_thread():
        seen["thread"] = str(current())
    thread = threading.Thread(target=in_thread)
    thread.start(); thread.join()
    seen["child"] = subprocess.run(
        [sys.executable, "-c", "from hal.scheduling import current; print(current())"],
        capture_output=True, text=True, check=True).stdout.strip()
    print(json.dumps(seen))
    """
)


def unit_value(key: str) -> str:
    found = re.search(rf"^{key}=(.*)$", UNIT.read_text(), re.MULTILINE)
    assert found, key
    return found.group(1)


def test_the_module_names_what_the_unit_asks_for() -> None:
    assert unit_value("CPUSchedulingPolicy") == realtime.UNIT_POLICY
    assert int(unit_value("CPUSchedulingPriority")) == realtime.UNIT_PRIORITY
    assert unit_value("CPUSchedulingResetOnFork") == "yes"


def test_the_units_policy_holds_for_the_started_thread_alone() -> None:
    # chrt applies the same sched_setscheduler systemd's CPUSchedulingPolicy= does.
    chrt = shutil.which("chrt")
    assert chrt, "chrt (util-linux) is part of every Debian install"
    if realtime.kernel_grants_realtime() is not None:
        pytest.skip("this machine refuses real-time scheduling to root")
    result = subprocess.run(
        [chrt, "--fifo", "--reset-on-fork", str(realtime.UNIT_PRIORITY), sys.executable, "-c",
         SEEN], capture_output=True, text=True, check=True,
    )
    seen = json.loads(result.stdout)
    assert seen["main"] == "fifo 10, reset on fork"
    assert seen["thread"] == "other"
    assert seen["child"] == "other"


def test_the_start_logs_the_scheduling_and_warns_when_the_unit_did_not_hold(capsys) -> None:
    env = dict(os.environ, INVOCATION_ID="0123456789abcdef0123456789abcdef")
    code = ("import sys; from kasparctl.log import configure_logging; "
            "configure_logging('info', 'json', stream=sys.stdout); "
            "from hal.scheduling import log_scheduling; log_scheduling()")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, env=env)
    line = json.loads(result.stdout)
    assert (line["event"], line["level"], line["policy"]) == ("scheduling", "warning", "other")
    assert line["expected"] == "fifo 10, reset on fork"
    del env["INVOCATION_ID"]
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, env=env)
    assert json.loads(result.stdout)["level"] == "info"


def test_check_says_whether_the_service_could_start() -> None:
    assert scheduling_row(None, as_root=True).ok
    refused = scheduling_row("sched_setscheduler(SCHED_FIFO, 10) refused: EPERM", as_root=True)
    assert not refused.ok and "214/SETSCHEDULER" in refused.detail
    unknown = scheduling_row("refused: EPERM", as_root=False)
    assert unknown.ok and unknown.warning and "root" in unknown.detail
