"""The paper's five steps as Kaspar plays them: placing, teaching, revealing, guessing,
farewell.

Each runs as a task of its own, started when its stage is entered and cancelled
when it is left (a pause or a fault stops Kaspar mid-sentence; a resume starts the
step again from the saved state, which is why every step carries on from what the
session has reached). A step that ends by itself returns, and the run loop moves
on; steps 1 and 3 wait for the researcher's "next" for ever. A step never fires a
trigger: it is given only a StepContext (kasparctl.game.context).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine, Mapping
from typing import Any

import msgspec
from msgspec import UNSET

from kasparctl.game.battery import Crossing
from kasparctl.game.bodywork import FAREWELL, GREETING
from kasparctl.game.buttons import ASKED, pressed, skipped
from kasparctl.game.context import StepContext
from kasparctl.game.events import GameEvent
from kasparctl.game.guess import Guess
from kasparctl.game.presses import Press
from kasparctl.game.records import HalEvent, HalRecord, PoseRecord, PressRecord, PromptRecord
from kasparctl.game.state import GameState, far_from


class Steps:
    """The steps of one open session; a new one for each step started."""

    def __init__(self, ctx: StepContext) -> None:
        """The steps of the session `ctx` is of."""
        self.ctx = ctx
        # A request to show a bag was asked in this step (the first of a round, or the
        # first after a pause, says who does what).
        self._requests = 0

    async def run(self, step: str) -> None:
        """Play `step` (a name of kasparctl.game.stages.STEPS) until it ends by itself."""
        scripts: dict[str, Callable[[], Coroutine[Any, Any, None]]] = {
            "placing": self.placing,
            "teaching": self.teaching,
            "revealing": self.revealing,
            "guessing": self.guessing,
            "farewell": self.farewell,
        }
        await scripts[step]()

    async def placing(self) -> None:
        """Step 1: the researcher places the bags."""
        # The greeting first: the researcher's start has no words of its own.
        await self._greet()
        await self._check_buttons()
        await self.ctx.speech.say("steps.place_bags", bags=str(len(self.ctx.settings.targets)))
        await self._wait_for_researcher("placing")

    async def revealing(self) -> None:
        """Step 3: the researcher shows what is in the bags."""
        await self.ctx.speech.say("steps.reveal_toys")
        await self._wait_for_researcher("revealing")

    async def teaching(self) -> None:
        """Step 2: the children move Kaspar's arm to each bag, one round per child."""
        ctx = self.ctx
        state, speech, servos = ctx.state, ctx.speech, ctx.servos
        group = ctx.settings.pointing_group
        if state.teach_round == 0 and state.teach_bag == 0:
            await speech.say("steps.teach_pointing")
            await speech.say("instructions.teach")
        ctx.body.set_alive(False)  # no gaze or idle while the children move the arm
        await servos.set_compliant(group, True)
        try:
            while state.teach_round < ctx.group_size:
                await self._teach_one_bag(state.teach_bag, state.teach_round, group)
        finally:
            ctx.body.set_alive(True)
            # Torque back on holding where the arm is, also on pause or fault. If the
            # arm was left outside its safe range this fails, and the step fails
            # into the fault state: the researcher moves the arm back and resumes.
            await asyncio.shield(servos.set_compliant(group, False))
        await speech.say("teach.all_done")

    async def guessing(self) -> None:
        """Step 4: Kaspar guesses until every target is learned or given up."""
        ctx = self.ctx
        state = ctx.state
        if state.trials == 0:
            if ctx.settings.variant == "pilot":
                # The pilot starts here: the greeting first.
                await self._greet()
                await self._check_buttons()
                await ctx.speech.say("steps.pilot")
            else:
                await ctx.speech.say("steps.guessing")
            await ctx.speech.say("instructions.buttons")
        while not state.all_done:
            await self._check_battery()
            await Guess(ctx).play()

    async def _check_battery(self) -> None:
        """Between trials: record a crossing of the battery's warning line; say a fall below it.

        Once per crossing (game.battery): a battery that stays low is not said every trial.
        """
        ctx = self.ctx
        reading = ctx.servos.battery()
        if reading is None or reading.voltage_v is None:
            return
        crossing = ctx.battery.reading(reading.voltage_v, reading.warn_below_v)
        if crossing is None:
            return
        event = HalEvent.BATTERY_LOW if crossing is Crossing.LOW else HalEvent.BATTERY_OK
        ctx.record(HalRecord(event=event, voltage_v=round(reading.voltage_v, 2),
                             warn_below_v=reading.warn_below_v, joint=reading.joint))
        if crossing is Crossing.LOW:
            await ctx.speech.say("fault.battery_low")

    async def farewell(self) -> None:
        """Step 5: Kaspar says what it learned, thanks the children, and rests."""
        ctx = self.ctx
        if all(p.learned is not None for p in ctx.state.progress):
            pilot = ctx.settings.variant == "pilot"
            await ctx.speech.say("react.all_learned_pilot" if pilot else "react.all_learned")
        await asyncio.gather(ctx.speech.say("session.thanks"), ctx.body.perform(FAREWELL))
        await ctx.servos.rest()

    def roles(self, teach_round: int) -> tuple[str, str]:
        """Who moves the arm and who presses in a round of step 2: every child does each
        job once over the rounds (one round per child); a child alone does both."""
        size, name = self.ctx.group_size, self.ctx.child_name
        return name(teach_round % size), name((teach_round + 1) % size)

    async def _greet(self) -> None:
        """Hello, said and shown together."""
        speech, body = self.ctx.speech, self.ctx.body
        await asyncio.gather(speech.say("session.greeting"), body.perform(GREETING))

    async def _check_buttons(self) -> None:
        """Kaspar asks for a green, then a red (kasparctl.game.buttons), once in a game;
        the researcher's "next" skips the rest."""
        ctx = self.ctx
        check = ctx.buttons
        if check.done:
            return
        skip = asyncio.ensure_future(check.begin().wait())
        answer: asyncio.Future[Press] | None = None
        try:
            if not skip.done():
                await ctx.speech.say("buttons.start")
            for asked in ASKED:
                if skip.done():
                    ctx.record(skipped(asked))
                    check.end()
                    return
                opened = ctx.presses.open(ctx.now())
                ctx.emit(GameEvent.ASKING, button_check=asked)
                await ctx.speech.say(f"buttons.{asked}")
                ctx.presses.asked(ctx.now())
                ctx.emit(GameEvent.BUTTON_CHECK, button=asked)
                prompts: tuple[tuple[str, dict[str, str]], ...] = (
                    (f"buttons.{asked}", {}),
                    ("prompt.ask_researcher", {}),
                )
                answer = asyncio.ensure_future(ctx.wait_with_prompts(opened, prompts))
                await asyncio.wait({answer, skip}, return_when=asyncio.FIRST_COMPLETED)
                if not answer.done():
                    ctx.presses.close(ctx.now())
                    ctx.record(skipped(asked))
                    check.end()
                    return
                button, at = answer.result()
                ctx.presses.answered(at, None)
                ctx.record(pressed(asked, button, at))
            check.end()
            await ctx.speech.say("buttons.thanks")
        finally:
            # Cut off (a pause, a fault) or skipped: nothing of it goes on prompting.
            for task in (skip, answer):
                if task is not None:
                    task.cancel()
            if not check.done:
                check.left()

    async def _wait_for_researcher(self, step: str) -> None:
        """Wait for the researcher's "next"; after a long quiet, say once that Kaspar is ready."""
        ctx = self.ctx
        ctx.emit(GameEvent.WAITING_FOR_RESEARCHER, step=step)
        delay = ctx.settings.step_prompt_after_s
        await asyncio.sleep(delay)
        ctx.record(PromptRecord(line="steps.ready", waited=delay))
        ctx.emit(GameEvent.PROMPT, line="steps.ready")
        await ctx.speech.say("steps.ready")
        await asyncio.Event().wait()  # the researcher's "next" moves on

    async def _say_roles(self, teach_round: int) -> None:
        mover, presser = self.roles(teach_round)
        if mover == presser:
            await self.ctx.speech.say("teach.roles_alone", mover=mover)
        else:
            await self.ctx.speech.say("teach.roles", mover=mover, presser=presser)

    async def _ask_for_bag(self, bag: int, teach_round: int, retry: str | None) -> None:
        """The request to show `bag`: again (`retry` says why), or the first of a round
        (or after a pause) with who does what."""
        speech, number = self.ctx.speech, str(bag + 1)
        if retry is not None:
            await speech.say(retry, bag=number)
        elif self._requests == 0 or bag == 0:
            if bag == 0 and teach_round > 0:
                await speech.say("teach.swap")
            await self._say_roles(teach_round)
            await speech.say("teach.bag_first", bag=number)
        else:
            await speech.say("teach.bag", bag=number)
        self._requests += 1

    async def _teach_one_bag(self, bag: int, teach_round: int, group: str) -> None:
        """Ask for one bag's pose until a child shows it; a pose far from where the bag
        was shown before is asked for once more (both count for the median)."""
        ctx = self.ctx
        mover, presser = self.roles(teach_round)
        number = str(bag + 1)
        checked = False
        refused = 0  # presses taken for an arm nobody moved
        retry: str | None = None
        while True:
            opened = ctx.presses.open(ctx.now())
            ctx.emit(GameEvent.ASKING, bag=bag, round=teach_round, mover=mover, presser=presser)
            await self._ask_for_bag(bag, teach_round, retry)
            ctx.presses.asked(ctx.now())
            ctx.emit(GameEvent.TEACH, bag=bag, round=teach_round, mover=mover, presser=presser)
            button, at = await ctx.wait_with_prompts(
                opened,
                (
                    ("prompt.teach", {"presser": presser, "bag": number}),
                    ("instructions.teach", {}),
                    ("prompt.ask_researcher", {}),
                ),
            )
            ctx.presses.answered(at, None)
            if button != "green":
                ctx.record(PressRecord(button=button, at=at, teach_retry=bag))
                retry = "teach.try_again"
                continue
            pose = await ctx.servos.read_positions(group)
            outside = self._outside_safe_range(pose)
            if outside:
                # Kaspar could never point there: ask again rather than log it.
                ctx.record(PressRecord(button=button, at=at, teach_retry=bag, outside=outside))
                retry = "teach.out_of_reach"
                continue
            unmoved = self._unmoved(pose, bag, teach_round)
            if unmoved is not None and refused < ctx.settings.unmoved_arm_asks:
                # Nobody moved the arm (a press too soon, or the jobs mixed up): not the
                # bag's pose. Asked in words that blame no one; after a few, taken.
                ctx.record(PressRecord(button=button, at=at, teach_retry=bag, unmoved=unmoved))
                refused += 1
                retry = "teach.not_moved"
                continue
            shown = _shown(ctx.state, ctx.settings.targets[bag])
            far = not checked and bool(far_from(pose, shown, ctx.settings.pose_check_deg))
            ctx.change(
                PoseRecord(
                    bag=bag,
                    round=teach_round,
                    pose=pose,
                    at=at,
                    rule="median",
                    mover=mover,
                    presser=presser,
                    check_again=True if far else UNSET,
                )
            )
            if far:
                checked, retry = True, "teach.check_again"
                continue
            if bag == 0 and teach_round == 0:
                await ctx.speech.say("teach.logged_first", bag=number)
            else:
                await ctx.speech.say("teach.logged")
            return

    def _unmoved(self, pose: dict[str, float], bag: int, teach_round: int) -> str | None:
        """Where the arm still is, if nobody moved it: "rest", or "bag N" for the bag
        shown just before (never the same bag's earlier round: that should be near)."""
        ctx = self.ctx
        limit = ctx.settings.unmoved_arm_deg
        if limit <= 0:
            return None
        if _within(pose, ctx.rest_pose, limit):
            return "rest"
        targets = ctx.settings.targets
        previous = (bag - 1) % len(targets)
        if (bag == 0 and teach_round == 0) or previous == bag:
            return None
        shown = _shown(ctx.state, targets[previous])
        before = shown[-1] if shown else ctx.state.poses.get(targets[previous], {})
        return f"bag {previous + 1}" if _within(pose, before, limit) else None

    def _outside_safe_range(self, pose: dict[str, float]) -> list[str]:
        ranges = self.ctx.joint_ranges
        return [
            name
            for name, degrees in pose.items()
            if name in ranges and not ranges[name][0] <= degrees <= ranges[name][1]
        ]


def _shown(state: GameState, target: str) -> list[dict[str, float]]:
    """Every pose shown for `target` so far (under the median rule)."""
    shown = state.shown_poses
    return [] if isinstance(shown, msgspec.UnsetType) else list(shown.get(target, []))


def _within(pose: dict[str, float], reference: Mapping[str, float], limit_deg: float) -> bool:
    """Every joint of `pose` within `limit_deg` of `reference` (which has them all)."""
    if not pose or any(joint not in reference for joint in pose):
        return False
    return all(abs(degrees - reference[joint]) <= limit_deg for joint, degrees in pose.items())
