"""Nothing mistaken: no researcher's command is taken as the children's answer, and no
child's press as a command, from every place the researcher's commands come from.

The one-keyfob case is the hard one: a researcher's pause held during an open question is
the same keys as a child's long hold. Neither is an answer (kasparctl.game.routing.HeldPress):
the question stays open, and a quick press answers it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rig_events import on_event
from test_game import config_for, play, records_of, trials_of
from test_interaction import with_researcher

from kasparctl.sim.demo import DemoRig


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
