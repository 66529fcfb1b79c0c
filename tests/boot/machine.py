"""Debian 12 booted with systemd as PID 1, in a systemd-nspawn container on this machine.

Three layers, each cached or torn down on its own:

- the base tree: debootstrap's minbase plus what a Debian install boots with, built once
  and kept outside the clone in CACHE/base-KEY (KEY hashes the suite, the base packages
  and the packages systemd/install.sh installs). Beside it, CACHE/base-KEY/debs holds
  those packages and their dependencies as a local apt repository, the tree's only
  source: the container has no network (--private-network), so install.sh's
  `apt-get update && apt-get install` reads them from there, as a robot would from a
  school's mirror;
- the wheelhouse, CACHE/wheels-KEY: the project's dependencies and its build backend as
  wheels for the container's Python, keyed by pyproject.toml's requirements (pip in the
  container reads it through PIP_NO_INDEX and PIP_FIND_LINKS, nothing else changes).
  This Python builds them where it is the container's version (Debian 12's 3.11); on a
  host of another (Debian 13's 3.13) the container's own Python does, in a throwaway
  overlay of the base tree;
- a Machine per run: an overlay over the base tree in its own CACHE/runs/NAME, booted by
  systemd-nspawn and entered with nsenter, always shut down, unmounted and removed. A run
  killed before it could clean up (SIGKILL) is cleaned up by the next one.

Each run holds its own lock (CACHE/runs/NAME.lock) and a shared lock on the trees it
uses, so two runs never collide and no tree is rebuilt or pruned while in use.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path

CACHE = Path(os.environ.get("KASPAR_BOOT_CACHE", "/var/cache/kasparctl-boot"))
SUITE = "bookworm"
MIRROR = "http://deb.debian.org/debian"
# What a Debian 12 install boots with beyond minbase: the init, the bus, udev, modprobe.
BASE_PACKAGES = ("systemd", "dbus", "udev", "kmod")
# Bumped whenever the way a tree is built changes, so that no older tree is reused.
BASE_FORMAT = 1
HOST_TOOLS = {
    "debootstrap": "debootstrap",
    "systemd-nspawn": "systemd-container",
    "nsenter": "util-linux",
}
DEBS_IN_CONTAINER = "/var/cache/kaspar-debs"
WHEELS_IN_CONTAINER = "/var/cache/kaspar-wheels"
# What the tree's own Python needs to build the wheelhouse (install.sh installs them too).
WHEEL_BUILDER_PACKAGES = ("python3-venv", "python3-dev", "gcc", "libc6-dev")
CONTAINER_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
# --system-call-filter=bpf lets the container's systemd load the BPF device
# programs behind DevicePolicy=; without it the policy could not be enforced.
NSPAWN_FLAGS = ("--register=no", "--keep-unit", "--private-network", "--system-call-filter=bpf")
COMPLETE = "complete"  # the file that marks a cached tree as fully built
CHECKOUT_LITTER = (
    ".git",
    ".venv",
    "build",
    "dist",
    "*.egg-info",
    "__pycache__",
    ".*_cache",
    ".hypothesis",
)


class BootError(Exception):
    """A step of building, booting or entering the container failed; says which and why."""


# -- the host ---------------------------------------------------------------------------


def host_problem() -> str | None:
    """Why this machine cannot run systemd-nspawn at all, or None if it can."""
    if not sys.platform.startswith("linux"):
        return f"systemd-nspawn needs Linux; this is {sys.platform}"
    if os.geteuid() != 0:
        return "booting a container needs root (systemd-nspawn, an overlay mount)"
    missing = [package for tool, package in HOST_TOOLS.items() if shutil.which(tool) is None]
    if missing and shutil.which("apt-get") is None:
        return f"{', '.join(missing)} not installed, and no apt-get to install them"
    return None


def ensure_host_tools() -> None:
    """Install debootstrap and systemd-nspawn from Debian's packages if they are missing."""
    missing = sorted({pkg for tool, pkg in HOST_TOOLS.items() if shutil.which(tool) is None})
    if not missing:
        return
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    _run(["apt-get", "update", "-qq"], "apt-get update on the host", env=env, timeout=600)
    _run(
        ["apt-get", "install", "-y", "-qq", "--no-install-recommends",
         "-o", "DPkg::Lock::Timeout=600", *missing],
        f"installing {' '.join(missing)} on the host",
        env=env,
        timeout=900,
    )  # fmt: skip


