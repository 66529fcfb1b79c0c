"""The game drives Kaspar's body: gaze and life, uncertainty shown by the body, reactions as
behaviours, and every behaviour cancelled by a pause, a fault or a stop.

The body is a recording fake (tests/body_fakes.py); the game, the sessions and the servos'
safety layer are the robot's own, in simulated time.
"""

from __future__ import annotations

import asyncio
import io
import math
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any, cast

import msgspec
import pytest
from body_fakes import RecordingBody
from rig_events import on_event
from test_game import config_for, records_of, trials_of

from hal.servos.api import FaultKind, ServoApi
from kasparctl.body.api import Gaze, GazeKind, StillBody
from kasparctl.config import Config, SessionPlan
from kasparctl.game import bodywork
from kasparctl.game.bodywork import PointStyle, normalised_entropy, point, point_style
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, DemoResult, DemoRig, body_note, build


def with_plan(config: Config, **changes: Any) -> Config:
    plan = SessionPlan(group="G1", **changes)
    return msgspec.structs.replace(config, sessions=(plan,))


def play_with_body(
    tmp_path: Path,
    config: Config,
    seed: int = 2,
    scenario: Callable[[DemoRig, RecordingBody], Coroutine[Any, Any, None]] | None = None,
    body: RecordingBody | None = None,
) -> tuple[DemoResult, RecordingBody, list[tuple[str, dict[str, Any]]], str]:
    """One game with a recording body; the game's events in order; the transcript."""
    out = io.StringIO()
    body = body or RecordingBody()
    events: list[tuple[str, dict[str, Any]]] = []

    async def main() -> DemoResult:
        rig = build(config, DemoOptions(state_dir=tmp_path, seed=seed, out=out), body=body)
        rig.game.listeners.append(lambda event, info: events.append((str(event), dict(info))))
        side = asyncio.create_task(scenario(rig, body)) if scenario else None
        result = await asyncio.wait_for(rig.run(), timeout=20_000)
        if side is not None:
            side.cancel()
            await asyncio.gather(side, return_exceptions=True)
        return result

    result = simtime.run(main(), virtual=True)
    return result, body, events, out.getvalue()


# -- the mapping from uncertainty to the body ----------------------------------------


def test_normalised_entropy_is_entropy_over_its_most() -> None:
    assert normalised_entropy(math.log2(6), 6) == pytest.approx(1.0)
    assert normalised_entropy(1.0, 4) == pytest.approx(0.5)
    assert normalised_entropy(0.0, 6) == 0.0
    assert normalised_entropy(0.3, 1) == 0.0  # one toy left: nothing to doubt
    assert normalised_entropy(5.0, 4) == 1.0  # rounding past the most stays at the most


def test_the_point_is_slow_and_hesitant_when_unsure_quick_with_a_nod_when_sure() -> None:
    assert point_style(None) == PointStyle(1.0)  # the body shows nothing: as always
    sure, middling, unsure = point_style(0.1), point_style(0.4), point_style(1.0)
    assert sure.duration_s < middling.duration_s < unsure.duration_s
    assert sure.nod and sure.pause_at is None
    assert not middling.nod and middling.pause_at is None
    assert unsure.pause_at == bodywork.HESITATE_AT and unsure.pause_s == bodywork.HESITATE_MAX_S
    assert point_style(0.0).duration_s == bodywork.POINT_FAST_S
    assert unsure.duration_s == pytest.approx(bodywork.POINT_SLOW_S)


class RecordingServos:
    def __init__(self, where: dict[str, float]) -> None:
        self.where = dict(where)
        self.moves: list[tuple[dict[str, float], float]] = []

    async def read_positions(self, group: str | None = None) -> dict[str, float]:
        return dict(self.where)

    async def move(self, pose: dict[str, float], duration: float, source: str = "move") -> None:
        self.moves.append((dict(pose), duration))
        self.where.update(pose)


