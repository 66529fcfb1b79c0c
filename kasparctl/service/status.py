"""The service's STATUS= line: where the game is, and every part that is not working.

`systemctl status kasparctl` shows it; it is the first thing a researcher (or
whoever helps them on the phone) reads. One line, bounded: the stage in words,
then each problem with its reason, e.g.
"fault: see the journal; 'pause' resumes once cleared | voice failing: player exited with 1:
ALSA lib confmisc.c:855:(parse_card) cannot find card '0' | ...".
"""

from __future__ import annotations

from collections.abc import Mapping

from hal.servos.api import BatteryReading
from kasparctl.config import GameSettings
from kasparctl.game import fold
from kasparctl.game.records import FaultSource
from kasparctl.game.recovery import reopen_record
from kasparctl.game.state import GameState

# The researcher's commands by name (next, pause, stop): a key of their own device, or a
# hold on the children's keyfob, as configured (README: the researcher's gestures).
STATUS_WORDS = {
    "idle": "waiting: 'next' starts the session",
    "placing": "step 1: placing the bags",
    "teaching": "step 2: teaching Kaspar to point",
    "revealing": "step 3: revealing the toys",
    "guessing": "step 4: Kaspar guesses the names",
    "farewell": "step 5: farewell",
    "finished": "session finished",
    "paused": "paused: 'pause' again resumes",
    "fault": "fault: see the journal; 'pause' resumes once cleared",
    "stopped": "session stopped",
}
PROBLEM_WORDS = {
    FaultSource.SERVO: "servo fault",
    FaultSource.KEYFOB: "keyfob not connected",
    FaultSource.VOICE: "voice failing",
    FaultSource.SOFTWARE: "software error",
    FaultSource.STORAGE: "CANNOT SAVE the records",
    FaultSource.RESEARCHER: "researcher's device not connected",
    FaultSource.KEYFOB_SILENT: "children's keyfob silent (battery?)",
}
# What the researcher does about it: nothing more is played until it saves again.
STORAGE_ADVICE = (
    " - stop the session ('stop') or free the disk; nothing is played unsaved, what is on disk"
    " is kept, and 'pause' resumes once it saves again"
)
# systemd keeps STATUS= whole, but a line this long is still read at a glance.
DETAIL_LIMIT = 200
STATUS_LIMIT = 600
# Said while the wall clock is not synchronised (kasparctl.game.wallclock; docs/install.md).
CLOCK_WORDS = "clock unsynchronised: record times may be wrong (order and ages are not)"


def status_line(
    stage: str,
    problems: Mapping[FaultSource, str] | None = None,
    notice: str | None = None,
    confused: str | None = None,
    battery: str | None = None,
    waiting: str | None = None,
    clock_unsynchronised: bool = False,
) -> str:
    """The STATUS= text for `stage` with `problems` (part -> why), each reason cut to a limit,
    and a `notice` (a session abandoned); `confused` (recovery_words) after the stage;
    CLOCK_WORDS when `clock_unsynchronised`; `battery` (battery_words) at the end;
    `waiting`, in idle, what "next" would start (kasparctl.game.opening.PlanQueue.words)."""
    words = waiting if stage == "idle" and waiting else STATUS_WORDS.get(stage, stage)
    if confused:
        words = f"{words} | {confused}"
    parts = [
        f"{PROBLEM_WORDS[kind]}: {_cut(detail, DETAIL_LIMIT)}"
        + (STORAGE_ADVICE if kind is FaultSource.STORAGE else "")
        for kind, detail in (problems or {}).items()
    ]
    if notice:
        parts.append(_cut(notice, DETAIL_LIMIT))
    if clock_unsynchronised:
        parts.append(CLOCK_WORDS)
    line = _cut(" | ".join([words, *parts]), STATUS_LIMIT - len(battery or "") - 3)
    return f"{line} | {battery}" if battery else line


def battery_words(reading: BatteryReading | None) -> str | None:
    """"battery 12.9 V", or "battery LOW: 11.6 V, below 11.8 V"; None when not watched."""
    if reading is None:
        return None
    if reading.voltage_v is None:
        return "battery not read yet"
    if reading.low:
        return f"battery LOW: {reading.voltage_v:.1f} V, below {reading.warn_below_v:.1f} V"
    return f"battery {reading.voltage_v:.1f} V"


def recovery_words(state: GameState | None, settings: GameSettings) -> str | None:
    """Kaspar is confused and asks the researcher (kasparctl.game.recovery): which target,
    and what their reopen would re-open; None when it is not confused (the one rule of
    kasparctl.game.fold, as the live view and the trials CSV read it: about a target still
    open only)."""
    if state is None or not isinstance(state.confused, int):
        return None
    confused = fold.standing(state.confused, [progress.done for progress in state.progress])
    if confused is None:
        return None
    target = settings.targets[confused]
    reopen = reopen_record(state, settings)
    if reopen is None:
        return f"Kaspar is confused about {target}"
    return f"Kaspar is confused about {target}: reopen re-opens {reopen.name} ({reopen.target})"


def _cut(text: str, limit: int) -> str:
    text = " ".join(text.split())  # one line, whatever the reason held
    return text if len(text) <= limit else text[: limit - 3] + "..."
