"""A power cut at any point loses nothing promised: the crash-state explorer of tests/crash_states.py.

A record is promised once the fsync after its write returned (the robot reacts
only then); a session once Session.create returned. Under POSIX rules a new
directory entry survives a power cut only once its directory is fsynced: each
one the records depend on is shown needed, by leaving its fsync out of the
recording and finding what the strictest crash state then loses.
"""

from __future__ import annotations

import pytest
from crash_states import explore, record_game, record_small, sample_points, strictest_losses

# Each directory entry the records depend on: the storage room's function that makes it
# durable, and the directory it fsyncs (relative to the state directory's parent).
ENTRIES = {
    "the state directory": ("_mkdir", "."),
    "sessions/": ("_mkdir", "state"),
    "each session directory": ("rename_new", "state/sessions"),
    "records.jsonl's creation": ("create_empty", "state/sessions/.{session}.new"),
    "events.jsonl's creation": ("_open", "state"),
}


def test_the_strictest_crash_state_at_every_point_keeps_every_promise() -> None:
    assert strictest_losses(record_small()) == []


@pytest.mark.parametrize("entry", ENTRIES)
def test_without_each_directory_fsync_a_crash_loses_what_was_promised(entry: str) -> None:
    caller, directory = ENTRIES[entry]
    if "{session}" in directory:
        ops = record_small()
        made = next(op[1] for op in ops if op[0] == "mkdir" and op[1].endswith(".new"))
        directory = made
    losses = strictest_losses(record_small((caller, directory)))
    assert losses, f"leaving out the fsync of {entry} lost nothing: the test is vacuous"


@pytest.mark.parametrize("variant", ["names", "pilot"])
def test_a_power_cut_in_a_whole_game_loses_no_record_and_leaves_nothing_damaged(
    variant: str,
) -> None:
    ops = record_game(variant)
    assert strictest_losses(ops) == []
    # Every point around the session's making and its first records, and a sample of the
    # rest (a fixed seed); bench/bench_power_cut.py explores them all.
    figures = explore(ops, variant, points=sample_points(ops, 10))
    assert figures.states > 50
    assert figures.promised_records > 0
    assert figures.clean, figures.examples
