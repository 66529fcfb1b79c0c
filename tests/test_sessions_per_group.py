"""Several sessions for one group, numbered; a stopped session resumed later or closed.

The daemon itself on the simulated rig (tests/fault_rig.py), in simulated time: the test
is the researcher.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fault_rig import FaultRig, phrase_said, run_daemon, write_config

from kasparctl.config import ConfigError, load_config
from kasparctl.game.events import GameEvent


def numbered(tmp_path: Path) -> Path:
    """The fault rig's robot with the demo group planned twice: sessions 1 and 2."""
    path = write_config(tmp_path, "pilot")
    text = path.read_text()
    second = '\n[[sessions]]\ngroup = "demo"\nnumber = 2\nprofile = "paper"\n'
    path.write_text(text.replace("\n[servos]", second + "\n[servos]", 1))
    load_config(str(path))
    return path


def plans(state_dir: Path) -> list[tuple[str, int]]:
    found = []
    for directory in sorted((state_dir / "sessions").iterdir()):
        meta = json.loads((directory / "plan.json").read_text())
        found.append((meta["group"], meta["number"]))
    return found


def test_a_stopped_session_is_reopened_by_next_and_closed_by_stop(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    async def scenario(rig: FaultRig) -> None:
        await rig.press("long green")  # next: session 1 of the demo group
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 3)
        await rig.press("both")  # stop: thanks and goodbye
        await rig.stage_is("stopped")
        await rig.stage_is("idle")  # the next game: session 1 waits for the choice
        mark = len(rig.events)
        await rig.press("long green")  # next: it carries on where it stopped
        await rig.event(GameEvent.STATE, lambda i: i["state"] == "guessing", since=mark)
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 5, since=mark)
        await rig.press("both")
        await rig.stage_is("stopped")
        await rig.stage_is("idle")
        await rig.press("both")  # stop in idle: session 1 closed for good
        await rig.until("the close", lambda: phrase_said(rig, "confirm", "close"))
        mark = len(rig.events)
        await rig.press("long green")  # next: the group's session 2
        await rig.event(GameEvent.STATE, lambda i: i["state"] == "guessing", since=mark)
        await rig.press("both")
        await rig.stage_is("idle")

    rig = run_daemon(tmp_path, monkeypatch, scenario, "pilot", config=numbered(tmp_path))
    assert plans(rig.state_dir) == [("demo", 1), ("demo", 2)]
    first, second = rig.session_records()
    events = [(r["kind"], r.get("event"), r.get("to")) for r in first]
    assert ("session", "resumed", None) in events and events[-1] == ("session", "closed", None)
    # The trials went on from where the stop left them, numbered once each.
    numbers = [r["trial"] for r in first if r["kind"] == "trial"]
    assert numbers == list(range(1, len(numbers) + 1)) and len(numbers) >= 4
    # The stop thanked and said goodbye, twice; the greeting came first when reopened.
    assert rig.said().count("We stop now. Thank you for teaching me. Goodbye!") == 3
    reopened = rig.said().index("We stop now. Thank you for teaching me. Goodbye!") + 1
    assert rig.said()[reopened] == "Hello. I am Kaspar. You are my teachers today."
    assert [r["to"] for r in second if r["kind"] == "step"] == ["guessing", "stopped"]


def test_a_group_planned_twice_needs_numbers(tmp_path: Path) -> None:
    path = numbered(tmp_path)
    path.write_text(path.read_text().replace("number = 2\n", ""))
    with pytest.raises(ConfigError) as caught:
        load_config(str(path))
    assert caught.value.key == "sessions[1].group"
    assert caught.value.message == (
        "group code 'demo' is planned twice as session 1; give a group's next session "
        "number = 2, 3..."
    )
