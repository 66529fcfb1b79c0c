"""One session's settings: its plan resolved against the configuration, and read back.

Everything that shapes what a group experiences (its learner, the greens needed
to learn, the toys or locations, the script and uncertainty mode, the prompts'
timing, the voice, the reactions, life, the movement speed, the language, the
robot) may be given by the session's `[[sessions]]` entry, by its learner
profile (`[learner.profiles.X]`), or robot-wide (`[game]`, `[voice]`, `language`),
in that order of precedence. `resolve_session` is the one place that order is applied;
the game, voice, body and recorder read the session's values from the frozen
SessionSettings it gives, never the robot-wide ones. `block` is what plan.json
keeps of it (its `settings`), and `recorded_session` reads that back for a resume, so a
session carries on with what it began with whatever the configuration says then.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar

import msgspec

from hal.voice.settings import VoiceSettings, voice_for_language
from kasparctl.config.errors import ConfigError
from kasparctl.config.schema import (
    LEARNER_KEYS,
    SPOKEN_MODES,
    Config,
    GameSettings,
    ProfileSettings,
    SessionPlan,
    UncertaintyMode,
    VoiceOverrides,
)
from kasparctl.learning.learner import LearnerParams

# The [game] keys a session or a profile may set, as kaspar.toml names them.
GAME_KEYS = (
    "toys",
    "locations",
    "correct_answers_to_learn",
    "max_trials_per_target",
    "script",
    "prompt_after_s",
    "step_prompt_after_s",
    "reactions",
    "alive",
    "speed_scale",
)
# The [voice] keys a session or a profile may set.
VOICE_KEYS = ("engine", "voice", "rate", "volume", "pitch")
# The [game] keys plan.json's `settings` keeps beside GAME_KEYS: they shape the game too.
RECORDED_GAME_KEYS = ("variant", *GAME_KEYS, "exclude_learned")
DEFAULT_ROBOT_NAME = "Kaspar"
_T = TypeVar("_T")


@dataclass(frozen=True, slots=True)
class SessionSettings:
    """What one session plays with, every level of precedence applied."""

    # The plan with its uncertainty mode, speak_uncertainty, script and life written out.
    plan: SessionPlan
    profile: str
    learner: LearnerParams
    # [game] with the session's values: what the game, its state and the recorder use.
    game: GameSettings
    # [voice] with the session's engine, voice, rate, volume and pitch.
    voice: VoiceSettings
    language: str
    robot_id: str
    robot_name: str = DEFAULT_ROBOT_NAME

    @property
    def uncertainty(self) -> UncertaintyMode:
        """How Kaspar shows how sure it is in this session."""
        return self.plan.uncertainty_mode

    @property
    def speed_scale(self) -> float:
        """Every joint's speed limit is multiplied by this for the session."""
        return self.game.speed_scale

    def block(self) -> dict[str, Any]:
        """plan.json's `settings`: every value above, keys named as in kaspar.toml."""
        game = msgspec.to_builtins(self.game)
        voice = msgspec.to_builtins(self.voice)
        return {
            **{key: game[key] for key in RECORDED_GAME_KEYS},
            "uncertainty": self.uncertainty,
            "language": self.language,
            "voice": {key: voice[key] for key in VOICE_KEYS},
            "learner": {
                "profile": self.profile,
                **{key: getattr(self.learner, key) for key in LEARNER_KEYS},
            },
        }

    def robot_block(self) -> dict[str, str]:
        """plan.json's `robot`: the robot's stable id and its name."""
        return {"id": self.robot_id, "name": self.robot_name}

    def config(self, config: Config) -> Config:
        """`config` as this session sees it: its game, voice, language and learner in place
        of the robot-wide ones (for what takes a whole Config, such as its phrase book)."""
        profiles = {**config.learner.profiles, self.profile: _profile_of(self.learner)}
        return msgspec.structs.replace(
            config,
            game=self.game,
            voice=self.voice,
            language=self.language,
            learner=msgspec.structs.replace(config.learner, profiles=profiles),
        )


def resolve_session(config: Config, plan: SessionPlan, *, profiles: bool = True) -> SessionSettings:
    """`plan`'s settings: its own values, else its profile's, else the robot-wide ones.

    KeyError when the plan's profile is not configured (`check` refuses that first).
    `profiles=False` leaves the profile's session keys out (a session recorded before
    they existed plays as it did).
    """
    profile = config.learner.all_profiles()[plan.profile]
    levels: tuple[SessionPlan | ProfileSettings, ...] = (plan, profile) if profiles else (plan,)
    game = _game(config.game, levels)
    language = _first(levels, "language", config.language)
    mode = _uncertainty(plan, profile if profiles else None)
    resolved_plan = msgspec.structs.replace(
        plan,
        uncertainty=mode,
        speak_uncertainty=mode in SPOKEN_MODES,
        script=game.script,
        alive=game.alive,
    )
    return SessionSettings(
        plan=resolved_plan,
        profile=plan.profile,
        learner=profile.params(),
        game=game,
        voice=_voice(config, language, levels),
        language=language,
        robot_id=config.robot(),
        robot_name=config.robot_settings.name,
    )


