"""`kasparctl reload`: ask the running service to reload, and fail when it refuses.

systemd's ExecReload= runs it (`systemctl reload kasparctl`), so a reload the
daemon refuses mid-session makes `systemctl reload` fail, saying why.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from kasparctl.commands.arguments import UsageError, number, path, whole
from kasparctl.log import PRIORITIES, connected_to_journal
from kasparctl.service.reload import request_reload, runtime_directory


def register(subparsers: Any) -> None:
    """Add `reload` and its options to the command line."""
    parser = subparsers.add_parser(
        "reload",
        help="reload the running service's configuration; exit 1 if it refuses (ExecReload)",
        description=__doc__,
    )
    parser.add_argument(
        "--pid", type=whole(1, 2**22), default=None,
        help="the service's process (default: $MAINPID)",
    )
    parser.add_argument(
        "--runtime-dir",
        default=None,
        type=path,
        help="where the service answers (default: $RUNTIME_DIRECTORY, as systemd sets it)",
    )
    parser.add_argument(
        "--timeout", type=number(0, 3600, low_open=True, unit="s"), default=10.0,
        help="seconds to wait for the answer (10)",
    )
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Send the request and SIGHUP, wait for the answer: 0 reloaded, 1 otherwise."""
    pid = arguments.pid if arguments.pid is not None else _int(os.environ.get("MAINPID", ""))
    directory = (
        Path(arguments.runtime_dir) if arguments.runtime_dir else runtime_directory()
    )
    if pid is None or pid <= 0:
        raise UsageError("--pid: expected the service's process id, or $MAINPID set")
    if directory is None:
        raise UsageError(
            "--runtime-dir: expected the service's runtime directory, or $RUNTIME_DIRECTORY set"
        )
    try:
        verdict = request_reload(pid, directory, arguments.timeout)
    except OSError as error:
        return _say(3, f"error: cannot ask process {pid} to reload: {error}")
    detail = f": {verdict.detail}" if verdict.detail else ""
    if verdict.ok:
        _say(PRIORITIES["info"], f"reloaded{detail}")
        return 0
    return _say(PRIORITIES["error"], f"reload {verdict.outcome}{detail}")


def _int(text: str) -> int | None:
    return int(text) if text.isdigit() else None


def _say(priority: int, line: str) -> int:
    """Print one line on stderr (with its priority for the journal); the exit status 1."""
    prefix = f"<{priority}>" if connected_to_journal(sys.stderr) else ""
    print(f"{prefix}kasparctl reload: {line}", file=sys.stderr)
    return 1
