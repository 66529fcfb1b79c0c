"""One command-line contract for every subcommand: argument types, usage errors, failures.

- A bad argument is a usage error: one line naming the option, what was expected and
  what was found (`kasparctl demo: error: argument --speed: expected a number from 0.001
  to 1e+06, found inf`), and exit 2. The types here refuse nan, inf and absurd values
  where argparse is told the type; UsageError says the same of an argument that only
  fails with another, or that a room refuses (`usage_of`), also exit 2.
- Anything else that goes wrong is a failure: one line on stderr naming the cause and
  exit 1, never a traceback (`kasparctl --debug ...` or KASPAR_DEBUG=1 shows it). The
  project's own errors (hal.errors.KasparError) say it in their message; an OSError is
  the system's reason with the file; anything else is a bug and says so (`describe`).
  cli.main applies this to every subcommand: a command neither catches nor prints them.
- A closed pipe (`kasparctl ... | head`) is not an error: exit 0, quietly.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import math
import os
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, NoReturn, TypeVar

from hal.errors import KasparError

T = TypeVar("T")

# An integer numpy seeds from, and plan.json keeps as a 64-bit integer.
SEED_LIMIT = 2**63 - 1
USAGE_EXIT = 2
FAILURE_EXIT = 1


class UsageError(KasparError):
    """An argument that cannot be used with the others (exit 2, as argparse's own)."""


class Parser(argparse.ArgumentParser):
    """The parser of `kasparctl` and of each subcommand: a usage error is one line, exit 2."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """As argparse's; the deepest subcommand's name is kept for a later UsageError."""
        super().__init__(*args, **kwargs)
        # A subcommand's defaults override its parent's: the one run names itself.
        self.set_defaults(usage_prog=self.prog)

    def error(self, message: str) -> NoReturn:
        """One line, as every failure: `kasparctl simulate: error: argument --seed: ...`."""
        self.exit(USAGE_EXIT, f"{self.prog}: error: {message}\n")


@contextlib.contextmanager
def usage_of(*kinds: type[Exception]) -> Iterator[None]:
    """Errors of `kinds` raised inside are usage errors: a room refusing an option's value."""
    try:
        yield
    except kinds as error:
        raise UsageError(str(error)) from error


def _refuse(expected: str, text: str) -> NoReturn:
    raise argparse.ArgumentTypeError(f"expected {expected}, found {text!r}")


def _named(parse: Callable[[str], T], name: str) -> Callable[[str], T]:
    parse.__name__ = name  # argparse names the type in its own messages
    return parse


def number(
    low: float, high: float, *, low_open: bool = False, unit: str = ""
) -> Callable[[str], float]:
    """A finite number from `low` to `high` (`low` itself excluded if `low_open`); nan, inf
    and anything outside are refused with what was expected."""
    after = f" {unit}" if unit else ""
    expected = (
        f"a number above {low:g} and up to {high:g}{after}"
        if low_open
        else f"a number from {low:g} to {high:g}{after}"
    )

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            _refuse(expected, text)
        too_low = value <= low if low_open else value < low
        if not math.isfinite(value) or too_low or value > high:
            raise argparse.ArgumentTypeError(f"expected {expected}, found {text}")
        return value

    return _named(parse, "number")


def finite(text: str) -> float:
    """Any finite number (the room checks it against its own limits)."""
    try:
        value = float(text)
    except ValueError:
        _refuse("a finite number", text)
    if not math.isfinite(value):
        _refuse("a finite number", text)
    return value


def whole(low: int, high: int | None) -> Callable[[str], int]:
    """An integer from `low` to `high` (no more than that; None: the room sets the limit)."""
    expected = f"a whole number from {low} to {high}"
    if high is None:
        expected = f"a whole number of at least {low}"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            _refuse(expected, text)
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"expected {expected}, found {text}")
        return value

    return _named(parse, "whole number")


_SEED = whole(0, SEED_LIMIT)
PROBABILITY = number(0.0, 1.0)


def seed(text: str) -> int:
    """The one seed rule of every command: 0 to 2**63 - 1 (numpy takes no negative seed)."""
    return _SEED(text)


def wholes(low: int, high: int) -> Callable[[str], tuple[int, ...]]:
    """Whole numbers from `low` to `high` separated by commas: "4,8,16"."""
    expected = f"whole numbers from {low} to {high} separated by commas"

    def parse(text: str) -> tuple[int, ...]:
        try:
            values = tuple(int(part) for part in text.split(","))
        except ValueError:
            _refuse(expected, text)
        if not all(low <= value <= high for value in values):
            _refuse(expected, text)
        return values

    return _named(parse, "whole numbers")


def whole_ranges(low: int, high: int, what: str = "numbers") -> Callable[[str], list[int]]:
    """Whole numbers from `low` to `high` as ranges and single ones: "1-5,9"; sorted, once each."""
    expected = f"{what} like 1-20 or 1,3,5, within {low}-{high}"

    def parse(text: str) -> list[int]:
        found: set[int] = set()
        try:
            for part in text.split(","):
                first, _, last = part.strip().partition("-")
                found.update(range(int(first), int(last or first) + 1))
        except ValueError:
            _refuse(expected, text)
        if not found or min(found) < low or max(found) > high:
            _refuse(expected, text)
        return sorted(found)

    return _named(parse, "ranges")


def names(text: str) -> list[str]:
    """Names separated by commas ("head_yaw,head_pitch"), each once, in the order given."""
    found = [name.strip() for name in text.split(",") if name.strip()]
    if not found:
        _refuse("names like a,b", text)
    return list(dict.fromkeys(found))


def pair(text: str) -> tuple[str, str]:
    """Two values separated by a comma: "A,B"."""
    values = [value.strip() for value in text.split(",")]
    if len(values) != 2 or not all(values):
        _refuse("two values A,B", text)
    return values[0], values[1]


