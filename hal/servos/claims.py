"""Who holds which joint: the joints layer's one arbiter between moves, streams and torque.

A claim names a set of joints. It is granted as soon as no claim asked before it
shares a joint with it, held or still waiting: claims on the same joints are granted
in the order they were asked (as the one lock was before), and claims with no joint in
common are granted at once, side by side. A claim that is cancelled, granted or still
waiting, lets its joints go at once. Everything runs on the event loop; no claim ever
waits for one asked after it, so no two claims wait for each other.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Iterable
from dataclasses import dataclass, field


@dataclass(eq=False)
class _Claim:
    joints: frozenset[str]
    holder: str  # who asked (move, point, set_compliant, rest): shown by repr()
    granted: bool = False
    # Resolved when granted: wakes the task waiting in claim().
    wake: asyncio.Future[None] = field(
        default_factory=lambda: asyncio.get_running_loop().create_future()
    )


class JointClaims:
    """The claims on a robot's joints, in the order they were asked."""

    def __init__(self) -> None:
        """No joint is claimed."""
        self._queue: list[_Claim] = []

    @contextlib.asynccontextmanager
    async def claim(self, joints: Iterable[str], holder: str) -> AsyncIterator[None]:
        """Hold `joints` for the body of the `async with`, once every earlier claim sharing
        one of them has ended; `holder` says who holds them (move, set_compliant, rest)."""
        claim = _Claim(frozenset(joints), holder)
        self._queue.append(claim)
        self._grant()
        try:
            await claim.wake
            yield
        finally:
            self._queue.remove(claim)
            claim.wake.cancel()  # nothing if it was granted: a done future stays done
            self._grant()

    def held(self) -> frozenset[str]:
        """Every joint a granted claim holds now."""
        held: set[str] = set()
        for claim in self._queue:
            if claim.granted:
                held |= claim.joints
        return frozenset(held)

    def _grant(self) -> None:
        asked_before: set[str] = set()
        for claim in self._queue:
            if claim.wake.cancelled():
                continue  # its task was cancelled while it waited: it is leaving
            if not claim.granted and not claim.joints & asked_before:
                claim.granted = True
                claim.wake.set_result(None)
            asked_before |= claim.joints
