"""One command-line contract for every subcommand: argument types, usage errors, failures.

- A bad argument is a usage error: argparse's message (`kasparctl demo: error: argument
  --speed: expected a number from 0.001 to 1000000, found inf`) and exit 2. The types
  here refuse nan, inf and absurd values where argparse is told the type, and
  UsageError says the same of an argument that only fails with another (exit 2).
- Anything else that goes wrong is a failure: one line on stderr naming the cause (the
  file, the device, the permission, the disk) and exit 1, never a traceback
  (`kasparctl --debug ...` or KASPAR_DEBUG=1 shows it). cli.main applies this to every
  subcommand, with `describe` below.
- A closed pipe (`kasparctl ... | head`) is not an error: exit 0, quietly.
"""

from __future__ import annotations

import argparse
import errno
import math
import os
import re
import sys
from collections.abc import Callable

# An integer numpy seeds from, and plan.json keeps as a 64-bit integer.
SEED_LIMIT = 2**63 - 1


class UsageError(Exception):
    """An argument that cannot be used with the others (exit 2, as argparse's own)."""


def number(
    low: float, high: float, *, low_open: bool = False, unit: str = ""
) -> Callable[[str], float]:
    """An argparse type: a finite number from `low` to `high` (`low` itself excluded if
    `low_open`); nan, inf and anything outside are refused with what was expected."""
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
            raise argparse.ArgumentTypeError(f"expected {expected}, found {text!r}") from None
        too_low = value <= low if low_open else value < low
        if not math.isfinite(value) or too_low or value > high:
            raise argparse.ArgumentTypeError(f"expected {expected}, found {text}")
        return value

    parse.__name__ = "number"  # argparse names the type in its own messages
    return parse


def language(text: str) -> str:
    """An argparse type: a language code such as "de" (letters, then "-" or "_" parts)."""
    if not re.fullmatch(r"[A-Za-z]{2,3}(?:[_-][A-Za-z0-9]{2,8})*", text):
        raise argparse.ArgumentTypeError(
            f"expected a language code such as 'en', 'nl', 'de', 'it' or 'fr', found {text!r}"
        )
    return text


def whole(low: int, high: int) -> Callable[[str], int]:
    """An argparse type: an integer from `low` to `high`."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a whole number from {low} to {high}, found {text!r}"
            ) from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(
                f"expected a whole number from {low} to {high}, found {text}"
            )
        return value

    parse.__name__ = "whole number"
    return parse


def seed(text: str) -> int:
    """An argparse type: a seed, 0 to 2**63 - 1 (numpy takes no negative seed)."""
    return whole(0, SEED_LIMIT)(text)


PROBABILITY = number(0.0, 1.0)


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


def describe(error: BaseException) -> str:
    """A failure as one line naming its cause; a bug says how to see its traceback."""
    if isinstance(error, OSError):
        reason = _HINTS.get(error.errno or 0) or error.strerror or str(error)
        where = error.filename
        text = f"{where}: {reason}" if where is not None else reason
        if error.filename2 is not None:
            text = f"{where} -> {error.filename2}: {reason}"
    elif _is_ours(error):
        text = str(error)
    else:
        text = (
            f"{type(error).__name__}: {error} (a bug: run it again with --debug, or with "
            "KASPAR_DEBUG=1, for the traceback, and report it)"
        )
    return " ".join(text.split())  # one line, whatever the message held


def _is_ours(error: BaseException) -> bool:
    """An error whose message was written for a person (it names what and where)."""
    module = type(error).__module__
    return module.startswith(("kasparctl.", "hal.")) and not isinstance(
        error, AssertionError | NotImplementedError
    )
