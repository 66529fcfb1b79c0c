"""Opening a new session: its plan.json, its directory, its first state.

One way to open a session, for the daemon and the demo alike: `open_new` writes
the plan (`planned`: what the session will play, frozen at its start, so a resume
plays it whatever the configuration says then) and makes its first GameState.
`session_script` reads back the script a session was planned with.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

import msgspec

from kasparctl.config import Config, SessionPlan
from kasparctl.game import recovery
from kasparctl.game.scripts import LEGACY_SCRIPT, Script, script
from kasparctl.game.session import Session, frozen_learner
from kasparctl.game.state import GameState


class OpenedSession(NamedTuple):
    """A session open on disk, the plan it plays, and the state it has reached."""

    session: Session
    plan: SessionPlan
    state: GameState


def planned(config: Config, plan: SessionPlan, seed: int | None) -> dict[str, Any]:
    """A session's plan.json (less its id and creation time, which Session.create adds).

    The group, its session number, the condition, the variant, the learner's seed,
    the uncertainty script and its version, the language, and the plan entry itself.
    """
    chosen = script(config.script(plan))
    return {
        "group": plan.group,
        "number": plan.number,
        "condition": plan.condition,
        "variant": config.game.variant,
        "seed": seed,
        "script": chosen.name,
        "script_version": chosen.version,
        # What Kaspar spoke (sessions planned before languages were recorded spoke "en").
        "language": config.language,
        # Confusion noticed, names re-opened (kasparctl.game.recovery); absent before.
        "recovery": recovery.RECOVERY_VERSION,
        "uncertainty": plan.uncertainty_mode,
        "plan": msgspec.to_builtins(plan.resolved()),
        # Frozen at the start: a resume uses these, whatever the configuration says then.
        "learner": frozen_learner(plan.profile, config.profile(plan.profile)),
    }


def open_new(state_dir: Path, config: Config, plan: SessionPlan, seed: int) -> OpenedSession:
    """A new session of `plan` in `state_dir`, its learner seeded with `seed`.

    StorageFailed when its directory or plan cannot be written.
    """
    session = Session.create(state_dir, planned(config, plan, seed), robot=config.robot())
    state = GameState.new(config.game, config.profile(plan.profile), seed)
    return OpenedSession(session, plan, state)


def session_script(session: Session) -> Script:
    """The script a session was planned with; the five varied bands before scripts existed."""
    return script(str(session.plan.get("script", LEGACY_SCRIPT)))
