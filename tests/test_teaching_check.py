"""Step 2 checks the teaching: a green with the arm where it already was is asked again,
in words that blame no one, and never logged as the bag's pose (simulated robot)."""

from __future__ import annotations

import asyncio
import io
from pathlib import Path
from typing import Any

import pytest
from rig_events import on_event
from test_game import config_for, records_of

from kasparctl.config import Config
from kasparctl.game.phrases import load_phrasebook
from kasparctl.sim import simtime
from kasparctl.sim.demo import DemoOptions, DemoResult, DemoRig, build

BOOK = load_phrasebook("en")
NOT_MOVED = "I did not feel my arm move. Please move it to bag {bag}."


def _play(
    tmp_path: Path, config: Config, seed: int = 3, p_unmoved_arm: float = 0.0, scenario=None
) -> tuple[DemoResult, DemoRig, str]:
    out = io.StringIO()
    options = DemoOptions(state_dir=tmp_path, seed=seed, out=out, p_unmoved_arm=p_unmoved_arm)

    async def main() -> tuple[DemoResult, DemoRig]:
        rig = build(config, options)
        side = asyncio.create_task(scenario(rig)) if scenario else None
        result = await asyncio.wait_for(rig.run(), timeout=20_000)
        if side is not None:
            side.cancel()
            await asyncio.gather(side, return_exceptions=True)
        return result, rig

    result, rig = simtime.run(main(), virtual=True)
    return result, rig, out.getvalue()


def _said(out: str) -> list[str]:
    return [line.split("Kaspar: ", 1)[1] for line in out.splitlines() if "Kaspar: " in line]


def _rest(config: Config, pose: dict[str, float]) -> dict[str, float]:
    rest = {joint.name: joint.rest_deg for joint in config.servos.joints}
    return {joint: rest[joint] for joint in pose}


def _near(a: dict[str, float], b: dict[str, float], limit: float) -> bool:
    return all(abs(a[joint] - b[joint]) <= limit for joint in a)


def test_children_who_press_before_moving_the_arm_are_asked_again_and_never_logged(
    tmp_path: Path,
) -> None:
    # Never taken unmoved (a bag is only taken at the arm's old place after unmoved_arm_asks).
    config = config_for(children_per_group=2, unmoved_arm_asks=10)
    result, _, out = _play(tmp_path, config, p_unmoved_arm=0.4)
    assert result.finished
    records = records_of(result)
    refused = [r for r in records if r["kind"] == "press" and "unmoved" in r]
    assert refused, "the children never pressed too soon: pick another seed"
    # The demo counts them, and every press was taken as the children meant it.
    assert result.unmoved_arm_refused == len(refused)
    assert result.answers_lost == 0
    # The arm still at the bag shown just before (it stays where the last child left it);
    # at rest, for bag 1 of the first round (the next test presses there).
    assert any(r["unmoved"].startswith("bag ") for r in refused)
    for record in refused:
        if record["unmoved"] != "rest":
            shown = (record["teach_retry"] - 1) % 6 + 1
            assert record["unmoved"] == f"bag {shown}"
    # Every bag was still taught once per child, and none of its poses is where the arm
    # was left (at rest, or at the bag shown just before).
    poses = [r for r in records if r["kind"] == "pose" and not r.get("check_again")]
    assert len(poses) == 6 * 2
    limit = config.game.unmoved_arm_deg
    previous: dict[str, float] | None = None
    for pose in poses:
        assert not _near(pose["pose"], _rest(config, pose["pose"]), limit)
        if previous is not None:
            assert not _near(pose["pose"], previous, limit)
        previous = pose["pose"]
    said = _said(out)
    asked = [line for line in said if line.startswith("I did not feel my arm move.")]
    assert asked == [NOT_MOVED.format(bag=r["teach_retry"] + 1) for r in refused]


