"""kaspar.toml into typed, validated, frozen settings.

Every error names the file, the key path, what was expected and what was
found; unknown keys are rejected, so a misspelt key never silently falls back
to a default in front of children.
"""

from __future__ import annotations

import re
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Literal

import msgspec

from hal.keyfob.settings import KeyfobSettings
from hal.servos.settings import ServoSettings
from hal.voice.settings import VoiceSettings
from kasparctl.learning.learner import LearnerError, LearnerParams
from kasparctl.vocabulary import MAX_CHILDREN, REQUIRED_COMMANDS, Command

DEFAULT_CONFIG_PATH = Path("/etc/kaspar/kaspar.toml")


class ConfigError(Exception):
    """A configuration that cannot be used, with where and why."""

    def __init__(self, source: str, key: str, message: str) -> None:
        super().__init__(f"{source}: {key}: {message}")
        self.source = source
        self.key = key
        self.message = message


class _Settings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Base of every table: strict (unknown keys rejected) and immutable."""


class LoggingSettings(_Settings):
    level: Literal["debug", "info", "warning", "error"] = "info"
    # "auto": JSON lines when stdout is not a terminal (journald), console otherwise.
    format: Literal["auto", "json", "console"] = "auto"


class ProfileSettings(_Settings):
    """A named learner profile; unset values take the paper's."""

    alpha: float = 0.6
    beta: float = 8.0
    gamma: float = 0.0
    reward_green: float = 1.0
    reward_red: float = -1.0
    initial_q: float = 0.0

    def params(self) -> LearnerParams:
        return LearnerParams(**msgspec.structs.asdict(self))


# "fast" and "slow" are the paper's future-work learners; the values come from
# `kasparctl simulate --sweep` (see the README for their trials to learn).
BUILTIN_PROFILES: dict[str, ProfileSettings] = {
    "paper": ProfileSettings(),
    "fast": ProfileSettings(alpha=0.9, beta=10.0),
    "slow": ProfileSettings(alpha=0.2, beta=4.0),
}


class LearnerSettings(_Settings):
    default_profile: str = "paper"
    # Merged over BUILTIN_PROFILES: a configuration may redefine "fast" or add its own.
    profiles: dict[str, ProfileSettings] = {}

    def all_profiles(self) -> dict[str, ProfileSettings]:
        return {**BUILTIN_PROFILES, **self.profiles}


class GameSettings(_Settings):
    # "names": children teach the name of each bagged toy (steps 1-5).
    # "pilot": the paper's pilot, locations are known poses and Kaspar learns which toy goes where.
    variant: Literal["names", "pilot"] = "names"
    toys: tuple[str, ...] = ("lion", "elephant", "giraffe", "monkey", "zebra", "crocodile")
    locations: tuple[str, ...] = ()
    children_per_group: int = 3
    # Correct answers in a row for the same label before a target counts as
    # learned; 2 gives the pilot's minimum of 2 trials per association.
    correct_answers_to_learn: int = 2
    # A target not learned after this many guesses is left to the researcher.
    max_trials_per_target: int = 30
    seed: int | None = None
    # The arm the children move by hand in step 2, and that points at the toys.
    pointing_group: str = "right_arm"
    # Pilot variant: where each location is (location -> joint -> degrees).
    poses: dict[str, dict[str, float]] = {}
    # Small expressive poses, joint -> degrees, held briefly then undone.
    happy_pose: dict[str, float] = {}
    sad_pose: dict[str, float] = {}
    # Seconds of silence after a question before each prompt: first, second,
    # then the line that asks the researcher for help.
    prompt_after_s: tuple[float, ...] = (8.0, 8.0, 12.0)
    # A press this soon after an answer is recorded as an extra, not an answer.
    extra_press_gap_s: float = 1.0
    # Researcher gestures on the keyfob and the commands they give.
    commands: dict[str, str] = msgspec.field(
        default_factory=lambda: {
            "long green": "next",
            "long red": "pause",
            "double red": "undo",
            "both": "stop",
        }
    )

    @property
    def targets(self) -> tuple[str, ...]:
        """What Kaspar points at: one bag per toy, or the pilot's locations."""
        if self.variant == "pilot":
            return self.locations
        return tuple(f"bag {number}" for number in range(1, len(self.toys) + 1))

    @property
    def exclude_learned(self) -> bool:
        """A learned name is no longer offered for the other bags (names variant only).

        In the pilot each location is its own problem over all toys, which is why
        every problem starts at the paper's log2(6) = 2.585 bits.
        """
        return self.variant == "names"