def _run(
    argv: Sequence[str | Path],
    what: str,
    *,
    timeout: float,
    env: Mapping[str, str] | None = None,
) -> str:
    """Run a host command; its output, or BootError naming the step with the output's end."""
    try:
        result = subprocess.run(
            [str(part) for part in argv],
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            errors="replace",
            env=env,
            timeout=timeout,
            check=False,
        )
    except subprocess.TimeoutExpired as error:
        raise BootError(f"{what}: no result after {timeout:.0f} s") from error
    if result.returncode != 0:
        tail = (result.stdout + result.stderr)[-3000:]
        raise BootError(f"{what} failed (exit {result.returncode}):\n{tail}")
    return result.stdout


# -- mounts and removal -------------------------------------------------------------------


def _mount_points_below(directory: Path) -> list[str]:
    """Mount points at or below `directory` in this mount namespace, deepest first."""
    prefix = os.path.realpath(directory)
    points = []
    for line in Path("/proc/self/mountinfo").read_text().splitlines():
        point = re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), line.split()[4])
        if point == prefix or point.startswith(prefix + "/"):
            points.append(point)
    return sorted(points, key=len, reverse=True)


def _unmount_below(directory: Path) -> None:
    """Unmount everything at or below `directory`; BootError if something stays mounted."""
    for _ in range(5):
        points = _mount_points_below(directory)
        if not points:
            return
        for point in points:
            if subprocess.run(["umount", point], capture_output=True, check=False).returncode:
                # Busy (a process still inside): detach now, freed when it exits.
                subprocess.run(["umount", "--lazy", point], capture_output=True, check=False)
    if left := _mount_points_below(directory):
        raise BootError(f"could not unmount {left}")


def _remove(directory: Path) -> None:
    """Remove a tree that may have held mounts: unmount first, and never cross a filesystem."""
    if not directory.exists():
        return
    _unmount_below(directory)
    subprocess.run(["rm", "-rf", "--one-file-system", str(directory)], check=True)


# -- cached trees ----------------------------------------------------------------------------


def _key(*parts: object) -> str:
    return hashlib.sha256(repr(parts).encode()).hexdigest()[:16]


