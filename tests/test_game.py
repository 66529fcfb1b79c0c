"""The five-step game end to end, on the simulated robot, in simulated time."""

from __future__ import annotations

import asyncio
import io
import itertools
import json
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import msgspec
import pytest
from rig_events import answer_the_check, on_event

from hal.servos.api import FaultKind
from kasparctl.config import Config
from kasparctl.game.session import RECORDS_FILE
from kasparctl.game.stages import STATES, TRANSITIONS
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, DemoResult, DemoRig, build, demo_config, with_variant
from kasparctl.sim.teacher import Messiness, Teacher


def config_for(variant: str = "names", **game_changes: Any) -> Config:
    config = with_variant(demo_config(), variant)
    if not game_changes:
        return config
    return msgspec.structs.replace(config, game=msgspec.structs.replace(config.game, **game_changes))


def records_of(result: DemoResult | Path) -> list[dict[str, Any]]:
    state_dir = Path(result.state_dir) if isinstance(result, DemoResult) else result
    (session_dir,) = (state_dir / "sessions").iterdir()
    return [json.loads(line) for line in (session_dir / RECORDS_FILE).read_text().splitlines()]


def trials_of(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in records if r["kind"] == "trial"]


def play(
    tmp_path: Path,
    config: Config | None = None,
    seed: int = 1,
    teacher: Teacher | None = None,
    scenario: Callable[[DemoRig], Coroutine[Any, Any, None]] | None = None,
    children_answers: list[int] | None = None,
    messiness: Messiness | None = None,
) -> tuple[DemoResult, DemoRig, str]:
    """One game in simulated time; `scenario` runs beside it, acting on the rig."""
    out = io.StringIO()
    options = DemoOptions(
        state_dir=tmp_path,
        seed=seed,
        teacher=teacher or Teacher(),
        messiness=messiness or Messiness(),
        out=out,
    )

    async def main() -> tuple[DemoResult, DemoRig]:
        rig = build(config or config_for(), options, children_answers)
        side = asyncio.create_task(scenario(rig)) if scenario else None
        result = await asyncio.wait_for(rig.run(), timeout=20_000)
        if side is not None:
            side.cancel()
            await asyncio.gather(side, return_exceptions=True)
        return result, rig

    result, rig = simtime.run(main(), virtual=True)
    return result, rig, out.getvalue()


def assert_trials_whole(records: list[dict[str, Any]]) -> None:
    trials = trials_of(records)
    assert [t["trial"] for t in trials] == list(range(1, len(trials) + 1))
    assert [r["seq"] for r in records] == list(range(1, len(records) + 1))


# -- complete games ----------------------------------------------------------------


def test_names_game_runs_all_five_steps(tmp_path: Path) -> None:
    result, rig, out = play(tmp_path)
    assert result.finished and result.learned == 6
    records = records_of(result)
    assert [r["to"] for r in records if r["kind"] == "step"] == [
        "placing",
        "teaching",
        "revealing",
        "guessing",
        "farewell",
        "finished",
    ]
    poses = [r for r in records if r["kind"] == "pose"]
    assert len(poses) == 6 * 3  # every bag, once per child of the group
    assert [p["round"] for p in poses] == [0] * 6 + [1] * 6 + [2] * 6
    assert set(poses[0]["pose"]) == {"right_shoulder_pitch", "right_shoulder_roll", "right_elbow"}
    # Every child moves the arm once and presses once, named by Kaspar.
    jobs = [(p["mover"], p["presser"]) for p in poses[::6]]
    assert jobs == [("child 1", "child 2"), ("child 2", "child 3"), ("child 3", "child 1")]
    assert all(p["rule"] == "median" for p in poses)
    assert_trials_whole(records)
    trials = trials_of(records)
    assert len(trials) == result.trials
    # Kaspar focuses on one bag until it is learned, in order.
    targets = [t["target_index"] for t in trials]
    assert targets == sorted(targets)
    # A learned name is no longer offered for the later bags.
    learned = [t["choice"] for t in trials if t["learned"]]
    assert len(set(learned)) == 6
    for trial in trials:
        offered = set(trial["candidates"])
        assert not offered & set(learned[: trial["target_index"]])
        assert sum(trial["probabilities"]) == pytest.approx(1.0)
    # Kaspar points with the median of the rounds' poses.
    assert "Kaspar points at bag 1" in out
    assert rig.game.session_state is not None
    shown = [p["pose"] for p in poses if p["bag"] == 0]
    assert rig.game.session_state.poses["bag 1"] == {
        joint: sorted(pose[joint] for pose in shown)[1] for joint in shown[0]
    }


