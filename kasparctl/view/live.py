"""The live view's loop: asleep in the kernel until a file changes, a key is pressed,
the writer exits, or a time on screen needs to read one second more.

One selector over: the inotify descriptor, the keyboard (when there is one),
a pipe that other threads and signal handlers write to wake it, and a pidfd
of the process holding the state directory's writer lock (readable when it
exits). The only timeout is the next moment a "12 s ago" on screen changes;
with nothing ageing on screen the loop waits without any.
"""

from __future__ import annotations

import _thread
import contextlib
import datetime as dt
import os
import selectors
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from kasparctl.game.wallclock import boot_id
from kasparctl.view.ages import Now
from kasparctl.view.follow import Follower
from kasparctl.view.frame import frame, seconds_to_redraw
from kasparctl.view.inotify import Inotify
from kasparctl.view.model import WatchView
from kasparctl.view.screen import Keys, Screen

T = TypeVar("T")
QUIT_KEYS = ("q", "Q")


def utc_now() -> dt.datetime:
    """The wall clock, as the records' times are written (UTC)."""
    return dt.datetime.now(dt.UTC)


class Waker:
    """A pipe whose reading end wakes a selector; writing to it is safe from any thread
    and from a signal handler."""

    def __init__(self) -> None:
        """Open the pipe, both ends non-blocking."""
        self.read_fd, self.write_fd = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)

    def wake(self) -> None:
        """Make the reading end readable (a full pipe is awake already)."""
        with contextlib.suppress(BlockingIOError, OSError):
            os.write(self.write_fd, b"!")

    def drain(self) -> None:
        """Read every byte waiting."""
        with contextlib.suppress(BlockingIOError):
            while os.read(self.read_fd, 4096):
                pass

    def close(self) -> None:
        """Close both ends."""
        os.close(self.read_fd)
        os.close(self.write_fd)


def live_now(view: WatchView, wall: dt.datetime, monotonic: float, boot: str) -> Now:
    """Now, for the live view: on the session's monotonic clock where its daemon's run is on
    this boot (the kernel's monotonic clock is the loop's), else on the wall clock alone."""
    session = view.session
    if session is not None and session.boot and session.boot == boot:
        return Now(wall, monotonic, session.run)
    return Now(wall)


