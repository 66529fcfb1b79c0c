"""The schema of kaspar.toml: one strict, frozen msgspec struct per table.

A key's own limits live on its type (msgspec.Meta), so msgspec holds them as it
reads; kasparctl.config.explain words a failure from them, and the rules that
span several keys are kasparctl.config.rules'. Every struct rejects unknown
keys: a misspelt key never silently falls back to a default in front of children.
"""

from __future__ import annotations

import hashlib
import socket
from pathlib import Path
from typing import Annotated, Literal

import msgspec

from hal.keyfob.settings import KeyfobSettings, ResearcherSettings
from hal.servos.settings import ServoSettings
from hal.voice.settings import VoiceName, VoiceSettings
from kasparctl.learning.learner import LearnerParams
from kasparctl.lexicon import ToyEntry, ToyWords, resolve
from kasparctl.vocabulary import MAX_CHILDREN


class _Settings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Base of every table: strict (unknown keys rejected) and immutable.

    Subclasses repeat frozen=True only for mypy, which does not see it inherited.
    """


# A field's own limits live on its type as msgspec.Meta; kasparctl.config.explain words
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


# How Kaspar shows how sure it is before each guess: "spoken" (the entropy's line, as in the
# paper), "body" (its thinking behaviour and the way it points), "both", or "none".
UncertaintyMode = Literal["spoken", "body", "both", "none"]
Reactions = Literal["paper", "all", "none"]
# Movement speed: every joint's speed limit times this, for a session (1: the limits).
SpeedScale = Annotated[float, msgspec.Meta(ge=0.1, le=1.0)]
Toys = Annotated[tuple[Name, ...], msgspec.Meta(min_length=2, extra={"item": "name"})]
PromptDelays = Annotated[
    tuple[Annotated[float, msgspec.Meta(ge=0.5, le=600.0, extra={"unit": "s"})], ...],
    msgspec.Meta(min_length=1, extra={"item": "delay"}),
]
StepPrompt = Annotated[float, msgspec.Meta(ge=5.0, le=3600.0, extra={"unit": "s"})]
Language = Annotated[
    str,
    msgspec.Meta(
        pattern=r"^[A-Za-z]{2,3}([_-][A-Za-z0-9]{2,8})*$",
        extra={"expected": "a language code such as 'en', 'nl', 'de', 'it' or 'fr'"},
    ),
]
Rate = Annotated[int, msgspec.Meta(ge=80, le=450, extra={"unit": "words per minute"})]
Volume = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
Pitch = Annotated[int, msgspec.Meta(ge=0, le=99)]
# The keys of a profile that are the learner's own (LearnerParams').
LEARNER_KEYS = ("alpha", "beta", "gamma", "reward_green", "reward_red", "initial_q")


class VoiceOverrides(_Settings, frozen=True):
    """A session's or a profile's voice: each key unset takes the next level's ([voice])."""

    engine: Literal["pyttsx3", "espeak-ng"] | None = None
    voice: VoiceName | None = None
    rate: Rate | None = None
    volume: Volume | None = None
    pitch: Pitch | None = None


class ProfileSettings(_Settings, frozen=True):
    """A named learner profile; unset values take the paper's. Its other keys shape
    every session of the profile.

    The limits are LearnerParams', checked by kasparctl.config.rules: one definition of a
    usable learner, shared with the simulator, which builds LearnerParams directly.
    """

    alpha: float = 0.6
    beta: float = 8.0
    gamma: float = 0.0
    reward_green: float = 1.0
    reward_red: float = -1.0
    initial_q: float = 0.0
    # What the profile gives every session that uses it, beside its learner; unset, the
    # robot-wide key of the same name ([game], [voice], language). A [[sessions]] entry's
    # own keys of the same names come first (kasparctl.config.session_settings).
    toys: Toys | None = None
    locations: tuple[Name, ...] | None = None
    correct_answers_to_learn: Annotated[int, msgspec.Meta(ge=1)] | None = None
    max_trials_per_target: int | None = None
    script: Literal["paper", "varied"] | None = None
    uncertainty: UncertaintyMode | None = None
    prompt_after_s: PromptDelays | None = None
    step_prompt_after_s: StepPrompt | None = None
    reactions: Reactions | None = None
    alive: bool | None = None
    speed_scale: SpeedScale | None = None
    language: Language | None = None
    voice: VoiceOverrides | None = None

    def params(self) -> LearnerParams:
        """The learner these settings describe; LearnerError names an unusable value."""
        return LearnerParams(**{name: getattr(self, name) for name in LEARNER_KEYS})

    def shaped(self, game: GameSettings) -> GameSettings:
        """`game` with this profile's game-shaping values over it (robot-wide < profile)."""
        if self.correct_answers_to_learn is None:
            return game
        return msgspec.structs.replace(game, correct_answers_to_learn=self.correct_answers_to_learn)


