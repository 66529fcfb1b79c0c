"""One guess of step 4: Kaspar asks, listens, takes the answer, records it, and reacts.

kasparctl.game.trial does the arithmetic (the question planned before it is asked,
the answer scored into a TrialRecord); this says it, shows it and waits for it.
What the answer showed the researcher should know (a right toy no longer offered,
Kaspar confused) is recorded and said (kasparctl.game.recovery).
"""

from __future__ import annotations

import asyncio
from typing import cast

import msgspec

from kasparctl.body.api import GazeKind
from kasparctl.game import recovery, rotation
from kasparctl.game.bodywork import HAPPY, NOD, SAD, THINKING, PointStyle, point_style
from kasparctl.game.context import StepContext
from kasparctl.game.events import GameEvent
from kasparctl.game.records import Button, ConfusedRecord, TrialRecord
from kasparctl.game.trial import Answer, TrialPlan, plan_trial, question_record, score_answer
from kasparctl.log import bind_context

# How long Kaspar takes to turn to its listening pose.
LISTEN_MOVE_S = 0.4
# The phrase key whose clip is the listening sound ([voice.clips]).
LISTENING_SOUND = "cue.listening"


class Guess:
    """One trial, asked of the open session's next child."""

    def __init__(self, ctx: StepContext) -> None:
        """A guess of the session `ctx` is a step of."""
        self.ctx = ctx

    async def play(self) -> None:
        """Ask, wait for the answer, record it (kasparctl.game.trial does the arithmetic), react."""
        ctx, state = self.ctx, self.ctx.state
        turn = ctx.turn
        # A child out of the rotation (away, or their keyfob absent) is passed over.
        for skipped in rotation.skips(
            state, ctx.group_size, turn.absent_children(), ctx.child_name, turn.seat_of
        ):
            ctx.change(skipped)
        plan = plan_trial(
            state, ctx.params, ctx.settings, ctx.plan, ctx.group_size, ctx.speech.book, ctx.script
        )
        bind_context(trial=plan.trial, target=plan.target_name)
        ctx.record(question_record(plan))  # history only: the open question, for readers
        # From here a press is early, until the guess itself is said.
        answer = ctx.presses.open(ctx.now())
        turn.asking, turn.answered_by = plan.child_index, None
        ctx.body.look_at(GazeKind.CHILD, plan.child_index, plan.child)
        self._tell(GameEvent.ASKING, plan)
        if ctx.group_size > 1 and state.turn < ctx.group_size:
            await ctx.speech.say("turn.first", child=plan.child)  # each child's first turn
        spoken = await self._ask(plan)
        ctx.presses.asked(ctx.now())
        self._tell(GameEvent.QUESTION, plan)
        listened = await self._listen() if ctx.presses.waiting else None
        button, pressed_at = await ctx.wait_with_prompts(
            answer,
            (
                ("instructions.buttons", {}),
                ("prompt.answer_again", {"child": plan.child}),
                ("prompt.ask_researcher", {}),
            ),
        )
        question_end = ctx.presses.question_end
        turn.asking = None
        heard = Answer(
            spoken, question_end, cast(Button, button), pressed_at, pressed_at < question_end
        )
        planned_with = "recovery" in ctx.session.plan
        scored = score_answer(
            plan, heard, state, ctx.params, ctx.settings, ctx.plan, recovery=planned_with
        )
        record = ctx.change(self._credited(scored, turn.answered_by))
        ctx.presses.answered(pressed_at, record.trial)
        ctx.emit(GameEvent.ANSWERED, trial=record.trial, feedback=button)
        confused = self._notice(record)
        await self._react(plan, record.green, record.learned, listened)
        if state.progress[plan.target].given_up:
            await ctx.speech.say("react.given_up")
        if confused is not None:
            await self._say_confused(confused)

    def _credited(self, scored: TrialRecord, seat: int | None) -> TrialRecord:
        """With one keyfob per child: the seat that answered, and the child credited."""
        seats = self.ctx.turn.seats
        if seat is None or not 0 <= seat < len(seats):
            return scored
        child = seats[seat].child
        return msgspec.structs.replace(
            scored,
            seat=seat + 1,
            device=seats[seat].device,
            credited=self.ctx.child_name(child),
            credited_index=child,
        )

    def _tell(self, event: GameEvent, plan: TrialPlan) -> None:
        self.ctx.emit(
            event,
            target=plan.target,
            choice=plan.choice,
            trial=plan.trial,
            child=plan.child,
            child_index=plan.child_index,
        )

    def _notice(self, record: TrialRecord) -> ConfusedRecord | None:
        """What the answer showed the researcher should know (kasparctl.game.recovery):
        a right toy no longer offered, and whether Kaspar is confused; recorded."""
        ctx = self.ctx
        for alert in recovery.alerts(ctx.state, record, ctx.settings, ctx.plan.answer_key):
            ctx.record(alert)
            ctx.emit(GameEvent.ALERT, target=alert.target, toy=alert.toy)
        confused = recovery.confusion(ctx.state, record, ctx.settings)
        if confused is None:
            return None
        return ctx.change(confused)

    async def _say_confused(self, confused: ConfusedRecord) -> None:
        """Said once; the researcher is told (GameEvent.CONFUSED) once Kaspar has asked."""
        speech = self.ctx.speech
        if confused.reason == recovery.LEARNED_ELSEWHERE and isinstance(confused.name, str):
            await speech.say("recovery.confused_learned", toy=confused.name)
        else:
            await speech.say("recovery.confused")
        if confused.reopen_name is not None:
            await speech.say("recovery.ask_researcher")
        state = self.ctx.state
        learned = [(t, state.progress[t].learned) for t in state.learned_targets()]
        self.ctx.emit(
            GameEvent.CONFUSED,
            target=confused.target_index,
            reason=confused.reason,
            learned=learned,
            reopen=confused.reopen_name,
        )

    async def _ask(self, plan: TrialPlan) -> tuple[str, ...]:
        """Point while saying how sure (if the plan says it), then the guess; the lines said.

        From the guess on, a press is the answer: it is the question's last words.
        """
        ctx = self.ctx
        spoken: list[str] = []
        key = plan.uncertainty_line
        strength = ctx.body.strength(plan.entropy, len(plan.candidates))
        style = point_style(strength)
        if key is not None:
            said, _ = await asyncio.gather(
                ctx.speech.say(key), self._think_and_point(plan, strength, style)
            )
            spoken.append(said)
        else:
            await self._think_and_point(plan, strength, style)
        ctx.presses.last_words(ctx.now())
        ctx.body.look_at(GazeKind.CHILD, plan.child_index, plan.child)
        if ctx.settings.variant == "pilot":
            guess = ctx.speech.say(
                "guess.pilot", child=plan.child, toy=plan.toy, where=self._where(plan)
            )
        else:
            guess = ctx.speech.say("guess.names", child=plan.child, toy=plan.toy)
        if style.nod and plan.likeliest:
            # Sure of the toy it names: a nod as it asks (never before a toy it is trying).
            said, _ = await asyncio.gather(guess, ctx.body.perform(NOD, 1.0 - (strength or 0.0)))
            spoken.append(said)
        else:
            spoken.append(await guess)
        return tuple(spoken)

    async def _think_and_point(
        self, plan: TrialPlan, strength: float | None, style: PointStyle
    ) -> None:
        """Thinking first, as hard as Kaspar is unsure, where the body shows it; then the point."""
        if strength is not None:
            await self.ctx.body.perform(THINKING, strength)
        await self.ctx.point_at(plan.target_name, plan.target, style)

    def _where(self, plan: TrialPlan) -> str:
        """How the pilot location of `plan` is said in a sentence ("on the shelf")."""
        location = plan.target_name
        phrase = self.ctx.settings.location_phrases.get(location)
        return phrase or self.ctx.speech.book.fill("names.where", location=location)

    async def _react(
        self, plan: TrialPlan, green: bool, learned: bool, listened: dict[str, float] | None
    ) -> None:
        """What the answer means, in words that agree with the learned rule, and the face."""
        settings = self.ctx.settings
        if green and learned:
            key = "react.learned"
        elif green:
            key = "react.right_check"
        else:
            key = "react.wrong"
        values = {"toy": plan.toy}
        if settings.variant == "pilot":
            key += "_pilot"
            values["where"] = self._where(plan)
        face = reaction(self.ctx.reactions, green, learned)
        expression = settings.happy_pose if face == HAPPY else settings.sad_pose
        # Face and words together; gather cancels both with the step and retrieves a
        # servo error from either, so none is left unheard.
        await asyncio.gather(
            self.ctx.speech.say(key, **values),
            self._face(listened, dict(expression), face),
        )

    async def _face(
        self,
        listened: dict[str, float] | None,
        expression: dict[str, float],
        behaviour: str | None,
    ) -> None:
        """Back from listening, then the body's behaviour; without a body, the expression
        pose (held briefly, then undone). No behaviour: the face stays as it is."""
        ctx = self.ctx
        if listened:
            await ctx.servos.move(listened, duration=LISTEN_MOVE_S)
        if behaviour is None:
            return
        if expression and ctx.body.fallback:
            await self._express(expression)
            return
        # The behaviour goes on while the game does: the next question must not wait for
        # the end of a smile (the body's own loop plays it; a move or a cancel ends it).
        shown = asyncio.ensure_future(ctx.body.perform(behaviour))
        ctx.showing.add(shown)
        shown.add_done_callback(ctx.showing.discard)

    async def _express(self, pose: dict[str, float]) -> None:
        servos = self.ctx.servos
        before = await servos.read_positions()
        await servos.move(pose, duration=0.6)
        await servos.move({joint: before[joint] for joint in pose}, duration=0.6)

    async def _listen(self) -> dict[str, float] | None:
        """Show that Kaspar listens: its listening pose and sound, where configured.

        Returns where the posed joints were, to go back to once answered.
        """
        ctx = self.ctx
        ctx.emit(GameEvent.LISTENING)
        if ctx.listening_sound:
            ctx.speech.sound_soon(LISTENING_SOUND)
        pose = ctx.settings.listening_pose
        if not pose:
            return None
        before = await ctx.servos.read_positions()
        await ctx.servos.move(dict(pose), duration=LISTEN_MOVE_S)
        return {joint: before[joint] for joint in pose if joint in before}


def reaction(reactions: str, green: bool, learned: bool) -> str | None:
    """The face Kaspar makes after an answer ([game] reactions), None for none.

    "paper": happy on learning a name only, as the paper's Kaspar (a sad face after a
    red may push children towards greens they do not mean); "all": happy after every
    green, sad after every red; "none": no face at all.
    """
    if reactions == "all":
        return HAPPY if green else SAD
    if reactions == "paper" and green and learned:
        return HAPPY
    return None