class SessionPlan(_Settings):
    """A session planned beforehand: nobody can type during one."""

    group: str
    profile: str = "paper"
    speak_uncertainty: bool = True
    # First names are optional; without them Kaspar says "child one", "child two"...
    children: tuple[str, ...] = ()
    group_size: int | None = None
    # The correct label for each target, in target order; for research records only.
    answer_key: tuple[str, ...] = ()

    @property
    def condition(self) -> str:
        return f"{self.profile}/{'spoken' if self.speak_uncertainty else 'silent'}"


class DaemonSettings(_Settings):
    # After SIGTERM Kaspar goes to rest at each joint's speed limit, then either
    # holds there ("hold": no slump while the computer shuts down) or goes limp.
    stop_action: Literal["hold", "torque_off"] = "hold"


class Config(_Settings):
    state_dir: str = "/var/lib/kaspar"
    # A directory of phrase files that overrides the shipped ones.
    phrases_dir: str | None = None
    language: str = "en"
    logging: LoggingSettings = LoggingSettings()
    learner: LearnerSettings = LearnerSettings()
    game: GameSettings = GameSettings()
    sessions: tuple[SessionPlan, ...] = ()
    servos: ServoSettings = ServoSettings()
    keyfob: KeyfobSettings = KeyfobSettings()
    voice: VoiceSettings = VoiceSettings()
    daemon: DaemonSettings = DaemonSettings()

    def profile(self, name: str | None = None) -> LearnerParams:
        return self.learner.all_profiles()[name or self.learner.default_profile].params()

    def group_size(self, plan: SessionPlan) -> int:
        if plan.children:
            return len(plan.children)
        return plan.group_size or self.game.children_per_group


def load_config(path: str | Path) -> Config:
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise ConfigError(str(path), "(file)", f"cannot read it: {error.strerror}") from error
    return parse_config(data, str(path), base_dir=path.parent)


def parse_config(data: bytes | str, source: str, base_dir: Path | None = None) -> Config:
    text = data.decode("utf-8", errors="replace") if isinstance(data, bytes) else data
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(source, "(syntax)", f"not valid TOML: {error}") from error
    try:
        config = msgspec.convert(raw, type=Config)
    except msgspec.ValidationError as error:
        key, message = _explain_validation_error(str(error), raw)
        raise ConfigError(source, key, message) from error
    _validate(config, source)
    if base_dir is not None:
        config = _resolve_paths(config, base_dir)
    return config


def _resolve_paths(config: Config, base_dir: Path) -> Config:
    """Relative paths in a configuration are relative to the file, not to the cwd."""
    changes: dict[str, Any] = {"state_dir": str(base_dir / config.state_dir)}
    if config.phrases_dir is not None:
        changes["phrases_dir"] = str(base_dir / config.phrases_dir)
    return msgspec.structs.replace(config, **changes)


_PATH_SEGMENT = re.compile(r"\.([A-Za-z_][\w-]*)|\[(\d+|\.\.\.)\]")


