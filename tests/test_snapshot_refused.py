"""A step's record fits on a nearly full disk but its snapshot does not (the records' last
page has room, a new file has none): the step is on disk, and the resume carries on in it.

On a real tmpfs this depends on how much room the records' last page has (the full-disk
tests see either case); here the snapshot is refused on purpose, in simulated time.
"""

from __future__ import annotations

import errno
import json
from pathlib import Path

import pytest
from fault_rig import FaultRig, run_daemon

from kasparctl.game import session as session_module
from kasparctl.game.session import RECORDS_FILE, STATE_FILE


def test_a_step_whose_snapshot_is_refused_is_resumed_in_that_step(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real_write = session_module.write_atomic
    refused: list[str] = []

    def write_atomic(path: Path, data: bytes) -> None:
        # The first snapshot of the teaching step: no room for a new file.
        if path.name == STATE_FILE and b'"step":"teaching"' in data and not refused:
            refused.append(path.name)
            raise OSError(errno.ENOSPC, "No space left on device")
        real_write(path, data)

    stages: list[str] = []

    async def scenario(rig: FaultRig) -> None:
        monkeypatch.setattr(session_module, "write_atomic", write_atomic)
        await rig.press("long green")
        await rig.stage_is("placing")
        await rig.press("long green")
        await rig.until("the fault stage", lambda: rig.stage == "fault")
        stages.append(rig.stage)
        await rig.press("long red")
        await rig.until("resumed", lambda: rig.stage != "fault")
        stages.append(rig.stage)
        await rig.press("long red")  # paused, to stop the game here
        await rig.until("paused", lambda: rig.stage == "paused")

    run_daemon(tmp_path, monkeypatch, scenario)
    (directory,) = (tmp_path / "state" / "sessions").iterdir()
    records = [json.loads(line) for line in (directory / RECORDS_FILE).read_text().splitlines()]
    steps = [r["to"] for r in records if r["kind"] == "step"]
    assert refused == [STATE_FILE]
    assert any(r["kind"] == "fault" and r["fault"] == "storage" for r in records)
    assert stages == ["fault", "teaching"]
    assert steps == ["placing", "teaching"]
