"""The rules of kaspar.toml that span several keys or tables, each naming the key at fault.

A key's own limits are on its field (kasparctl.config.schema, msgspec.Meta) and
held as it is read; these come after: the learner's profiles, the game's
names, controls and poses against the servos, the planned sessions, the
researcher's commands, the body, the toys' words. One `_check_*` per table.
`validate` holds those of any configuration; `check_playable` those of a robot
the game is played on.
"""

from __future__ import annotations

import math
import typing

from kasparctl.config.errors import ConfigError
from kasparctl.config.poses import check_pose
from kasparctl.config.schema import (
    SPOKEN_MODES,
    Config,
    GameSettings,
    LearnerSettings,
    ProfileSettings,
    SessionPlan,
)
from kasparctl.config.session_settings import resolve_session
from kasparctl.learning.learner import LearnerError
from kasparctl.lexicon import LexiconError, words
from kasparctl.lexicon import resolve as resolve_lexicon
from kasparctl.vocabulary import MISSING_MARKERS, REQUIRED_COMMANDS, Command

# Raises the ConfigError for a key and a message.
_Fail = typing.Callable[[str, str], typing.NoReturn]


def validate(config: Config, source: str) -> None:
    """Rules that span several keys, table by table; each names the key that is wrong.

    A key's own limits are on its field (msgspec.Meta) and already held.
    """

    def fail(key: str, message: str) -> typing.NoReturn:
        raise ConfigError(source, key, message)

    _check_learner(config.learner, fail)
    _check_game(config.game, fail)
    _check_profile_greens(config, fail)
    _check_game_controls(config.game, fail)
    _check_game_servos(config, fail)
    _check_sessions(config, fail)
    _check_researcher(config, fail)
    _check_seats(config, fail)
    _check_interaction(config.game, fail)
    _check_body(config, fail)
    _check_toy_names(config, source)
    _check_word(config.robot_settings.name, "robot.name", NAME_LIMIT, fail)


def check_playable(config: Config, source: str) -> None:
    """The rules of a robot the game is played on, beyond those of any configuration:
    the arm that points in step 2 is a group of its joints. ConfigError otherwise."""

    def fail(key: str, message: str) -> typing.NoReturn:
        raise ConfigError(source, key, message)

    _check_pointing_group(config, fail)


def _check_toy_names(config: Config, source: str) -> None:
    """Every configured toy has its words in the language; every [toy_names] entry is usable."""
    try:
        for language, entries in config.toy_names.items():
            for toy, entry in entries.items():
                words(entry, language, source, f"toy_names.{language}.{toy}")
        config.toy_words(source=source)
    except LexiconError as error:
        # error.source: kaspar.toml, or the shipped lexicon an entry came from.
        raise ConfigError(error.source, error.key, error.message) from error


def _check_learner(learner: LearnerSettings, fail: _Fail) -> None:
    for name, profile in learner.profiles.items():
        try:
            profile.params()
        except LearnerError as error:
            fail(f"learner.profiles.{name}.{error.key}", str(error))
        _check_overrides(profile, f"learner.profiles.{name}", fail)
    _check_profile_name(learner, learner.default_profile, "learner.default_profile", fail)


def _check_profile_greens(config: Config, fail: _Fail) -> None:
    """The greens to learn of every profile configured or used fit within the game's
    guesses per target (a built-in profile nobody uses is not held to it)."""
    limit = config.game.max_trials_per_target
    profiles = config.learner.all_profiles()
    used = {config.learner.default_profile, *(plan.profile for plan in config.sessions)}
    for name in dict.fromkeys([*config.learner.profiles, *sorted(used)]):
        if name not in profiles:
            continue  # named in its own error
        greens = profiles[name].correct_answers_to_learn
        if greens is not None and greens > limit:
            fail(
                f"learner.profiles.{name}.correct_answers_to_learn",
                f"expected at most game.max_trials_per_target ({limit}), found {greens}",
            )


def _check_profile_name(learner: LearnerSettings, name: str, key: str, fail: _Fail) -> None:
    profiles = learner.all_profiles()
    if name not in profiles:
        fail(key, f"expected one of {', '.join(sorted(profiles))}, found {name!r}")


# What a spoken line and a file name can hold: a toy, a location or a child's name is
# said aloud in a sentence; a group code names the session's directory.
NAME_LIMIT = 40
GROUP_CODE_LIMIT = 64
# numpy seeds its generator from a number >= 0; plan.json keeps it as a 64-bit integer.
SEED_LIMIT = 2**63 - 1
MAX_TRIALS_LIMIT = 1000


