"""kaspar.toml into typed, validated, frozen settings.

Every error names the file, the key path, what was expected and what was
found; unknown keys are rejected, so a misspelt key never silently falls back
to a default in front of children.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import socket
import tomllib
import types
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

import msgspec

from hal.errors import KasparError
from hal.keyfob.settings import KeyfobSettings, ResearcherSettings
from hal.servos.settings import ServoSettings
from hal.voice.settings import VoiceSettings, voice_for_language
from kasparctl.learning.learner import LearnerError, LearnerParams
from kasparctl.lexicon import LexiconError, ToyEntry, ToyWords, resolve, words
from kasparctl.vocabulary import MAX_CHILDREN, REQUIRED_COMMANDS, Command

DEFAULT_CONFIG_PATH = Path("/etc/kaspar/kaspar.toml")


def default_config_path() -> str:
    """The configuration to read when none is given: $KASPAR_CONFIG, else DEFAULT_CONFIG_PATH."""
    return os.environ.get("KASPAR_CONFIG", str(DEFAULT_CONFIG_PATH))


class ConfigError(KasparError):
    """A configuration that cannot be used, with where and why."""

    def __init__(self, source: str, key: str, message: str) -> None:
        """Say `SOURCE: KEY: MESSAGE`; the three parts stay readable on their own."""
        super().__init__(f"{source}: {key}: {message}")
        self.source = source
        self.key = key
        self.message = message


class _Settings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Base of every table: strict (unknown keys rejected) and immutable.

    Subclasses repeat frozen=True only for mypy, which does not see it inherited.
    """


# A field's own limits live on its type as msgspec.Meta; _explain_constraint words
# a failure from them. `extra` may hold: "expected" (the words for what is expected,
# replacing the limits'), "unit" (after a range: "0 to 10 s") and "item" (what a
# sequence holds: "at least 2 names").
Name = Annotated[str, msgspec.Meta(pattern=r"\S", extra={"expected": "a name"})]
# A pseudonymous code for a child or a robot: letters, digits, "-" and "_", starting with a
# letter or digit, so it is safe in a file name, a CSV cell (never read as a formula) and R.
CODE_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_-]{0,31}$"
Code = Annotated[
    str,
    msgspec.Meta(
        pattern=CODE_PATTERN,
        extra={"expected": "a code: 1 to 32 letters, digits, '-' or '_', first a letter or digit"},
    ),
]
# Where a robot's default id comes from: systemd's machine id (never used as it is: hashed).
MACHINE_ID_FILES = (Path("/etc/machine-id"), Path("/var/lib/dbus/machine-id"))


def default_robot_id(machine_id_files: tuple[Path, ...] = MACHINE_ID_FILES) -> str:
    """This computer's robot id: "robot-" and 12 hex digits of a hash of its machine id.

    Stable for as long as the operating system is installed; the machine id
    itself never leaves the robot (systemd asks applications to hash it). Without
    a machine id, the host name is hashed instead.
    """
    source = ""
    for path in machine_id_files:
        try:
            source = path.read_text(encoding="ascii").strip()
        except (OSError, UnicodeDecodeError):
            continue
        if source:
            break
    if not source:
        source = "host:" + socket.gethostname()
    digest = hashlib.sha256(b"kaspar robot id\0" + source.encode()).hexdigest()
    return f"robot-{digest[:12]}"


class LoggingSettings(_Settings, frozen=True):
    """The `[logging]` table: how much the daemon logs, and in which form."""

    level: Literal["debug", "info", "warning", "error"] = "info"
    # "auto": JSON lines when stdout is not a terminal (journald), console otherwise.
    format: Literal["auto", "json", "console"] = "auto"


class ProfileSettings(_Settings, frozen=True):
    """A named learner profile; unset values take the paper's.

    The limits are LearnerParams', checked in _check_learner: one definition of a
    usable learner, shared with the simulator, which builds LearnerParams directly.
    """

    alpha: float = 0.6
    beta: float = 8.0
    gamma: float = 0.0
    reward_green: float = 1.0
    reward_red: float = -1.0
    initial_q: float = 0.0

    def params(self) -> LearnerParams:
        """The learner these settings describe; LearnerError names an unusable value."""
        return LearnerParams(**msgspec.structs.asdict(self))