def test_a_hesitant_point_stops_part_of_the_way_then_goes_on() -> None:
    servos = RecordingServos({"shoulder": 0.0, "elbow": 10.0})
    style = point_style(0.8)

    async def main() -> float:
        start = asyncio.get_running_loop().time()
        await point(cast(ServoApi, servos), {"shoulder": -50.0, "elbow": 60.0}, style)
        return asyncio.get_running_loop().time() - start

    took = simtime.run(main(), virtual=True)
    (part, first), (whole, second) = servos.moves
    assert part == pytest.approx({"shoulder": -30.0, "elbow": 40.0})  # 60 % of the way
    assert whole == {"shoulder": -50.0, "elbow": 60.0}
    assert first + second == pytest.approx(style.duration_s)
    assert took == pytest.approx(style.pause_s)  # the fake's moves take no time; the pause does
    direct = RecordingServos({"shoulder": 0.0})
    simtime.run(point(cast(ServoApi, direct), {"shoulder": -50.0}, point_style(0.1)), virtual=True)
    assert direct.moves == [({"shoulder": -50.0}, point_style(0.1).duration_s)]


# -- uncertainty by mode -----------------------------------------------------------


@pytest.mark.parametrize("mode", ["spoken", "body", "both", "none"])
def test_each_mode_says_and_shows_what_it_should(tmp_path: Path, mode: str) -> None:
    config = with_plan(config_for("pilot"), uncertainty=mode)
    result, body, events, out = play_with_body(tmp_path, config)
    assert result.finished
    trials = trials_of(records_of(result))
    thinking = body.performed("thinking")
    if mode in ("body", "both"):
        # Before every guess, as hard as the learner is unsure.
        assert len(thinking) == len(trials)
        for call, trial in zip(thinking, trials, strict=True):
            expected = normalised_entropy(trial["entropy"], len(trial["candidates"]))
            assert call.args[1] == pytest.approx(expected)
            assert call.at <= trial["question_end"]
        # Each point as sure or unsure as the thinking before it.
        points = [info for event, info in events if event == "point"]
        assert [p["style"] for p in points] == [
            point_style(call.args[1]).words for call in thinking
        ]
        # A nod when sure, never before a toy that is not the likeliest (Eq. 2 drew another).
        nods = body.performed("nod")
        likeliest = [
            t["probabilities"][t["choice_index"]] >= max(t["probabilities"]) for t in trials
        ]
        assert len(nods) == sum(
            point_style(call.args[1]).nod and sure_of
            for call, sure_of in zip(thinking, likeliest, strict=True)
        )
        assert "(Kaspar tilts its head, thinking" in out
    else:
        assert thinking == [] and body.performed("nod") == []
        assert {info["style"] for event, info in events if event == "point"} == {""}
    said = {trial["band"] is not None for trial in trials}
    assert said == {mode in ("spoken", "both")}


# -- gaze and life ------------------------------------------------------------------


def test_kaspar_looks_at_the_child_whose_turn_it_is_and_at_the_bag_it_points_at(
    tmp_path: Path,
) -> None:
    result, body, _, out = play_with_body(tmp_path, config_for("names"))
    assert result.finished
    trials = trials_of(records_of(result))
    children = [
        (call.args[0].index, call.at)
        for call in body.named("look_at")
        if call.args[0].kind is GazeKind.CHILD
    ]
    for trial in trials:
        # The child whose turn it is, looked at as Kaspar turns to them, before the guess.
        assert any(
            index == trial["child_index"] and at <= trial["question_end"] for index, at in children
        )
    bags = [call for call in body.named("look_at") if call.args[0].kind is GazeKind.BAG]
    assert [call.args[0].index for call in bags] == [trial["target_index"] for trial in trials]
    # While pointing the head is still: life off from the bag's look to the point's end.
    sequence = [(c.name, c.args) for c in body.calls if c.name in ("look_at", "set_alive")]
    for index, (name, args) in enumerate(sequence):
        if name == "look_at" and args[0].kind is GazeKind.BAG:
            assert sequence[index + 1] == ("set_alive", (False,))
            assert sequence[index + 2] == ("set_alive", (True,))
    assert "(Kaspar looks at child 2)" in out