class LiveView:
    """Follows a state directory and draws it, until `q`, `stop()` or an interrupt."""

    def __init__(
        self,
        state_dir: Path,
        screen: Screen,
        keys: Keys | None = None,
        now: Callable[[], dt.datetime] = utc_now,
        monotonic: Callable[[], float] = time.monotonic,
        boot: Callable[[], str] = boot_id,
    ) -> None:
        """Draw `state_dir` on `screen`; quit on q from `keys`, if given. The clocks (the
        wall clock, the monotonic one and this boot's id) are injected for tests."""
        self.state_dir = state_dir
        self.screen = screen
        self.keys = keys
        self.now = now
        self.monotonic = monotonic
        self.boot = boot()
        self.waker = Waker()
        self._stopping = threading.Event()
        self._note = ""
        self._lock = threading.Lock()
        # What is on screen, for a redraw without reading anything.
        self.view: WatchView | None = None
        self.draws = 0

    # -- from other threads and signal handlers --------------------------------

    def stop(self) -> None:
        """End run() soon; safe from any thread."""
        self._stopping.set()
        self.waker.wake()

    def note(self, text: str) -> None:
        """Show `text` in the footer; safe from any thread."""
        with self._lock:
            self._note = text
        self.waker.wake()

    def redraw(self) -> None:
        """Draw again (the terminal was resized); safe from a signal handler."""
        self.waker.wake()

    # -- the loop ---------------------------------------------------------------

    def footer(self) -> str:
        """The footer: the note, the keys, and what is followed."""
        with self._lock:
            note = self._note
        keys = "q quits  " if self.keys is not None else ""
        followed = f"following {self.state_dir} (read-only)"
        return f"{note}  {keys}{followed}" if note else f"{keys}{followed}"

    def run(self) -> None:
        """Follow and draw until asked to stop; the terminal is given back by the caller."""
        with Inotify() as inotify, selectors.DefaultSelector() as selector:
            follower = Follower(self.state_dir, inotify)
            selector.register(inotify, selectors.EVENT_READ, "inotify")
            selector.register(self.waker.read_fd, selectors.EVENT_READ, "wake")
            if self.keys is not None:
                selector.register(self.keys, selectors.EVENT_READ, "keys")
            writer = _WriterExit(selector)
            stale = True
            try:
                while not self._stopping.is_set():
                    if stale:
                        self.view = follower.observe(self.footer())
                        writer.follow(self.view.writer)
                        stale = False
                    timeout = self._draw()
                    for key, _ in selector.select(timeout):
                        if key.data == "inotify":
                            stale |= follower.handle(inotify.read())
                        elif key.data == "keys" and self.keys is not None:
                            if any(k in QUIT_KEYS for k in self.keys.read()):
                                return
                        elif key.data == "wake":
                            self.waker.drain()
                            stale = True
                        elif key.data == "writer":
                            writer.exited()
                            stale = True
            finally:
                writer.close()

    def close(self) -> None:
        """Close the wake-up pipe (after run() has returned)."""
        self.waker.close()

    def _draw(self) -> float | None:
        """Draw the view as of now; how long until it needs drawing again."""
        assert self.view is not None
        now = live_now(self.view, self.now(), self.monotonic(), self.boot)
        width, height = self.screen.size()
        self.screen.draw(frame(self.view, now, width, height, self.screen.glyphs))
        self.draws += 1
        return seconds_to_redraw(self.view, now) if self.screen.live else None


class _WriterExit:
    """A pidfd of the writer, in the selector: it becomes readable when the process exits."""

    def __init__(self, selector: selectors.BaseSelector) -> None:
        self.selector = selector
        self.pid: int | None = None
        self.fd = -1

    def follow(self, pid: int | None) -> None:
        if pid == self.pid:
            return
        self.close()
        self.pid = pid
        if pid is None:
            return
        try:
            self.fd = os.pidfd_open(pid)
        except OSError:
            # Gone already, or a kernel without pidfds: the next record tells.
            return
        self.selector.register(self.fd, selectors.EVENT_READ, "writer")

    def exited(self) -> None:
        self.close()
        # Known gone: the next observe() asks the kernel again.
        self.pid = None

    def close(self) -> None:
        if self.fd >= 0:
            self.selector.unregister(self.fd)
            os.close(self.fd)
            self.fd = -1


def run_with_view(
    state_dir: Path,
    work: Callable[[], T],
    screen: Screen,
    keys: Keys | None,
    done_note: Callable[[T], str],
) -> T:
    """Run `work` (the demo) while a LiveView of `state_dir` draws in a thread.

    When the work ends the view says so (done_note) and stays until q; without
    keys it closes at once. A q while the work still runs interrupts it as
    Ctrl-C would (the session stays unfinished on disk, resumable).
    """
    view = LiveView(state_dir, screen, keys)
    finished = threading.Event()

    def show() -> None:
        try:
            view.run()
        finally:
            if not finished.is_set():
                # q before the end: stop the work the way Ctrl-C does.
                _thread.interrupt_main()

    thread = threading.Thread(target=show, name="live view", daemon=True)
    # A resize wakes the view (signal handlers run in the main thread, which runs the work).
    previous = signal.signal(signal.SIGWINCH, lambda _signum, _frame: view.redraw())
    thread.start()
    try:
        result = work()
        finished.set()
        if keys is None or not thread.is_alive():
            view.stop()
        else:
            view.note(done_note(result))
        thread.join()
        return result
    finally:
        finished.set()
        view.stop()
        thread.join()
        signal.signal(signal.SIGWINCH, previous)
        view.close()
