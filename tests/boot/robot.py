"""The kasparctl service inside a booted Machine, as a test sees it.

systemctl properties, the journal (structlog's JSON lines decoded), keys pressed on
the simulated keyfob, waits with deadlines, and probes run as transient units with
the installed unit's own sandbox. A new check needs nothing more than these.
"""

from __future__ import annotations

import contextlib
import json
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

from boot.machine import BootError, Machine
from kasparctl.service.status import CLOCK_WORDS

UNIT = "kasparctl.service"
UNIT_FILE = "/etc/systemd/system/kasparctl.service"
KEYS_FIFO = "/run/kaspar-keys"
TUN = "/dev/net/tun"  # a device the container has and the unit's DeviceAllow= does not
# The test's changes to the installed service: simulated hardware, and the keyfob's
# keys read from a fifo the test writes into (kaspar-keys.service holds it open, so
# that neither the service's open nor the test's write ever waits for the other).
DROP_IN = f"""\
# The boot test's drop-in: simulated hardware, keys from {KEYS_FIFO}.
[Unit]
Wants=kaspar-keys.service
After=kaspar-keys.service

[Service]
ExecStart=
ExecStart=/opt/kasparctl/bin/kasparctl run --sim --config /etc/kaspar/kaspar.toml
StandardInput=file:{KEYS_FIFO}
StandardOutput=journal
StandardError=journal
"""
KEYS_TMPFILES = f"p {KEYS_FIFO} 0600 root root -\n"
KEYS_HOLDER = f"""\
[Unit]
Description=Holds the boot test's keyfob fifo open

[Service]
ExecStart=/bin/sh -c 'exec 3<>{KEYS_FIFO}; exec sleep infinity'
"""
# The unit's settings that make it the service (how it starts, restarts, is watched)
# rather than the sandbox it runs in; a probe takes every other one.
LIFECYCLE_KEYS = {
    "Type", "NotifyAccess", "ExecStart", "ExecStartPre", "ExecStartPost", "ExecReload",
    "ExecStop", "ExecStopPost", "Restart", "RestartSec", "WatchdogSec", "TimeoutStartSec",
    "TimeoutStopSec", "TimeoutSec",
}  # fmt: skip

T = TypeVar("T")


def install_test_files(machine: Machine) -> None:
    """Put the drop-in, the fifo and its holder in place before the container boots."""
    machine.write(f"/etc/systemd/system/{UNIT}.d/boot-test.conf", DROP_IN)
    machine.write("/etc/tmpfiles.d/kaspar-keys.conf", KEYS_TMPFILES)
    machine.write("/etc/systemd/system/kaspar-keys.service", KEYS_HOLDER)


def usec(value: str) -> float:
    """A systemd monotonic timestamp property (microseconds) in seconds."""
    return int(value) / 1e6


def without_battery(status: str) -> str:
    """STATUS= without its battery part ("... | battery 13.2 V"), which changes with time."""
    return re.sub(r" \| battery [^|]*", "", status)