def test_no_life_while_the_children_teach_and_the_researcher_is_looked_at(tmp_path: Path) -> None:
    result, body, events, _ = play_with_body(tmp_path, config_for("names"))
    states = [(index, info["state"]) for index, (event, info) in enumerate(events) if event == "state"]
    teaching = next(i for i, state in states if state == "teaching")
    revealing = next(i for i, state in states if state == "revealing")
    alive = [
        info["alive"]
        for event, info in events[teaching:revealing]
        if event == "body" and info["kind"] == "alive"
    ]
    assert alive == [False, True]  # off for the whole step (the arm is limp), back after
    # Every bag was asked for while life was off.
    life = True
    for event, info in events[teaching:revealing]:
        if event == "body" and info["kind"] == "alive":
            life = info["alive"]
        if event == "teach":
            assert life is False
    researcher = [c for c in body.named("look_at") if c.args[0] == Gaze(GazeKind.RESEARCHER)]
    commands = [r for r in records_of(result) if r["kind"] == "command" and r["applied"]]
    assert len(researcher) == len(commands) >= 3  # start, and "next" twice at least
    # The session's end: life off.
    assert body.named("set_alive")[-1].args == (False,)


def test_gaze_and_life_switched_off_for_a_session(tmp_path: Path) -> None:
    config = with_plan(config_for("names"), alive=False, uncertainty="body")
    result, body, events, _ = play_with_body(tmp_path, config)
    assert result.finished
    # From the session's start (before it, in idle, the game does not know its plan).
    opened = next(i for i, (event, _) in enumerate(events) if event == "session")
    during = [info for event, info in events[opened:] if event == "body"]
    assert [info for info in during if info["kind"] == "look"] == []
    assert {info["alive"] for info in during if info["kind"] == "alive"} <= {False}
    assert body.alive is False
    # Behaviours are not gaze and life: thinking still shows the uncertainty.
    assert len(body.performed("thinking")) == result.trials


# -- reactions, greeting, farewell -----------------------------------------------------


EXPECTED_FACES = {
    # The paper's Kaspar smiles on learning a name, and shows nothing after a red.
    "paper": lambda t: ["happy"] if t["learned"] else [],
    # What Kaspar did before: a smile after every green, a sad face after every red.
    "all": lambda t: ["happy" if t["feedback"] == "green" else "sad"],
    "none": lambda t: [],
}


@pytest.mark.parametrize("reactions", ["paper", "all", "none"])
def test_reactions_follow_the_setting(tmp_path: Path, reactions: str) -> None:
    result, body, _, out = play_with_body(tmp_path, config_for("names", reactions=reactions))
    assert result.finished
    trials = trials_of(records_of(result))
    faces = [c.args[0] for c in body.performed() if c.args[0] in ("happy", "sad")]
    assert faces == [face for t in trials for face in EXPECTED_FACES[reactions](t)]
    assert ("(Kaspar smiles)" in out) == (reactions != "none")


def test_reactions_greeting_and_farewell_are_behaviours_and_replace_the_poses(
    tmp_path: Path,
) -> None:
    result, body, _, out = play_with_body(tmp_path, config_for("names", reactions="all"))
    trials = trials_of(records_of(result))
    reactions = [c.args[0] for c in body.performed() if c.args[0] in ("happy", "sad")]
    assert reactions == ["happy" if t["feedback"] == "green" else "sad" for t in trials]
    names = [c.args[0] for c in body.performed()]
    assert names[0] == "greeting" and names[-1] == "farewell"
    assert all(c.ended == "done" for c in body.performed())
    assert "(Kaspar smiles)" in out and "(Kaspar waves goodbye)" in out
    assert body.named("start") and body.named("close")


