"""What tests need from the machine beyond Python, probed before they need it.

A probe says why this machine lacks something a test needs, or None. `need` skips the
test with that reason, so the README's test command passes on any machine it names
(Debian 12 or 13, a container included), saying what it could not check there.

Under CI=true a skip is a failure (tests/conftest.py turns every one into a failure):
CI runs `bash .ci/run` as root on a fresh Debian 12 machine of its own, a VM rather
than a container, and that machine has everything probed here: root, root's power
over file permissions taken away by setpriv, man pages for systemd-analyze,
systemd-nspawn, a DevicePolicy= that the booted container enforces, and the Debian
packages .ci/run installs (espeak-ng, tmux...). A skip there is a missing install
step or a broken machine, never a pass.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

# Root without its power over file permissions, for a command run as root that must
# meet them as any user does: CAP_DAC_OVERRIDE and CAP_DAC_READ_SEARCH out of its
# bounding set, and its inheritable set emptied, since exec gives root the
# capabilities of its inheritable set whatever the bounding set says (a container's
# init may fill it: systemd-nspawn's does).
NO_OVERRIDE = ("setpriv", "--inh-caps=-all", "--bounding-set=-dac_override,-dac_read_search", "--")
NOBODY = 65534


def in_ci() -> bool:
    """CI=true (or 1, yes): a skip is a failure."""
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


def need(capability: str, problem: str | None) -> None:
    """Skip the test, naming `capability` and why it is missing, unless `problem` is None."""
    if problem is not None:
        pytest.skip(f"needs {capability}: {problem}")


@functools.cache
def override_problem() -> str | None:
    """Why NO_OVERRIDE cannot make root meet a directory private to another user, or None."""
    if os.geteuid() != 0:
        return "not root"
    if shutil.which("setpriv") is None:
        return "setpriv is not installed (Debian's util-linux)"
    with tempfile.TemporaryDirectory() as scratch:
        private = Path(scratch) / "private"
        private.mkdir(mode=0o700)
        os.chown(private, NOBODY, NOBODY)
        result = subprocess.run(
            [*NO_OVERRIDE, "ls", "--", str(private)],
            capture_output=True, text=True, timeout=30, check=False,
        )  # fmt: skip
    if result.returncode == 0:
        return (
            f"{' '.join(NO_OVERRIDE[:-1])} leaves root able to list a directory of mode 0700 "
            "owned by another user (a user namespace, or a kernel that grants it otherwise)"
        )
    if "Permission denied" not in result.stderr:
        return f"{' '.join(NO_OVERRIDE[:-1])} failed: {result.stderr.strip()}"
    return None


def man_page_problem(page: str, section: str) -> str | None:
    """Why `man` cannot find the page (systemd-analyze verify looks up Documentation=)."""
    if shutil.which("man") is None:
        return "man is not installed (Debian's man-db)"
    found = subprocess.run(
        ["man", "-w", section, page], capture_output=True, text=True, timeout=30, check=False
    )
    if found.returncode != 0:
        return f"man finds no page {page}({section}): {found.stderr.strip()}"
    return None
