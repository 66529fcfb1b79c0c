"""Nothing mistaken: no researcher's command is taken as the children's answer, and no
child's press as a command, from every place the researcher's commands come from.

The one-keyfob case is the hard one: a researcher's pause held during an open question is
the same keys as a child's long hold. Neither is an answer (kasparctl.game.routing.HeldPress):
the question stays open, and a quick press answers it.
"""

from __future__ import annotations

import asyncio
import tempfile
from pathlib import Path
from typing import Any

import msgspec
from hypothesis import given, settings
from hypothesis import strategies as st
from rig_events import answer_the_check, on_event
from test_game import config_for, play, records_of, trials_of
from test_interaction import with_researcher

from kasparctl.config import Config
from kasparctl.sim.demo import DemoRig
from kasparctl.sim.teacher import Messiness


def test_on_one_keyfob_a_pause_held_during_an_open_question_is_not_the_answer(
    tmp_path: Path,
) -> None:
    """The report: `press ... gesture 'long red', extra` then `trial 2 ... feedback red`
    after a green: the researcher's pause had become the children's red."""
    config = with_researcher(config_for("pilot"), source="keyfob")
    seen: dict[str, Any] = {}

    async def scenario(rig: DemoRig) -> None:
        assert rig.children is not None
        rig.game.listeners.remove(rig.children)  # the test is the children and the researcher
        answer_the_check(rig)
        await rig.command("next")
        question = await on_event(rig, "question", lambda info: info["trial"] == 1)
        right = question["choice"] == rig.children.answers[question["target"]]
        meant = "green" if right else "red"
        # The researcher holds red (their pause) while the question is open...
        seen["hold"] = await rig.keyfob.perform("hold red 3.3")
        # ...and then a child answers with a quick press.
        seen["answer"] = await rig.keyfob.perform(meant)
        seen["meant"] = meant
        # Nobody answers the next: once Kaspar asks for a grown-up, a hold is theirs.
        await on_event(rig, "prompt", lambda info: info["line"] == "prompt.ask_researcher")
        await rig.command("stop")

    result, _, _ = play(tmp_path, config=config, scenario=scenario)
    records = records_of(result)
    trials = trials_of(records)
    assert trials[0]["feedback_at"] == seen["answer"]
    assert trials[0]["feedback"] == seen["meant"]
    assert all(t["feedback_at"] != seen["hold"] for t in trials)
    held = [r for r in records if r["kind"] == "press" and r["at"] == seen["hold"]]
    assert [(r["button"], r["gesture"], r.get("extra")) for r in held] == [
        ("red", "long red", None)
    ]
    assert held[0]["ignored"] == "held as long as a researcher's command: not an answer"
    # Not a command either: begun while the children were asked.
    assert [r["command"] for r in records if r["kind"] == "command"] == ["next", "stop"]


# -- every source, any moment -------------------------------------------------------------

KEYPAD = {"KEY_F1": "next", "KEY_F2": "pause", "KEY_F3": "undo", "KEY_F4": "stop"}


def config_from(source: str) -> Config:
    config = with_researcher(config_for("pilot"), source=source)
    if source == "keypad":
        keyfob = msgspec.structs.replace(config.keyfob, commands=KEYPAD)
        config = msgspec.structs.replace(config, keyfob=keyfob)
    return config


CONFIGS = {source: config_from(source) for source in ("device", "keypad", "keyfob")}


@settings(max_examples=40, deadline=None, derandomize=True)
@given(
    source=st.sampled_from(sorted(CONFIGS)),
    seed=st.integers(0, 10_000),
    command=st.sampled_from(["pause", "undo", "stop"]),
    trial=st.integers(1, 4),
    # From the question's start: during Kaspar's words, its last words, the listening,
    # a child's press, the feedback, the next question.
    after=st.floats(0.0, 14.0),
    messy=st.booleans(),
)
def test_no_command_is_an_answer_and_no_press_a_command_at_any_moment(
    source: str, seed: int, command: str, trial: int, after: float, messy: bool
) -> None:
    messiness = Messiness(p_hold=0.3, p_double=0.2, p_both=0.2, p_early=0.3) if messy else None
    given: list[str] = []

    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "asking", lambda info: info.get("trial") == trial)
        await asyncio.sleep(after)
        given.append(rig.game.stage)
        await rig.command(command)
        await asyncio.sleep(4.0)
        while command == "pause" and rig.game.stage == "paused":
            await rig.command("pause")  # the researcher resumes
            await asyncio.sleep(2.0)

    with tempfile.TemporaryDirectory(prefix="kaspar-mistaken-") as scratch:
        result, rig, _ = play(
            Path(scratch), config=CONFIGS[source], seed=seed, scenario=scenario,
            messiness=messiness,
        )  # fmt: skip
        records = records_of(result)
    assert result.commands_taken_as_answers == 0
    assert result.accidental_commands == 0
    assert result.answers_lost == 0
    assert result.final_state in ("finished", "stopped")
    # The check itself sees the researcher's keys: every command they gave is theirs.
    downs = {down for action in rig.researcher_actions for down in action.downs}
    assert given and all(r["at"] in downs for r in records if r["kind"] == "command")