def _check_words(names: tuple[str, ...], key: str, limit: int, fail: _Fail) -> None:
    for index, name in enumerate(names):
        _check_word(name, f"{key}[{index}]", limit, fail)


def _check_word(name: str, key: str, limit: int, fail: _Fail) -> None:
    """A name said aloud or used in a file name: printable, and short enough to say."""
    if not name.isprintable():
        fail(key, f"expected printable text, found {name!r} (a control character)")
    if len(name) > limit:
        fail(key, f"expected at most {limit} characters, found {len(name)}: {name[:24]!r}...")
    if name != name.strip():
        fail(key, f"expected no spaces at either end, found {name!r}")


def _check_game(game: GameSettings, fail: _Fail) -> None:
    _check_words(game.toys, "game.toys", NAME_LIMIT, fail)
    _check_words(game.locations, "game.locations", NAME_LIMIT, fail)
    if game.seed is not None and not 0 <= game.seed <= SEED_LIMIT:
        fail("game.seed", f"expected 0 to {SEED_LIMIT}, found {game.seed}")
    if not 1 <= game.max_trials_per_target <= MAX_TRIALS_LIMIT:
        fail(
            "game.max_trials_per_target",
            f"expected 1 to {MAX_TRIALS_LIMIT}, found {game.max_trials_per_target}",
        )
    _check_distinct(game.toys, "game.toys", fail)
    if game.variant == "pilot":
        if not game.locations:
            fail("game.locations", "expected at least 1 names, found 0")
        _check_distinct(game.locations, "game.locations", fail)
    elif game.locations:
        fail(
            "game.locations",
            "only the pilot variant uses locations; remove it or set variant = 'pilot'",
        )
    if game.max_trials_per_target < game.correct_answers_to_learn:
        fail(
            "game.max_trials_per_target",
            f"expected >= correct_answers_to_learn ({game.correct_answers_to_learn}), "
            f"found {game.max_trials_per_target}",
        )


def _check_game_servos(config: Config, fail: _Fail) -> None:
    """Every pose the game holds names configured joints, with finite degrees within
    their safe ranges (the poses file's are checked as it is read)."""
    game, servos = config.game, config.servos
    poses = {"game.happy_pose": game.happy_pose, "game.sad_pose": game.sad_pose}
    poses.update({f"game.poses.{name}": pose for name, pose in game.poses.items()})
    for key, pose in poses.items():
        for joint, degrees in pose.items():
            if not math.isfinite(degrees):
                fail(f"{key}.{joint}", f"expected a finite number of degrees, found {degrees}")
        try:
            check_pose(pose, key.removeprefix("game."), servos, "")
        except ConfigError as error:
            fail(f"game.{error.key}", error.message)


def _check_body(config: Config, fail: _Fail) -> None:
    """The body's intervals are ordered, and its mouth and gaze name configured joints
    within their ranges (only checked when it is enabled on a robot with joints)."""
    body = config.body
    for key in ("blink_interval_s", "idle_interval_s"):
        low, high = getattr(body, key)
        if low > high:
            fail(f"body.{key}", f"expected [shortest, longest], found [{low}, {high}]")
    if not body.enabled or not config.servos.joints:
        return
    joints = {joint.name: joint for joint in config.servos.joints}
    if body.mouth_joint and body.mouth_joint not in joints:
        fail("body.mouth_joint", f"expected a configured joint ({', '.join(joints)}) or \"\", "
                                 f"found {body.mouth_joint!r}")
    gaze = body.gaze
    poses = {"ahead": gaze.ahead, "researcher": gaze.researcher}
    poses.update({f"children[{i}]": pose for i, pose in enumerate(gaze.children)})
    poses.update({f"bags[{i}]": pose for i, pose in enumerate(gaze.bags)})
    for key, pose in poses.items():
        for joint, degrees in pose.items():
            if not math.isfinite(degrees):
                fail(f"body.gaze.{key}.{joint}", f"expected a finite number, found {degrees}")
        try:
            check_pose(pose, key, config.servos, "")
        except ConfigError as error:
            fail(f"body.gaze.{error.key}", error.message)


def _check_pointing_group(config: Config, fail: _Fail) -> None:
    game, groups = config.game, config.servos.groups
    if game.variant == "names" and game.pointing_group not in groups:
        known = ", ".join(groups) or "none: no joints are configured in [servos]"
        fail(
            "game.pointing_group",
            f"expected a group of the configured joints ({known}), found "
            f"{game.pointing_group!r}: step 2 teaches with it",
        )


