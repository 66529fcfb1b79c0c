"""The HAL's named failures: every exception the servo stack raises derives from HalError."""

from __future__ import annotations


class HalError(Exception):
    """Base of every hardware-abstraction failure."""


class CodecError(HalError):
    """A packet that cannot be built or a reply that cannot be decoded.

    Each protocol family has its own subclass, so a caller can tell a corrupt
    Dynamixel reply from a corrupt HerkuleX one.
    """


class BusError(HalError):
    """A serial transaction that did not complete."""


class BusTimeout(BusError):
    """No complete, valid reply within the deadline, after every retry."""


class PortUnavailable(BusError):
    """The serial adapter is unplugged or cannot be opened; the bus keeps retrying."""


class BusClosed(BusError):
    """The bus was closed; no more transactions are accepted."""


class ServoFaultError(HalError):
    """A command refused because a latched fault holds the robot in its safe state."""


class UnsafeCommand(HalError):
    """A command that would break a safety rule and cannot be made safe by clamping."""


class RepeatFilter:
    """Lets the first of a run of identical errors through and counts the rest.

    A servo that stays silent would otherwise log one line per poll, forever;
    this logs it once, then once more with the count when the error changes or ends.
    """

    def __init__(self) -> None:
        self._last: dict[str, tuple[str, int]] = {}

    def first(self, key: str, message: str) -> bool:
        """True when `message` is new for `key` (log it); False when it repeats (counted)."""
        last = self._last.get(key)
        if last is not None and last[0] == message:
            self._last[key] = (message, last[1] + 1)
            return False
        self._last[key] = (message, 1)
        return True

    def end(self, key: str) -> tuple[str, int] | None:
        """Forget `key`; returns (message, times seen) if the error had repeated."""
        last = self._last.pop(key, None)
        return last if last is not None and last[1] > 1 else None

    def count(self, key: str) -> int:
        last = self._last.get(key)
        return last[1] if last else 0


class ServoSilent(BusTimeout):
    """A given servo did not answer, after the retries."""

    def __init__(self, servo_id: int, message: str) -> None:
        super().__init__(message)
        self.servo_id = servo_id
