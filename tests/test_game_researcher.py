"""Which researcher command applies where: the full table, and the machine agreeing with it."""

from __future__ import annotations

import itertools

import msgspec
import numpy as np
import pytest

from hal import Hardware
from hal.keyfob.gestures import Gesture, GestureKind
from kasparctl.config import GameSettings
from kasparctl.game.machine import Game, Lasting, Setup
from kasparctl.game.phrases import PhrasePicker, load_phrasebook
from kasparctl.game.records import Confirmation
from kasparctl.game.researcher import (
    TRIGGERS,
    Facts,
    commands_by_gesture,
    confirmation,
    gesture_name,
    gesture_needs,
)
from kasparctl.game.stages import STATES, STEPS, TRANSITIONS, Conditions, may
from kasparctl.game.state import GameState
from kasparctl.learning.learner import LearnerParams
from kasparctl.sim.demo import demo_config
from kasparctl.vocabulary import Command

C = Confirmation
N, P, U, S, R = Command.NEXT, Command.PAUSE, Command.UNDO, Command.STOP, Command.REOPEN
W, CH, AB = Command.AWAY, Command.CHOOSE, Command.ABSENT

# Every (stage, command): what it confirms with the facts all false, and all true.
# All true: the bags are taught, an answer can be undone, the keyfob is connected, a
# learned name can be re-opened (kasparctl.game.recovery).
TABLE: dict[tuple[str, Command], tuple[Confirmation | None, Confirmation | None]] = {
    ("idle", N): (C.START, C.START),
    ("idle", P): (None, None),
    ("idle", U): (None, None),
    ("idle", S): (None, None),
    ("idle", R): (None, None),
    ("placing", N): (C.NEXT_STEP, C.NEXT_STEP),
    ("placing", P): (C.PAUSE, C.PAUSE),
    ("placing", U): (None, None),
    ("placing", S): (C.STOP, C.STOP),
    ("placing", R): (None, None),
    ("teaching", N): (None, C.NEXT_STEP),  # only once every bag is taught
    ("teaching", P): (C.PAUSE, C.PAUSE),
    ("teaching", U): (None, None),
    ("teaching", S): (C.STOP, C.STOP),
    ("teaching", R): (None, None),
    ("revealing", N): (C.NEXT_STEP, C.NEXT_STEP),
    ("revealing", P): (C.PAUSE, C.PAUSE),
    ("revealing", U): (None, None),
    ("revealing", S): (C.STOP, C.STOP),
    ("revealing", R): (None, None),
    ("guessing", N): (None, None),  # step 4 ends by itself
    ("guessing", P): (C.PAUSE, C.PAUSE),
    ("guessing", U): (None, C.UNDO),  # only with an answer to take back
    ("guessing", S): (C.STOP, C.STOP),
    ("guessing", R): (None, C.REOPEN),  # only with a learned name and a target still open
    ("farewell", N): (None, None),
    ("farewell", P): (None, None),
    ("farewell", U): (None, None),
    ("farewell", S): (C.STOP, C.STOP),
    ("farewell", R): (None, None),
    ("finished", N): (None, None),
    ("finished", P): (None, None),
    ("finished", U): (None, None),
    ("finished", S): (None, None),
    ("finished", R): (None, None),
    ("paused", N): (None, None),
    ("paused", P): (C.RESUME, C.RESUME),
    ("paused", U): (None, None),
    ("paused", S): (C.STOP, C.STOP),
    ("paused", R): (None, None),
    ("fault", N): (None, None),
    ("fault", P): (None, C.RESUME),  # only once the keyfob is back
    ("fault", U): (None, None),
    ("fault", S): (C.STOP, C.STOP),
    ("fault", R): (None, None),
    ("stopped", N): (None, None),
    ("stopped", P): (None, None),
    ("stopped", U): (None, None),
    ("stopped", S): (None, None),
    ("stopped", R): (None, None),
    # A child away applies in step 4 only, with a child who can be taken out (or back).
    **{(stage, W): (None, None) for stage in STATES if stage != "guessing"},
    ("guessing", W): (None, C.AWAY),
    # Choosing the group, and marking it absent: in idle only, with plans to choose from.
    **{(stage, CH): (None, None) for stage in STATES if stage != "idle"},
    **{(stage, AB): (None, None) for stage in STATES if stage != "idle"},
    ("idle", CH): (None, C.CHOOSE),
    ("idle", AB): (None, C.ABSENT),
}


def facts(stage: str, on: bool, plays_names: bool = True) -> Facts:
    # Paused and faulted stages return to the step they left: here, guessing.
    resume_step = "guessing" if stage in ("paused", "fault") else stage
    conditions = Conditions(
        plays_names=plays_names, bags_taught=on, all_done=False, resume_step=resume_step
    )
    return Facts(
        conditions,
        undo_available=on,
        hardware_ready=on,
        reopen_available=on,
        away=C.AWAY if on else None,
        plans_to_choose=on,
    )


def test_the_table_covers_every_stage_and_command() -> None:
    assert set(TABLE) == set(itertools.product(STATES, Command))
    assert len(TABLE) == 80


@pytest.mark.parametrize(("stage", "command"), sorted(TABLE), ids=lambda v: str(v))
def test_every_command_in_every_stage(stage: str, command: Command) -> None:
    off, on = TABLE[stage, command]
    assert confirmation(stage, command, facts(stage, on=False)) is off
    assert confirmation(stage, command, facts(stage, on=True)) is on
    # The pilot starts differently, but "next" starts it all the same.
    assert confirmation(stage, command, facts(stage, on=True, plays_names=False)) is on