def _check_sessions(config: Config, fail: _Fail) -> None:
    seen: set[tuple[str, int]] = set()
    for index, plan in enumerate(config.sessions):
        where = f"sessions[{index}]"
        if (plan.group, plan.number) in seen:
            # A group's second session is numbered: a code planned twice is a typo.
            fail(
                f"{where}.group",
                f"group code {plan.group!r} is planned twice as session {plan.number}; "
                "give a group's next session number = 2, 3...",
            )
        seen.add((plan.group, plan.number))
        _check_plan(plan, where, config, fail)


def _check_overrides(level: ProfileSettings | SessionPlan, where: str, fail: _Fail) -> None:
    """A session's or a profile's own game values, held as [game]'s are."""
    if level.toys is not None:
        _check_words(level.toys, f"{where}.toys", NAME_LIMIT, fail)
        _check_distinct(level.toys, f"{where}.toys", fail)
    if level.locations is not None:
        _check_words(level.locations, f"{where}.locations", NAME_LIMIT, fail)
        _check_distinct(level.locations, f"{where}.locations", fail)
    trials = level.max_trials_per_target
    if trials is not None and not 1 <= trials <= MAX_TRIALS_LIMIT:
        fail(f"{where}.max_trials_per_target", f"expected 1 to {MAX_TRIALS_LIMIT}, found {trials}")


def _check_session_game(plan: SessionPlan, where: str, config: Config, fail: _Fail) -> None:
    """The game a session plays, its profile's and its own values applied, holds [game]'s
    rules; the key named is the one that gave the value at fault."""
    settings = resolve_session(config, plan)
    game, profile = settings.game, config.learner.all_profiles()[plan.profile]

    def origin(key: str) -> str:
        if getattr(plan, key, None) is not None:
            return f"{where}.{key}"
        if getattr(profile, key, None) is not None:
            return f"learner.profiles.{plan.profile}.{key}"
        return f"game.{key}"

    if game.max_trials_per_target < game.correct_answers_to_learn:
        key = "max_trials_per_target" if plan.max_trials_per_target is not None else (
            "correct_answers_to_learn"
        )
        fail(
            origin(key),
            f"expected max_trials_per_target ({game.max_trials_per_target}) >= "
            f"correct_answers_to_learn ({game.correct_answers_to_learn}) in {where}",
        )
    if game.variant == "pilot" and not game.locations:
        fail(origin("locations"), "expected at least 1 names, found 0")
    if game.variant == "names" and game.locations:
        fail(
            origin("locations"),
            "only the pilot variant uses locations; remove it or set game.variant = 'pilot'",
        )
    if game.variant == "pilot" and game.poses and set(game.poses) != set(game.locations):
        fail(
            origin("locations"),
            f"expected the locations of game.poses ({', '.join(game.poses)}), "
            f"found {', '.join(game.locations)}",
        )
    if game.toys != config.game.toys or settings.language != config.language:
        try:
            resolve_words(settings.language, game.toys, config, f"{where}")
        except LexiconError as error:
            fail(origin("toys") if game.toys != config.game.toys else origin("language"),
                 error.message)


def resolve_words(language: str, toys: tuple[str, ...], config: Config, source: str) -> None:
    """Every toy has its words in `language` (LexiconError otherwise)."""
    resolve_lexicon(language, toys, config.toy_names.get(language, {}), source)


def _check_plan(plan: SessionPlan, where: str, config: Config, fail: _Fail) -> None:
    _check_profile_name(config.learner, plan.profile, f"{where}.profile", fail)
    _check_overrides(plan, where, fail)
    _check_session_game(plan, where, config, fail)
    _check_word(plan.group, f"{where}.group", GROUP_CODE_LIMIT, fail)
    _check_not_missing((plan.group,), f"{where}.group", "a group code", fail)
    _check_not_missing(plan.children, f"{where}.children", "a first name", fail)
    _check_not_missing(plan.participants, f"{where}.participants", "a participant code", fail)
    _check_words(plan.children, f"{where}.children", NAME_LIMIT, fail)
    _check_distinct(plan.children, f"{where}.children", fail)
    if plan.children and plan.group_size not in (None, len(plan.children)):
        fail(
            f"{where}.group_size",
            f"expected {len(plan.children)} (one per name in children), found {plan.group_size}",
        )
    _check_distinct(plan.participants, f"{where}.participants", fail)
    if plan.participants:
        size = len(plan.children) or plan.group_size
        if size not in (None, len(plan.participants)):
            what = "name in children" if plan.children else "child of group_size"
            fail(
                f"{where}.participants",
                f"expected {size} codes (one per {what}), found {len(plan.participants)}",
            )
    if plan.answer_key:
        game = resolve_session(config, plan).game
        _check_answer_key(plan.answer_key, game, f"{where}.answer_key", fail)
    _check_uncertainty(plan, where, fail)


