"""Shared test set-up."""

from __future__ import annotations

from collections.abc import Iterator

import msgspec
import pytest
import structlog

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
