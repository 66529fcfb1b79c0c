"""The project's named failures: KasparError, the base of them all, and the HAL's own.

Every exception hal/ and kasparctl/ raise on purpose derives from KasparError:
its message is written for a person (it names the file, key, device or option,
what was expected and what was found), so the command line prints it as one
line; anything else that escapes is a bug. The base lives here because hal may
import nothing of kasparctl and every room may import hal.errors. (The one
exception is kasparctl.learning.learner, which imports nothing of the project:
its LearnerError is turned into the caller's own error where a person's value
reaches the learner.)

Every exception the HAL raises on purpose derives from HalError. A caller
that must outlive hardware trouble (the game, the daemon) catches HalError.
Where a failure used to surface as a built-in exception, its named class also
derives from that built-in (UnknownJoint is a KeyError, SettingsError a
ValueError), so older handlers keep working. Settings failures must stay
ValueErrors: msgspec turns a ValueError raised while a settings table is
decoded into a ValidationError naming the table.
"""

from __future__ import annotations


class KasparError(Exception):
    """Base of every error the project raises on purpose; its message is for a person."""


class HalError(KasparError):
    """Base of every hardware-abstraction failure."""


class SettingsError(HalError, ValueError):
    """A settings value the HAL cannot use; the message says which key, what and why."""


class InvalidArgument(HalError, ValueError):
    """A call the HAL cannot act on, whatever the hardware does.

    An unknown keyfob action or button, a malformed script line, a sink given
    both a directory and a file, a bus exchange without its framing.
    """


class UnknownName(HalError, KeyError):
    """A name that is not configured; a KeyError too, as it always was.

    str() gives the message itself, not KeyError's quoted repr of it.
    """

    def __str__(self) -> str:
        """The message as given, unquoted."""
        return str(self.args[0]) if self.args else ""


class UnknownJoint(UnknownName):
    """A joint or group name that is not in the servo settings."""


class UnknownBus(UnknownName):
    """A bus name that is not in the servo settings."""


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


class ServoSilent(BusTimeout):
    """A given servo did not answer, after the retries."""

    def __init__(self, servo_id: int, message: str) -> None:
        """`servo_id` names the servo (the first silent one of a group read)."""
        super().__init__(message)
        self.servo_id = servo_id


class ServoFaultError(HalError):
    """A command refused because a latched fault holds the robot in its safe state."""


class UnsafeCommand(HalError):
    """A command that would break a safety rule and cannot be made safe by clamping."""


class KeyfobError(HalError):
    """The keyfob cannot be found or opened (it is retried; this names why)."""


class VoiceError(HalError):
    """An engine or the player failed for one utterance (the fallback is tried).

    Also raised by say() on a closed voice; a failed utterance is otherwise
    a Spoken result with status FAILED, not an exception.
    """


class EmptyRender(VoiceError):
    """A render that finished without error and without a single sample."""


class RepeatFilter:
    """Lets the first of a run of identical errors through and counts the rest.

    A servo that stays silent would otherwise log one line per poll, forever;
    this logs it once, then once more with the count when the error changes or ends.
    Not thread-safe: each owner (the joints layer, one bus thread) has its own.
    """

    def __init__(self) -> None:
        """Start with no error seen."""
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
        """How many times the current error of `key` has been seen in a row; 0 if none."""
        last = self._last.get(key)
        return last[1] if last else 0
