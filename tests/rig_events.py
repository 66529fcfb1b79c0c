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


def answer_the_check(rig: DemoRig) -> None:
    """The children's part of Kaspar's check of the buttons at the session's start, for a
    test that plays the children itself: each button asked for is pressed at once."""
    pressing: set[asyncio.Task[float]] = set()

    def listener(event: str, info: dict[str, Any]) -> None:
        if event == "button_check":
            task = asyncio.get_running_loop().create_task(rig.keyfob.perform(info["button"]))
            pressing.add(task)
            task.add_done_callback(pressing.discard)

    rig.game.listeners.append(listener)