# "fast" and "slow" are the paper's future-work learners; the values come from
# `kasparctl simulate --sweep` (see the README for their trials to learn).
BUILTIN_PROFILES: dict[str, ProfileSettings] = {
    "paper": ProfileSettings(),
    "fast": ProfileSettings(alpha=0.9, beta=10.0),
    "slow": ProfileSettings(alpha=0.2, beta=4.0),
}


class LearnerSettings(_Settings, frozen=True):
    """The `[learner]` table: the default profile and the configuration's own profiles."""

    default_profile: str = "paper"
    # Merged over BUILTIN_PROFILES: a configuration may redefine "fast" or add its own.
    profiles: dict[str, ProfileSettings] = {}

    def all_profiles(self) -> dict[str, ProfileSettings]:
        """Every profile by name: the built-in ones, overridden or added to by the file's."""
        return {**BUILTIN_PROFILES, **self.profiles}


ExcludeLearned = Literal["names", "always", "never"]


class GameSettings(_Settings, frozen=True):
    """The `[game]` table: the variant, its toys or locations, timings and researcher controls."""

    # "names": children teach the name of each bagged toy (steps 1-5).
    # "pilot": the paper's pilot, locations are known poses and Kaspar learns which toy goes where.
    variant: Literal["names", "pilot"] = "names"
    toys: Annotated[tuple[Name, ...], msgspec.Meta(min_length=2, extra={"item": "name"})] = (
        "lion",
        "elephant",
        "giraffe",
        "monkey",
        "zebra",
        "crocodile",
    )
    locations: tuple[Name, ...] = ()
    children_per_group: Annotated[int, msgspec.Meta(ge=1, le=MAX_CHILDREN)] = 3
    # Correct answers in a row for the same label before a target counts as
    # learned; 2 gives the pilot's minimum of 2 trials per association.
    correct_answers_to_learn: Annotated[int, msgspec.Meta(ge=1)] = 2
    # A target not learned after this many guesses is left to the researcher.
    max_trials_per_target: int = 30
    # Whether a learned toy is withdrawn from the later targets' choices: "names" (only in
    # the names game, as the paper's step 4 says; in the pilot every location is a problem
    # over all the toys, as its Fig. 2 starting at 2.585 bits for every problem says),
    # "always" (the pilot too: the paper's step-4 elimination across its locations) or
    # "never". docs/simulation.md compares how well each fits the pilot's figures.
    exclude_learned_rule: ExcludeLearned = msgspec.field(default="names", name="exclude_learned")
    seed: int | None = None
    # The arm the children move by hand in step 2, and that points at the toys.
    pointing_group: str = "right_arm"
    # Pilot variant: where each location is (location -> joint -> degrees).
    poses: dict[str, dict[str, float]] = {}
    # Small expressive poses, joint -> degrees, held briefly then undone.
    happy_pose: dict[str, float] = {}
    sad_pose: dict[str, float] = {}
    # Seconds of silence after a question (or a request to show a bag) before each
    # prompt: first, second, then the line that asks the researcher for help.
    prompt_after_s: Annotated[
        tuple[Annotated[float, msgspec.Meta(ge=0.5, le=600.0, extra={"unit": "s"})], ...],
        msgspec.Meta(min_length=1, extra={"item": "delay"}),
    ] = (8.0, 8.0, 12.0)
    # Steps 1 and 3 wait for the researcher's "next": after this long Kaspar says once
    # that it is ready (the children are busy with the bags meanwhile).
    step_prompt_after_s: Annotated[
        float, msgspec.Meta(ge=5.0, le=3600.0, extra={"unit": "s"})
    ] = 90.0
    # A press this soon after an answer is recorded as an extra, not an answer.
    extra_press_gap_s: Annotated[float, msgspec.Meta(ge=0.0, le=10.0, extra={"unit": "s"})] = 1.0
    # The researcher's gestures when their commands are on the children's keyfob
    # ([researcher] source = "keyfob", or while their own device is away): holds of
    # researcher.hold_s, never a double press (children double-tap).
    commands: dict[str, str] = msgspec.field(
        default_factory=lambda: {"long green": "next", "long red": "pause", "both": "stop"}
    )
    # How Kaspar says how sure it is: "paper" (the paper's three levels, one fixed
    # line each, and every line in its first wording) or "varied" (five levels,
    # wordings varied). A session's plan may choose its own.
    script: Literal["paper", "varied"] = "paper"
    # Kaspar's "I'm listening" pose, held from the end of a question until the answer
    # (joint -> degrees; or the poses file's "listening" pose). A clip for the phrase
    # key "cue.listening" in [voice.clips] plays a short sound then too.
    listening_pose: dict[str, float] = {}
    # Pilot: how each location is said in a sentence ("in the box", "on the shelf");
    # a location without one is said with the phrase book's names.where.
    location_phrases: dict[str, Name] = {}
    # Step 2: a bag shown further than this from where it was shown before (in any
    # joint, degrees) is asked for once more; 0 never asks. Kaspar points with the
    # median of every pose shown for the bag.
    pose_check_deg: Annotated[float, msgspec.Meta(ge=0.0, le=360.0, extra={"unit": "deg"})] = 20.0

    @property
    def targets(self) -> tuple[str, ...]:
        """What Kaspar points at: one bag per toy, or the pilot's locations."""
        if self.variant == "pilot":
            return self.locations
        return tuple(f"bag {number}" for number in range(1, len(self.toys) + 1))

    @property
    def exclude_learned(self) -> bool:
        """Whether a learned label is no longer offered for the other targets.

        By `exclude_learned` ("names" by default): in the names game a learned name
        is withdrawn from the later bags (the paper's step 4); in the pilot each
        location is its own problem over all toys unless the rule is "always".
        """
        if self.exclude_learned_rule == "names":
            return self.variant == "names"
        return self.exclude_learned_rule == "always"