# "fast" and "slow" are the paper's future-work learners, designed with `kasparctl simulate`
# to be told apart by children (docs/simulation.md, "fast, paper and slow"): the number of
# greens is what changes the game's length; alpha * beta stays at or above the paper's 4.8,
# so neither comes back to a toy just answered red more often than the paper's learner.
BUILTIN_PROFILES: dict[str, ProfileSettings] = {
    "paper": ProfileSettings(),
    "fast": ProfileSettings(alpha=0.9, beta=10.0, correct_answers_to_learn=1),
    "slow": ProfileSettings(alpha=0.6, beta=8.0, correct_answers_to_learn=3),
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
OutOfTurn = Literal["ignore", "take"]


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
    # One keyfob per child ([[keyfob.children]]): a press in step 4 from a child whose
    # turn it is not is recorded and not taken ("ignore"), or taken as the answer and
    # credited to that child ("take"). A session's plan may choose its own.
    answer_out_of_turn: OutOfTurn = "ignore"
    # Gaze and life for every session that does not say (a session's `alive`, its profile's).
    alive: bool = True
    # Every joint's speed limit times this in a session: a slower robot (0.1 to 1).
    speed_scale: SpeedScale = 1.0
    # Kaspar's expressions after an answer: "paper" (happy on learning a name only, as in
    # the paper), "all" (happy on learning, sad after a red) or "none".
    reactions: Literal["paper", "all", "none"] = "paper"
    # Step 2: a green with the arm within this many degrees (every joint of the pointing
    # arm) of its rest pose or of the bag shown just before is taken for an arm nobody
    # moved: Kaspar asks again, up to unmoved_arm_asks times for a bag, then takes it (a
    # bag may really be there). 0 never asks.
    unmoved_arm_deg: Annotated[float, msgspec.Meta(ge=0.0, le=90.0, extra={"unit": "deg"})] = 4.0
    unmoved_arm_asks: Annotated[int, msgspec.Meta(ge=0, le=10)] = 2

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
    # Not given: the profile's, else game.alive.
    alive: bool | None = None
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
    # With one keyfob per child: this session's game.answer_out_of_turn.
    answer_out_of_turn: OutOfTurn | None = None
    # What this session's group experiences, each unset taking its profile's, then the
    # robot-wide key of the same name ([game], [voice], language): see
    # kasparctl.config.session_settings, which resolves them, and docs/configuration.md.
    toys: Toys | None = None
    locations: tuple[Name, ...] | None = None
    correct_answers_to_learn: Annotated[int, msgspec.Meta(ge=1)] | None = None
    max_trials_per_target: int | None = None
    prompt_after_s: PromptDelays | None = None
    step_prompt_after_s: StepPrompt | None = None
    reactions: Reactions | None = None
    speed_scale: SpeedScale | None = None
    language: Language | None = None
    voice: VoiceOverrides | None = None

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


class RobotSettings(_Settings, frozen=True):
    """The `[robot]` table: who this robot is to the children and in the records."""

    # Said in the greeting ("I am Kaspar"): two robots of one study can be told apart.
    name: Annotated[str, msgspec.Meta(pattern=r"^\S(.*\S)?$", extra={"expected": "a name"})] = (
        "Kaspar"
    )


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
    # This individual robot's servo centres (`[joint] centre_raw = N` tables), relative to
    # this file, merged over [servos] (kasparctl.config.centres; docs/servos.md).
    centres_file: str | None = None
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
    # The planned sessions in a file of their own (`kasparctl plan` writes one per robot),
    # relative to this file, instead of [[sessions]] here (kasparctl.config.sessions_file).
    sessions_file: str | None = None
    # [robot]; `robot()` is the robot's id (robot_id), this its table.
    robot_settings: RobotSettings = msgspec.field(default_factory=RobotSettings, name="robot")

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