def number_range(most: int) -> Callable[[str], list[float]]:
    """START:STOP:STEP (inclusive, STEP > 0, at most `most` values) or one VALUE."""
    expected = "START:STOP:STEP (finite numbers, STEP > 0, STOP >= START) or one VALUE"

    def parse(text: str) -> list[float]:
        try:
            parts = [float(part) for part in text.split(":")]
        except ValueError:
            _refuse(expected, text)
        if len(parts) not in (1, 3) or not all(math.isfinite(part) for part in parts):
            _refuse(expected, text)
        if len(parts) == 1:
            return parts
        start, stop, step = parts
        if step <= 0.0 or stop < start:
            _refuse(expected, text)
        # The small allowance keeps STOP in the range despite decimal steps (0.1 * 9).
        count = math.floor((stop - start) / step + 1e-9) + 1
        if count > most:
            raise argparse.ArgumentTypeError(
                f"expected at most {most} values, found {count} in {text!r}"
            )
        # Rounded so that 0.1 + 2 * 0.1 prints and compares as 0.3.
        return [round(start + i * step, 12) for i in range(count)]

    return _named(parse, "range")


def assignment(
    value: Callable[[str], T], keys: Sequence[str] | None = None, form: str = "NAME=VALUE"
) -> Callable[[str], tuple[str, T]]:
    """NAME=VALUE: NAME one of `keys` (any name without them), VALUE parsed by `value`."""
    known = f" with NAME one of {', '.join(keys)}" if keys else ""

    def parse(text: str) -> tuple[str, T]:
        key, equals, rest = text.partition("=")
        key = key.strip()
        if not equals or not key or (keys and key not in keys):
            _refuse(f"{form}{known}", text)
        try:
            return key, value(rest)
        except argparse.ArgumentTypeError as error:
            raise argparse.ArgumentTypeError(f"{key}: {error} (in {text!r})") from None

    return _named(parse, "assignment")


def key(text: str) -> str:
    """A name that is a TOML bare key (a pose's, a behaviour's): letters, digits, _ and -."""
    if not re.fullmatch(r"[A-Za-z0-9_-]+", text):
        _refuse("letters, digits, _ and -", text)
    return text


def language(text: str) -> str:
    """A language code such as "de" (letters, then "-" or "_" parts)."""
    if not re.fullmatch(r"[A-Za-z]{2,3}(?:[_-][A-Za-z0-9]{2,8})*", text):
        _refuse("a language code such as 'en', 'nl', 'de', 'it' or 'fr'", text)
    return text


def path(text: str) -> str:
    """A file or directory's path: not empty, no NUL byte (the system takes neither)."""
    if not text or "\0" in text:
        _refuse("a path", text)
    return text


def output_file(text: str) -> Path:
    """A file to write: not a directory, in a folder that exists and may be written."""
    path(text)
    target = Path(text)
    if target.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: is a directory, expected a file")
    folder = target.resolve().parent
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: no such directory: {folder}")
    if not os.access(folder, os.W_OK):
        raise argparse.ArgumentTypeError(f"{text}: {folder}: permission denied")
    return target


def add_sources(
    parser: argparse.ArgumentParser, sessions: bool = True, condition: bool = False
) -> None:
    """Add SESSION..., --state-dir and --config (and --condition) to a research command.

    kasparctl.research.source.read_sessions reads the sessions they name.
    """
    if sessions:
        parser.add_argument(
            "sessions",
            nargs="*",
            type=path,
            metavar="SESSION",
            help="session ids or session directories (default: every session)",
        )
    parser.add_argument(
        "--state-dir",
        action="append",
        default=None,
        type=path,
        metavar="DIR",
        help="a robot's state directory (default: the config's); repeat to pool several "
        "robots or days",
    )
    parser.add_argument(
        "--config",
        default=None,
        type=path,
        help="kaspar.toml whose state_dir and learner profiles to use "
        "(default: $KASPAR_CONFIG or /etc/kaspar/kaspar.toml)",
    )
    if condition:
        parser.add_argument(
            "--condition",
            default=None,
            metavar="LABEL",
            help="only the sessions of this condition (profile/spoken or profile/silent)",
        )


def stdin_readable() -> bool:
    """Whether standard input is open (a closed one, `<&-`, has nothing to read keys from)."""
    stream = sys.stdin
    if stream is None or stream.closed:
        return False
    try:
        os.fstat(stream.fileno())
    except (OSError, ValueError):
        return False
    return True


# What an OSError means to the person at the terminal, where the system's words are not
# enough on their own.
_HINTS = {
    errno.EACCES: "permission denied (run it as the service's user, e.g. with sudo -u kaspar)",
    errno.EPERM: "not permitted (run it as the service's user, e.g. with sudo -u kaspar)",
    errno.ENOSPC: "no space left on the disk",
    errno.EROFS: "the file system is read-only",
    errno.ENOENT: "no such file or directory",
    errno.ENODEV: "no such device",
}
BUG_HINT = (
    "a bug: run it again with --debug, or with KASPAR_DEBUG=1, for the traceback, and report it"
)


def describe(error: BaseException) -> str:
    """A failure as one line: the project's message, the system's reason, or a bug named."""
    if isinstance(error, KasparError):
        text = str(error)
    elif isinstance(error, OSError):
        reason = _HINTS.get(error.errno or 0) or error.strerror or str(error)
        where = [name for name in (error.filename, error.filename2) if name is not None]
        text = f"{' -> '.join(map(str, where))}: {reason}" if where else reason
    else:
        text = f"{type(error).__name__}: {error} ({BUG_HINT})"
    return " ".join(text.split())  # one line, whatever the message held
