"""Shared test set-up."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import structlog


@pytest.fixture(autouse=True)
def fresh_logging() -> Iterator[None]:
    # Commands configure structlog with the stderr of their moment; under pytest
    # that stream is a per-test capture, closed once the test ends.
    yield
    structlog.reset_defaults()
    structlog.contextvars.clear_contextvars()
