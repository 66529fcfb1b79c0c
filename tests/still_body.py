"""The still body that conftest's still_body_unless_asked gives a test's games, for the games
a module-scoped fixture plays.

pytest sets up a module-scoped fixture before any function-scoped one, the autouse
still_body_unless_asked included, so without this those games got the demo robot's live
body: the same records but for their times, at about eight times the cost (a study of six
sessions took 30 s rather than 3.6 s here).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import msgspec
import pytest

from kasparctl.body import build
from kasparctl.body.api import Body
from kasparctl.config import Config


@contextlib.contextmanager
def still_body() -> Iterator[None]:
    """Within: games and daemons run in this process get `[body] enabled = false`."""
    real = build.make_body

    def still(config: Config, *args: object, **kwargs: object) -> Body:
        config = msgspec.structs.replace(
            config, body=msgspec.structs.replace(config.body, enabled=False))
        return real(config, *args, **kwargs)  # type: ignore[arg-type]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr("kasparctl.sim.demo.make_body", still)
        patch.setattr("kasparctl.service.daemon.make_body", still)
        yield
