"""The frame on a terminal: full screen with rich, or plain text; and the keys pressed.

Colours are the terminal's own eight, chosen to read on light and dark
themes alike: text in the theme's foreground, green and red for answers,
magenta (not yellow, which fades on white) for warnings, and badges that
bring their own background (reverse video, or black on a colour). rich
drops every colour when NO_COLOR is set; a dumb terminal or a pipe gets the
plain screen, which prints each new picture as text.
"""

from __future__ import annotations

import os
import sys
import termios
import tty
from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol, TextIO

from kasparctl.view.frame import ASCII, UNICODE, Glyphs, Line, Style, plain_text

if TYPE_CHECKING:
    from rich.console import Console, ScreenContext

STYLES: dict[Style, str] = {
    "": "",
    "title": "bold",
    "dim": "dim",
    "good": "green",
    "bad": "bold red",
    "warn": "magenta",
    "chosen": "bold",
    "trough": "dim",
    "badge": "bold reverse",
    "badge-good": "bold black on green",
    "badge-bad": "bold white on red",
    "badge-warn": "bold black on yellow",
}

PLAIN_WIDTH, PLAIN_HEIGHT = 80, 24


class Screen(Protocol):
    """Where frames go."""

    # Whether a frame replaces the last in place (so ageing times are worth redrawing).
    live: bool
    glyphs: Glyphs

    def size(self) -> tuple[int, int]:
        """Columns and rows to lay the frame out for."""

    def draw(self, lines: Sequence[Line]) -> None:
        """Show a frame."""

    def close(self) -> None:
        """Give the terminal back as it was."""


def glyphs_for(stream: TextIO) -> Glyphs:
    """Unicode blocks where the stream can encode them, ASCII elsewhere."""
    encoding = (getattr(stream, "encoding", None) or "ascii").lower().replace("-", "")
    return UNICODE if encoding in ("utf8", "utf16", "utf32") else ASCII


class PlainScreen:
    """Each new picture as plain text, under a rule: for pipes, logs and dumb terminals."""

    live = False

    def __init__(self, out: TextIO, width: int = PLAIN_WIDTH, height: int = PLAIN_HEIGHT) -> None:
        """Print to `out`, laid out for `width` x `height`."""
        self.out = out
        self.glyphs = glyphs_for(out)
        self._size = (width, height)
        self._last = ""

    def size(self) -> tuple[int, int]:
        """The fixed size given."""
        return self._size

    def draw(self, lines: Sequence[Line]) -> None:
        """Print the frame if it differs from the last one printed."""
        text = "\n".join(plain_text(line).rstrip() for line in lines).strip("\n")
        if self.glyphs is ASCII:
            text = text.replace("…", "~")
        if text == self._last:
            return
        self._last = text
        self.out.write(f"{self.glyphs.separator * self._size[0]}\n{text}\n")
        self.out.flush()

    def close(self) -> None:
        """Nothing to give back."""


class RichScreen:
    """The frame full screen, on the terminal's alternate screen, drawn with rich."""

    live = True

    def __init__(self, out: TextIO) -> None:
        """Take over the terminal behind `out` (a tty); close() gives it back."""
        from rich.console import Console

        self.console: Console = Console(file=out, highlight=False, emoji=False, markup=False)
        self.glyphs = glyphs_for(out)
        self._screen: ScreenContext = self.console.screen(hide_cursor=True)
        self._screen.__enter__()

    def size(self) -> tuple[int, int]:
        """The terminal's size now (it follows a resize)."""
        width, height = self.console.size
        return width, height

    def draw(self, lines: Sequence[Line]) -> None:
        """Replace what is on the screen with the frame."""
        from rich.console import Group
        from rich.text import Text

        texts = [
            Text.assemble(
                *((text, STYLES[style]) for text, style in line), no_wrap=True, overflow="crop"
            )
            for line in lines
        ]
        self._screen.update(Group(*texts))

    def close(self) -> None:
        """Leave the alternate screen and show the cursor again."""
        self._screen.__exit__(None, None, None)


def rich_available() -> bool:
    """Whether the optional `view` extra (rich) is installed."""
    try:
        import rich.console  # noqa: F401
    except ImportError:
        return False
    return True


def full_screen_possible(out: TextIO) -> bool:
    """A terminal that can be drawn on: a tty that is not dumb, with rich installed."""
    term = os.environ.get("TERM", "")
    return out.isatty() and term not in ("", "dumb") and rich_available()


def open_screen(out: TextIO, plain: bool = False) -> Screen:
    """The full screen where the terminal allows it, else the plain one."""
    if not plain and full_screen_possible(out):
        return RichScreen(out)
    return PlainScreen(out)


# Escape sequences of the keys the views use, as the terminal sends them.
_SEQUENCES = {
    b"\x1b[C": "right",
    b"\x1b[D": "left",
    b"\x1b[A": "up",
    b"\x1b[B": "down",
    b"\x1b[H": "home",
    b"\x1b[F": "end",
    b"\x1b[1~": "home",
    b"\x1b[4~": "end",
    b"\x1bOC": "right",
    b"\x1bOD": "left",
    b"\x1bOH": "home",
    b"\x1bOF": "end",
}


def parse_keys(data: bytes) -> list[str]:
    """Key names from what a terminal sent: a character, or "left", "right", "home"..."""
    keys = []
    index = 0
    while index < len(data):
        for sequence, name in _SEQUENCES.items():
            if data.startswith(sequence, index):
                keys.append(name)
                index += len(sequence)
                break
        else:
            keys.append(chr(data[index]) if data[index] < 128 else "?")
            index += 1
    return keys


class Keys:
    """Key presses from a terminal, one at a time, without echo (cbreak: Ctrl-C still works)."""

    def __init__(self, fd: int) -> None:
        """Put the terminal on `fd` in cbreak mode until close()."""
        self.fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)

    def fileno(self) -> int:
        """The terminal's descriptor, readable when a key was pressed."""
        return self.fd

    def read(self) -> list[str]:
        """The keys pressed since the last read."""
        return parse_keys(os.read(self.fd, 64))

    def close(self) -> None:
        """Give the terminal its mode back."""
        termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)


def open_keys(stream: TextIO = sys.stdin) -> Keys | None:
    """Keys from `stream` when it is a terminal; None otherwise (a pipe, /dev/null)."""
    try:
        if not stream.isatty():
            return None
        return Keys(stream.fileno())
    except (OSError, ValueError, termios.error):
        return None