# How Kaspar shows how sure it is before each guess: "spoken" (the entropy's line, as in the
# paper), "body" (its thinking behaviour and the way it points), "both", or "none".
UncertaintyMode = Literal["spoken", "body", "both", "none"]
UNCERTAINTY_MODES: tuple[UncertaintyMode, ...] = ("spoken", "body", "both", "none")
# The modes in which Kaspar says it (speak_uncertainty = true).
SPOKEN_MODES = ("spoken", "both")
# A mode's word in the condition label "profile/word": "none" keeps the word sessions had
# before modes ("silent"), so old and new sessions of one condition pool.
CONDITION_LABELS: dict[str, str] = {
    "spoken": "spoken",
    "body": "body",
    "both": "both",
    "none": "silent",
}


class SessionPlan(_Settings, frozen=True):
    """A session planned beforehand: nobody can type during one."""

    group: Annotated[str, msgspec.Meta(pattern=r"\S", extra={"expected": "a group code"})]
    # The group's session: 1 for its first, 2 for the one more it asked for...
    number: Annotated[int, msgspec.Meta(ge=1, le=99)] = 1
    profile: str = "paper"
    # The uncertainty script of this session (game.script when not given).
    script: Literal["paper", "varied"] | None = None
    # How Kaspar shows how sure it is before each guess (UNCERTAINTY_MODES); not given,
    # it follows speak_uncertainty (true: "spoken", false: "none"), else "spoken".
    uncertainty: UncertaintyMode | None = None
    # The older switch, still read: true is "spoken", false is "none". Given together with
    # `uncertainty` it must agree with it (true with spoken or both, false with body or none).
    speak_uncertainty: bool | None = None
    # Gaze and life: Kaspar looks at the child whose turn it is, at the bag it points at and
    # at the researcher, blinks and moves a little; false keeps all of it still this session.
    alive: bool = True
    # First names are optional; without them Kaspar says "child one", "child two"...
    children: Annotated[
        tuple[Name, ...], msgspec.Meta(max_length=MAX_CHILDREN, extra={"item": "name"})
    ] = ()
    # Pseudonymous codes of the children in turn order ("P07"), stable across sessions: what
    # links a child's answers over sessions and to the study's participants.csv.
    participants: Annotated[
        tuple[Code, ...], msgspec.Meta(max_length=MAX_CHILDREN, extra={"item": "code"})
    ] = ()
    group_size: Annotated[int, msgspec.Meta(ge=1, le=MAX_CHILDREN)] | None = None
    # The correct label for each target, in target order; for research records only.
    answer_key: tuple[str, ...] = ()

    @property
    def uncertainty_mode(self) -> UncertaintyMode:
        """The uncertainty mode: `uncertainty`, else speak_uncertainty's, else "spoken"."""
        if self.uncertainty is not None:
            return self.uncertainty
        return "none" if self.speak_uncertainty is False else "spoken"

    @property
    def says_uncertainty(self) -> bool:
        """Whether Kaspar says how sure it is before each guess (spoken or both)."""
        return self.uncertainty_mode in SPOKEN_MODES

    @property
    def shows_uncertainty(self) -> bool:
        """Whether Kaspar's body shows how sure it is before each guess (body or both)."""
        return self.uncertainty_mode in ("body", "both")

    def resolved(self) -> SessionPlan:
        """This plan with its uncertainty mode and speak_uncertainty both written out, as
        plan.json keeps it (older readers read speak_uncertainty)."""
        mode = self.uncertainty_mode
        return msgspec.structs.replace(
            self, uncertainty=mode, speak_uncertainty=mode in SPOKEN_MODES
        )

    @property
    def condition(self) -> str:
        """The experimental condition, "profile/<mode label>" (CONDITION_LABELS)."""
        return f"{self.profile}/{CONDITION_LABELS[self.uncertainty_mode]}"