def test_trial_records_carry_everything_the_researchers_need(tmp_path: Path) -> None:
    result, _, _ = play(tmp_path, seed=4)
    trial = trials_of(records_of(result))[0]
    for key in (
        "trial",
        "problem_trial",
        "target",
        "child",
        "candidates",
        "probabilities",
        "entropy",
        "band",
        "spoken",
        "choice",
        "feedback",
        "feedback_at",
        "question_end",
        "reaction_time",
        "reward",
        "q_before",
        "q_after",
        "perseverative",
        "win_shift",
        "correct",
        "feedback_right",
    ):
        assert key in trial, key
    assert trial["entropy"] == pytest.approx(2.584962500721156)
    assert trial["band"] == "no_idea"
    assert trial["child"] == "child 1"
    assert trial["reaction_time"] > 0
    assert trial["feedback_right"] is True  # honest children
    assert trial["q_after"][trial["choice_index"]] == pytest.approx(0.6 * trial["reward"])


def test_pilot_game_skips_steps_one_to_three(tmp_path: Path) -> None:
    result, _, out = play(tmp_path, config=config_for("pilot"))
    assert result.finished and result.learned == 3
    records = records_of(result)
    assert [r["to"] for r in records if r["kind"] == "step"] == ["guessing", "farewell", "finished"]
    assert not [r for r in records if r["kind"] == "pose"]
    trials = trials_of(records)
    # In the pilot every location is its own problem over all six toys.
    firsts = [t for t in trials if t["problem_trial"] == 1]
    assert len(firsts) == 3 and all(len(t["candidates"]) == 6 for t in firsts)
    assert "Kaspar points at box" in out


def test_same_seed_same_game(tmp_path: Path) -> None:
    first, _, out1 = play(tmp_path / "a", seed=9)
    second, _, out2 = play(tmp_path / "b", seed=9)
    strip = lambda records: [  # noqa: E731
        {k: v for k, v in r.items() if k not in ("time",)}
        for r in records
        if r["kind"] != "session"
    ]
    assert strip(records_of(first)) == strip(records_of(second))
    # Session ids carry the wall-clock start time; everything else is the same.
    assert out1.replace(first.session, "ID") == out2.replace(second.session, "ID")


# -- children's presses ---------------------------------------------------------------


def test_presses_during_speech_are_recorded_and_ignored(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "point", lambda info: info["target"] == "bag 2")
        await asyncio.sleep(0.5)  # Kaspar is still saying how sure it is
        await rig.keyfob.perform("green")

    result, _, _ = play(tmp_path, scenario=scenario)
    records = records_of(result)
    early = [r for r in records if r["kind"] == "press" and r.get("ignored")]
    assert early and early[0]["ignored"] == "before the question was finished"
    trials = trials_of(records)
    assert all(t["feedback_at"] >= t["question_end"] for t in trials)
    assert result.finished


def test_nobody_answers_then_prompts(tmp_path: Path) -> None:
    result, _, _ = play(tmp_path, config=config_for("pilot"), teacher=Teacher(p_no_answer=1.0))
    records = records_of(result)
    prompts = [r for r in records if r["kind"] == "prompt"]
    # Each question waits for a prompt before the silent child answers.
    assert len(prompts) == result.trials
    assert {p["line"] for p in prompts} == {"instructions.buttons"}
    assert result.finished