@dataclass
class Robot:
    """The service in the machine: what the checks ask and do."""

    machine: Machine
    timings: dict[str, float] = field(default_factory=dict)
    # What one check leaves for a later one (the session's invocation, a listing...).
    story: dict[str, Any] = field(default_factory=dict)

    # -- systemd ----------------------------------------------------------------------

    def systemctl(self, *arguments: str, check: bool = True) -> str:
        """systemctl's output; a failure (with check) raises BootError."""
        return self.machine.run(["systemctl", "--no-pager", *arguments], check=check).stdout

    def show(self, *properties: str, unit: str = UNIT) -> dict[str, str]:
        """Unit properties by name (`systemctl show -p`)."""
        arguments = [argument for name in properties for argument in ("-p", name)]
        text = self.systemctl("show", unit, *arguments)
        return dict(line.split("=", 1) for line in text.splitlines() if "=" in line)

    def main_pid(self) -> int:
        """The service's main process, as the container numbers it (0 when none)."""
        return int(self.show("MainPID")["MainPID"])

    def wait_for(self, what: str, condition: Callable[[], T | None], timeout: float = 30.0) -> T:
        """Poll `condition` until it returns something truthy; AssertionError naming `what`."""
        deadline = time.monotonic() + timeout
        while True:
            found = condition()
            if found:
                return found
            if time.monotonic() > deadline:
                raise AssertionError(f"{what}: not within {timeout:.0f} s")
            time.sleep(0.1)

    def wait_for_status(self, status: str, timeout: float = 30.0) -> None:
        """Wait until the service's STATUS= is `status` (its battery part aside: it falls;
        and with the clock's warning after it or not: whether the container's clock is
        synchronised is not the test's)."""

        def reached() -> bool:
            return without_clock(self.show("StatusText")["StatusText"]) == status

        try:
            self.wait_for(f"STATUS={status}", reached, timeout)
        except AssertionError as error:
            raise AssertionError(f"{error}; it is {self.show('StatusText')}") from None

    def override(self, name: str, text: str | None) -> None:
        """Put a drop-in `name` on the unit (None: take it away), then daemon-reload."""
        path = f"/etc/systemd/system/{UNIT}.d/{name}.conf"
        if text is None:
            self.machine.run(["rm", "-f", path])
        else:
            self.machine.write(path, text)
        self.systemctl("daemon-reload")

    def status_text(self) -> str:
        """The service's STATUS= as systemctl shows it."""
        return self.show("StatusText")["StatusText"]

    def wait_for_status_where(self, what: str, wanted: Callable[[str], bool]) -> str:
        """Wait until STATUS= satisfies wanted(text); returns it."""

        def reached() -> str | None:
            text = self.status_text()
            return text if wanted(text) else None

        try:
            return self.wait_for(what, reached)
        except AssertionError as error:
            raise AssertionError(f"{error}; it is {self.status_text()!r}") from None

    # -- the keyfob --------------------------------------------------------------------

    def press(self, keys: str) -> None:
        """Keys of the simulated keyfob (G long green, g green, r red, b both, ...)."""
        self.machine.run(["sh", "-c", f'printf %s "$1" > {KEYS_FIFO}', "sh", keys])

    # -- the journal -------------------------------------------------------------------

    def journal(
        self,
        unit: str = UNIT,
        *,
        priority: str | None = None,
        invocation: str | None = None,
    ) -> list[dict[str, Any]]:
        """The unit's journal entries of this boot, oldest first; a structlog line's JSON
        is decoded into entry["log"]."""
        arguments = ["journalctl", "--no-pager", "-b", "-o", "json", "-u", unit]
        if priority is not None:
            arguments += ["-p", priority]
        if invocation is not None:
            arguments.append(f"_SYSTEMD_INVOCATION_ID={invocation}")
        entries = []
        for line in self.machine.run(arguments).stdout.splitlines():
            entry = json.loads(line)
            message = entry.get("MESSAGE")
            if isinstance(message, list):  # journald sends non-UTF-8 messages as bytes
                message = bytes(message).decode(errors="replace")
                entry["MESSAGE"] = message
            if isinstance(message, str) and message.startswith("{"):
                with contextlib.suppress(ValueError):  # a line that only looks like JSON
                    entry["log"] = json.loads(message)
            entries.append(entry)
        return entries

    def log_events(self, invocation: str | None = None) -> list[str]:
        """The `event` of every structlog line the service logged (of one invocation)."""
        return [
            entry["log"]["event"]
            for entry in self.journal(invocation=invocation)
            if isinstance(entry.get("log"), dict) and "event" in entry["log"]
        ]

    # -- probes in the unit's sandbox -----------------------------------------------------

    def unit_sandbox(self, runtime_directory: str) -> list[str]:
        """systemd-run -p options carrying the installed unit's [Service] settings, except
        those that make it the service; its RuntimeDirectory renamed, so that a probe
        never empties the running service's."""
        text = self.machine.read_bytes(UNIT_FILE).decode()
        section = re.search(r"^\[Service\]\n(.*?)(?=^\[|\Z)", text, re.M | re.S)
        if section is None:
            raise BootError(f"{UNIT_FILE} has no [Service] section")
        options = []
        for line in section.group(1).splitlines():
            if not line or line.startswith(("#", ";")):
                continue
            key, _, value = line.partition("=")
            if key in LIFECYCLE_KEYS:
                continue
            if key == "RuntimeDirectory":
                value = runtime_directory
            value = re.sub(r"/run/kaspar(?=[\s/]|$)", f"/run/{runtime_directory}", value)
            options += ["-p", f"{key}={value}"]
        return options

    def device_policy_problem(self) -> str | None:
        """Why this machine's systemd does not enforce DevicePolicy=, or None.

        The control of the unit's own check: a transient unit with DevicePolicy=closed
        and nothing else, as root, opens /dev/net/tun (systemd-nspawn makes it). Where
        its systemd cannot attach the device filter (a container inside a container),
        systemd starts the unit all the same, and the device opens.
        """
        if self.machine.run(["test", "-c", TUN], check=False).returncode != 0:
            return f"no {TUN} in the container to try the policy on"
        result = self.machine.run(
            ["systemd-run", "--quiet", "--wait", "--pipe", "--collect",
             "-p", "DevicePolicy=closed", "--", "sh", "-c", f"exec 3<>{TUN}"],
            check=False,
        )  # fmt: skip
        if result.returncode == 0:
            return f"a unit with DevicePolicy=closed and nothing else opened {TUN} as root"
        return None

    def probe(
        self, argv: Sequence[str], runtime_directory: str = "kaspar-probe", timeout: float = 60.0
    ) -> tuple[int, str]:
        """Run `argv` as a transient unit with the unit's sandbox (its user, devices, system
        calls, MemoryDenyWriteExecute...); its exit status and output. The runtime directory
        is kept afterwards, for the test to read and then remove."""
        result = self.machine.run(
            ["systemd-run", "--quiet", "--wait", "--pipe", "--collect",
             *self.unit_sandbox(runtime_directory), "-p", "RuntimeDirectoryPreserve=yes",
             "--", *argv],
            check=False,
            timeout=timeout,
        )  # fmt: skip
        return result.returncode, result.stdout + result.stderr


def without_clock(status: str) -> str:
    """STATUS= without its battery part and the clock's warning (kasparctl.service.status):
    the simulated battery falls with time, and the container's clock is not the test's."""
    return without_battery(status).removesuffix(f" | {CLOCK_WORDS}")
