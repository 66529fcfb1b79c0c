"""The view's entry points for `kasparctl watch`: follow, replay, or print once.

Each gives the terminal back as it found it (cbreak mode, alternate screen,
cursor) however it ends: q, Ctrl-C, or SIGTERM, which unwinds like Ctrl-C.
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from kasparctl.view.follow import Follower
from kasparctl.view.frame import frame
from kasparctl.view.inotify import Inotify
from kasparctl.view.live import LiveView, utc_now
from kasparctl.view.replay import Replay, find_session
from kasparctl.view.screen import (
    Keys,
    PlainScreen,
    Screen,
    full_screen_possible,
    open_keys,
    open_screen,
)


def print_once(state_dir: Path) -> None:
    """The picture of `state_dir` now, as plain text on stdout."""
    screen = PlainScreen(sys.stdout)
    with Inotify() as inotify:
        view = Follower(state_dir, inotify).observe(f"{state_dir} at {utc_now():%H:%M:%S} UTC")
    width, height = screen.size()
    screen.draw(frame(view, utc_now(), width, height, screen.glyphs))


def follow(state_dir: Path, plain: bool = False) -> None:
    """Follow `state_dir` on the terminal until q or Ctrl-C."""
    with terminal(plain) as (screen, keys):
        view = LiveView(state_dir, screen, keys)
        with _on_resize(view.redraw):
            try:
                view.run()
            finally:
                view.close()


def replay(session: str, state_dir: Path | None, speed: float, plain: bool = False) -> None:
    """Replay a session (an id in `state_dir`, or a directory); ReplayError if there is none."""
    directory = find_session(session, state_dir)
    with terminal(plain) as (screen, keys):
        player = Replay(directory, screen, keys, speed=speed)
        with _on_resize(player.waker.wake):
            try:
                player.run()
            finally:
                player.close()


@contextlib.contextmanager
def terminal(plain: bool) -> Iterator[tuple[Screen, Keys | None]]:
    """The screen and the keys, given back as they were however the view ends."""
    keys = open_keys(sys.stdin)
    screen = open_screen(sys.stdout, plain=plain or not full_screen_possible(sys.stdout))
    previous = signal.getsignal(signal.SIGTERM)
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        yield screen, keys
    finally:
        signal.signal(signal.SIGTERM, previous)
        screen.close()
        if keys is not None:
            keys.close()


def _interrupt(_signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


@contextlib.contextmanager
def _on_resize(wake: Callable[[], None]) -> Iterator[None]:
    previous = signal.signal(signal.SIGWINCH, lambda _signum, _frame: wake())
    try:
        yield
    finally:
        signal.signal(signal.SIGWINCH, previous)
