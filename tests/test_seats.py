"""One keyfob per child: who pressed, a press out of turn, a seat whose keyfob is away.

The daemon itself on the simulated rig (tests/fault_rig.py), in simulated time, with
two seats ([[keyfob.children]]), each a simulated keyfob of its own; honest children
answer on the asked child's keyfob.
"""

from __future__ import annotations

import asyncio
import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from fault_rig import TOYS, FaultRig, run_daemon, seated

from hal.build import build
from hal.clock import LoopClock
from hal.keyfob.api import KeyfobLost
from hal.keyfob.gestures import Gesture
from hal.keyfob.seats import Seats
from hal.keyfob.sim import SimKeyfob
from kasparctl.config import ConfigError, load_config
from kasparctl.game.events import GameEvent


def wrong(rig: FaultRig, info: dict[str, Any]) -> str:
    """The answer the answer key says is wrong for the question `info`."""
    answers = [TOYS.index(toy) for toy in rig.daemon.config.sessions[0].answer_key]
    return "red" if info["choice"] == answers[info["target"]] else "green"


@pytest.mark.parametrize("rule", ["ignore", "take"])
def test_a_press_out_of_turn_is_recorded_and_taken_only_by_the_rule(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, rule: str
) -> None:
    """Trial 2 asks the second child; the first child presses the wrong answer on their own
    keyfob just after the question, before the second answers on theirs."""

    async def scenario(rig: FaultRig) -> None:
        question = rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 2)
        await rig.press("long green")  # next, on the researcher's device
        info = await question
        assert info["child_index"] == 1
        await asyncio.sleep(0.3)  # before the asked child's own answer (1 s)
        await rig.seats[0].perform(wrong(rig, info))
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 3)
        await rig.press("both")  # stop
        await rig.stage_is("idle")

    rig = run_daemon(tmp_path, monkeypatch, scenario, config=seated(tmp_path, rule))
    (records,) = rig.session_records()
    trials = {r["trial"]: r for r in records if r["kind"] == "trial"}
    first, second = trials[1], trials[2]
    assert (first["child_index"], first["seat"], first["credited_index"]) == (0, 1, 0)
    assert first["device"] == "/dev/input/kaspar-seat1"
    assert second["child_index"] == 1  # whose turn it was, in both rules
    out_of_turn = [r for r in records if r["kind"] == "press" and r.get("ignored") == "out of turn"]
    wrong_answer = wrong(rig, {"choice": second["choice_index"], "target": second["target_index"]})
    if rule == "ignore":
        # Recorded, never taken: the second child's own answer is the trial's.
        (press,) = out_of_turn
        assert (press["seat"], press["device"]) == (1, "/dev/input/kaspar-seat1")
        assert (press["pressed_by_index"], press["turn_of_index"]) == (0, 1)
        assert press["button"] == wrong_answer
        assert (second["seat"], second["credited_index"]) == (2, 1)
        assert second["feedback"] != wrong_answer
    else:
        # Taken, and credited to who pressed: the first child, on seat 1.
        assert out_of_turn == []
        assert (second["seat"], second["credited_index"]) == (1, 0)
        assert second["feedback"] == wrong_answer
        # The second child's press a moment later is an extra of that answer, from seat 2.
        late = [r for r in records if r["kind"] == "press" and r.get("seat") == 2]
        assert late and late[0].get("extra") is True
    plan = rig.daemon.state_dir / "sessions"
    (directory,) = plan.iterdir()
    assert '"answer_out_of_turn":"' + rule + '"' in (directory / "plan.json").read_text()


