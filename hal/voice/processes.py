"""The voice's child processes: never on our stdout, always killed and reaped.

Standard output carries the JSON log lines, so no child may write there. A
child still running when its utterance ends (timed out, cancelled) is killed
and waited for, so none outlives the utterance or is left as a zombie.

A child that fails is reported with its telling lines: the first ones and
the last ones of its stderr, bounded. aplay without a sound card writes the
cause first ("cannot find card '0'") and eight lines of consequences after
it; the end alone would hide it.
"""

from __future__ import annotations

import asyncio
import contextlib
import subprocess

from hal.errors import VoiceError


async def spawn(
    argv: list[str], *, stdin: bool | int = False, stdout: int | None = None
) -> asyncio.subprocess.Process:
    """Start `argv` with stderr captured for the error message.

    `stdin` is True for a pipe to write into, a file descriptor, or False for
    /dev/null; `stdout` is a file descriptor, /dev/null by default. Raises
    VoiceError when the program cannot be run (missing, not executable).
    """
    try:
        return await asyncio.create_subprocess_exec(
            *argv,
            stdin=asyncio.subprocess.PIPE if stdin is True else (stdin or subprocess.DEVNULL),
            # Never our stdout: that is where the JSON log lines go.
            stdout=stdout if stdout is not None else subprocess.DEVNULL,
            stderr=asyncio.subprocess.PIPE,
        )
    except OSError as error:
        raise VoiceError(f"cannot run {argv[0]}: {error.strerror}") from error


async def finish(process: asyncio.subprocess.Process, what: str, text: bytes | None) -> None:
    """Write `text` to the process's stdin (if given) and wait for it to end.

    Raises VoiceError naming `what` with the exit status and the telling lines
    of its stderr (telling_lines) when it exits non-zero.
    """
    _, errors = await process.communicate(text)
    if process.returncode != 0:
        detail = telling_lines(errors.decode(errors="replace"))
        raise VoiceError(f"{what} exited with {process.returncode}: {detail}")


# How much of a failed child's stderr is kept: its first lines (where the cause is
# said), its last lines (where the program sums up), each cut to a width.
HEAD_LINES = 3
TAIL_LINES = 2
LINE_WIDTH = 160


def telling_lines(
    stderr: str, head: int = HEAD_LINES, tail: int = TAIL_LINES, width: int = LINE_WIDTH
) -> str:
    """The first `head` and last `tail` non-blank lines of `stderr`, joined with " | ".

    Lines left out in between are counted ("... 4 more lines ..."); a line
    longer than `width` characters is cut with "...". The result is at most
    (head + tail + 1) lines of `width`, however much the program wrote.
    """
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    if len(lines) > head + tail:
        left_out = len(lines) - head - tail
        lines = [*lines[:head], f"... {left_out} more lines ...", *lines[len(lines) - tail :]]
    return " | ".join(line if len(line) <= width else line[: width - 3] + "..." for line in lines)


async def run(argv: list[str], what: str) -> None:
    """Run `argv` to its end; VoiceError if it cannot start or fails, killed if cancelled."""
    process = await spawn(argv)
    try:
        await finish(process, what, None)
    finally:
        await stop(process)


async def stop(process: asyncio.subprocess.Process) -> None:
    """Kill a process still running (timeout or cancel) and reap it.

    The wait is shielded: a second cancellation while reaping does not leave
    a zombie behind.
    """
    if process.returncode is None:
        with contextlib.suppress(ProcessLookupError):
            process.kill()
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.shield(process.wait())