class DaemonSettings(_Settings, frozen=True):
    """The `[daemon]` table: what the service does with the robot when it stops."""

    # After SIGTERM Kaspar goes to rest at each joint's speed limit, then either
    # holds there ("hold": no slump while the computer shuts down) or goes limp.
    stop_action: Literal["hold", "torque_off"] = "hold"


class GazeSettings(_Settings, frozen=True):
    """The `[body.gaze]` table: where Kaspar's head and eyes turn, as poses (joint = degrees)."""

    ahead: dict[str, float] = {}
    # One pose per seat (the first child's first) and per bag; an index beyond them
    # looks ahead.
    children: tuple[dict[str, float], ...] = ()
    bags: tuple[dict[str, float], ...] = ()
    researcher: dict[str, float] = {}


Seconds = Annotated[float, msgspec.Meta(ge=0.1, le=120.0, extra={"unit": "s"})]


class BodySettings(_Settings, frozen=True):
    """The `[body]` table: Kaspar's body language (kasparctl.body, docs/body.md)."""

    # Off: the game's body shows nothing (kasparctl.body.api.StillBody).
    enabled: bool = False
    # The body's control loop: goals per second to every joint a layer moves.
    rate_hz: Annotated[float, msgspec.Meta(ge=5.0, le=200.0, extra={"unit": "Hz"})] = 50.0
    # The joint that opens the mouth with the voice ("" for none), how far it opens from
    # its rest (signed degrees) and the sound level (RMS of full scale) that opens it fully.
    mouth_joint: str = "mouth_open"
    mouth_open_deg: Annotated[float, msgspec.Meta(ge=-90.0, le=90.0, extra={"unit": "deg"})] = 10.0
    mouth_full_level: Annotated[float, msgspec.Meta(gt=0.0, le=1.0)] = 0.2
    # Seconds between the samples reaching the player and being heard; unset: the
    # player's default (docs/body.md).
    latency_s: Annotated[float, msgspec.Meta(ge=0.0, le=2.0, extra={"unit": "s"})] | None = None
    # Blinks and idle movements at random intervals drawn between the two bounds.
    blink_interval_s: tuple[Seconds, Seconds] = (2.0, 6.0)
    idle_interval_s: tuple[Seconds, Seconds] = (3.0, 9.0)
    # Scales the idle behaviour's offsets (0: no idle movement).
    idle_amplitude: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 1.0
    # A directory of behaviour files replacing the shipped phrases/behaviours/.
    behaviours_dir: str | None = None
    gaze: GazeSettings = GazeSettings()


