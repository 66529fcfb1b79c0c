"""Lip sync: how closely the mouth follows the voice, over 20 different lines.

For each line, `kasparctl say LINE --wav OUT.wav --motion OUT.csv` (the path the
command takes, in-process) renders the WAV with espeak-ng and the simulated robot's
mouth goals. The WAV's RMS envelope and the mouth's commanded opening are resampled
on one 5 ms grid from the WAV's first sample, and cross-correlated (both centred):
the lag of the peak is how late (+) or early (-) the mouth is; |lag| target <= 40 ms
(audiovisual asynchrony becomes noticeable beyond about 45 ms of audio lead).
Run: .venv/bin/python bench/bench_lipsync.py
"""

from __future__ import annotations

import csv
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT)]

from hal.voice.envelope import wav_levels  # noqa: E402
from hal.voice.settings import VoiceSettings  # noqa: E402
from kasparctl.commands.motion import say_with_motion  # noqa: E402
from kasparctl.sim.demo import demo_config  # noqa: E402

TARGET_LAG_MS = 40.0
GRID_S = 0.005
MAX_LAG_S = 0.25
LINES = [
    "Hello, I am Kaspar.",
    "Shall we play a game together?",
    "I think this is the lion.",
    "Is it the elephant? I am not sure.",
    "Yes! I got it right.",
    "Oh no, that was wrong.",
    "Can you show me where the giraffe is?",
    "Thank you for teaching me.",
    "Let me think about it for a moment.",
    "The monkey lives in the second bag.",
    "I am quite sure it is the zebra.",
    "Maybe it is the crocodile, maybe not.",
    "Please press the green button if I am right.",
    "Goodbye, and thank you for playing with me!",
    "One, two, three, four, five.",
    "Now it is your turn, Sam.",
    "Alex, can you help me?",
    "I have learned all the animals now.",
    "Wait a second, I need to look again.",
    "Wonderful! You are a very good teacher.",
]


def series(values_at: list[tuple[float, float]], grid: np.ndarray) -> np.ndarray:
    """A step signal (each value held until the next) sampled on `grid`."""
    times = np.array([t for t, _ in values_at])
    values = np.array([v for _, v in values_at])
    index = np.searchsorted(times, grid, side="right") - 1
    return np.where(index >= 0, values[np.clip(index, 0, None)], 0.0)


def measure(line: str, folder: Path, number: int) -> tuple[float, float]:
    config = demo_config()
    wav, motion = folder / f"{number}.wav", folder / f"{number}.csv"
    spoken, _ = say_with_motion(config, VoiceSettings(engine="espeak-ng"), line, None,
                                str(wav), str(motion))
    assert spoken.finished, spoken
    levels, frame = wav_levels(wav)
    seconds = len(levels) * frame
    grid = np.arange(0.0, seconds, GRID_S)
    audio = series([(i * frame, level) for i, level in enumerate(levels)], grid)
    with motion.open(encoding="utf-8") as file:
        rows = [(float(r["time_s"]), float(r["position_deg"])) for r in csv.DictReader(file)
                if r["joint"] == config.body.mouth_joint]
    mouth = series(rows, grid)
    a, m = audio - audio.mean(), mouth - mouth.mean()
    lags = range(-int(MAX_LAG_S / GRID_S), int(MAX_LAG_S / GRID_S) + 1)
    scores = [float(np.dot(a[max(0, -k): len(a) - max(0, k)], m[max(0, k): len(m) - max(0, -k)]))
              for k in lags]
    best = int(np.argmax(scores))
    lag_ms = lags[best] * GRID_S * 1000.0
    correlation = float(np.corrcoef(
        a[max(0, -lags[best]): len(a) - max(0, lags[best])],
        m[max(0, lags[best]): len(m) - max(0, -lags[best])],
    )[0, 1])
    return lag_ms, correlation


def main() -> None:
    print(f"lip sync over {len(LINES)} lines (espeak-ng, demo robot, say --motion path)")
    print(f"  {'line':<48} {'lag ms':>8} {'corr':>6}")
    lags, correlations = [], []
    with tempfile.TemporaryDirectory() as scratch:
        for number, line in enumerate(LINES):
            lag, correlation = measure(line, Path(scratch), number)
            lags.append(lag)
            correlations.append(correlation)
            print(f"  {line[:48]:<48} {lag:>8.0f} {correlation:>6.2f}")
    worst = max(abs(lag) for lag in lags)
    verdict = "ok" if worst <= TARGET_LAG_MS else "MISSED"
    print(f"  overall: median lag {statistics.median(lags):.0f} ms, worst |lag| {worst:.0f} ms"
          f" (target <= {TARGET_LAG_MS:.0f} ms) {verdict}; correlation median "
          f"{statistics.median(correlations):.2f}, lowest {min(correlations):.2f}")


if __name__ == "__main__":
    main()