def test_an_arm_left_at_rest_is_refused_then_taken_after_the_configured_asks(
    tmp_path: Path,
) -> None:
    """A bag may really be where the arm rests: after unmoved_arm_asks refusals the
    children's green is taken."""
    config = config_for(children_per_group=1, unmoved_arm_asks=2)
    pressed: list[float] = []

    async def scenario(rig: DemoRig) -> None:
        assert rig.children is not None
        # Kaspar starts asking for bag 1: from here the test is the child, until it is taken.
        await on_event(rig, "asking", lambda info: info.get("bag") == 0)
        rig.game.listeners.remove(rig.children)
        for _ in range(3):
            # Asked (again) for bag 1; the arm left where it rests.
            await on_event(rig, "teach", lambda info: info["bag"] == 0)
            await asyncio.sleep(0.5)
            pressed.append(await rig.keyfob.perform("green"))
        rig.game.listeners.append(rig.children)  # the children teach the other bags

    result, _, out = _play(tmp_path, config, scenario=scenario)
    records = records_of(result)
    refused = [r for r in records if r["kind"] == "press" and "unmoved" in r]
    assert [(r["unmoved"], r["teach_retry"], r["at"]) for r in refused] == [
        ("rest", 0, pressed[0]),
        ("rest", 0, pressed[1]),
    ]
    first_pose = next(r for r in records if r["kind"] == "pose")
    assert first_pose["bag"] == 0 and first_pose["at"] == pressed[2]
    # At rest, to the servos' resolution.
    assert _near(first_pose["pose"], _rest(config, first_pose["pose"]), 0.5)
    assert _said(out).count(NOT_MOVED.format(bag=1)) == 2


def test_unmoved_arm_deg_zero_never_asks(tmp_path: Path) -> None:
    config = config_for(children_per_group=1, unmoved_arm_deg=0.0)
    result, _, out = _play(tmp_path, config, p_unmoved_arm=0.5)
    records = records_of(result)
    assert not [r for r in records if r["kind"] == "press" and "unmoved" in r]
    assert not any(line.startswith("I did not feel my arm move") for line in _said(out))


def test_the_rule_s_keys_are_read_and_checked(tmp_path: Path) -> None:
    from kasparctl.config import ConfigError
    from kasparctl.config.loading import parse_config

    config = parse_config("[game]\nunmoved_arm_deg = 2.5\nunmoved_arm_asks = 1\n", "k.toml")
    assert (config.game.unmoved_arm_deg, config.game.unmoved_arm_asks) == (2.5, 1)
    try:
        parse_config("[game]\nunmoved_arm_deg = -1\n", "k.toml")
    except ConfigError as error:
        assert "game.unmoved_arm_deg" in str(error) and "-1" in str(error)
    else:
        raise AssertionError("a negative distance was accepted")


def test_the_round_comparison_line_blames_neither_showing(tmp_path: Path) -> None:
    config = config_for(children_per_group=3)
    far = {"right_shoulder_pitch": 50.0, "right_shoulder_roll": 70.0, "right_elbow": 80.0}

    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "teach", lambda info: info["bag"] == 0 and info["round"] == 1)
        await asyncio.sleep(0.2)
        for joint, degrees in far.items():
            rig.servos.push(joint, degrees)
        await rig.keyfob.perform("green")

    _, _, out = _play(tmp_path, config, seed=7, scenario=scenario)
    said = _said(out)
    assert "I have two places for bag 1. Please show me once more." in said
    # No line of step 2 says that where a child showed a bag was wrong.
    for key in ("teach.check_again", "teach.not_moved"):
        for line in BOOK.variants(key):
            assert "before" not in line and "wrong" not in line


def test_demo_p_unmoved_arm_is_checked(capsys: Any) -> None:
    from kasparctl.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--fast", "--p-unmoved-arm", "1.5"])
    assert exit_.value.code == 2
    assert "--p-unmoved-arm" in capsys.readouterr().err