def test_prompts_go_on_to_the_researcher(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        assert rig.children is not None
        rig.game.listeners.remove(rig.children)  # the children do not answer
        answer_the_check(rig)
        prompted = on_event(rig, "prompt", lambda info: info["line"] == "prompt.ask_researcher")
        await rig.command("next")
        await prompted
        await asyncio.sleep(60)
        await rig.command("stop")  # the researcher ends the session

    result, _, _ = play(tmp_path, config=config_for("pilot"), scenario=scenario)
    lines = [r["line"] for r in records_of(result) if r["kind"] == "prompt"]
    assert lines == ["instructions.buttons", "prompt.answer_again", "prompt.ask_researcher"]
    assert result.final_state == "stopped" and result.trials == 0


def test_an_extra_press_right_after_an_answer_is_recorded_as_extra(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "answered", lambda info: info["trial"] == 1)
        await rig.keyfob.perform("green")  # a second child, a moment too late

    result, _, _ = play(tmp_path, config=config_for("pilot"), scenario=scenario)
    extras = [r for r in records_of(result) if r["kind"] == "press" and r.get("extra")]
    assert len(extras) == 1 and extras[0]["trial"] == 1


# -- researcher commands -----------------------------------------------------------


def test_undo_restores_the_learner_row_and_keeps_trial_numbers(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "question", lambda info: info["trial"] == 2)
        await rig.command("undo")

    result, _, _ = play(tmp_path, config=config_for("pilot"), scenario=scenario, seed=3)
    records = records_of(result)
    undos = [r for r in records if r["kind"] == "undo"]
    assert [u["trial"] for u in undos] == [1]
    assert_trials_whole(records)
    trials = trials_of(records)
    # The answer to trial 1 was taken back: trial 2 starts from trial 1's learner row.
    assert trials[1]["q_before"] == trials[0]["q_before"]
    assert trials[1]["problem_trial"] == 1
    command = next(r for r in records if r["kind"] == "command" and r["command"] == "undo")
    assert command["applied"] and command["confirm"] == "undo"
    assert result.finished


def test_pause_mid_question_and_resume_asks_the_same_question(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "point", lambda info: info["target"] == "shelf")
        await asyncio.sleep(1.5)  # pointing done, saying how sure it is
        await rig.command("pause")
        await asyncio.sleep(30)
        await rig.command("pause")

    plain, _, _ = play(tmp_path / "plain", config=config_for("pilot"), seed=5)
    paused, _, out = play(
        tmp_path / "paused", config=config_for("pilot"), seed=5, scenario=scenario
    )
    records = records_of(paused)
    commands = [(r["command"], r["confirm"]) for r in records if r["kind"] == "command"]
    assert ("pause", "pause") in commands and ("pause", "resume") in commands
    # Pausing cut Kaspar off and did not change what it learns or chooses.
    choices = lambda result: [t["choice"] for t in trials_of(records_of(result))]  # noqa: E731
    assert choices(paused) == choices(plain)
    # Kaspar stopped mid-line: the guess it was about to make came only after the resume.
    lines = out.splitlines()
    pointed = next(i for i, line in enumerate(lines) if "points at shelf" in line)
    assert "Kaspar: " in lines[pointed - 1]  # how sure it is, said as it points, cut off
    assert "(the game is paused)" in lines[pointed + 1]
    assert paused.finished


def test_every_command_where_it_applies_and_ignored_elsewhere(tmp_path: Path) -> None:
    ignored_until: list[float] = []

    async def researcher(rig: DemoRig) -> None:
        assert rig.children is not None
        rig.game.listeners.remove(rig.children)
        answer_the_check(rig)

        async def gesture(command: str, then: str | None = None) -> None:
            """One command; with `then`, wait until the game has entered that stage."""
            entered = on_event(rig, "state", lambda info: info["state"] == then)
            await rig.command(command)
            if then is not None:
                await entered

        await on_event(rig, "waiting_for_researcher", lambda info: info["step"] == "idle")
        # idle: only "next" applies (stop closes a stopped session; there is none).
        for command in ("pause", "undo", "stop"):
            await gesture(command)
        ignored_until.append(asyncio.get_running_loop().time())
        await gesture("next", then="placing")
        await gesture("undo")  # placing: no answer to undo
        await gesture("pause", then="paused")
        await gesture("next")  # paused: next does not apply
        await gesture("pause", then="placing")  # resume
        await gesture("next", then="teaching")  # in the greeting: the check not begun
        await gesture("next")  # teaching: next does not apply before the bags are taught
        await gesture("stop", then="stopped")  # stop applies everywhere

    result, _, _ = play(tmp_path, scenario=researcher)
    records = records_of(result)
    # Before the session there is nothing to record in; the first record is its start,
    # after the three gestures that did not apply in idle.
    assert records[0]["kind"] == "session" and records[0]["clock"] >= ignored_until[0]
    commands = [(r["state"], r["command"], r["applied"]) for r in records if r["kind"] == "command"]
    assert commands == [
        ("idle", "next", True),
        ("placing", "undo", False),
        ("placing", "pause", True),
        ("paused", "next", False),
        ("paused", "pause", True),
        ("placing", "next", True),
        ("teaching", "next", False),
        ("teaching", "stop", True),
    ]
    assert {r["source"] for r in records if r["kind"] == "command"} == {"researcher"}
    assert result.final_state == "stopped"


# -- faults ------------------------------------------------------------------------


def test_servo_fault_in_step_four_and_recovery(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "question", lambda info: info["trial"] == 3)
        rig.servos.inject_fault("right_elbow", FaultKind.OVERHEATING)
        await on_event(rig, "fault")
        await asyncio.sleep(1.0)
        rig.servos.inject_fault("right_elbow", None)  # it cooled down before the researcher resumes

    result, _, out = play(tmp_path, scenario=scenario, seed=2)
    records = records_of(result)
    faults = [r for r in records if r["kind"] == "fault"]
    assert faults[0]["fault"] == "servo" and faults[0]["joint"] == "right_elbow"
    # The joint is for the records; the children hear that a grown-up is needed.
    assert "Kaspar: Part of my body is not working. I need a grown-up to help me." in out
    assert "elbow" not in "".join(line for line in out.splitlines() if "Kaspar:" in line)
    resumed = [r for r in records if r["kind"] == "command" and r.get("confirm") == "resume"]
    assert resumed and resumed[0]["state"] == "fault"
    assert_trials_whole(records)
    assert result.finished


def test_a_lost_bus_is_said_once_recorded_per_joint_and_resumed_at_once(tmp_path: Path) -> None:
    # Found by the soak: an unplugged adapter latches every joint on the bus, and the
    # game used to announce each one (half a minute of "my ... is not working") while
    # the researcher's resume waited behind them, and was then applied out of date.
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "question", lambda info: info["trial"] == 2)
        for joint in rig.servos.joints:
            rig.servos.inject_fault(joint, FaultKind.BUS_LOST)
        await on_event(rig, "fault")
        await asyncio.sleep(1.0)
        for joint in rig.servos.joints:
            rig.servos.inject_fault(joint, None)  # the adapter is back

    result, rig, out = play(tmp_path, scenario=scenario, seed=2)
    records = records_of(result)
    lost = [r for r in records if r["kind"] == "fault" and "bus_lost" in r["detail"]]
    assert {r["joint"] for r in lost} == set(rig.servos.joints)
    said = [line for line in out.splitlines() if "Kaspar:" in line and "grown-up" in line]
    assert len(said) == 1, said
    commands = [r for r in records if r["kind"] == "command" and r["command"] == "pause"]
    # One resume, taken in the fault state: no stale press paused the game afterwards.
    assert [(c["confirm"], c["state"]) for c in commands] == [("resume", "fault")]
    assert_trials_whole(records)
    assert result.finished


