"""Knowing the buttons work: at the start of every session Kaspar asks for a green and a
red (kasparctl.game.buttons), recorded, never a trial or an answer, skipped by the
researcher's "next"; a keyfob silent through a whole prompt cycle while the researcher's
device works is reported as a flat battery, suspected (recorded, STATUS=, said once).
"""

from __future__ import annotations

import asyncio
import tempfile
from pathlib import Path
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st
from rig_events import on_event
from test_game import config_for, play, records_of, trials_of
from test_interaction import first, said, with_researcher

from kasparctl.game.faults import FaultSource
from kasparctl.game.records import HalEvent, PromptRecord
from kasparctl.research.catalogue import load_session
from kasparctl.research.tidy import event_rows, toy_columns, trial_rows
from kasparctl.research.walk import walk
from kasparctl.service.status import status_line
from kasparctl.sim.demo import DemoRig


def test_every_session_starts_with_a_green_and_a_red_recorded_and_never_a_trial(
    tmp_path: Path,
) -> None:
    result, rig, out = play(tmp_path)
    records = records_of(result)
    checks = [r for r in records if r["kind"] == "button_check"]
    assert [(r["asked"], r["pressed"]) for r in checks] == [("green", "green"), ("red", "red")]
    assert rig.children is not None
    pressed = [p for p in rig.children.presses if p.check]
    assert [(p.button, p.downs[0]) for p in pressed] == [(r["pressed"], r["at"]) for r in checks]
    # Said after the greeting, before the first step's own words; thanked once.
    lines = said(out)
    start = lines.index(first("buttons.start"))
    assert lines[start - 1] == first("session.greeting")
    assert lines[start + 1 : start + 5] == [
        first("buttons.green"),
        first("buttons.red"),
        first("buttons.thanks"),
        first("steps.place_bags").format(bags="6"),
    ]
    # No trial, no answer: every trial's answer is a press for a question, the trials
    # CSV has a row per trial only, and the events CSV names what was asked.
    trials = trials_of(records)
    check_times = {r["at"] for r in checks}
    assert not check_times & {t["feedback_at"] for t in trials}
    session = load_session(Path(result.state_dir, "sessions", result.session))
    rows = list(trial_rows(session, toy_columns([session])))
    assert [row["trial"] for row in rows] == [t["trial"] for t in trials]
    events = [row for row in event_rows(session) if row["kind"] == "button_check"]
    assert [row["name"] for row in events] == ["green", "red"]
    assert all(row["participant"] is None for row in events)
    assert result.answers_lost == 0 and result.finished


def test_the_researchers_next_skips_the_check_and_not_the_step(tmp_path: Path) -> None:
    seen: dict[str, Any] = {}

    async def scenario(rig: DemoRig) -> None:
        assert rig.children is not None
        rig.game.listeners.remove(rig.children)  # nobody presses: the researcher skips
        await rig.command("next")
        await on_event(rig, "button_check", lambda info: info["button"] == "green")
        await rig.command("next")
        waiting = await on_event(rig, "waiting_for_researcher")
        seen["stage"], seen["step"] = rig.game.stage, waiting["step"]
        await rig.command("stop")

    result, _, out = play(tmp_path, scenario=scenario)
    records = records_of(result)
    checks = [r for r in records if r["kind"] == "button_check"]
    assert checks == [{**checks[0], "asked": "green", "skipped": True}]
    commands = [(r["command"], r.get("confirm"), r["state"]) for r in records if r["kind"] == "command"]
    assert commands[:2] == [("next", "start", "idle"), ("next", "skip_check", "placing")]
    assert seen == {"stage": "placing", "step": "placing"}
    assert first("buttons.red") not in said(out)
    # Skipped before anybody was silent long: no battery suspected.
    assert not any(r["kind"] == "hal" for r in records)


def test_a_keyfob_silent_through_the_prompts_is_a_suspected_battery_said_once(
    tmp_path: Path,
) -> None:
    seen: dict[str, Any] = {}

    async def scenario(rig: DemoRig) -> None:
        assert rig.children is not None
        rig.game.listeners.remove(rig.children)  # the keyfob's battery is flat: no key
        await rig.command("next")
        await on_event(rig, "prompt", lambda info: info["line"] == "prompt.ask_researcher")
        await asyncio.sleep(8)
        seen["problems"] = dict(rig.game.problems)
        seen["status"] = status_line(rig.game.stage, rig.game.problems)
        await rig.command("next")  # the researcher skips the check and changes the battery
        await on_event(rig, "waiting_for_researcher")
        await rig.keyfob.perform("green")  # heard again
        await asyncio.sleep(1)
        seen["after"] = dict(rig.game.problems)
        await rig.command("stop")

    result, _, out = play(tmp_path, scenario=scenario)
    records = records_of(result)
    hal = [r for r in records if r["kind"] == "hal"]
    assert [r["event"] for r in hal] == [HalEvent.KEYFOB_SILENT, HalEvent.KEYFOB_HEARD]
    assert "battery" in hal[0]["reason"]
    assert FaultSource.KEYFOB_SILENT in seen["problems"]
    assert "children's keyfob silent (battery?)" in seen["status"]
    assert FaultSource.KEYFOB_SILENT not in seen["after"]
    assert said(out).count(first("fault.keyfob_silent")) == 1
    # It stopped nothing: the step went on when the researcher moved on.
    steps = [r["to"] for r in records if r["kind"] == "step"]
    assert steps[:1] == ["placing"] and "fault" not in steps