class Config(_Settings, frozen=True):
    """The whole of kaspar.toml, every table with its defaults."""

    state_dir: str = "/var/lib/kaspar"
    # Names this robot in every session it records (default: default_robot_id()).
    robot_id: Code | None = None
    # A directory of phrase files that overrides the shipped ones.
    phrases_dir: str | None = None
    # Poses recorded by demonstration (`kasparctl pose record`), relative to this file.
    # Its "happy" and "sad" poses are the game's expressions, a pose named like a pilot
    # location is where Kaspar points for it, and "rest" gives the joints' rest positions.
    poses_file: str | None = None
    # What Kaspar speaks: its phrase book, its toys' words and (unless [voice] names
    # one) its voice. docs/languages.md.
    language: Annotated[
        str,
        msgspec.Meta(
            pattern=r"^[A-Za-z]{2,3}([_-][A-Za-z0-9]{2,8})*$",
            extra={"expected": "a language code such as 'en', 'nl', 'de', 'it' or 'fr'"},
        ),
    ] = "en"
    # Toys' words per language, beside or instead of the shipped lexicon
    # (phrases/toys/<language>.toml): language -> toy id -> { name, gender, the }.
    toy_names: dict[str, dict[str, ToyEntry]] = {}
    logging: LoggingSettings = LoggingSettings()
    learner: LearnerSettings = LearnerSettings()
    game: GameSettings = GameSettings()
    sessions: tuple[SessionPlan, ...] = ()
    servos: ServoSettings = ServoSettings()
    keyfob: KeyfobSettings = KeyfobSettings()
    # Where the researcher's commands come from (their own device by default).
    researcher: ResearcherSettings = ResearcherSettings()
    voice: VoiceSettings = VoiceSettings()
    daemon: DaemonSettings = DaemonSettings()
    body: BodySettings = BodySettings()

    def profile(self, name: str | None = None) -> LearnerParams:
        """A profile's learner (the default profile's without a name); KeyError if unknown."""
        return self.learner.all_profiles()[name or self.learner.default_profile].params()

    def robot(self) -> str:
        """The robot's id: the configured robot_id, else the one derived from its machine id."""
        return self.robot_id or default_robot_id()

    def group_size(self, plan: SessionPlan) -> int:
        """How many children a session has: its names or codes, its size, else the game's."""
        if plan.children:
            return len(plan.children)
        if plan.participants:
            return len(plan.participants)
        return plan.group_size or self.game.children_per_group

    def script(self, plan: SessionPlan) -> str:
        """The uncertainty script a planned session uses: its own, else the game's."""
        return plan.script or self.game.script

    def toy_words(self, language: str | None = None, source: str = "kaspar.toml") -> dict[
        str, ToyWords
    ]:
        """The words of each configured toy in `language` (the configured one by default).

        LexiconError for a toy without words in that language (kasparctl.lexicon.resolve).
        """
        language = language or self.language
        return resolve(language, self.game.toys, self.toy_names.get(language, {}), source)


def load_config(path: str | Path, *, poses: bool = True, playable: bool = False) -> Config:
    """Read and validate a configuration file; ConfigError says what is wrong and where.

    `poses=False` leaves the poses file unread (the bring-up commands that write it
    read it themselves, pose by pose). `playable` also holds the rules of a robot the
    game is played on (check_playable): `check`, `run` and `demo` ask for them; the
    bring-up tools read a robot still being put together.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise ConfigError(str(path), "(file)", f"cannot read it: {error.strerror}") from error
    config = parse_config(data, str(path), base_dir=path.parent, poses=poses)
    if playable:
        check_playable(config, str(path))
    return config


def check_playable(config: Config, source: str) -> None:
    """The rules of a robot the game is played on, beyond those of any configuration:
    the arm that points in step 2 is a group of its joints. ConfigError otherwise."""

    def fail(key: str, message: str) -> typing.NoReturn:
        raise ConfigError(source, key, message)

    _check_pointing_group(config, fail)


def parse_config(
    data: bytes | str, source: str, base_dir: Path | None = None, *, poses: bool = True
) -> Config:
    """Validate a configuration's text; `source` names it in errors, `base_dir` anchors paths.

    With `poses`, the poses file (if named) fills the game's poses and the rest
    positions; see apply_poses_file.
    """
    text = _utf8(data, source) if isinstance(data, bytes) else data
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
    if "voice" not in raw.get("voice", {}):
        # The voice follows the language unless the file names one.
        voice = msgspec.structs.replace(config.voice, voice=voice_for_language(config.language))
        config = msgspec.structs.replace(config, voice=voice)
    if base_dir is not None:
        config = _resolve_paths(config, base_dir)
    if poses and config.poses_file is not None:
        config = apply_poses_file(config, source)
    return config


def _utf8(data: bytes, source: str) -> str:
    """The file's text; a byte that is not UTF-8 is an error naming where it is, never
    replaced (a name said aloud and kept in the records must be what the file says)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        column = error.start - (data.rfind(b"\n", 0, error.start) + 1) + 1
        byte = data[error.start : error.start + 1].hex()
        raise ConfigError(
            source,
            "(file)",
            f"expected UTF-8 text, found byte 0x{byte} at line {line}, column {column} "
            f"(byte offset {error.start}): save the file as UTF-8",
        ) from None


