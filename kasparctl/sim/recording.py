"""What a simulated game did, kept for anyone to see: every goal each joint received, and
the voice rendered for real.

`kasparctl demo --motion OUT.csv` writes a row for every goal the joints layer wrote,
by any path (the game's moves and points, the body's stream: gaze, blinks, the mouth),
as it is written: `time_s, joint, position_deg, source`. The first three columns are
those of `kasparctl say --motion` (write_csv); time is the session's clock (the
transcript's and the records' times); `source` is the move's name ("move", "point",
"rest"), the body's layer ("mouth", "blink", "gaze", "idle", "home",
"gesture:<behaviour>") or the joints layer's own ("torque_on", "into_range").

`kasparctl demo --voice espeak-ng` has the simulated voice speak every line for real too,
into WAV files (recorded_voice), and the body's mouth follows their real envelope.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from pathlib import Path
from typing import TextIO

import msgspec

from hal.clock import LoopClock
from hal.servos.api import Goal, ServoApi
from hal.voice.api import VoiceOutput
from hal.voice.speaker import WHERE_SOUND_GOES, Voice
from kasparctl.config import Config

HEADER = ("time_s", "joint", "position_deg")
SOURCE = "source"
# Where the lines' WAV files go in the state directory, unless voice.wav_dir says.
VOICE_DIR = "voice"


def row(time: float, joint: str, degrees: float, *source: str) -> tuple[str, ...]:
    """One row as every motion CSV writes it: time to 0.1 ms, degrees to 0.001."""
    return (f"{time:.4f}", joint, f"{degrees:.3f}", *source)


def write_csv(rows: Iterable[tuple[float, str, float]], path: Path) -> int:
    """Rows (time_s, joint, position_deg) with their header into `path`; how many."""
    count = 0
    with path.open("w", newline="", encoding="utf-8") as file:
        writer = csv.writer(file)
        writer.writerow(HEADER)
        for time, joint, degrees in rows:
            writer.writerow(row(time, joint, degrees))
            count += 1
    return count


class MotionRecord:
    """Every goal `servos` write from now on, a CSV row each as it is written (with its source)."""

    def __init__(self, servos: ServoApi, path: Path) -> None:
        """Start writing `path` (replaced) with the goals of `servos`; OSError if it cannot be."""
        self._servos = servos
        self.path = path
        self._file: TextIO | None = path.open("w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file)
        self._writer.writerow((*HEADER, SOURCE))
        self.rows = 0
        servos.on_goals(self._written)

    def _written(self, goal: Goal) -> None:
        if self._file is None:
            return
        self._writer.writerow(row(goal.time, goal.joint, goal.degrees, goal.source))
        self.rows += 1

    def close(self) -> None:
        """Stop listening and close the file; idempotent."""
        self._servos.off_goals(self._written)
        if self._file is not None:
            self._file.close()
            self._file = None


def recorded_voice(config: Config, engine: str | None, state_dir: Path) -> VoiceOutput | None:
    """The configured voice with `engine` (None: no real voice), rendering every line into
    WAV files: voice.wav_dir, or <state_dir>/voice. Stamped on the loop's clock (the
    session's), so the mouth follows each file's envelope from when it is said."""
    if engine is None:
        return None
    folder = config.voice.wav_dir or str(state_dir / VOICE_DIR)
    settings = msgspec.structs.replace(config.voice, engine=engine, wav_dir=folder)
    # A session's voice changes its voice, rate, volume and pitch, never the engine asked for.
    return Voice(settings, LoopClock(), keep=(*WHERE_SOUND_GOES, "engine"))