def test_a_seat_whose_keyfob_is_away_is_passed_over_until_it_is_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    async def scenario(rig: FaultRig) -> None:
        await rig.press("long green")
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 2)
        await rig.seats[1].perform("lost")  # the second child's battery, as they are asked
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 4)
        await rig.seats[1].perform("back")
        await rig.event(GameEvent.QUESTION, lambda info: info["trial"] == 6)
        await rig.press("both")
        await rig.stage_is("idle")

    rig = run_daemon(tmp_path, monkeypatch, scenario, config=seated(tmp_path))
    (records,) = rig.session_records()
    children = [r["child_index"] for r in records if r["kind"] == "trial"]
    # Trial 2 went to the first child once the second's keyfob was lost, and so did
    # trial 3 (the second child's turn passed over); from its return they alternate.
    assert children[:3] == [0, 0, 0]
    assert 1 in children[3:5]
    skipped = [r for r in records if r["kind"] == "rotation"]
    assert skipped and all(r["event"] == "skipped" for r in skipped)
    assert {(r["child_index"], r["reason"], r["seat"]) for r in skipped} == {
        (1, "keyfob absent", 2)
    }
    hal = [(r["event"], r.get("seat")) for r in records if r["kind"] == "hal"]
    assert ("keyfob_lost", 2) in hal and ("keyfob_back", 2) in hal
    # Nothing stopped for it: one seat away is no keyfob fault.
    assert not [r for r in records if r["kind"] == "fault"]


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (
            lambda t: t.replace("children_per_group = 2", "children_per_group = 3"),
            "keyfob.children: expected a seat for each of the 3 children of sessions[0], "
            "found none for child 3",
        ),
        (
            lambda t: t.replace("child = 2", "child = 1"),
            "keyfob.children[1].child: expected each child seated once, found child 1 seated "
            "already (keyfob.children[0])",
        ),
        (
            lambda t: t.replace("kaspar-seat2", "kaspar-seat1"),
            "keyfob.children[1]: expected a keyfob of its own, found "
            "'/dev/input/kaspar-seat1', the keyfob of keyfob.children[0]",
        ),
        (
            lambda t: t.replace('device = "/dev/input/kaspar-seat2"', 'name = "x"\ndevice = "/y"'),
            "keyfob.children[1]: set device or name (exactly one) for each seat",
        ),
        (
            lambda t: t.replace("child = 2", "child = 7"),
            "keyfob.children[1].child: expected a child's place, 1 to 6, found 7",
        ),
        (
            lambda t: t.replace('answer_out_of_turn = "ignore"', 'answer_out_of_turn = "maybe"'),
            "game.answer_out_of_turn: expected one of 'ignore', 'take', found 'maybe'",
        ),
    ],
)
def test_the_seats_are_held_to_the_groups_they_serve(
    tmp_path: Path, edit: Callable[[str], str], expected: str
) -> None:
    path = seated(tmp_path)
    path.write_text(edit(path.read_text()))
    with pytest.raises(ConfigError) as caught:
        load_config(str(path))
    assert str(caught.value) == f"{path}: {expected}"


async def test_each_seat_s_events_come_tagged_with_its_seat() -> None:
    clock = LoopClock()
    first, second = SimKeyfob(clock), SimKeyfob(clock)
    seats = Seats([first, second], ["/dev/input/a", "/dev/input/b"])
    await seats.start()
    try:
        await second.perform("green")
        event = await seats.next_event()
        assert isinstance(event, Gesture) and (event.button, event.seat) == ("green", 1)
        await first.perform("lost")
        lost = await seats.next_event()
        assert isinstance(lost, KeyfobLost) and lost.seat == 0
        # One seat away: the seats are still read; the last away, they are not.
        assert seats.connected and not seats.seat_connected(0)
        await second.perform("lost")
        assert (await seats.next_event()).seat == 1
        assert not seats.connected
    finally:
        await seats.close()


def test_the_simulated_hardware_has_a_keyfob_per_seat(tmp_path: Path) -> None:
    config = load_config(str(seated(tmp_path)))
    hardware = build(
        config.servos, config.keyfob, config.voice, LoopClock(), sim=True, sim_keys=io.StringIO()
    )
    assert isinstance(hardware.keyfob, Seats)
    assert hardware.keyfob.devices == ("/dev/input/kaspar-seat1", "/dev/input/kaspar-seat2")
    assert len(hardware.keyfob.keyfobs) == 2
