"""Logging: JSON lines for journald, console on a terminal, context bound per trial."""

from __future__ import annotations

import io
import json

import structlog

from kasparctl.log import bind_context, clear_context, configure_logging


class TerminalStream(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_json_lines_when_not_a_terminal_with_bound_context() -> None:
    stream = io.StringIO()
    configure_logging("info", "auto", stream)
    try:
        bind_context(session="s-1", step="guess")
        structlog.get_logger().info("trial recorded", trial=3)
        structlog.get_logger().debug("not shown at info")
        clear_context("step")
        structlog.get_logger().warning("after step")
    finally:
        clear_context()
    lines = [json.loads(line) for line in stream.getvalue().splitlines()]
    assert len(lines) == 2
    assert lines[0]["event"] == "trial recorded"
    assert (lines[0]["session"], lines[0]["step"], lines[0]["trial"]) == ("s-1", "guess", 3)
    assert lines[0]["level"] == "info" and "timestamp" in lines[0]
    assert "step" not in lines[1] and lines[1]["session"] == "s-1"


def test_console_on_a_terminal() -> None:
    stream = TerminalStream()
    configure_logging("debug", "auto", stream)
    structlog.get_logger().debug("hello", joint="left_elbow")
    text = stream.getvalue()
    assert "hello" in text and "joint" in text
    assert not text.lstrip().startswith("{")


def test_json_forced_on_a_terminal() -> None:
    stream = TerminalStream()
    configure_logging("info", "json", stream)
    structlog.get_logger().info("forced")
    assert json.loads(stream.getvalue())["event"] == "forced"
