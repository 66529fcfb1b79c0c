"""structlog, configured once for the whole process.

JSON lines when stdout is not a terminal (journald keeps one event a line),
a readable console on a terminal. Context (session, step, trial) is bound with
structlog.contextvars so every line of a trial carries it.

Under systemd each JSON line starts with its syslog priority, "<4>" for a
warning (sd-daemon(3)): journald reads that prefix on a stream line
(SyslogLevelPrefix=, on by default), stores the line at that priority without
the prefix, so `journalctl -u kasparctl -p warning` shows the warnings and
errors and MESSAGE is the JSON object alone. Warnings and errors of the standard
library's logging (asyncio's "Task exception was never retrieved", a library's
warning) go the same way, as structlog lines of their own level, rather than
as bare text on stderr that journald would keep at info. The prefix is written only when
the stream is the journal's (the JOURNAL_STREAM systemd sets names its device
and inode); anywhere else the lines are plain JSON. journald's native protocol
would carry fields too, but needs its socket and a second path for the lines
that must still reach stdout; the prefix keeps one stream, in order.
"""

from __future__ import annotations

import io
import logging
import os
import sys
from typing import Any, Literal, TextIO

import structlog

_LEVELS = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "warning": logging.WARNING,
    "error": logging.ERROR,
}
# structlog's level names (add_log_level) as syslog priorities.
PRIORITIES = {
    "debug": 7,
    "info": 6,
    "notice": 5,
    "warning": 4,
    "warn": 4,
    "error": 3,
    "exception": 3,
    "critical": 2,
}


def connected_to_journal(stream: TextIO, environ: dict[str, str] | None = None) -> bool:
    """Whether `stream` is the journal stream systemd named in JOURNAL_STREAM ("dev:inode")."""
    device, _, inode = (environ if environ is not None else os.environ).get(
        "JOURNAL_STREAM", ""
    ).partition(":")
    if not (device.isdigit() and inode.isdigit()):
        return False
    try:
        status = os.fstat(stream.fileno())
    except (OSError, ValueError, io.UnsupportedOperation):
        return False  # a stream with no descriptor (a test's StringIO) is not the journal
    return (status.st_dev, status.st_ino) == (int(device), int(inode))


def wants_colour(stream: TextIO, environ: dict[str, str] | None = None) -> bool:
    """Colour only on a terminal that can show it and a person who did not ask for none:
    NO_COLOR set (to anything, https://no-color.org) or TERM=dumb turn it off."""
    environ = environ if environ is not None else dict(os.environ)
    if "NO_COLOR" in environ or environ.get("TERM") == "dumb":
        return False
    try:
        return stream.isatty()
    except (ValueError, AttributeError):
        return False


class JournalPriority:
    """Wraps a renderer: each rendered line starts with its level's "<N>" syslog prefix."""

    def __init__(self, renderer: structlog.typing.Processor) -> None:
        """Prefix what `renderer` makes of each event."""
        self._renderer = renderer

    def __call__(self, logger: Any, name: str, event_dict: structlog.typing.EventDict) -> str:
        """The rendered line with "<N>" before it (info when the level is unknown)."""
        priority = PRIORITIES.get(str(event_dict.get("level", "info")), PRIORITIES["info"])
        rendered = self._renderer(logger, name, event_dict)
        if isinstance(rendered, bytes | bytearray):
            rendered = rendered.decode(errors="replace")
        return f"<{priority}>{rendered}"


def configure_logging(
    level: str = "info",
    output_format: Literal["auto", "json", "console"] = "auto",
    stream: TextIO | None = None,
    journal: bool | None = None,
) -> None:
    """Send the process's structlog events to `stream` (stdout) at `level` and above.

    `journal` forces the "<N>" priority prefix on (or off); by default it is on
    for JSON lines going to the journal's stream (connected_to_journal).
    """
    stream = stream or sys.stdout
    use_json = output_format == "json" or (output_format == "auto" and not stream.isatty())
    renderer: structlog.typing.Processor = (
        structlog.processors.JSONRenderer()
        if use_json
        else structlog.dev.ConsoleRenderer(colors=wants_colour(stream))
    )
    prefixed = connected_to_journal(stream) if journal is None else journal
    if prefixed and use_json:
        renderer = JournalPriority(renderer)
    _forward_standard_logging()
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.processors.add_log_level,
            structlog.processors.TimeStamper(fmt="iso", utc=True),
            structlog.processors.StackInfoRenderer(),
            structlog.processors.format_exc_info,
            renderer,
        ],
        wrapper_class=structlog.make_filtering_bound_logger(_LEVELS[level]),
        logger_factory=structlog.PrintLoggerFactory(file=stream),
        # Caching would freeze the first configuration; tests reconfigure.
        cache_logger_on_first_use=False,
    )


class _ToStructlog(logging.Handler):
    """The standard library's log records as structlog lines of the same level."""

    def emit(self, record: logging.LogRecord) -> None:
        """Log `record` through structlog, with its logger's name and any exception."""
        level = record.levelname.lower()
        method = level if level in ("debug", "info", "warning", "error", "critical") else "error"
        try:
            message = record.getMessage()
        except (TypeError, ValueError):  # a record whose arguments do not fit its format
            message = str(record.msg)
        if record.name.startswith("transitions") and message.endswith("CancelledError()"):
            # A game ended (the daemon reading its sessions again, a demo whose reader went
            # away) while a trigger ran: how it is ended, not an error.
            method = "debug"
        logger = structlog.get_logger(record.name)
        getattr(logger, method)(message, logger=record.name, exc_info=record.exc_info or None)


def _forward_standard_logging() -> None:
    root = logging.getLogger()
    if not any(isinstance(handler, _ToStructlog) for handler in root.handlers):
        handler = _ToStructlog(level=logging.WARNING)
        root.addHandler(handler)
    if root.level > logging.WARNING or root.level == logging.NOTSET:
        root.setLevel(logging.WARNING)


def bind_context(**context: object) -> None:
    """Bind session, step or trial to every log line that follows."""
    structlog.contextvars.bind_contextvars(**context)


def clear_context(*keys: str) -> None:
    """Unbind these context keys, or every one when none is named."""
    if keys:
        structlog.contextvars.unbind_contextvars(*keys)
    else:
        structlog.contextvars.clear_contextvars()
