"""kasparctl on a real systemd: Debian 12 booted in a container, installed by the README's steps.

tests/boot/machine.py boots Debian 12 with systemd as PID 1 in systemd-nspawn on this
machine (the base tree and the wheels cached in /var/cache/kasparctl-boot, a fresh
overlay per run, always torn down). Inside, the README's install lines run from a copy
of the checkout; a drop-in (tests/boot/robot.py) runs the service on simulated hardware
with the keyfob's keys read from a fifo the test writes into.

The container checks run in file order on one booted robot, as a story: each leaves
the robot as the next expects (installed and idle, a session under way, restarted by
the watchdog, stopped, uninstalled). A new check is a test function at the point of the
story it needs, using the `robot` fixture's helpers; timings go into robot.timings and
the summary line printed at the end.

Without CI=true the container checks are skipped only when this machine cannot run
systemd-nspawn at all (not Linux, not root, no way to install it), and the check of
DevicePolicy= where the container's systemd does not enforce it at all (a container
inside a container: tests/boot/robot.py probes it); with CI=true each is a failure. docs/install.md has the measured times.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import signal
import subprocess
import sys
import time
import wave
from array import array
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from boot.machine import (
    DEBS_IN_CONTAINER,
    WHEELS_IN_CONTAINER,
    BootError,
    Machine,
    base_tree_name,
    build_base_tree,
    build_wheels,
    cached_tree,
    container_python,
    ensure_host_tools,
    host_problem,
    project_requirements,
    prune_trees,
    wheels_name,
)
from boot.robot import (
    UNIT,
    UNIT_FILE,
    Robot,
    install_test_files,
    usec,
    without_clock,
)
from capabilities import in_ci, need

REPO = Path(__file__).resolve().parents[1]
INSTALL_SH = REPO / "systemd" / "install.sh"
README = REPO / "README.md"
CHECKOUT = "/root/kasparctl"
# pip's own settings point it at the wheelhouse: the container has no network.
OFFLINE_PIP = {"PIP_NO_INDEX": "1", "PIP_FIND_LINKS": WHEELS_IN_CONTAINER}
STATE_DIR = "/var/lib/kaspar"
CONFIG = "/etc/kaspar/kaspar.toml"
RESEARCHER_EDIT = "# edited by the researcher\n"
# Idle names the group "next" starts (or reopens): the example configuration plans A1 first.
IDLE = "waiting: 'next' "
FRESH_IDLE = "waiting: 'next' starts group A1, session 1"
PLACING = "step 1: placing the bags"
# What the install puts on the machine, and so what a dry run must not.
INSTALLED = {
    "the venv": "test -x /opt/kasparctl/bin/kasparctl",
    "the kaspar user": "getent passwd kaspar",
    "the unit": f"test -e {UNIT_FILE}",
    "the configuration": f"test -e {CONFIG}",
    "the sysusers file": "test -e /etc/sysusers.d/kasparctl.conf",
    "the udev rules": "test -e /etc/udev/rules.d/99-kaspar-serial.rules",
    "the remotes' rules": "test -e /etc/udev/rules.d/99-kaspar-keyfob.rules"
    " && test -e /etc/udev/rules.d/99-kaspar-researcher.rules",
}
SESSION_PATH = re.compile(
    r"sessions(/[^/]+(/(plan\.json|state\.json|records\.jsonl(\.torn)?))?)?|events\.jsonl(\.torn)?"
)


# -- the install script on this machine (no container) ------------------------------------


def run_install_sh(*arguments: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", str(INSTALL_SH), *arguments], capture_output=True, text=True, check=False
    )


def step_titles(output: str) -> list[str]:
    return re.findall(r"^# \d+\. (.*)$", output, re.M)


def test_install_script_dry_run_prints_every_step_and_changes_nothing() -> None:
    targets = [
        Path(p)
        for p in ("/opt/kasparctl", UNIT_FILE, "/etc/sysusers.d/kasparctl.conf", CONFIG,
                  "/etc/modules-load.d/kasparctl.conf", "/etc/udev/rules.d/99-kaspar-serial.rules")
    ]  # fmt: skip
    before = {path: path.exists() for path in targets}
    result = run_install_sh("--dry-run")
    assert result.returncode == 0, result.stderr
    assert {path: path.exists() for path in targets} == before
    titles = " | ".join(step_titles(result.stdout))
    for step in (
        "Debian packages",
        "virtual environment",
        "wheel",
        "user",
        "kernel modules",
        "udev",
        "configuration",
        "the service",
    ):
        assert step in titles, step
    for expected in (
        "systemd-sysusers /etc/sysusers.d/kasparctl.conf",
        "/etc/modules-load.d/kasparctl.conf",
        "modprobe -a ftdi_sio cdc_acm",
        "udevadm control --reload",
        "systemctl enable kasparctl.service",
        "pip wheel --quiet --no-deps",
    ):
        assert expected in result.stdout, expected
    # Every file it installs from the checkout is there.
    for path in re.findall(rf"{re.escape(str(REPO))}/systemd/[\w.-]+", result.stdout):
        assert Path(path).is_file(), path


def test_install_script_names_its_packages() -> None:
    result = run_install_sh("--packages")
    assert result.returncode == 0
    packages = result.stdout.split()
    assert {"python3-venv", "python3-dev", "gcc", "espeak-ng", "alsa-utils"} <= set(packages)


def test_install_script_refuses_an_unknown_option() -> None:
    result = run_install_sh("--force")
    assert result.returncode == 2
    assert "unknown option --force" in result.stderr


def test_readme_installs_with_the_script() -> None:
    lines = readme_install_lines()
    assert any("--dry-run" in line for line in lines), lines
    assert "bash systemd/install.sh" in lines


def readme_install_lines() -> list[str]:
    """The install commands of the README's "On the robot" section, in order."""
    section = README.read_text().split("\n## On the robot\n", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```sh\n(.*?)```", section, re.S)
    return [
        line.split("#", 1)[0].strip()
        for block in blocks
        for line in block.splitlines()
        if line.startswith("bash systemd/install.sh")
    ]


# -- the booted robot --------------------------------------------------------------------------


@dataclass
class InstallRun:
    line: str
    output: str
    returncode: int
    seconds: float
    installed_after: dict[str, bool]


@contextlib.contextmanager
def torn_down_on_sigterm() -> Iterator[None]:
    """A SIGTERM (a CI timeout) unwinds as ^C does: the container is torn down, pytest stops."""

    def unwind(signum: int, frame: object) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    previous = signal.signal(signal.SIGTERM, unwind)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def installed(machine: Machine) -> dict[str, bool]:
    return {
        what: machine.run(["sh", "-c", check], check=False).returncode == 0
        for what, check in INSTALLED.items()
    }


def checkout_listing(machine: Machine) -> set[tuple[str, int]]:
    root = machine.path(CHECKOUT)
    return {
        (str(path.relative_to(root)), path.stat().st_size if path.is_file() else -1)
        for path in root.rglob("*")
    }


@pytest.fixture(scope="module")
def robot(request: pytest.FixtureRequest) -> Iterator[Robot]:
    """Debian 12 booted, kasparctl installed by the README's lines and started (simulated)."""
    if problem := host_problem():
        if in_ci():
            pytest.fail(f"the boot test must run in CI, but: {problem}")
        pytest.skip(f"this machine cannot boot a container: {problem}")
    timings: dict[str, float] = {}
    with torn_down_on_sigterm():
        ensure_host_tools()
        packages = run_install_sh("--packages").stdout.split()
        started = time.monotonic()
        base_name = base_tree_name(packages)

        def build_base(work: Path) -> None:
            build_base_tree(work, packages)
            timings["base built"] = time.monotonic() - started

        with cached_tree(base_name, build_base) as base:
            python = container_python(base / "debs")
            requirements = project_requirements(REPO / "pyproject.toml")
            wheels_started = time.monotonic()

            def build_wheelhouse(work: Path) -> None:
                build_wheels(work, requirements, python, base)
                timings["wheels built"] = time.monotonic() - wheels_started

            with cached_tree(wheels_name(requirements, python), build_wheelhouse) as wheels:
                prune_trees(keep=[base.name, wheels.name])
                binds = {base / "debs": DEBS_IN_CONTAINER, wheels: WHEELS_IN_CONTAINER}
                with Machine(base, binds) as machine:
                    machine.copy_checkout(REPO, CHECKOUT)
                    install_test_files(machine)
                    machine.boot()
                    assert machine.boot_seconds is not None
                    timings["boot"] = machine.boot_seconds
                    robot = Robot(machine, timings)
                    robot.story["install runs"] = run_readme_lines(robot)
                    try:
                        yield robot
                    finally:
                        report(request, robot)


def run_readme_lines(robot: Robot) -> list[InstallRun]:
    machine = robot.machine
    robot.story["checkout"] = checkout_listing(machine)
    runs = []
    for line in readme_install_lines():
        started = time.monotonic()
        result = machine.run(
            ["bash", "-c", line], check=False, cwd=CHECKOUT, env=OFFLINE_PIP, timeout=1200
        )
        runs.append(
            InstallRun(
                line,
                result.stdout + result.stderr,
                result.returncode,
                time.monotonic() - started,
                installed(machine),
            )
        )
        if result.returncode != 0:
            raise BootError(f"{line} failed ({result.returncode}):\n{runs[-1].output[-4000:]}")
    robot.timings["install"] = sum(run.seconds for run in runs if "--dry-run" not in run.line)
    return runs


def report(request: pytest.FixtureRequest, robot: Robot) -> None:
    """The one summary line, on the terminal after the module's results."""
    t = robot.timings

    def seconds(name: str, digits: int = 1) -> str:
        return f"{t[name]:.{digits}f} s" if name in t else "not measured"

    cache = ", ".join(
        f"{name} in {t[name]:.0f} s" for name in ("base built", "wheels built") if name in t
    )
    line = (
        f"boot test: start to READY {seconds('ready', 2)}, stop {seconds('stop', 2)}, "
        f"watchdog restart {seconds('watchdog restart')} (SIGSTOP to READY, "
        f"{seconds('restart after timeout')} of it after the timeout), "
        f"a keyfob plugged in late found in {seconds('keyfob found', 2)}; "
        f"boot {seconds('boot')}, install {seconds('install')}, "
        f"{cache or 'trees from the cache'}"
    )
    if "lateness" in robot.story:
        line += "; body loop tick lateness p99 (empty-loop floor) " + ", ".join(
            f"{label} {late:.2f} ms ({floor:.2f} ms)"
            for label, (late, floor) in robot.story["lateness"].items()
        )
    if "no sound card" in robot.story:
        line += f"; without a sound card the player said first: {robot.story['no sound card']!r}"
    plugins = request.config.pluginmanager
    reporter, capture = plugins.get_plugin("terminalreporter"), plugins.get_plugin("capturemanager")
    if reporter is None or capture is None:
        print(line, file=sys.stderr)
        return
    with capture.global_and_fixture_disabled():
        reporter.write("\n")  # after the progress dots
        reporter.write_line(line)


# -- the story: installed and idle ---------------------------------------------------------------


def test_readme_lines_install_it_and_the_dry_run_changes_nothing(robot: Robot) -> None:
    runs: list[InstallRun] = robot.story["install runs"]
    dry = next(run for run in runs if "--dry-run" in run.line)
    real = next(run for run in runs if "--dry-run" not in run.line)
    assert not any(dry.installed_after.values()), dry.installed_after
    assert all(real.installed_after.values()), real.installed_after
    # The dry run printed the steps the install then took.
    assert step_titles(dry.output) == step_titles(real.output)
    # On a fresh machine: packages through apt-get update, nothing assumed installed.
    assert "apt-get update" in real.output
    # What a container lacks is explained, not fatal.
    assert "note: the modules could not be loaded now" in real.output
    assert "note: udev is not running here" in real.output


def test_the_install_leaves_the_checkout_as_it_was(robot: Robot) -> None:
    assert checkout_listing(robot.machine) == robot.story["checkout"]


def test_the_service_is_ready_with_its_status(robot: Robot) -> None:
    p = robot.show(
        "Type", "ActiveState", "SubState", "StatusText", "NRestarts",
        "ExecMainStartTimestampMonotonic", "ActiveEnterTimestampMonotonic",
    )  # fmt: skip
    assert (p["Type"], p["ActiveState"], p["SubState"]) == ("notify", "active", "running"), p
    assert without_clock(p["StatusText"]) == FRESH_IDLE
    assert re.search(r" \| battery 1[0-3]\.\d V$", p["StatusText"]), p  # the simulated LiFePO4
    assert p["NRestarts"] == "0"
    # Type=notify: active means READY=1 arrived.
    ready = usec(p["ActiveEnterTimestampMonotonic"]) - usec(p["ExecMainStartTimestampMonotonic"])
    robot.timings["ready"] = ready
    assert 0 < ready < 10, ready
    assert "ready" in robot.log_events()


def test_check_looks_for_the_researchers_device_by_its_rule(robot: Robot) -> None:
    """No input device can exist in the container (no uinput; the host's sysfs has none):
    the researcher's rule is installed as shipped, `check` looks for the node it makes
    and names it, and the running service says nothing about missing buttons."""
    rule = "/etc/udev/rules.d/99-kaspar-researcher.rules"
    shipped = (REPO / "systemd" / "99-kaspar-researcher.rules").read_text()
    assert robot.machine.path(rule).read_text() == shipped
    checked = robot.machine.run(
        ["/opt/kasparctl/bin/kasparctl", "check", "--quiet", "--config", CONFIG], check=False
    )
    rows = [line for line in checked.stdout.splitlines() if line.startswith("researcher")]
    assert rows and "/dev/input/kaspar-researcher" in rows[0], checked.stdout
    assert not any("not connected" in event for event in robot.log_events()), robot.log_events()


def test_the_configuration_is_readable_by_the_service_alone(robot: Robot) -> None:
    mode = robot.machine.run(["stat", "-c", "%a %U %G", CONFIG]).stdout.split()
    assert mode == ["640", "root", "kaspar"]


def test_installing_again_keeps_the_configuration_and_the_running_service(robot: Robot) -> None:
    pid = robot.main_pid()
    robot.machine.run(["sh", "-c", f"printf '{RESEARCHER_EDIT}' >> {CONFIG}"])
    started = time.monotonic()
    result = robot.machine.run(
        ["bash", "systemd/install.sh"], cwd=CHECKOUT, env=OFFLINE_PIP, timeout=1200
    )
    robot.timings["reinstall"] = time.monotonic() - started
    assert "all installed" in result.stdout  # no apt-get at all the second time
    assert f"{CONFIG} exists: kept" in result.stdout
    assert "was already running" in result.stdout
    assert robot.main_pid() == pid  # not restarted under a possible session
    assert robot.machine.read_bytes(CONFIG).decode().endswith(RESEARCHER_EDIT)


def test_watchdog_pings_arrive(robot: Robot) -> None:
    p = robot.show("WatchdogUSec", "WatchdogTimestampMonotonic")
    assert p["WatchdogUSec"] == "10s"

    def pinged_again() -> bool:
        later = robot.show("WatchdogTimestampMonotonic")["WatchdogTimestampMonotonic"]
        return later != p["WatchdogTimestampMonotonic"]

    robot.wait_for("a watchdog ping", pinged_again, timeout=12)


def test_the_running_daemon_holds_no_privilege(robot: Robot) -> None:
    pid = robot.main_pid()
    status = dict(
        line.split(":\t", 1)
        for line in robot.machine.read_bytes(f"/proc/{pid}/status").decode().splitlines()
        if ":\t" in line
    )
    uid = robot.machine.run(["id", "-u", "kaspar"]).stdout.strip()
    assert status["Uid"].split() == [uid] * 4
    for capabilities in ("CapInh", "CapPrm", "CapEff", "CapBnd", "CapAmb"):
        assert int(status[capabilities], 16) == 0, (capabilities, status[capabilities])
    assert status["NoNewPrivs"].strip() == "1"
    assert status["Seccomp"].strip() == "2"  # a system-call filter


def thread_scheduling(robot: Robot, pid: int) -> dict[str, tuple[str, int]]:
    """Each thread of `pid`: its name, and (policy, real-time priority) from /proc's stat."""
    policies = {0: "other", 1: "fifo", 2: "rr", 3: "batch", 5: "idle"}
    seen = {}
    for task in robot.machine.run(["ls", f"/proc/{pid}/task"]).stdout.split():
        stat = robot.machine.read_bytes(f"/proc/{pid}/task/{task}/stat").decode()
        name = stat[stat.index("(") + 1 : stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2 :].split()
        # stat(5): rt_priority and policy are fields 40 and 41, the 38th and 39th after comm.
        seen[f"{task} {name}"] = (policies.get(int(fields[38]), fields[38]), int(fields[37]))
    return seen


def test_the_body_loops_thread_alone_runs_real_time(robot: Robot) -> None:
    pid = robot.main_pid()
    threads = thread_scheduling(robot, pid)
    main = next(key for key in threads if key.startswith(f"{pid} "))
    assert threads.pop(main) == ("fifo", 10), main
    # Reset on fork: the buses', the executor's and the voice's threads are normal.
    assert threads, "the daemon has its bus and voice threads"
    assert set(threads.values()) == {("other", 0)}, threads
    assert "scheduling" in robot.log_events()


# Seconds of each of the two runs of the body loop's benchmark (and a third of it on the
# empty loop first); KASPAR_BOOT_LATENESS_S longer for bench/bench_realtime.py's figures.
LATENESS_SECONDS = os.environ.get("KASPAR_BOOT_LATENESS_S", "3")
REAL_TIME = ["-p", "CPUSchedulingPolicy=fifo", "-p", "CPUSchedulingPriority=10",
             "-p", "CPUSchedulingResetOnFork=yes"]  # fmt: skip


def test_the_body_loops_lateness_with_and_without_real_time(robot: Robot) -> None:
    """Measured, not asserted (a shared machine's timing is no test): the figures go to the
    report line; asserted is that each run ran under the policy it was given."""
    figures = {}
    for label, properties in (("normal", []), ("fifo 10", REAL_TIME)):
        result = robot.machine.run(
            ["systemd-run", "--quiet", "--wait", "--pipe", "--collect", *properties, "--",
             "/opt/kasparctl/bin/python", f"{CHECKOUT}/bench/bench_body_loop.py",
             LATENESS_SECONDS],
            timeout=120,
        )  # fmt: skip
        out = result.stdout
        policy = re.search(r"scheduling: (.*)", out)
        assert policy and policy.group(1).startswith(label.split()[0].replace("normal", "other")), out
        late = re.search(r"tick lateness p99\s+(\d+\.\d+) ms", out)
        floor = re.search(r"empty loop just before: p99 (\d+\.\d+) ms", out)
        assert late and floor, out
        figures[label] = (float(late.group(1)), float(floor.group(1)))
    robot.story["lateness"] = figures


OPEN_DEVICES = (
    "for device in /dev/null /dev/net/tun; do "
    'if (exec 3<>"$device") 2>/dev/null; then echo "$device opened"; '
    'else echo "$device refused"; fi; done'
)


def test_a_device_outside_device_allow_is_refused(robot: Robot) -> None:
    need("a systemd that enforces DevicePolicy= in the container", robot.device_policy_problem())
    p = robot.show("DevicePolicy", "DeviceAllow")
    assert p["DevicePolicy"] == "closed"
    assert "char-ttyUSB rw" in p["DeviceAllow"]
    code, output = robot.probe(["id", "-un"])
    assert (code, output.strip()) == (0, "kaspar")  # the probe is sandboxed as the service is
    # /dev/net/tun is in the container (nspawn makes it) but not in DeviceAllow=.
    code, output = robot.probe(["sh", "-c", OPEN_DEVICES])
    assert code == 0, output
    assert output.split("\n")[:2] == ["/dev/null opened", "/dev/net/tun refused"], output
    # Refused by the policy, not by file permissions: the same user opens it outside.
    control = robot.machine.run(["runuser", "-u", "kaspar", "--", "sh", "-c", OPEN_DEVICES])
    assert "/dev/net/tun opened" in control.stdout


def spoken_seconds(data: bytes) -> float:
    """The length of the WAV, checked to hold sound rather than silence."""
    with wave.open(io.BytesIO(data)) as wav:
        assert wav.getsampwidth() == 2
        frames = wav.readframes(wav.getnframes())
        seconds: float = wav.getnframes() / wav.getframerate()
    samples = array("h", frames)
    assert max(abs(sample) for sample in samples) > 1000, "silence"
    return seconds


def test_speech_is_rendered_under_the_units_hardening(robot: Robot) -> None:
    for engine in ("espeak-ng", "pyttsx3"):
        wav = f"/run/kaspar-probe/{engine}.wav"
        code, output = robot.probe(
            ["/opt/kasparctl/bin/kasparctl", "say", "--engine", engine, "--wav", wav,
             "Hello, I am Kaspar. Shall we play?"]
        )  # fmt: skip
        assert code == 0, output
        assert f"({engine})" in output, output  # no fallback to the other engine
        assert spoken_seconds(robot.machine.read_bytes(wav)) > 1.0
    # Played (there is no sound card here): the sound stack keeps its files in the
    # private runtime directory, and nothing lands among the research records.
    robot.probe(["espeak-ng", "Hello"])
    left = robot.machine.run(["ls", "-A", "/run/kaspar-probe"]).stdout.split()
    assert "pulse" in left, left
    robot.machine.run(["rm", "-rf", "/run/kaspar-probe"])
    assert robot.machine.run(["ls", "-A", STATE_DIR]).stdout.split() == []


# -- a session under way ------------------------------------------------------------------------


def session_dirs(robot: Robot) -> list[str]:
    result = robot.machine.run(["ls", "-A", f"{STATE_DIR}/sessions"], check=False)
    return result.stdout.split()


def test_reload_between_sessions_succeeds(robot: Robot) -> None:
    pid = robot.main_pid()
    result = robot.machine.run(["systemctl", "reload", UNIT], check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    robot.wait_for("the reload", lambda: "configuration reloaded" in robot.log_events())
    assert robot.main_pid() == pid
    robot.wait_for_status_where("idle", lambda text: text.startswith(IDLE))


def test_long_green_starts_a_session(robot: Robot) -> None:
    robot.press("G")
    robot.wait_for_status(PLACING)
    assert len(session_dirs(robot)) == 1


def test_reload_is_refused_mid_session_and_systemctl_reload_fails(robot: Robot) -> None:
    pid = robot.main_pid()
    # ExecReload= (kasparctl reload) sends SIGHUP and waits for the daemon's answer.
    result = robot.machine.run(["systemctl", "reload", UNIT], check=False)
    assert result.returncode != 0, result.stdout
    assert f"Job for {UNIT} failed" in result.stderr, result.stderr
    assert any(event.startswith("reload refused") for event in robot.log_events())
    said = [str(e.get("MESSAGE")) for e in robot.journal()]
    assert any(m.startswith("kasparctl reload: reload refused: a session is running") for m in said)
    p = robot.show("MainPID", "ActiveState", "StatusText")
    status = without_clock(p["StatusText"])
    assert (int(p["MainPID"]), p["ActiveState"], status) == (pid, "active", PLACING)


def test_the_journal_keeps_each_lines_priority(robot: Robot) -> None:
    # journald took each line's "<N>" (SyslogLevelPrefix=): -p warning shows the refused
    # reload, and no line logged at info.
    warnings = robot.journal(priority="warning")
    logged = [e["log"] for e in warnings if isinstance(e.get("log"), dict)]
    assert any(line["event"].startswith("reload refused") for line in logged), logged
    assert {line["level"] for line in logged} <= {"warning", "error", "critical"}, logged
    assert all(int(e["PRIORITY"]) <= 4 for e in warnings)
    everything = robot.journal()
    ready = [e for e in everything if isinstance(e.get("log"), dict) and e["log"]["event"] == "ready"]
    assert ready and {e["PRIORITY"] for e in ready} == {"6"}
    refused = [e for e in everything if str(e.get("MESSAGE")).startswith("kasparctl reload: reload")]
    assert refused and refused[-1]["PRIORITY"] == "3"


def test_the_watchdog_restarts_a_stopped_daemon_and_the_session_resumes(robot: Robot) -> None:
    before = robot.show("MainPID", "NRestarts")
    sessions = session_dirs(robot)
    stopped_at = time.monotonic()  # CLOCK_MONOTONIC, the clock of systemd's timestamps
    robot.systemctl("kill", "--kill-whom=main", "--signal=SIGSTOP", UNIT)

    def restarted() -> dict[str, str] | None:
        p = robot.show(
            "NRestarts", "ActiveState", "MainPID", "ActiveEnterTimestampMonotonic", "InvocationID"
        )
        return p if p["NRestarts"] != before["NRestarts"] and p["ActiveState"] == "active" else None

    after = robot.wait_for("a restart by the watchdog", restarted, timeout=40)
    robot.timings["watchdog restart"] = usec(after["ActiveEnterTimestampMonotonic"]) - stopped_at
    assert after["MainPID"] != before["MainPID"]
    timeouts = [e for e in robot.journal() if "Watchdog timeout" in str(e.get("MESSAGE"))]
    assert timeouts, "no watchdog timeout in the journal"
    timed_out = usec(timeouts[-1]["__MONOTONIC_TIMESTAMP"])
    robot.timings["restart after timeout"] = (
        usec(after["ActiveEnterTimestampMonotonic"]) - timed_out
    )
    robot.wait_for_status(PLACING)
    assert "resuming session" in robot.log_events(invocation=after["InvocationID"])
    assert session_dirs(robot) == sessions
    robot.story["invocation"] = after["InvocationID"]


# -- stopped ------------------------------------------------------------------------------------


def test_stop_is_clean(robot: Robot) -> None:
    robot.systemctl("stop", UNIT)
    p = robot.show(
        "ActiveState", "Result", "ExecMainCode", "ExecMainStatus",
        "ActiveExitTimestampMonotonic", "InactiveEnterTimestampMonotonic",
    )  # fmt: skip
    assert (p["ActiveState"], p["Result"]) == ("inactive", "success"), p
    assert (p["ExecMainCode"], p["ExecMainStatus"]) == ("1", "0"), p  # exited, status 0
    stop = usec(p["InactiveEnterTimestampMonotonic"]) - usec(p["ActiveExitTimestampMonotonic"])
    robot.timings["stop"] = stop
    assert stop < 5, stop
    assert "stopped" in robot.log_events(invocation=robot.story["invocation"])


def test_records_are_private_and_owned_by_kaspar(robot: Robot) -> None:
    listing = robot.machine.run(["find", STATE_DIR, "-printf", "%y %m %u %g %P\n"]).stdout
    entries = [line.split(" ", 4) for line in listing.splitlines()]
    names = {Path(entry[4]).name for entry in entries}
    assert {"plan.json", "records.jsonl", "state.json"} <= names, names
    for kind, mode, user, group, path in entries:
        expected = ["700"] if kind == "d" else ["600"]
        assert [mode, user, group] == [*expected, "kaspar", "kaspar"], (kind, path)


def test_the_state_directory_holds_only_sessions(robot: Robot) -> None:
    listing = robot.machine.run(["find", STATE_DIR, "-mindepth", "1", "-printf", "%P\n"]).stdout
    for path in listing.split():
        assert SESSION_PATH.fullmatch(path), path


# -- uninstalled -----------------------------------------------------------------------------


def test_uninstall_removes_the_service_and_keeps_records_and_configuration(robot: Robot) -> None:
    records_before = robot.machine.run(["find", STATE_DIR, "-printf", "%P %s\n"]).stdout
    result = robot.machine.run(["bash", "systemd/install.sh", "--uninstall"], cwd=CHECKOUT)
    assert f"Kept: the research records in {STATE_DIR}" in result.stdout
    state = installed(robot.machine)
    assert state == {what: what == "the configuration" for what in INSTALLED}, state
    assert robot.show("LoadState")["LoadState"] == "not-found"
    assert robot.machine.run(["find", STATE_DIR, "-printf", "%P %s\n"]).stdout == records_before
    assert robot.machine.read_bytes(CONFIG).decode().endswith(RESEARCHER_EDIT)


def test_installing_again_resumes_the_kept_session(robot: Robot) -> None:
    sessions = session_dirs(robot)
    robot.machine.run(["bash", "systemd/install.sh"], cwd=CHECKOUT, env=OFFLINE_PIP, timeout=1200)
    robot.wait_for_status(PLACING)  # the unfinished session, resumed
    assert "resuming session" in robot.log_events(
        invocation=robot.show("InvocationID")["InvocationID"]
    )
    assert session_dirs(robot) == sessions
    owners = robot.machine.run(["find", STATE_DIR, "-printf", "%u %g\n"]).stdout.split("\n")
    assert set(filter(None, owners)) == {"kaspar kaspar"}  # handed to the new user


# -- faults on the robot -------------------------------------------------------------------------

NOSOUND_CONFIG = "/etc/kaspar/nosound.toml"
LATE_KEYFOB = "/run/kaspar/keyfob"


def session_records(robot: Robot) -> list[dict[str, Any]]:
    """The records of the newest session."""
    newest = sorted(session_dirs(robot))[-1]
    text = robot.machine.read_bytes(f"{STATE_DIR}/sessions/{newest}/records.jsonl").decode()
    return [json.loads(line) for line in text.splitlines()]


def test_stop_ends_the_resumed_session(robot: Robot) -> None:
    robot.press("b")  # both: stop
    robot.wait_for_status_where("idle", lambda text: text.startswith(IDLE))
    assert [r["to"] for r in session_records(robot) if r["kind"] == "step"][-1] == "stopped"


def test_no_sound_card_the_session_runs_is_recorded_and_stops(robot: Robot) -> None:
    """The real voice (espeak-ng into aplay) in the unit's sandbox, on a machine with no
    sound card: the simulated robot and keyfob of the demo, sessions in the state dir."""
    demo = robot.machine.read_bytes(f"{CHECKOUT}/kasparctl/sim/demo.toml").decode()
    config = demo.replace('level = "warning"', 'level = "info"') + '\n[keyfob]\nbackend = "sim"\n'
    robot.machine.write(NOSOUND_CONFIG, config, mode=0o640)
    robot.machine.run(["chgrp", "kaspar", NOSOUND_CONFIG])
    robot.override(
        "nosound",
        "[Service]\nExecStart=\n"
        f"ExecStart=/opt/kasparctl/bin/kasparctl run --config {NOSOUND_CONFIG} --state-dir {STATE_DIR}\n",
    )
    try:
        robot.systemctl("restart", UNIT)
        robot.wait_for_status_where("idle", lambda text: text.startswith(IDLE))
        before = session_dirs(robot)
        written = len(session_records(robot)) if before else 0
        # Next: the session stopped by the test before reopens (or a new one opens).
        robot.press("G")
        status = robot.wait_for_status_where(
            "a voice fault", lambda text: text.startswith("fault") and "voice failing" in text
        )
        assert robot.show("ActiveState")["ActiveState"] == "active"
        # The session is written: a new one, or the stopped one carried on.
        assert session_dirs(robot) != before or len(session_records(robot)) > written
        records = session_records(robot)
        unheard = [r for r in records if r["kind"] == "hal" and r["event"] == "voice"]
        assert unheard and unheard[0]["status"] == "failed", records
        # aplay's first line (its cause) is kept, as aplay says it in the same sandbox.
        _, aplay = robot.probe(["sh", "-c", "aplay -q /dev/zero 2>&1 >/dev/null | head -n 1"])
        first = aplay.strip().splitlines()[0]
        assert first and first in unheard[0]["error"], (first, unheard[0]["error"])
        assert first[:60] in status
        faults = [r for r in records if r["kind"] == "fault"]
        assert faults and faults[0]["fault"] == "voice", records
        errors = [e["log"] for e in robot.journal(priority="err") if isinstance(e.get("log"), dict)]
        assert any(line["event"] == "fault" and line["fault"] == "voice" for line in errors)
        robot.story["no sound card"] = first
        # Stop, without sound.
        robot.press("b")
        robot.wait_for_status_where("idle again", lambda text: text.startswith(IDLE))
        assert [r["to"] for r in session_records(robot) if r["kind"] == "step"][-1] == "stopped"
    finally:
        robot.override("nosound", None)


def test_the_keyfob_absent_at_start_starts_the_session_once_plugged_in(robot: Robot) -> None:
    """The simulated keyfob's keys from a fifo in the runtime directory, which is emptied
    at every start: not there when the service starts, created later by the test (as
    udev makes a keyfob's node); the service watches for it with inotify, in its sandbox."""
    robot.override(
        "late-keyfob",
        "[Service]\nExecStart=\n"
        f"ExecStart=/opt/kasparctl/bin/kasparctl run --sim --config {CONFIG} --keys {LATE_KEYFOB}\n",
    )
    try:
        robot.systemctl("restart", UNIT)
        invocation = robot.show("InvocationID")["InvocationID"]
        status = robot.wait_for_status_where("no keyfob", lambda text: "keyfob not connected" in text)
        assert status.startswith(IDLE) and "not available at start" in status, status
        warnings = robot.journal(priority="warning", invocation=invocation)
        assert any(
            isinstance(e.get("log"), dict) and e["log"]["event"] == "keyfob not connected; watching for it"
            for e in warnings
        )
        plugged = time.monotonic()
        robot.machine.run(["sh", "-c", f"mkfifo -m 0600 {LATE_KEYFOB} && chown kaspar:kaspar {LATE_KEYFOB}"])
        robot.wait_for_status_where("idle", lambda text: text.startswith(IDLE))
        robot.timings["keyfob found"] = time.monotonic() - plugged
        found = [
            (e["PRIORITY"], e["log"]) for e in robot.journal(invocation=invocation)
            if isinstance(e.get("log"), dict) and e["log"]["event"] not in ("ready",)
        ]  # fmt: skip
        assert robot.timings["keyfob found"] < 2.0, found  # inotify, not the 5 s look-again
        robot.machine.run(["sh", "-c", f"printf G > {LATE_KEYFOB}"])  # long green, no restart
        robot.wait_for_status(PLACING)
        assert robot.show("InvocationID")["InvocationID"] == invocation
    finally:
        robot.override("late-keyfob", None)
        robot.systemctl("stop", UNIT)