@contextlib.contextmanager
def cached_tree(name: str, build: Callable[[Path], None]) -> Iterator[Path]:
    """CACHE/name, built by `build` once (under an exclusive lock); held shared while in use."""
    CACHE.mkdir(parents=True, exist_ok=True)
    final = CACHE / name
    descriptor = os.open(CACHE / f"{name}.lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_SH)
        if not (final / COMPLETE).exists():
            # Conversion drops the shared lock first: two runs that both find the tree
            # missing wait for each other here, then the second finds it built.
            fcntl.flock(descriptor, fcntl.LOCK_EX)
            if not (final / COMPLETE).exists():
                building = CACHE / f".{name}.building"
                _remove(final)  # half built by a run that was killed
                _remove(building)
                building.mkdir()
                try:
                    build(building)
                finally:
                    _unmount_below(building)
                (building / COMPLETE).write_text(f"built {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
                building.rename(final)
            fcntl.flock(descriptor, fcntl.LOCK_SH)
        yield final
    finally:
        os.close(descriptor)


def prune_trees(keep: Sequence[str]) -> list[str]:
    """Remove cached trees other than `keep` that no run is using; the names removed."""
    removed = []
    for lock in sorted(CACHE.glob("*.lock")):
        name = lock.name.removesuffix(".lock")
        if name in keep or not re.fullmatch(r"(base|wheels)-[0-9a-f]{16}", name):
            continue
        descriptor = os.open(lock, os.O_RDWR | os.O_CLOEXEC)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            continue  # in use by another run
        else:
            _remove(CACHE / name)
            _remove(CACHE / f".{name}.building")
            lock.unlink()
            removed.append(name)
        finally:
            os.close(descriptor)
    return removed


def base_tree_name(packages: Sequence[str]) -> str:
    """The cache name of the base tree for install.sh's package list."""
    return f"base-{_key(BASE_FORMAT, SUITE, MIRROR, BASE_PACKAGES, sorted(packages))}"


def build_base_tree(work: Path, packages: Sequence[str]) -> None:
    """debootstrap a Debian 12 into work/root, and the packages' .debs into work/debs."""
    root = work / "root"
    _run(
        ["debootstrap", "--variant=minbase", f"--include={','.join(BASE_PACKAGES)}",
         SUITE, root, MIRROR],
        "debootstrap",
        timeout=1800,
    )  # fmt: skip
    # The chroot shares this machine's network: apt fetches what install.sh will ask for
    # (with every dependency the fresh tree lacks), without installing it.
    env = {"PATH": CONTAINER_PATH, "DEBIAN_FRONTEND": "noninteractive", "LANG": "C.UTF-8"}
    _run(["chroot", root, "apt-get", "update", "-qq"], "apt-get update in the new tree",
         env=env, timeout=600)  # fmt: skip
    _run(
        ["chroot", root, "apt-get", "install", "-y", "-qq", "--download-only",
         "--no-install-recommends", *packages],
        "downloading install.sh's packages",
        env=env,
        timeout=1800,
    )  # fmt: skip
    debs = work / "debs"
    debs.mkdir()
    for deb in (root / "var/cache/apt/archives").glob("*.deb"):
        deb.rename(debs / deb.name)
    write_packages_index(debs)
    # The container starts as a machine that never ran apt-get update, whose one
    # source is the local repository.
    for path in [*(root / "var/lib/apt/lists").glob("*"), *(root / "var/cache/apt").glob("*.bin")]:
        if path.is_file():
            path.unlink()
    (root / "etc/apt/sources.list").write_text(f"deb [trusted=yes] file:{DEBS_IN_CONTAINER} ./\n")
    (root / "etc/hostname").write_text("kaspar-boot\n")


def write_packages_index(debs: Path) -> None:
    """A flat apt repository's Packages file for the .debs in `debs` (no tool but dpkg-deb)."""
    stanzas = []
    for deb in sorted(debs.glob("*.deb")):
        control = _run(["dpkg-deb", "--field", deb], f"reading {deb.name}", timeout=60)
        data = deb.read_bytes()
        stanzas.append(
            f"{control.rstrip()}\nFilename: ./{deb.name}\nSize: {len(data)}\n"
            f"SHA256: {hashlib.sha256(data).hexdigest()}\n"
        )
    (debs / "Packages").write_text("\n".join(stanzas))


def container_python(debs: Path) -> tuple[int, int]:
    """The Python version the container will have, from the python3.X package among the .debs."""
    for deb in debs.glob("python3.*_*.deb"):
        if found := re.match(r"python3\.(\d+)_", deb.name):
            return 3, int(found.group(1))
    raise BootError(f"no python3.X package among the .debs in {debs}")


def project_requirements(pyproject: Path) -> list[str]:
    """Everything pip needs to build and install the project: its dependencies and build backend."""
    data = tomllib.loads(pyproject.read_text())
    return sorted([*data["project"]["dependencies"], *data["build-system"]["requires"]])


def wheels_name(requirements: Sequence[str], python: tuple[int, int]) -> str:
    """The cache name of the wheelhouse for these requirements and Python."""
    return f"wheels-{_key(sorted(requirements), python, os.uname().machine)}"


def build_wheels(
    work: Path, requirements: Sequence[str], python: tuple[int, int], base: Path
) -> None:
    """Wheels of `requirements` for the container's Python: built by this Python where it
    is the same version, else by the container's own (a host of another Debian)."""
    if sys.version_info[:2] == python:
        _run(
            [sys.executable, "-m", "pip", "wheel", "--quiet", "--wheel-dir", work, *requirements],
            "building the wheelhouse",
            timeout=1800,
        )
    else:
        _build_wheels_in_tree(work, requirements, base)


def _build_wheels_in_tree(work: Path, requirements: Sequence[str], base: Path) -> None:
    """pip wheel run by the base tree's own Python, in a throwaway overlay of the tree.

    The Python, its headers and a compiler (python-evdev has no wheels) come from the
    tree's local repository, as install.sh takes them; pip reaches the network through
    this machine's, as debootstrap did. Nothing of it is left in the base tree.
    """
    scratch = CACHE / f".wheels-{secrets.token_hex(4)}"
    root = scratch / "root"
    try:
        for part in ("upper", "work", "root"):
            (scratch / part).mkdir(parents=True)
        _run(
            ["mount", "-t", "overlay", "overlay", "-o",
             f"lowerdir={base / 'root'},upperdir={scratch / 'upper'},workdir={scratch / 'work'}",
             root],
            "mounting an overlay of the base tree for pip",
            timeout=60,
        )  # fmt: skip
        _run(["mount", "-t", "proc", "proc", root / "proc"], "mounting /proc", timeout=60)
        for host, inside in ((base / "debs", DEBS_IN_CONTAINER), (work, WHEELS_IN_CONTAINER)):
            (root / inside.lstrip("/")).mkdir(parents=True, exist_ok=True)
            _run(["mount", "--bind", host, root / inside.lstrip("/")], f"binding {host}", timeout=60)
        env = {"PATH": CONTAINER_PATH, "DEBIAN_FRONTEND": "noninteractive", "LANG": "C.UTF-8",
               "HOME": "/root"}  # fmt: skip
        # A network whose TLS is re-signed by its own authority: pip's file of it goes in too.
        if (cert := os.environ.get("PIP_CERT")) and Path(cert).is_file():
            shutil.copyfile(cert, root / "etc/pip-cert.pem")
            env["PIP_CERT"] = "/etc/pip-cert.pem"
        _run(["chroot", root, "apt-get", "update", "-qq"], "apt-get update in the overlay",
             env=env, timeout=600)  # fmt: skip
        _run(
            ["chroot", root, "apt-get", "install", "-y", "-qq", "--no-install-recommends",
             *WHEEL_BUILDER_PACKAGES],
            "installing the tree's Python and compiler in the overlay",
            env=env,
            timeout=1800,
        )  # fmt: skip
        _run(["chroot", root, "python3", "-m", "venv", "/opt/wheel-builder"],
             "a venv of the tree's Python", env=env, timeout=600)  # fmt: skip
        _run(
            ["chroot", root, "/opt/wheel-builder/bin/pip", "wheel", "--quiet",
             "--disable-pip-version-check", "--wheel-dir", WHEELS_IN_CONTAINER, *requirements],
            "building the wheelhouse with the tree's Python",
            env=env,
            timeout=1800,
        )  # fmt: skip
    finally:
        _remove(scratch)


# -- a booted machine ------------------------------------------------------------------------


def sweep_stale_runs() -> list[str]:
    """Shut down and remove the runs whose owner died without cleaning up; their names."""
    runs = CACHE / "runs"
    swept = []
    for lock in sorted(runs.glob("*.lock")):
        descriptor = os.open(lock, os.O_RDWR | os.O_CLOEXEC)
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            continue  # its run is alive
        else:
            run_dir = runs / lock.name.removesuffix(".lock")
            _kill_stale_container(run_dir)
            _remove(run_dir)
            lock.unlink()
            swept.append(run_dir.name)
        finally:
            os.close(descriptor)
    return swept


def _kill_stale_container(run_dir: Path) -> None:
    try:
        pid = int((run_dir / "nspawn.pid").read_text())
        cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except (OSError, ValueError):
        return
    if "systemd-nspawn" not in cmdline or str(run_dir) not in cmdline:
        return  # that pid is now some other process
    for child in _children(pid):
        with contextlib.suppress(ProcessLookupError):
            os.kill(child, signal.SIGKILL)  # the container's PID 1: its whole namespace goes
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
    for _ in range(100):
        if not Path(f"/proc/{pid}").exists():
            return
        time.sleep(0.1)


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(child) for child in text.split()]


class Machine:
    """One container: an overlay over the base tree, booted, entered, always torn down.

    `root` is the container's / as seen from here, for writing files before boot;
    after boot, `run` executes a command inside (all namespaces, a clean environment).
    """

    def __init__(self, base: Path, binds: Mapping[Path, str] | None = None) -> None:
        self.base = base
        self.binds = dict(binds or {})
        self.name = f"kaspar-boot-{secrets.token_hex(4)}"
        self.run_dir = CACHE / "runs" / self.name
        self.root = self.run_dir / "root"
        self.leader: int | None = None
        self.boot_seconds: float | None = None
        self._lock: int | None = None
        self._nspawn: subprocess.Popen[bytes] | None = None
        self._console = self.run_dir / "console.log"

    def __enter__(self) -> Machine:
        (CACHE / "runs").mkdir(parents=True, exist_ok=True)
        sweep_stale_runs()
        # The lock first, then the directory: a sweeper never sees a run without its lock.
        self._lock = os.open(
            CACHE / "runs" / f"{self.name}.lock", os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600
        )
        fcntl.flock(self._lock, fcntl.LOCK_EX)
        try:
            for part in ("upper", "work", "root"):
                (self.run_dir / part).mkdir(parents=True)
            _run(
                ["mount", "-t", "overlay", "overlay", "-o",
                 f"lowerdir={self.base / 'root'},upperdir={self.run_dir / 'upper'},"
                 f"workdir={self.run_dir / 'work'}", self.root],
                "mounting the overlay",
                timeout=60,
            )  # fmt: skip
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- before boot --------------------------------------------------------------------

    def path(self, inside: str) -> Path:
        """A path of the container as seen from here; refuses one that leads outside it."""
        target = self.root / inside.lstrip("/")
        if not os.path.realpath(target).startswith(os.path.realpath(self.root) + "/"):
            raise BootError(f"{inside} leads outside the container")
        return target

    def write(self, inside: str, text: str, mode: int = 0o644) -> None:
        """Write a file into the container (before boot, or on its disk after)."""
        target = self.path(inside)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text)
        target.chmod(mode)

    def copy_checkout(self, checkout: Path, inside: str) -> None:
        """A copy of the checkout, as a clone would have it (without .git, venvs and caches)."""
        shutil.copytree(
            checkout, self.path(inside), symlinks=True,
            ignore=shutil.ignore_patterns(*CHECKOUT_LITTER),
        )  # fmt: skip

    # -- boot ----------------------------------------------------------------------------

    def boot(self, timeout: float = 120.0) -> None:
        """Boot the container with systemd as PID 1 and wait until its boot has finished."""
        started = time.monotonic()
        binds = [f"--bind-ro={host}:{inside}" for host, inside in self.binds.items()]
        with self._console.open("wb") as console:
            self._nspawn = subprocess.Popen(
                ["systemd-nspawn", *NSPAWN_FLAGS, f"--machine={self.name}", *binds,
                 "--boot", f"--directory={self.root}"],
                stdin=subprocess.DEVNULL,
                stdout=console,
                stderr=subprocess.STDOUT,
                env=dict(os.environ, SYSTEMD_NSPAWN_UNIFIED_HIERARCHY="1"),
                start_new_session=True,  # a ^C to the test reaches the test, which shuts it down
            )  # fmt: skip
        (self.run_dir / "nspawn.pid").write_text(str(self._nspawn.pid))
        deadline = started + timeout
        self.leader = self._wait_for_leader(deadline)
        state = ""
        while time.monotonic() < deadline:
            result = self.run(
                ["systemctl", "is-system-running", "--wait"],
                check=False,
                timeout=max(1.0, deadline - time.monotonic()),
            )
            state = result.stdout.strip()
            if state in ("running", "degraded"):
                self.boot_seconds = time.monotonic() - started
                return
            time.sleep(0.2)  # systemd's bus not up yet: ask again
        raise BootError(f"the container did not finish booting ({state!r}):\n{self.console_tail()}")

    def _wait_for_leader(self, deadline: float) -> int:
        assert self._nspawn is not None
        while time.monotonic() < deadline:
            if self._nspawn.poll() is not None:
                raise BootError(
                    f"systemd-nspawn exited ({self._nspawn.returncode}):\n{self.console_tail()}"
                )
            for child in _children(self._nspawn.pid):
                with contextlib.suppress(OSError):
                    if Path(f"/proc/{child}/comm").read_text().strip() == "systemd":
                        return child
            time.sleep(0.05)
        raise BootError(f"no systemd started in the container:\n{self.console_tail()}")

    def console_tail(self, characters: int = 4000) -> str:
        """The end of the container's console output."""
        try:
            return self._console.read_text(errors="replace")[-characters:]
        except OSError:
            return "(no console output)"

    # -- inside ---------------------------------------------------------------------------

    def command(
        self, argv: Sequence[str], env: Mapping[str, str] | None = None, cwd: str = "/"
    ) -> list[str]:
        """The host command line that runs `argv` inside, as root, in a clean environment."""
        if self.leader is None:
            raise BootError("the container is not booted")
        variables = {"PATH": CONTAINER_PATH, "HOME": "/root", "LANG": "C.UTF-8", "TERM": "dumb"}
        variables.update(env or {})
        return [
            "nsenter", f"--target={self.leader}", "--all",
            "env", "-i", f"--chdir={cwd}", *(f"{key}={value}" for key, value in variables.items()),
            *argv,
        ]  # fmt: skip

    def run(
        self,
        argv: Sequence[str],
        *,
        check: bool = True,
        timeout: float = 60.0,
        env: Mapping[str, str] | None = None,
        cwd: str = "/",
    ) -> subprocess.CompletedProcess[str]:
        """Run a command inside; with `check`, a failure raises BootError with its output."""
        result = subprocess.run(
            self.command(argv, env, cwd),
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            errors="replace",
            timeout=timeout,
            check=False,
        )
        if check and result.returncode != 0:
            raise BootError(
                f"{' '.join(argv)} failed in the container (exit {result.returncode}):\n"
                f"{result.stdout[-3000:]}{result.stderr[-3000:]}"
            )
        return result

    def read_bytes(self, inside: str) -> bytes:
        """A file's bytes, read inside (where /run and /tmp are the container's own)."""
        result = subprocess.run(
            self.command(["cat", "--", inside]), capture_output=True, timeout=60, check=False
        )
        if result.returncode != 0:
            raise BootError(f"cannot read {inside}: {result.stderr.decode(errors='replace')}")
        return result.stdout

    # -- teardown --------------------------------------------------------------------------

    def close(self) -> None:
        """Shut the container down (killed if it does not stop), unmount, remove the run."""
        try:
            self._stop_container()
        finally:
            try:
                _remove(self.run_dir)
            finally:
                if self._lock is not None:
                    with contextlib.suppress(FileNotFoundError):
                        (CACHE / "runs" / f"{self.name}.lock").unlink()
                    os.close(self._lock)
                    self._lock = None

    def _stop_container(self) -> None:
        process = self._nspawn
        if process is None or process.poll() is not None:
            return
        process.send_signal(signal.SIGTERM)  # nspawn asks the container's systemd to power off
        try:
            process.wait(timeout=30)
            return
        except subprocess.TimeoutExpired:
            pass
        if self.leader is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.leader, signal.SIGKILL)
        process.kill()
        process.wait(timeout=30)
