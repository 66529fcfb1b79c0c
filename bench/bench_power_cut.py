"""A power cut at every point of a whole names game and a pilot game: what is lost.

Run on demand: .venv/bin/python bench/bench_power_cut.py [--variant names|pilot] [--json]

The crash-state explorer of tests/crash_states.py at every crash point (the suite's
tests/test_power_cut.py samples them): each game's storage operations recorded
through the storage room, every state a POSIX file system may leave after each
one (unsynced writes lost, torn or zero-filled; directory entries not yet durable
undone) built on disk, and `kasparctl sessions`, `kasparctl export` and the resume
run on each.

Targets: 0 fsynced records lost, 0 sessions lost, 0 half-made sessions reported as
damaged, 0 sessions abandoned, 0 readers failing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from crash_states import Figures, explore, record_game, strictest_losses

TARGETS = ("records_lost", "sessions_lost", "damaged_reported", "abandoned", "failures")


def main() -> int:
    """Explore every crash point of each game asked for; print the figures, exit 1 on a miss."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variant", choices=("names", "pilot"), action="append")
    parser.add_argument("--json", action="store_true")
    arguments = parser.parse_args()
    total = Figures()
    rows = {}
    for variant in arguments.variant or ["names", "pilot"]:
        started = time.monotonic()
        ops = record_game(variant)
        strict = strictest_losses(ops)
        figures = explore(ops, variant)
        total.add(figures)
        rows[variant] = {
            "operations": len(ops),
            "crash_points": figures.crash_points,
            "states": figures.states,
            "promised_records_checked": figures.promised_records,
            "strictest_state_losses": len(strict),
            **{name: getattr(figures, name) for name in TARGETS},
            "seconds": round(time.monotonic() - started, 1),
            "examples": figures.examples,
        }
        total.records_lost += len(strict)
    if arguments.json:
        print(json.dumps(rows, indent=1))
    else:
        for variant, row in rows.items():
            print(
                f"{variant}: {row['operations']} storage operations, {row['crash_points']} crash "
                f"points, {row['states']} distinct states explored ({row['seconds']} s)"
            )
            for name in ("strictest_state_losses", *TARGETS):
                print(f"  {name:24} {row[name]:6}   target 0")
            for example in row["examples"]:
                print(f"  e.g. {example}")
    return 0 if total.clean else 1


if __name__ == "__main__":
    sys.exit(main())
