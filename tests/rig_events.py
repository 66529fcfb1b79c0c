"""Waiting for a game event in the tests that drive a demo rig."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from kasparctl.sim.demo import DemoRig


def on_event(
    rig: DemoRig, wanted: str, when: Callable[[dict[str, Any]], bool] = lambda _: True
) -> asyncio.Future[dict[str, Any]]:
    """A future for the first game event `wanted` whose info satisfies `when`."""
    future: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()

    def listener(event: str, info: dict[str, Any]) -> None:
        if event == wanted and not future.done() and when(info):
            future.set_result(info)

    rig.game.listeners.append(listener)
    return future