def _explain_validation_error(text: str, raw: dict[str, Any]) -> tuple[str, str]:
    """Turn msgspec's "message - at `$.a.b[0]`" into a key path and a readable message."""
    message, _, where = text.rpartition(" - at ")
    if not message:
        message, where = text, ""
    segments = [name or f"[{index}]" for name, index in _PATH_SEGMENT.findall(where.strip("`$"))]
    segments = _name_dict_keys(segments, raw)
    field_type = _type_at(segments)
    unknown = re.fullmatch(r"Object contains unknown field `(.+)`", message)
    if unknown:
        segments.append(unknown.group(1))
        allowed = _field_names(field_type)
        message = (
            f"unknown key; expected one of: {', '.join(allowed)}" if allowed else "unknown key"
        )
    missing = re.fullmatch(r"Object missing required field `(.+)`", message)
    if missing:
        segments.append(missing.group(1))
        message = "required key is missing"
    bad_choice = re.fullmatch(r"Invalid enum value (.+)", message)
    if bad_choice and typing.get_origin(field_type) is Literal:
        choices = ", ".join(repr(choice) for choice in typing.get_args(field_type))
        message = f"expected one of {choices}, found {bad_choice.group(1)}"
    got = re.fullmatch(r"Expected `(.+)`, got `(.+)`", message)
    if got:
        message = f"expected {got.group(1)}, found {got.group(2)}"
    key = "".join(s if s.startswith("[") else f".{s}" for s in segments).lstrip(".")
    return key or "(top level)", message


def _name_dict_keys(segments: list[str], raw: Any) -> list[str]:
    """msgspec writes a table of tables' key as [...]; find which entry fails."""
    named: list[str] = []
    for segment in segments:
        if segment == "[...]" and isinstance(raw, dict):
            entry_type = _type_at([*named, "[...]"])
            segment = next(
                (key for key, value in raw.items() if not _converts(value, entry_type)), "[...]"
            )
            named.append(segment)
            raw = raw.get(segment)
            continue
        named.append(segment)
        if isinstance(raw, dict):
            raw = raw.get(segment)
        elif isinstance(raw, list) and segment.strip("[]").isdigit():
            index = int(segment.strip("[]"))
            raw = raw[index] if index < len(raw) else None
    return named


def _converts(value: Any, target_type: Any) -> bool:
    try:
        msgspec.convert(value, type=target_type)
    except msgspec.ValidationError:
        return False
    return True


def _type_at(segments: list[str]) -> Any:
    current: Any = Config
    for segment in segments:
        if isinstance(current, type) and issubclass(current, msgspec.Struct):
            hints = typing.get_type_hints(current)
            current = hints.get(segment)
        elif typing.get_origin(current) in (tuple, list, dict):
            current = typing.get_args(current)[-1 if typing.get_origin(current) is dict else 0]
        if typing.get_origin(current) in (typing.Union, types.UnionType):
            current = next(a for a in typing.get_args(current) if a is not type(None))
    return current


def _field_names(struct_type: Any) -> list[str]:
    if isinstance(struct_type, type) and issubclass(struct_type, msgspec.Struct):
        return [f.encode_name for f in msgspec.structs.fields(struct_type)]
    return []


def _validate(config: Config, source: str) -> None:
    """Checks that span several keys; each names the key that is wrong."""

    def fail(key: str, message: str) -> typing.NoReturn:
        raise ConfigError(source, key, message)

    profiles = config.learner.all_profiles()
    for name, profile in config.learner.profiles.items():
        try:
            profile.params()
        except LearnerError as error:
            fail(f"learner.profiles.{name}.{error.key}", str(error))
    known_profiles = ", ".join(sorted(profiles))
    if config.learner.default_profile not in profiles:
        found = config.learner.default_profile
        fail("learner.default_profile", f"expected one of {known_profiles}, found {found!r}")

    game = config.game
    _check_names(game.toys, "game.toys", fail, minimum=2)
    if game.variant == "pilot":
        _check_names(game.locations, "game.locations", fail, minimum=1)
    elif game.locations:
        fail(
            "game.locations",
            "only the pilot variant uses locations; remove it or set variant = 'pilot'",
        )
    if not 1 <= game.children_per_group <= MAX_CHILDREN:
        fail(
            "game.children_per_group",
            f"expected 1 to {MAX_CHILDREN}, found {game.children_per_group}",
        )
    if game.correct_answers_to_learn < 1:
        fail(
            "game.correct_answers_to_learn", f"expected >= 1, found {game.correct_answers_to_learn}"
        )
    if game.max_trials_per_target < game.correct_answers_to_learn:
        fail(
            "game.max_trials_per_target",
            f"expected >= correct_answers_to_learn ({game.correct_answers_to_learn}), "
            f"found {game.max_trials_per_target}",
        )

    _check_game_controls(game, fail)

    seen_groups: set[str] = set()
    for index, plan in enumerate(config.sessions):
        where = f"sessions[{index}]"
        if not plan.group.strip():
            fail(f"{where}.group", "expected a group code, found an empty string")
        if plan.group in seen_groups:
            fail(f"{where}.group", f"group code {plan.group!r} is planned twice")
        seen_groups.add(plan.group)
        if plan.profile not in profiles:
            fail(
                f"{where}.profile",
                f"expected one of {known_profiles}, found {plan.profile!r}",
            )
        if plan.children:
            _check_names(plan.children, f"{where}.children", fail, minimum=1)
            if plan.group_size is not None and plan.group_size != len(plan.children):
                fail(
                    f"{where}.group_size",
                    f"expected {len(plan.children)} (one per name in children), "
                    f"found {plan.group_size}",
                )
        if plan.group_size is not None and not 1 <= plan.group_size <= MAX_CHILDREN:
            fail(f"{where}.group_size", f"expected 1 to {MAX_CHILDREN}, found {plan.group_size}")
        if plan.answer_key:
            _check_answer_key(plan.answer_key, game, f"{where}.answer_key", fail)