def test_a_servo_fault_during_farewell_is_resumed_and_the_game_finishes(tmp_path: Path) -> None:
    # Found by the soak: farewell was not a state a fault could stop, so a servo that
    # went silent while Kaspar said goodbye left the game in farewell for good.
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "state", lambda info: info["state"] == "farewell")
        rig.servos.inject_fault("head_yaw", FaultKind.SILENT)
        await on_event(rig, "fault")
        await asyncio.sleep(1.0)
        rig.servos.inject_fault("head_yaw", None)

    result, _, _ = play(tmp_path, config=config_for("pilot"), scenario=scenario)
    records = records_of(result)
    assert any(r["kind"] == "fault" and r["state"] == "farewell" for r in records)
    resumes = [r for r in records if r["kind"] == "command" and r.get("confirm") == "resume"]
    assert resumes and resumes[0]["state"] == "fault"
    assert result.finished and result.final_state == "finished"


def test_a_step_that_swallows_its_cancellation_is_cancelled_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The game waits for a cancelled step to end before it enters the next state; a
    # step that carried on (a library dropping the cancellation) used to hang it there.
    from kasparctl.game.steps import Steps

    deaf: list[bool] = []
    swallowed: list[bool] = []
    teach_one_bag = Steps._teach_one_bag

    async def deaf_once(self: Steps, bag: int, teach_round: int, group: str) -> None:
        if not deaf:
            deaf.append(True)
            try:
                await asyncio.Event().wait()
            except asyncio.CancelledError:
                swallowed.append(True)  # and carries on, as if the cancel never came:
                # a press that only the blocked run loop gives
                await self.ctx.presses.open(asyncio.get_running_loop().time())
        await teach_one_bag(self, bag, teach_round, group)

    monkeypatch.setattr(Steps, "_teach_one_bag", deaf_once)

    async def scenario(rig: DemoRig) -> None:
        while not deaf:
            await asyncio.sleep(0.5)
        paused = on_event(rig, "state", lambda info: info["state"] == "paused")
        await rig.command("pause")  # pause
        await paused
        await asyncio.sleep(2.0)
        await rig.command("pause")  # resume

    result, _, _ = play(tmp_path, scenario=scenario)
    assert swallowed == [True]
    assert result.finished


