"""Shared test set-up; what the machine must have for a test (tests/capabilities.py)."""

from __future__ import annotations

import os
from collections.abc import Iterator

import msgspec
import pytest
import structlog
from capabilities import NO_OVERRIDE, in_ci, need, override_problem

from kasparctl.body import build
from kasparctl.body.api import Body
from kasparctl.config import Config


@pytest.fixture(autouse=True)
def fresh_logging() -> Iterator[None]:
    # Commands configure structlog with the stderr of their moment; under pytest
    # that stream is a per-test capture, closed once the test ends.
    yield
    structlog.reset_defaults()
    structlog.contextvars.clear_contextvars()


@pytest.fixture(autouse=True)
def still_body_unless_asked(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """Games and daemons run in this process get a still body, as `replicate` gives its
    games, unless the test is marked `live_body`.

    The demo's robot has `[body] enabled`: its 50 Hz loop doubles the time of a game in
    simulated time and changes no answer, record or line those tests read. The body's
    own tests, the soak and every command run as a subprocess keep the live body.
    """
    if request.node.get_closest_marker("live_body") is not None:
        return
    real = build.make_body

    def still(config: Config, *args: object, **kwargs: object) -> Body:
        config = msgspec.structs.replace(
            config, body=msgspec.structs.replace(config.body, enabled=False))
        return real(config, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr("kasparctl.sim.demo.make_body", still)
    monkeypatch.setattr("kasparctl.service.daemon.make_body", still)


# -- what the machine has -------------------------------------------------------------


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Iterator[None]:
    """Under CI=true a skipped test fails: CI's machine has all a test here can need
    (tests/capabilities.py), so a skip there hides a missing install step."""
    outcome = yield
    report: pytest.TestReport = outcome.get_result()  # type: ignore[attr-defined]
    if report.skipped and in_ci() and not hasattr(report, "wasxfail"):
        longrepr = report.longrepr
        reason = longrepr[2] if isinstance(longrepr, tuple) else str(longrepr)
        report.outcome = "failed"
        report.longrepr = f"a skip under CI=true is a failure (CI has what every test needs): {reason}"


@pytest.fixture
def without_override() -> list[str]:
    """The prefix that runs a command as this user without power over file permissions:
    as root, tests/capabilities.NO_OVERRIDE (skipped where it cannot take that power
    away); as another user, none."""
    if os.geteuid() != 0:
        return []
    need("root without its power over file permissions", override_problem())
    return list(NO_OVERRIDE)