def servo_backend_given(path: str | Path) -> bool:
    """Whether the file says which servos it drives: a [servos] table with its `backend`.

    Without one the servos default to simulated ones, which on the robot would be a
    silent simulation: `kasparctl run` (without --sim) and `check` refuse it.
    """
    try:
        raw = tomllib.loads(Path(path).read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False  # load_config says what is wrong with the file itself
    servos = raw.get("servos")
    return isinstance(servos, dict) and "backend" in servos


def _resolve_paths(config: Config, base_dir: Path) -> Config:
    """Relative paths in a configuration are relative to the file, not to the cwd."""
    changes: dict[str, Any] = {"state_dir": str(base_dir / config.state_dir)}
    if config.phrases_dir is not None:
        changes["phrases_dir"] = str(base_dir / config.phrases_dir)
    if config.poses_file is not None:
        changes["poses_file"] = str(base_dir / config.poses_file)
    return msgspec.structs.replace(config, **changes)


# --- the poses file (kept apart: only poses_file reaches here) ---------------------------

# The poses the game takes from the poses file, besides the pilot's locations.
REST_POSE = "rest"
HAPPY_POSE = "happy"
SAD_POSE = "sad"
LISTENING_POSE = "listening"


def read_poses(path: str | Path) -> dict[str, dict[str, float]]:
    """The poses of a poses file: `[name]` tables of joint = degrees.

    ConfigError names the file, and the pose and joint at fault, for a file that
    cannot be read or parsed and for a value that is not a finite number.
    """
    source = str(path)
    try:
        text = _utf8(Path(path).read_bytes(), source)
    except OSError as error:
        raise ConfigError(source, "(file)", f"cannot read it: {error.strerror}") from error
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(source, "(syntax)", f"not valid TOML: {error}") from error
    poses: dict[str, dict[str, float]] = {}
    for name, table in raw.items():
        if not isinstance(table, dict):
            found = type(table).__name__
            raise ConfigError(source, name, f"expected a [{name}] table of joint = degrees, "
                              f"found a {found}")
        pose = {}
        for joint, degrees in table.items():
            if isinstance(degrees, bool) or not isinstance(degrees, int | float) or not (
                math.isfinite(degrees)
            ):
                raise ConfigError(source, f"{name}.{joint}",
                                  f"expected a finite number of degrees, found {degrees!r}")
            pose[joint] = float(degrees)
        poses[name] = pose
    return poses


def check_pose(
    pose: dict[str, float], name: str, servos: ServoSettings, source: str
) -> None:
    """Refuse a pose with an unknown joint or one outside its safe range, naming both."""
    joints = {joint.name: joint for joint in servos.joints}
    for joint_name, degrees in pose.items():
        joint = joints.get(joint_name)
        if joint is None:
            known = ", ".join(joints) or "none configured"
            raise ConfigError(source, f"{name}.{joint_name}",
                              f"not a configured joint (joints: {known})")
        low, high = joint.range_deg
        if not low <= degrees <= high:
            raise ConfigError(
                source, f"{name}.{joint_name}",
                f"pose {name!r} puts joint {joint_name!r} at {degrees} deg, outside its "
                f"safe range [{low}, {high}]",
            )


def apply_poses_file(config: Config, config_source: str) -> Config:
    """The configuration with the poses file's poses in the game and the joints' rest.

    Every pose is checked against the joints' ranges. "happy", "sad" and "listening"
    become game.happy_pose, game.sad_pose and game.listening_pose, a pose named like a
    pilot location game.poses[location], and "rest" the rest_deg of the joints it names. A pose
    also written inline in [game] is refused, as is a pilot whose locations are
    only partly posed. Errors name the poses file, the pose and the joint.
    """
    assert config.poses_file is not None
    source = config.poses_file
    poses = read_poses(source)
    for name, pose in poses.items():
        check_pose(pose, name, config.servos, source)
    game = config.game
    changes: dict[str, Any] = {}
    named = ((HAPPY_POSE, "happy_pose"), (SAD_POSE, "sad_pose"), (LISTENING_POSE, "listening_pose"))
    for name, field in named:
        if name in poses:
            if getattr(game, field):
                raise ConfigError(config_source, f"game.{field}",
                                  f"also given as pose {name!r} in {source}: keep one")
            changes[field] = poses[name]
    located = {location: poses[location] for location in game.locations if location in poses}
    if located:
        if game.poses:
            raise ConfigError(config_source, "game.poses",
                              f"also given as poses in {source}: keep one")
        missing = [location for location in game.locations if location not in located]
        if missing:
            raise ConfigError(source, "(poses)",
                              f"no pose for pilot location {', '.join(map(repr, missing))}: "
                              "record one per location, or none")
        changes["poses"] = located
    servos = config.servos
    if REST_POSE in poses:
        rest = poses[REST_POSE]
        servos = msgspec.structs.replace(servos, joints=tuple(
            msgspec.structs.replace(j, rest_deg=rest[j.name]) if j.name in rest else j
            for j in servos.joints
        ))
    return msgspec.structs.replace(
        config, game=msgspec.structs.replace(game, **changes), servos=servos
    )


_PATH_SEGMENT = re.compile(r"\.([A-Za-z_][\w-]*)|\[(\d+|\.\.\.)\]")
# msgspec's words for a value outside a field's msgspec.Meta limits.
_CONSTRAINT = re.compile(
    r"Expected `\w+` (?:(?P<length>of length )|(?P<regex>matching regex )|[<>]=? )"
)


def _explain_validation_error(text: str, raw: dict[str, Any]) -> tuple[str, str]:
    """Turn msgspec's "message - at `$.a.b[0]`" into a key path and a readable message."""
    message, _, where = text.rpartition(" - at ")
    if not message:
        message, where = text, ""
    segments = [name or f"[{index}]" for name, index in _PATH_SEGMENT.findall(where.strip("`$"))]
    segments, value = _follow(segments, raw)
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
    if bad_choice and typing.get_origin(_bare(field_type)) is Literal:
        choices = ", ".join(repr(choice) for choice in typing.get_args(_bare(field_type)))
        message = f"expected one of {choices}, found {bad_choice.group(1)}"
    got = re.fullmatch(r"Expected `(.+)`, got `(.+)`", message)
    if got:
        # TOML has no null: a key that may be left out is not "bool | null" to its reader.
        message = f"expected {got.group(1).removesuffix(' | null')}, found {got.group(2)}"
    constraint = _CONSTRAINT.match(message)
    if constraint:
        message = _explain_constraint(constraint, field_type, value)
    key = "".join(s if s.startswith("[") else f".{s}" for s in segments).lstrip(".")
    return key or "(top level)", message


def _follow(segments: list[str], raw: Any) -> tuple[list[str], Any]:
    """The failing value, found by following the path through the parsed TOML.

    msgspec writes a table of tables' key as [...]; the entry that fails is named.
    The value is None where the path leads nowhere (TOML itself has no null).
    """
    named: list[str] = []
    for segment in segments:
        if segment == "[...]" and isinstance(raw, dict):
            entry_type = _type_at([*named, "[...]"])
            segment = next(
                (key for key, value in raw.items() if not _converts(value, entry_type)), "[...]"
            )
        named.append(segment)
        if isinstance(raw, dict):
            raw = raw.get(segment)
        elif isinstance(raw, list) and segment.strip("[]").isdigit():
            index = int(segment.strip("[]"))
            raw = raw[index] if index < len(raw) else None
        else:
            raw = None
    return named, raw


def _converts(value: Any, target_type: Any) -> bool:
    try:
        msgspec.convert(value, type=target_type)
    except msgspec.ValidationError:
        return False
    return True


def _type_at(segments: list[str]) -> Any:
    """The declared type at a key path, with its Annotated limits kept."""
    current: Any = Config
    for segment in segments:
        bare = _bare(current)
        if isinstance(bare, type) and issubclass(bare, msgspec.Struct):
            # A field may have another name in the file than in Python (exclude_learned).
            names = {f.encode_name: f.name for f in msgspec.structs.fields(bare)}
            hints = typing.get_type_hints(bare, include_extras=True)
            current = hints.get(names.get(segment, segment))
        elif typing.get_origin(bare) in (tuple, list, dict):
            current = typing.get_args(bare)[-1 if typing.get_origin(bare) is dict else 0]
        if typing.get_origin(current) in (typing.Union, types.UnionType):
            current = next(a for a in typing.get_args(current) if a is not type(None))
    return current


def _bare(annotated: Any) -> Any:
    """A type without its Annotated limits."""
    while typing.get_origin(annotated) is Annotated:
        annotated = typing.get_args(annotated)[0]
    return annotated


def _field_names(struct_type: Any) -> list[str]:
    struct_type = _bare(struct_type)
    if isinstance(struct_type, type) and issubclass(struct_type, msgspec.Struct):
        return [f.encode_name for f in msgspec.structs.fields(struct_type)]
    return []


def _explain_constraint(constraint: re.Match[str], field_type: Any, value: Any) -> str:
    """Word a failed msgspec.Meta limit as "expected 1 to 6, found 9", from the field's limits."""
    limits = _Limits.of(field_type)
    if constraint["length"]:
        expected = limits.expected or limits.length()
        found = None if value is None else str(len(value))
    else:
        expected = limits.expected or limits.value(pattern=bool(constraint["regex"]))
        found = _describe(value, _bare(field_type))
    return f"expected {expected}" if found is None else f"expected {expected}, found {found}"


class _Limits(msgspec.Struct, frozen=True, kw_only=True):
    """The msgspec.Meta limits of one field, merged, with the words to say them."""

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    min_length: int | None = None
    max_length: int | None = None
    pattern: str | None = None
    expected: str | None = None
    unit: str = ""
    item: str = "item"

    @classmethod
    def of(cls, field_type: Any) -> _Limits:
        """The limits in a type's Annotated metadata; Annotated may be nested."""
        limits: dict[str, Any] = {"item": "character"} if _bare(field_type) is str else {}
        while typing.get_origin(field_type) is Annotated:
            field_type, *metadata = typing.get_args(field_type)
            for meta in metadata:
                if isinstance(meta, msgspec.Meta):
                    limits.update(
                        (name, getattr(meta, name))
                        for name in cls.__struct_fields__
                        if getattr(meta, name, None) is not None
                    )
                    limits.update(meta.extra or {})
        return cls(**{name: limits[name] for name in cls.__struct_fields__ if name in limits})

    def value(self, pattern: bool) -> str:
        """A number's range ("0 to 10 s", ">= 1"), or a text's pattern."""
        if pattern:
            return f"text matching {self.pattern!r}"
        if self.ge is not None and self.le is not None:
            bounds = f"{_number(self.ge)} to {_number(self.le)}"
        else:
            signs = {">=": self.ge, ">": self.gt, "<=": self.le, "<": self.lt}
            bounds = " and ".join(
                f"{sign} {_number(bound)}" for sign, bound in signs.items() if bound is not None
            )
        return f"{bounds} {self.unit}".rstrip()

    def length(self) -> str:
        """A sequence's size: "at least 2 names", "1 to 3 delays", "at most 1 item"."""
        low, high = self.min_length, self.max_length
        if high is None:
            count, last = f"at least {low}", low
        elif low is None:
            count, last = f"at most {high}", high
        else:
            count, last = (f"{low} to {high}" if low < high else f"exactly {high}"), high
        return f"{count} {self.item}{'' if last == 1 else 's'}"


def _number(value: float) -> str:
    """A limit as a person writes it: 10.0 is "10", 0.5 stays "0.5"."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return str(value)


def _describe(value: Any, field_type: Any) -> str | None:
    """A found value as the messages show it: a number as is, text quoted, blank named."""
    if value is None:
        return None
    if isinstance(value, str):
        return repr(value) if value.strip() else "an empty string"
    if field_type is float and isinstance(value, int) and not isinstance(value, bool):
        return str(float(value))  # TOML's 5 read into a float field is 5.0
    return str(value)


# Raises the ConfigError for a key and a message.
_Fail = typing.Callable[[str, str], typing.NoReturn]


def _validate(config: Config, source: str) -> None:
    """Rules that span several keys, table by table; each names the key that is wrong.

    A key's own limits are on its field (msgspec.Meta) and already held.
    """

    def fail(key: str, message: str) -> typing.NoReturn:
        raise ConfigError(source, key, message)

    _check_learner(config.learner, fail)
    _check_game(config.game, fail)
    _check_game_controls(config.game, fail)
    _check_game_servos(config, fail)
    _check_sessions(config, fail)
    _check_researcher(config, fail)
    _check_interaction(config.game, fail)
    _check_body(config, fail)
    _check_toy_names(config, source)


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
    _check_profile_name(learner, learner.default_profile, "learner.default_profile", fail)


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


def _check_plan(plan: SessionPlan, where: str, config: Config, fail: _Fail) -> None:
    _check_profile_name(config.learner, plan.profile, f"{where}.profile", fail)
    _check_word(plan.group, f"{where}.group", GROUP_CODE_LIMIT, fail)
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
        _check_answer_key(plan.answer_key, config.game, f"{where}.answer_key", fail)
    _check_uncertainty(plan, where, fail)


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


def _check_researcher(config: Config, fail: _Fail) -> None:
    """The researcher's commands: each a command, the ones a session needs all there."""
    researcher = config.researcher
    if researcher.source == "device":
        keys, where = researcher.keys, "researcher.keys"
    elif researcher.source == "keypad":
        keys, where = config.keyfob.commands, "keyfob.commands"
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