def test_a_resume_goes_back_where_the_game_was() -> None:
    for step in STEPS:
        conditions = Conditions(True, True, False, resume_step=step)
        expected_from_paused = step if step != "farewell" else None
        assert may("resume", "paused", conditions) == expected_from_paused
        assert may("resume", "fault", conditions) == step
    assert may("resume", "fault", Conditions(True, False, False, resume_step="idle")) == "idle"


def test_each_confirmation_fires_a_trigger_of_the_table() -> None:
    triggers = {transition["trigger"] for transition in TRANSITIONS}
    assert set(TRIGGERS.values()) <= triggers
    # An undo, a re-open, closing a stopped session and skipping the check of the
    # buttons move no stage.
    assert set(TRIGGERS) == set(Confirmation) - {
        Confirmation.UNDO,
        Confirmation.CLOSE,
        Confirmation.REOPEN,
        Confirmation.AWAY,
        Confirmation.BACK,
        Confirmation.CHOOSE,
        Confirmation.ABSENT,
        Confirmation.PRESENT,
        Confirmation.SKIP_CHECK,
    }


def test_next_while_kaspar_checks_the_buttons_skips_the_check_not_the_step() -> None:
    checking = Facts(
        Conditions(True, False, False, resume_step="placing"),
        undo_available=False,
        hardware_ready=True,
        checking_buttons=True,
    )
    for stage in ("placing", "guessing"):
        assert confirmation(stage, Command.NEXT, checking) is Confirmation.SKIP_CHECK
    # Every other command does what it always does; paused, "next" is not a skip.
    assert confirmation("placing", Command.PAUSE, checking) is Confirmation.PAUSE
    assert confirmation("placing", Command.STOP, checking) is Confirmation.STOP
    assert confirmation("paused", Command.NEXT, checking) is None


def test_in_idle_a_stopped_session_waits_for_next_or_stop() -> None:
    """The researcher chooses: "next" reopens the stopped session, "stop" closes it."""
    conditions = Conditions(plays_names=True, bags_taught=False, all_done=False, resume_step="idle")
    waiting = Facts(conditions, undo_available=False, hardware_ready=True, stopped_waiting=True)
    assert confirmation("idle", S, waiting) is C.CLOSE
    assert confirmation("idle", N, waiting) is C.START
    assert confirmation("idle", P, waiting) is None
    assert confirmation("placing", S, waiting) is C.STOP
    reopened = Conditions(True, True, False, resume_step="guessing")
    assert may("reopen", "idle", reopened) == "guessing"
    assert may("reopen", "placing", reopened) is None


def _game(settings: GameSettings) -> Game:
    config = msgspec.structs.replace(demo_config(), game=settings)
    picker = PhrasePicker(load_phrasebook("en"), np.random.default_rng(0))
    hardware = Hardware(servos=None, keyfob=None, voice=None)  # type: ignore[arg-type]
    return Game(Setup(config, hardware, picker), Lasting.new(None, lambda: None))  # type: ignore[arg-type,return-value]


@pytest.mark.parametrize("variant", ["names", "pilot"])
async def test_the_live_machine_agrees_with_may(variant: str) -> None:
    """transitions' own may_<trigger> and the pure `may` give the same answer everywhere."""
    settings = demo_config().game if variant == "names" else GameSettings(
        variant="pilot", locations=("box", "shelf")
    )
    game = _game(settings)
    params = LearnerParams()
    triggers = sorted({transition["trigger"] for transition in TRANSITIONS})
    sessions: list[GameState | None] = [None]
    for step, taught, done in itertools.product(("idle", *STEPS), (False, True), (False, True)):
        state = GameState.new(settings, params, seed=1)
        state.step = step
        if taught:
            state.poses = {target: {"right_elbow": 0.0} for target in settings.targets}
        if done:
            for progress in state.progress:
                progress.trials = progress.max_trials
        sessions.append(state)
    checked = 0
    for state, stage in itertools.product(sessions, STATES):
        game.session_state = state
        game.machine.set_state(stage)
        for trigger in triggers:
            live = await getattr(game, f"may_{trigger}")()
            assert live == (may(trigger, stage, game.conditions()) is not None), (
                stage,
                trigger,
                None if state is None else state.step,
            )
            checked += 1
    assert checked == len(sessions) * len(STATES) * len(triggers)


def test_gestures_are_named_as_the_configuration_names_them() -> None:
    def gesture(kind: GestureKind, button: str) -> Gesture:
        return Gesture(kind=kind, button=button, at=0.0, decided=0.0)

    assert gesture_name(gesture(GestureKind.LONG, "green")) == "long green"
    assert gesture_name(gesture(GestureKind.DOUBLE, "red")) == "double red"
    assert gesture_name(gesture(GestureKind.BOTH, "both")) == "both"
    assert gesture_name(gesture(GestureKind.COMMAND, "next")) == "next"


def test_on_one_keyfob_only_the_holds_some_command_uses_are_waited_for() -> None:
    commands = commands_by_gesture(GameSettings().commands)
    # No double press: children double-tap, so it is an answer, never a command.
    assert commands == {"long green": N, "long red": P, "both": S}
    needs = gesture_needs(commands, hold_s=3.0)
    assert needs.green == needs.red == {GestureKind.PRESS, GestureKind.LONG}
    assert needs.both and needs.long_press == 3.0
    fewer = gesture_needs({"long green": N, "both": S}, hold_s=4.0)
    assert fewer.red == {GestureKind.PRESS} and fewer.both and fewer.long_press == 4.0