def _check_not_missing(values: tuple[str, ...], key: str, what: str, fail: _Fail) -> None:
    """No value that R or pandas would read back from a CSV as a missing value."""
    for value in values:
        if value.strip() in MISSING_MARKERS:
            fail(
                key,
                f"expected {what} that R and pandas read as text, found {value!r} "
                "(read back from a CSV as a missing value)",
            )


def _check_uncertainty(plan: SessionPlan, where: str, fail: _Fail) -> None:
    """speak_uncertainty, the older key, may stand beside `uncertainty` only if they agree."""
    mode, spoken = plan.uncertainty, plan.speak_uncertainty
    if mode is None or spoken is None or spoken == (mode in SPOKEN_MODES):
        return
    agreeing = "true" if mode in SPOKEN_MODES else "false"
    fail(
        f"{where}.speak_uncertainty",
        f"expected {agreeing} to agree with uncertainty = {mode!r} (or leave it out: "
        f"uncertainty says it all), found {str(spoken).lower()}",
    )


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


def _check_seats(config: Config, fail: _Fail) -> None:
    """One keyfob per child: every child of every planned group has a seat (a child
    without one could never answer their turn)."""
    seats = config.keyfob.children
    if not seats:
        return
    children: dict[int, int] = {}
    devices: dict[str, int] = {}
    for index, seat in enumerate(seats):
        if seat.child in children:
            fail(
                f"keyfob.children[{index}].child",
                f"expected each child seated once, found child {seat.child} seated already "
                f"(keyfob.children[{children[seat.child]}])",
            )
        if seat.where in devices:
            fail(
                f"keyfob.children[{index}]",
                f"expected a keyfob of its own, found {seat.where!r}, the keyfob of "
                f"keyfob.children[{devices[seat.where]}]",
            )
        children[seat.child] = devices[seat.where] = index
    seated = set(children)
    plans = [(f"sessions[{i}]", plan) for i, plan in enumerate(config.sessions)]
    sizes = [(where, config.group_size(plan)) for where, plan in plans] or [
        ("game.children_per_group", config.game.children_per_group)
    ]
    for where, size in sizes:
        missing = [child for child in range(1, size + 1) if child not in seated]
        if missing:
            fail(
                "keyfob.children",
                f"expected a seat for each of the {size} children of {where}, found none for "
                f"child {', '.join(str(child) for child in missing)}",
            )


def _check_researcher(config: Config, fail: _Fail) -> None:
    """The researcher's commands: each a command, the ones a session needs all there."""
    researcher = config.researcher
    if researcher.source == "device":
        keys = researcher.commands_given()
        where = "researcher.keys" if researcher.keys else "researcher.profile"
    elif researcher.source == "keypad":
        keys, where = config.keyfob.commands_given(), "keyfob.commands"
    else:
        keys, where = {}, ""
    for key, command in keys.items():
        if command not in tuple(Command):
            fail(f"{where}.{key}", f"expected one of {', '.join(Command)}, found {command!r}")
    if where:
        for command in REQUIRED_COMMANDS:
            if command not in keys.values():
                fail(
                    where,
                    f"expected a key for {command.value!r} (researcher.source = "
                    f"{researcher.source!r}): a session cannot be run without it",
                )
    # game.commands are holds on the children's keyfob: never what children do.
    for gesture in config.game.commands:
        if gesture.startswith("double "):
            fail(
                f"game.commands.{gesture}",
                "expected long green, long red or both: a double press is what children "
                "do, so it is an answer, never a command",
            )


def _check_interaction(game: GameSettings, fail: _Fail) -> None:
    """The pilot's location phrases name locations."""
    for location in game.location_phrases:
        if location not in game.locations:
            fail(
                f"game.location_phrases.{location}",
                f"expected one of game.locations ({', '.join(game.locations) or 'none'}), "
                f"found {location!r}",
            )


def _check_distinct(names: tuple[str, ...], key: str, fail: _Fail) -> None:
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        fail(
            key, f"expected distinct names, found {', '.join(map(repr, duplicates))} more than once"
        )


def _check_answer_key(
    answer_key: tuple[str, ...],
    game: GameSettings,
    key: str,
    fail: _Fail,
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
    _check_distinct(answer_key, key, fail)