GESTURES = ("long green", "long red", "double green", "double red", "both")


def _check_game_controls(
    game: GameSettings, fail: typing.Callable[[str, str], typing.NoReturn]
) -> None:
    for gesture, command in game.commands.items():
        if gesture not in GESTURES:
            fail(f"game.commands.{gesture}", f"expected a gesture, one of {', '.join(GESTURES)}")
        if command not in tuple(Command):
            fail(
                f"game.commands.{gesture}",
                f"expected one of {', '.join(Command)}, found {command!r}",
            )
    for command in REQUIRED_COMMANDS:
        if command not in game.commands.values():
            fail(
                "game.commands",
                f"expected a gesture for {command.value!r}: a session cannot be run without it",
            )
    if game.variant == "pilot" and game.poses and set(game.poses) != set(game.locations):
        fail(
            "game.poses",
            f"expected one pose per location ({', '.join(game.locations)}), "
            f"found {', '.join(game.poses)}",
        )
    if game.variant == "names" and game.poses:
        fail(
            "game.poses",
            "only the pilot variant has configured poses; step 2 teaches the bags' poses",
        )
    if not game.prompt_after_s or any(not 0.5 <= s <= 600 for s in game.prompt_after_s):
        fail(
            "game.prompt_after_s",
            f"expected 1 or more delays of 0.5 to 600 s, found {list(game.prompt_after_s)}",
        )
    if not 0.0 <= game.extra_press_gap_s <= 10.0:
        fail("game.extra_press_gap_s", f"expected 0 to 10 s, found {game.extra_press_gap_s}")


def _check_names(
    names: tuple[str, ...],
    key: str,
    fail: typing.Callable[[str, str], typing.NoReturn],
    minimum: int,
) -> None:
    if len(names) < minimum:
        fail(key, f"expected at least {minimum} names, found {len(names)}")
    for index, name in enumerate(names):
        if not name.strip():
            fail(f"{key}[{index}]", "expected a name, found an empty string")
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        fail(
            key, f"expected distinct names, found {', '.join(map(repr, duplicates))} more than once"
        )


def _check_answer_key(
    answer_key: tuple[str, ...],
    game: GameSettings,
    key: str,
    fail: typing.Callable[[str, str], typing.NoReturn],
) -> None:
    targets = game.targets
    if len(answer_key) != len(targets):
        fail(
            key,
            f"expected {len(targets)} toys (one per target: {', '.join(targets)}), "
            f"found {len(answer_key)}",
        )
    for index, toy in enumerate(answer_key):
        if toy not in game.toys:
            fail(
                f"{key}[{index}]",
                f"expected one of game.toys ({', '.join(game.toys)}), found {toy!r}",
            )
    _check_names(answer_key, key, fail, minimum=1)
