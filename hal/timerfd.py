"""The kernel's high-resolution timer as a file descriptor (Linux timerfd).

asyncio wakes for its own timers through epoll, whose timeout is whole
milliseconds (rounded up), so a 50 Hz loop on asyncio.sleep runs up to 1 ms late
on every tick. A timerfd armed at an absolute CLOCK_MONOTONIC moment becomes
readable at that moment, to the kernel's timer slack, and epoll returns for it at
once. Python 3.13 has os.timerfd_*; before that libc is called through ctypes.
"""

from __future__ import annotations

import ctypes
import os
from collections.abc import Callable

from hal.errors import KasparError

CLOCK_MONOTONIC = 1
TFD_TIMER_ABSTIME = 1
TFD_CLOEXEC = os.O_CLOEXEC
TFD_NONBLOCK = os.O_NONBLOCK


class TimerUnavailable(KasparError, OSError):
    """No timerfd here (not Linux, or the call failed): wait on the event loop instead."""


class _Timespec(ctypes.Structure):
    # The glibc symbols called here take the C library's long time_t, also on 32-bit ARM.
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class _Itimerspec(ctypes.Structure):
    _fields_ = [("it_interval", _Timespec), ("it_value", _Timespec)]


def _libc_calls() -> tuple[Callable[[int, int], int], Callable[[int, int, float], None]]:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        create = libc.timerfd_create
        settime = libc.timerfd_settime
    except (OSError, AttributeError) as error:
        raise TimerUnavailable(f"timerfd not in the C library: {error}") from None
    create.argtypes = [ctypes.c_int, ctypes.c_int]
    create.restype = ctypes.c_int
    settime.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Itimerspec),
                        ctypes.POINTER(_Itimerspec)]
    settime.restype = ctypes.c_int

    def timer_create(clock: int, flags: int) -> int:
        fd = int(create(clock, flags))
        if fd < 0:
            errno = ctypes.get_errno()
            raise TimerUnavailable(errno, os.strerror(errno))
        return fd

    def timer_set_absolute(fd: int, flags: int, moment: float) -> None:
        seconds = int(moment)
        nanoseconds = round((moment - seconds) * 1e9)
        seconds, nanoseconds = seconds + nanoseconds // 1_000_000_000, nanoseconds % 1_000_000_000
        value = _Itimerspec(_Timespec(0, 0), _Timespec(seconds, nanoseconds))
        if settime(fd, flags, ctypes.byref(value), None) != 0:
            errno = ctypes.get_errno()
            raise OSError(errno, os.strerror(errno))

    return timer_create, timer_set_absolute


class MonotonicTimer:
    """One timerfd on CLOCK_MONOTONIC (time.monotonic's clock), non-blocking.

    Raises TimerUnavailable when there is none. arm(moment) makes `fileno` readable
    at `moment` (at once when it has passed); take() reads off its expiry (arming
    again resets it too).
    """

    def __init__(self) -> None:
        """Open the timer, disarmed; TimerUnavailable when this system has none."""
        if hasattr(os, "timerfd_create"):
            self._create: Callable[[int, int], int] = self._create_native
            self._set: Callable[[int, int, float], None] = self._set_native
        else:
            self._create, self._set = _libc_calls()
        try:
            self.fileno = self._create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC)
        except OSError as error:
            raise TimerUnavailable(f"timerfd_create failed: {error}") from None

    @staticmethod
    def _create_native(clock: int, flags: int) -> int:
        return int(os.timerfd_create(clock, flags=flags))  # type: ignore[attr-defined]

    @staticmethod
    def _set_native(fd: int, flags: int, moment: float) -> None:
        os.timerfd_settime(fd, flags=flags, initial=moment)  # type: ignore[attr-defined]

    def arm(self, moment: float) -> None:
        """Readable at `moment` of time.monotonic(); a moment already past fires at once."""
        # Zero would disarm the timer: a moment at or before the clock's start is "now".
        self._set(self.fileno, TFD_TIMER_ABSTIME, max(moment, 1e-9))

    def take(self) -> bool:
        """Read off the expiries: whether the timer had fired since it was armed."""
        try:
            os.read(self.fileno, 8)
        except BlockingIOError:
            return False
        return True

    def close(self) -> None:
        """Close the descriptor."""
        os.close(self.fileno)