def test_without_a_body_the_happy_and_sad_poses_are_the_face(tmp_path: Path) -> None:
    moved: list[dict[str, float]] = []

    async def watch(rig: DemoRig, body: RecordingBody) -> None:
        original = rig.servos.move

        async def move(pose: dict[str, float], duration: float, **how: Any) -> None:
            moved.append(dict(pose))
            await original(pose, duration, **how)

        rig.servos.move = move  # type: ignore[method-assign]

    # With a body, the poses are not played: the behaviours are the face.
    play_with_body(tmp_path / "body", config_for("names"), scenario=watch)
    happy = dict(config_for("names").game.happy_pose)
    assert happy not in moved
    # With a StillBody (no body configured), today's poses.
    still_moves: list[dict[str, float]] = []

    async def main() -> None:
        options = DemoOptions(state_dir=tmp_path / "still", seed=2, out=io.StringIO())
        rig = build(config_for("names"), options, body=StillBody())
        original = rig.servos.move

        async def move(pose: dict[str, float], duration: float, **how: Any) -> None:
            still_moves.append(dict(pose))
            await original(pose, duration, **how)

        rig.servos.move = move  # type: ignore[method-assign]
        await rig.run()

    simtime.run(main(), virtual=True)
    assert happy in still_moves


# -- cancelled at once ---------------------------------------------------------------


async def test_after_a_cancel_the_next_set_alive_reaches_the_body_again() -> None:
    body = RecordingBody()
    told: list[dict[str, Any]] = []
    work = bodywork.BodyWork(body, lambda: None, told.append)
    work.set_alive(True)
    work.set_alive(True)  # asked twice: the body hears it once
    work.cancel()  # a researcher's command: the body is still until asked again
    work.set_alive(True)
    assert [call.args for call in body.named("set_alive")] == [(True,), (True,)]
    assert [info["alive"] for info in told if info["kind"] == "alive"] == [True]  # no news


def test_a_pause_cancels_the_thinking_at_once(tmp_path: Path) -> None:
    async def pause_while_thinking(rig: DemoRig, body: RecordingBody) -> None:
        await on_event(rig, "body", lambda i: i.get("behaviour") == "thinking")
        await asyncio.sleep(0.1)
        await rig.command("pause")
        await asyncio.sleep(20)
        await rig.command("pause")  # resume

    config = with_plan(config_for("pilot"), uncertainty="body")
    result, body, _, _ = play_with_body(tmp_path, config, scenario=pause_while_thinking)
    assert result.finished
    first = body.performed("thinking")[0]
    assert first.ended in ("cancelled", "task cancelled")
    cancels = [c.at for c in body.named("cancel")]
    assert any(first.at < at < first.at + 2.0 for at in cancels)


def test_a_fault_and_a_stop_cancel_every_behaviour(tmp_path: Path) -> None:
    seen: dict[str, int] = {}

    async def fault_then_stop(rig: DemoRig, body: RecordingBody) -> None:
        await on_event(rig, "body", lambda i: i.get("behaviour") == "thinking")
        # Thinking lasts long here: the fault (seen at the next health poll) lands in it.
        rig.servos.inject_fault("right_shoulder_pitch", FaultKind.OVERHEATING)
        await on_event(rig, "state", lambda i: i["state"] == "fault")
        seen["at_fault"] = len(body.named("cancel"))
        await asyncio.sleep(5)
        await rig.command("stop")
        await on_event(rig, "state", lambda i: i["state"] == "stopped")
        seen["at_stop"] = len(body.named("cancel"))

    config = with_plan(config_for("pilot"), uncertainty="both")
    body = RecordingBody(durations={"thinking": 60.0})
    result, body, _, _ = play_with_body(tmp_path, config, scenario=fault_then_stop, body=body)
    assert result.final_state == "stopped"
    assert body.performed("thinking")[0].ended in ("cancelled", "task cancelled")
    assert seen["at_fault"] >= 1 and seen["at_stop"] > seen["at_fault"]
    assert body.named("set_alive")[-1].args == (False,)


# -- the transcript ----------------------------------------------------------------------


def test_the_transcript_names_what_the_body_was_asked() -> None:
    assert body_note({"kind": "perform", "behaviour": "thinking", "strength": 0.9}) == (
        "Kaspar tilts its head, thinking hard"
    )
    assert body_note({"kind": "perform", "behaviour": "nod", "strength": 1.0}) == "Kaspar nods"
    assert body_note({"kind": "look", "gaze": "child", "index": 1, "name": "child 2"}) == (
        "Kaspar looks at child 2"
    )
    assert body_note({"kind": "look", "gaze": "bag", "index": 1, "name": "bag 2"}) is None
    assert body_note({"kind": "alive", "alive": False}) is None