def test_keyfob_lost_and_back(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "question", lambda info: info["trial"] == 2)
        await rig.keyfob.perform("lost")
        await asyncio.sleep(20)
        await rig.keyfob.perform("back")

    result, _, _ = play(tmp_path, config=config_for("pilot"), scenario=scenario)
    records = records_of(result)
    events = [r["event"] for r in records if r["kind"] == "hal"]
    assert events[:2] == ["keyfob_lost", "keyfob_back"]
    assert any(r["kind"] == "fault" and r["fault"] == "keyfob" for r in records)
    assert_trials_whole(records)
    assert result.finished


# -- the answer key ------------------------------------------------------------------


def test_the_learner_never_sees_the_answer_key(tmp_path: Path) -> None:
    """Same children (they believe the same answers), different answer keys in the plan:
    every choice and learner value is the same; only the research grading differs."""
    believed = [0, 1, 2, 3, 4, 5]
    base = config_for()
    key_a = msgspec.structs.replace(base.sessions[0], answer_key=tuple(base.game.toys))
    key_b = msgspec.structs.replace(base.sessions[0], answer_key=tuple(reversed(base.game.toys)))
    results = []
    for name, plan in (("a", key_a), ("b", key_b)):
        config = msgspec.structs.replace(base, sessions=(plan,))
        result, _, _ = play(tmp_path / name, config=config, seed=6, children_answers=believed)
        results.append(trials_of(records_of(result)))
    learner_view = lambda trials: [  # noqa: E731
        (t["choice"], t["feedback"], t["q_before"], t["q_after"], t["probabilities"])
        for t in trials
    ]
    assert learner_view(results[0]) == learner_view(results[1])
    assert [t["correct"] for t in results[0]] != [t["correct"] for t in results[1]]


# -- the machine ----------------------------------------------------------------------


def test_every_state_is_reachable_in_the_machine_table() -> None:
    destinations = {t["dest"] for t in TRANSITIONS} | {"idle"}
    assert set(STATES) == destinations


def test_a_session_resumed_before_its_first_step_carries_on_in_the_same_directory(
    tmp_path: Path,
) -> None:
    """A crash between opening a session and its first step: the resume must not open another."""
    first, _, _ = play(tmp_path / "whole", config=config_for("pilot"), seed=12)
    plan = records_of(first)[0]["plan"]
    from kasparctl.game.records import SessionEvent, SessionRecord
    from kasparctl.game.session import Session

    crashed = Session.create(tmp_path / "crashed", plan)
    crashed.record(SessionRecord(event=SessionEvent.START, plan=plan), 0.0)
    crashed.close()
    resumed, _, out = play(tmp_path / "crashed", config=config_for("pilot"), seed=12)
    assert resumed.resumed and resumed.finished
    assert len(list((tmp_path / "crashed" / "sessions").iterdir())) == 1
    assert "resumed" in out