def test_children_who_do_not_answer_are_no_battery(tmp_path: Path) -> None:
    """The keyfob sent a key during the prompts (a press too early), or the researcher has
    no device of their own to tell the keyfob apart: nothing is suspected."""

    async def early_then_silent(rig: DemoRig) -> None:
        assert rig.children is not None
        rig.game.listeners.remove(rig.children)
        await rig.command("next")
        await on_event(rig, "asking", lambda info: info.get("button_check") == "green")
        await rig.keyfob.perform("red")  # early: no answer, but the keyfob works
        await on_event(rig, "prompt", lambda info: info["line"] == "prompt.ask_researcher")
        await asyncio.sleep(8)
        await rig.command("stop")

    for name, config, scenario in (
        ("early", config_for(), early_then_silent),
        ("keyfob", with_researcher(config_for(), source="keyfob"), _silent_on_one_keyfob),
    ):
        result, _, out = play(tmp_path / name, config=config, scenario=scenario)
        records = records_of(result)
        assert any(r["kind"] == "prompt" and r["line"] == "prompt.ask_researcher" for r in records)
        assert not [r for r in records if r["kind"] == "hal"], name
        assert first("fault.keyfob_silent") not in said(out)


async def _silent_on_one_keyfob(rig: DemoRig) -> None:
    assert rig.children is not None
    rig.game.listeners.remove(rig.children)
    await rig.command("next")  # a hold on the keyfob: it works, but read as the researcher's
    await on_event(rig, "prompt", lambda info: info["line"] == "prompt.ask_researcher")
    await asyncio.sleep(8)
    await rig.command("stop")


def test_in_the_pilot_the_checks_prompt_is_no_childs_turn(tmp_path: Path) -> None:
    """The pilot checks the buttons in step 4, before its first question: a prompt of the
    check is to the whole group, as the events CSV says (no participant)."""

    async def scenario(rig: DemoRig) -> None:
        assert rig.children is not None
        rig.game.listeners.remove(rig.children)
        await rig.command("next")
        await on_event(rig, "prompt", lambda info: info["line"] == "buttons.green")
        await rig.keyfob.perform("green")
        await on_event(rig, "button_check", lambda info: info["button"] == "red")
        await rig.keyfob.perform("red")
        await on_event(rig, "question", lambda info: info["trial"] == 1)
        await rig.command("stop")

    result, _, _ = play(tmp_path, config=config_for("pilot"), scenario=scenario)
    session = load_session(Path(result.state_dir, "sessions", result.session))
    rows = [row for row in event_rows(session) if row["kind"] in ("prompt", "button_check")]
    assert [(row["kind"], row["name"]) for row in rows] == [
        ("prompt", "buttons.green"),
        ("button_check", "green"),
        ("button_check", "red"),
    ]
    # As the research walks it: nobody's turn (the first question is child 1's).
    prompts = [w for w in walk(session) if isinstance(w.record, PromptRecord)]
    assert [(w.record.line, w.child_index) for w in prompts] == [("buttons.green", None)]


@settings(max_examples=15, deadline=None, derandomize=True)
@given(after=st.floats(0.0, 18.0), seed=st.integers(0, 1000))
def test_a_next_at_any_moment_skips_the_check_while_it_runs_and_the_step_otherwise(
    after: float, seed: int
) -> None:
    seen: dict[str, Any] = {}

    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "session")
        await asyncio.sleep(after)
        seen["checking"] = rig.game.buttons.running
        await rig.command("next")
        await asyncio.sleep(8.0)  # past the greeting, if it was skipped during it
        await rig.command("stop")

    with tempfile.TemporaryDirectory(prefix="kaspar-check-") as scratch:
        result, _, out = play(Path(scratch), seed=seed, scenario=scenario)
        records = records_of(result)
    checks = [r for r in records if r["kind"] == "button_check"]
    confirms = [r.get("confirm") for r in records if r["kind"] == "command"]
    pressed = [(r["asked"], r.get("pressed")) for r in checks if not r.get("skipped")]
    assert pressed == [("green", "green"), ("red", "red")][: len(pressed)]
    if seen["checking"]:
        # The rest of the check skipped (recorded, unless every button was pressed as
        # the skip came), and step 1 played on: Kaspar asked for the bags.
        assert confirms.count("skip_check") == 1
        assert len(pressed) == 2 or checks[-1].get("skipped") is True
        assert first("steps.place_bags").format(bags="6") in said(out)
    else:
        # Before the check began (the greeting) "next" moved on from step 1, as ever;
        # after it, too. Never a skip of the check.
        assert "skip_check" not in confirms and "next_step" in confirms
        assert len(pressed) in (0, 2) and not any(r.get("skipped") for r in checks)
    assert not {r.get("at") for r in checks} & {
        r["feedback_at"] for r in records if r["kind"] == "trial"
    }
