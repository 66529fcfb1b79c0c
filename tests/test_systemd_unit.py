"""The service unit as systemd itself reads it: clean, and exposed as little as possible."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

from capabilities import man_page_problem, need

REPO = Path(__file__).resolve().parents[1]
UNIT = REPO / "systemd" / "kasparctl.service"
# systemd-analyze security rates the unit 0.6 ("SAFE"; 0.7 before PrivateMounts=); a change
# that exposes more fails.
EXPOSURE_LIMIT = 0.6


def unit_for_this_machine(tmp_path: Path) -> Path:
    """The unit with ExecStart= pointing at this checkout's kasparctl (verify checks it exists)."""
    kasparctl = Path(sys.executable).with_name("kasparctl")
    assert kasparctl.exists(), kasparctl
    copy = tmp_path / "kasparctl.service"
    copy.write_text(UNIT.read_text().replace("/opt/kasparctl/bin/kasparctl", str(kasparctl)))
    return copy


def systemd_analyze() -> str:
    found = shutil.which("systemd-analyze")
    need("systemd-analyze", None if found else "not installed (Debian's systemd)")
    assert found is not None
    return found


def documentation_problem() -> str | None:
    """Why man cannot show a page the unit's Documentation= names, or None: verify runs
    `man` for each, and says so on stderr when one is missing."""
    documentation = re.search(r"^Documentation=(.*)$", UNIT.read_text(), re.M)
    assert documentation, "the unit has no Documentation="
    for page, section in re.findall(r"man:([\w.@-]+)\((\w+)\)", documentation.group(1)):
        if problem := man_page_problem(page, section):
            return problem
    return None


def test_systemd_analyze_verify_says_nothing(tmp_path: Path) -> None:
    need("the man pages of the unit's Documentation= (man-db)", documentation_problem())
    # verify exits 0 even on unknown keys, so its stderr is the verdict.
    result = subprocess.run(
        [systemd_analyze(), "verify", str(unit_for_this_machine(tmp_path))],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.stderr == "" and result.returncode == 0, result.stderr


def test_security_exposure_is_at_most_0_6(tmp_path: Path) -> None:
    result = subprocess.run(
        [
            systemd_analyze(),
            "security",
            "--offline=true",
            "--no-pager",
            str(unit_for_this_machine(tmp_path)),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    found = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", result.stdout)
    assert found, result.stdout + result.stderr
    assert float(found.group(1)) <= EXPOSURE_LIMIT, result.stdout


def test_unit_keeps_what_the_robot_needs() -> None:
    text = UNIT.read_text()
    for line in (
        "Type=notify",
        "WatchdogSec=",
        "Restart=on-failure",
        "StateDirectoryMode=0700",
        "SupplementaryGroups=dialout input audio",
        "DevicePolicy=closed",
        "CapabilityBoundingSet=\n",
        "NoNewPrivileges=yes",
        "ProtectSystem=strict",
        "PrivateNetwork=yes",
        "SystemCallFilter=@system-service",
        "StartLimitBurst=",
        # systemctl reload fails when the daemon refuses (kasparctl.service.reload).
        "ExecReload=/opt/kasparctl/bin/kasparctl reload --pid $MAINPID",
        "SyslogLevelPrefix=yes",
        # The body loop's thread: SCHED_FIFO, not inherited (tests/test_realtime.py),
        # and the process may not raise it further.
        "CPUSchedulingPolicy=fifo\n",
        "CPUSchedulingResetOnFork=yes\n",
        "RestrictRealtime=yes\n",
    ):
        assert line in text, line


def test_install_print_runs_the_install_script(capsys) -> None:
    # One source of truth: --print says how to run systemd/install.sh, whose
    # --dry-run lists the steps (tests/boot runs it for real on a booted Debian).
    from kasparctl.cli import main

    assert main(["install", "--print"]) == 0
    printed = capsys.readouterr().out
    script = REPO / "systemd" / "install.sh"
    assert f"bash {script} --dry-run" in printed
    assert f"bash {script}\n" in printed
    assert f"bash {script} --uninstall" in printed