def test_stop_works_even_while_a_fault_will_not_clear(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        assert rig.children is not None
        await on_event(rig, "question", lambda info: info["trial"] == 2)
        rig.game.listeners.remove(rig.children)  # the researcher takes over
        answer_the_check(rig)
        rig.servos.inject_fault("head_yaw", FaultKind.SILENT)  # and it never comes back
        await on_event(rig, "fault")
        await asyncio.sleep(3)
        await rig.command("pause")  # resume is refused: still faulty
        await asyncio.sleep(5)
        await rig.command("stop")

    result, _, _ = play(tmp_path, config=config_for("pilot"), scenario=scenario)
    commands = [
        (r["command"], r["applied"], r.get("ignored"))
        for r in records_of(result)
        if r["kind"] == "command"
    ]
    assert ("pause", False, "the hardware is still faulty") in commands
    assert commands[-1] == ("stop", True, None)
    assert result.final_state == "stopped"


def test_while_children_teach_only_the_pointing_arm_is_compliant(tmp_path: Path) -> None:
    seen: list[dict[str, bool]] = []

    async def scenario(rig: DemoRig) -> None:
        for bag in range(3):
            await on_event(rig, "teach", lambda info, bag=bag: info["bag"] == bag)
            seen.append({joint: rig.servos.servo(joint).torque for joint in rig.servos.joints})

    result, rig, _ = play(tmp_path, scenario=scenario)
    arm = set(rig.servos.groups["right_arm"])
    for torque in seen:
        assert {joint for joint, on in torque.items() if not on} == arm
    # After teaching every joint holds again, and nothing was left limp.
    assert all(rig.servos.servo(joint).torque for joint in rig.servos.joints)
    assert result.finished


def test_every_motion_path_of_the_game_stays_in_range_and_under_speed(tmp_path: Path) -> None:
    """The safety audit's end-to-end check (docs/safety-audit.md): pointing at configured
    poses far outside the ranges, taught poses, expressions, a resume after a fault, the
    stop gesture's rest. Every joint, sampled as the simulated robot really moves, stays in
    its range and never moves faster than its limit."""
    wild = {"right_shoulder_pitch": -500.0, "right_shoulder_roll": 500.0, "right_elbow": 1e6}
    config = config_for(
        "pilot",
        poses={"box": wild, "shelf": {"right_elbow": -1e6}, "basket": wild},
        happy_pose={"smile": 400.0, "head_pitch": -400.0},
        sad_pose={"head_pitch": 400.0, "head_yaw": -1e9},
    )
    samples: list[tuple[float, dict[str, float]]] = []

    async def sample(rig: DemoRig) -> None:
        while True:
            now = asyncio.get_running_loop().time()
            samples.append((now, {j: rig.servos.true_position(j) for j in rig.servos.joints}))
            await asyncio.sleep(0.05)

    async def scenario(rig: DemoRig) -> None:
        sampler = asyncio.create_task(sample(rig))
        try:
            await on_event(rig, "question", lambda info: info["trial"] == 3)
            rig.servos.inject_fault("head_yaw", FaultKind.OVERLOAD)
            await on_event(rig, "fault")
            rig.servos.inject_fault("head_yaw", None)
            await on_event(rig, "question", lambda info: info["trial"] == 6)
            await rig.command("stop")  # stop: rest pose at the speed limits
            await asyncio.sleep(30)
        finally:
            sampler.cancel()

    result, rig, _ = play(tmp_path, config=config, scenario=scenario)
    assert result.final_state == "stopped"
    settings = {j.name: j for j in rig.servos.settings.joints}
    moved = set()
    for (before, old), (after, new) in itertools.pairwise(samples):
        for joint, degrees in new.items():
            limits = settings[joint]
            unit = limits.servo.degrees_per_unit
            assert limits.range_deg[0] - unit <= degrees <= limits.range_deg[1] + unit, joint
            speed = abs(degrees - old[joint]) / (after - before)
            assert speed <= limits.max_speed_dps * 1.01 + unit / (after - before), (joint, before)
            if abs(degrees - old[joint]) > unit:
                moved.add(joint)
    # The wild poses really were attempted: the arm and the face moved, to their limits.
    assert {"right_shoulder_pitch", "right_elbow", "smile", "head_pitch"} <= moved
    assert min(s[1]["right_shoulder_pitch"] for s in samples) == pytest.approx(-90.0, abs=1.0)
