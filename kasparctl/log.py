"""structlog, configured once for the whole process.

JSON lines when stdout is not a terminal (journald keeps one event a line),
a readable console on a terminal. Context (session, step, trial) is bound with
structlog.contextvars so every line of a trial carries it.
"""

from __future__ import annotations

import logging
import sys
from typing import Literal, TextIO

import structlog

_LEVELS = {
    "debug": logging.DEBUG,
    "info": logging.INFO,
    "warning": logging.WARNING,
    "error": logging.ERROR,
}


def configure_logging(
    level: str = "info",
    output_format: Literal["auto", "json", "console"] = "auto",
    stream: TextIO | None = None,
) -> None:
    """Send the process's structlog events to `stream` (stdout) at `level` and above."""
    stream = stream or sys.stdout
    use_json = output_format == "json" or (output_format == "auto" and not stream.isatty())
    renderer: structlog.typing.Processor = (
        structlog.processors.JSONRenderer()
        if use_json
        else structlog.dev.ConsoleRenderer(colors=stream.isatty())
    )
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


def bind_context(**context: object) -> None:
    """Bind session, step or trial to every log line that follows."""
    structlog.contextvars.bind_contextvars(**context)


def clear_context(*keys: str) -> None:
    """Unbind these context keys, or every one when none is named."""
    if keys:
        structlog.contextvars.unbind_contextvars(*keys)
    else:
        structlog.contextvars.clear_contextvars()