def recorded_session(
    meta: dict[str, Any], config: Config, plan: SessionPlan, learner: LearnerParams, source: str
) -> SessionSettings:
    """A session's settings as its plan.json keeps them (`meta`); a session recorded before
    `settings` existed gets the configuration's robot-wide values, as it had then.

    ConfigError (naming `source`, the key, expected and found) when the block is unusable.
    """
    block = meta.get("settings")
    if not isinstance(block, dict):
        legacy = resolve_session(config, plan, profiles=False)
        robot = meta.get("robot")
        return SessionSettings(
            plan=legacy.plan,
            profile=plan.profile,
            learner=learner,
            game=legacy.game,
            voice=legacy.voice,
            language=legacy.language,
            robot_id=robot if isinstance(robot, str) else legacy.robot_id,
            robot_name=legacy.robot_name,
        )
    game = recorded_game(meta, config.game, source)
    voice_in = block.get("voice") or {}
    if not isinstance(voice_in, dict):
        raise ConfigError(source, "settings.voice", f"expected an object, found {voice_in!r}")
    given = {key: voice_in[key] for key in VOICE_KEYS if key in voice_in}
    voice = _converted(
        {**msgspec.to_builtins(config.voice), **given},
        VoiceSettings,
        source,
        "settings.voice",
    )
    mode = block.get("uncertainty", plan.uncertainty_mode)
    resolved_plan = msgspec.structs.replace(
        plan,
        uncertainty=mode,
        speak_uncertainty=mode in SPOKEN_MODES,
        script=game.script,
        alive=game.alive,
    )
    robot = meta.get("robot")
    robot = robot if isinstance(robot, dict) else {"id": robot}
    return SessionSettings(
        plan=_converted(msgspec.to_builtins(resolved_plan), SessionPlan, source, "plan"),
        profile=plan.profile,
        learner=learner,
        game=game,
        voice=voice,
        language=str(block.get("language", meta.get("language", config.language))),
        robot_id=str(robot.get("id") or config.robot()),
        robot_name=str(robot.get("name") or DEFAULT_ROBOT_NAME),
    )


def recorded_game(meta: dict[str, Any], game: GameSettings, source: str) -> GameSettings:
    """The game a session was recorded with: its plan.json's `settings` over `game` (all
    of `game` for a session recorded before settings were kept). ConfigError when the
    block is not the settings of a game."""
    block = meta.get("settings")
    if block is None:
        return game
    if not isinstance(block, dict):
        raise ConfigError(source, "settings", f"expected an object, found {block!r}")
    given = {key: block[key] for key in RECORDED_GAME_KEYS if key in block}
    return _converted({**msgspec.to_builtins(game), **given}, GameSettings, source, "settings")


def _first(levels: tuple[Any, ...], key: str, default: Any) -> Any:
    """The first level's value of `key` that is given, else `default`."""
    for level in levels:
        value = getattr(level, key, None)
        if value is not None:
            return value
    return default


def _game(game: GameSettings, levels: tuple[Any, ...]) -> GameSettings:
    changes = {key: _first(levels, key, getattr(game, key)) for key in GAME_KEYS}
    return msgspec.structs.replace(game, **changes)


def _voice(config: Config, language: str, levels: tuple[Any, ...]) -> VoiceSettings:
    """[voice] with the levels' keys; a session in another language speaks with that
    language's voice unless a level names one."""
    voices: tuple[VoiceOverrides, ...] = tuple(
        level.voice for level in levels if getattr(level, "voice", None) is not None
    )
    base = config.voice
    if language != config.language:
        base = msgspec.structs.replace(base, voice=voice_for_language(language))
    changes = {key: _first(voices, key, getattr(base, key)) for key in VOICE_KEYS}
    return msgspec.structs.replace(base, **changes)


def _uncertainty(plan: SessionPlan, profile: ProfileSettings | None) -> UncertaintyMode:
    """The plan's mode (or its speak_uncertainty's), else the profile's, else "spoken"."""
    unset = plan.uncertainty is None and plan.speak_uncertainty is None
    if unset and profile is not None and profile.uncertainty is not None:
        return profile.uncertainty
    return plan.uncertainty_mode


def _profile_of(learner: LearnerParams) -> ProfileSettings:
    return ProfileSettings(**{key: getattr(learner, key) for key in LEARNER_KEYS})


def _converted(data: dict[str, Any], kind: type[_T], source: str, key: str) -> _T:
    try:
        return msgspec.convert(data, type=kind)
    except (msgspec.ValidationError, ValueError) as error:
        message = f"expected the settings a session records: {error}"
        raise ConfigError(source, key, message) from None
