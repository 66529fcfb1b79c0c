"""What a session records: one typed struct per kind of record, a tagged union on "kind".

Each line of records.jsonl is one of these, as a JSON object whose "kind"
names its struct. kasparctl.game.jsonl is the one place that encodes and
decodes them; everything else (the game, GameState.apply, the research
exports, the statistics, the simulations) reads their typed fields.

Every record carries `seq` (its place in the log, from 1), `time` (UTC, ISO
8601) and `clock` (the event loop's clock), stamped by the session when it is
written. A field that only some records of a kind have (a press's `ignored`,
a fault's `joint`) is UNSET when absent, and then not written at all: a
record reads back exactly as it was written, which keeps the sessions
recorded before these structs existed readable and their exports unchanged.
"""

from __future__ import annotations

import enum
from typing import Any, Literal

import msgspec
from msgspec import UNSET, UnsetType

from kasparctl.vocabulary import Command


class SessionEvent(enum.StrEnum):
    """What a "session" record says happened to the session as a whole."""

    START = "start"
    RESUMED = "resumed"
    # The daemon stopped mid-session: it is left unfinished, to be resumed at the next start.
    SHUTDOWN = "shutdown"
    # An unfinished session that could not be resumed (its records damaged, its learner
    # profile gone...): closed for good, with the reason; the next session starts anew.
    ABANDONED = "abandoned"
    # The researcher closed a stopped session for good: its plan is done.
    CLOSED = "closed"
    # The planned group did not come: marked absent in idle, never opened (the session's
    # only records); PRESENT takes the mark back (the group came after all).
    ABSENT = "absent"
    PRESENT = "present"


class HalEvent(enum.StrEnum):
    """What a "hal" record reports of the hardware."""

    KEYFOB_LOST = "keyfob_lost"
    KEYFOB_BACK = "keyfob_back"
    # The researcher's own device (a keypad) gone and back.
    RESEARCHER_LOST = "researcher_lost"
    RESEARCHER_BACK = "researcher_back"
    # A line that was not heard to its end (timed out or failed).
    VOICE = "voice"
    # The battery fell below [servos.battery] warn_below_v, or came back above it.
    BATTERY_LOW = "battery_low"
    BATTERY_OK = "battery_ok"
    # The children's keyfob sent nothing through a whole prompt cycle while the
    # researcher's device was there: a flat battery, suspected; heard again at its next key.
    KEYFOB_SILENT = "keyfob_silent"
    KEYFOB_HEARD = "keyfob_heard"


class FaultSource(enum.StrEnum):
    """Which part failed: what a "fault" record's `fault` names, and what Kaspar says about it."""

    SERVO = "servo"
    KEYFOB = "keyfob"
    VOICE = "voice"
    # A step that raised an error no hardware explains: a bug, recorded and stopped like a fault.
    SOFTWARE = "software"
    # A record or snapshot that could not be written (the disk full, the state directory
    # unwritable): the game stops rather than play on unsaved.
    STORAGE = "storage"
    # The researcher's own device is gone: nothing stops (their commands go to the
    # children's keyfob as holds meanwhile), but it is shown and said.
    RESEARCHER = "researcher"
    # The children's keyfob silent through a whole prompt cycle while the researcher's
    # device works (its battery, suspected): nothing stops, it is shown and said once.
    KEYFOB_SILENT = "keyfob_silent"


class Confirmation(enum.StrEnum):
    """What a researcher's command did; Kaspar confirms it with the phrase confirm.<value>."""

    START = "start"
    NEXT_STEP = "next_step"
    PAUSE = "pause"
    RESUME = "resume"
    UNDO = "undo"
    STOP = "stop"
    # A stop given in idle while a stopped session waits: it is closed for good.
    CLOSE = "close"
    # The name learned last is learned no more (kasparctl.game.recovery).
    REOPEN = "reopen"
    # In idle: the next planned session chosen; the chosen group marked absent, or the
    # mark taken back (kasparctl.game.opening). Kaspar says nothing to the children.
    CHOOSE = "choose"
    ABSENT = "absent"
    PRESENT = "present"
    # Step 4: the child whose turn it is taken out of the rotation; a child brought back
    # (kasparctl.game.rotation).
    AWAY = "away"
    BACK = "back"
    # The researcher's "next" while Kaspar checks the buttons: the check is skipped.
    SKIP_CHECK = "skip_check"


Button = Literal["green", "red"]


class Record(msgspec.Struct, tag_field="kind", frozen=True):
    """Fields every record has; the session stamps them when it writes the record."""

    seq: int = 0
    time: str = ""
    clock: float = 0.0


class SessionRecord(Record, tag="session", kw_only=True, frozen=True):
    """The session started (with its plan), was resumed, or was left at a shutdown."""

    event: SessionEvent
    # start: plan.json as written (session, created, group, condition, variant, seed, plan).
    plan: dict[str, Any] | UnsetType = UNSET
    # resumed: the machine's state it resumed in, and the trials recorded before.
    step: str | UnsetType = UNSET
    trials: int | UnsetType = UNSET
    # shutdown: why the daemon stopped, and the machine's state then; abandoned: why the
    # session could not be resumed, and the step it had reached ("unknown" if unreadable).
    reason: str | UnsetType = UNSET
    state: str | UnsetType = UNSET
    # resumed: what the resume found and repaired (a torn last line moved aside), one
    # line each; absent when it found nothing.
    repaired: list[str] | UnsetType = UNSET


class CommandRecord(Record, tag="command", kw_only=True, frozen=True):
    """A researcher's command: applied (with its confirmation) or ignored (with why)."""

    command: Command
    gesture: str
    at: float
    # The machine's state when the command came.
    state: str
    applied: bool
    confirm: Confirmation | UnsetType = UNSET
    ignored: str | UnsetType = UNSET
    # Where it came from: "researcher" (their own device), "keypad" (an extra key of
    # the children's keypad) or "keyfob" (a hold on the children's keyfob).
    source: str | UnsetType = UNSET
    # choose, absent, and next starting a chosen session: the planned group and number.
    group: str | UnsetType = UNSET
    number: int | UnsetType = UNSET
    # away: the child taken out or brought back.
    child: str | UnsetType = UNSET
    child_index: int | UnsetType = UNSET


class PressRecord(Record, tag="press", kw_only=True, frozen=True):
    """A key press that was not an answer: too early, extra, a retry while teaching, or unused."""

    button: str
    at: float
    # The gesture's name: one that had no command, or what an answer's press went on to
    # be ("long green", "both": an extra of the answer, never a command).
    gesture: str | UnsetType = UNSET
    ignored: str | UnsetType = UNSET
    # Before Kaspar had finished asking; `acknowledged` when Kaspar said so.
    early: bool | UnsetType = UNSET
    acknowledged: bool | UnsetType = UNSET
    # A second press right after an answer (or the rest of the answer's gesture), and
    # the trial it followed (absent while teaching: a pose has no trial).
    extra: bool | UnsetType = UNSET
    trial: int | UnsetType = UNSET
    # While teaching: the bag whose pose was asked again, and joints outside their range.
    teach_retry: int | UnsetType = UNSET
    outside: list[str] | UnsetType = UNSET
    # While teaching: the arm was where it had been, "rest" or "bag N" (GameSettings.
    # unmoved_arm_deg), so the press was not taken as the bag's pose.
    unmoved: str | UnsetType = UNSET
    # One keyfob per child: the seat (from 1) and device pressed, the child seated there
    # (their place from 0), and, for a press out of turn, the child whose turn it was.
    seat: int | UnsetType = UNSET
    device: str | UnsetType = UNSET
    pressed_by: str | UnsetType = UNSET
    pressed_by_index: int | UnsetType = UNSET
    turn_of_index: int | UnsetType = UNSET


class PromptRecord(Record, tag="prompt", kw_only=True, frozen=True):
    """Nobody answered for `waited` seconds, so Kaspar said the prompt `line` (a phrase key)."""

    line: str
    waited: float


class FaultRecord(Record, tag="fault", kw_only=True, frozen=True):
    """A part failed, in the machine's `state`; `joint` for a servo, null for other parts."""

    fault: FaultSource
    detail: str
    state: str
    # Written by a fault the game stopped for (null unless a servo joint); absent for a
    # failure while resting or rearming, which is recorded but stops nothing.
    joint: str | UnsetType | None = UNSET


class HalRecord(Record, tag="hal", kw_only=True, frozen=True):
    """The keyfob lost or back, a line of speech not heard to its end, the battery low or ok."""

    event: HalEvent
    reason: str | UnsetType = UNSET  # keyfob_lost
    device: str | UnsetType = UNSET  # keyfob_back
    status: str | UnsetType = UNSET  # voice: the SpokenStatus value
    text: str | UnsetType = UNSET  # voice
    error: str | UnsetType | None = UNSET  # voice
    voltage_v: float | UnsetType = UNSET  # battery_low, battery_ok: the reading
    warn_below_v: float | UnsetType = UNSET  # battery: the line it crossed
    joint: str | UnsetType = UNSET  # battery: whose servo read it
    # One keyfob per child: the seat (from 1) whose keyfob was lost or is back.
    seat: int | UnsetType = UNSET


class PoseRecord(Record, tag="pose", kw_only=True, frozen=True):
    """A child showed Kaspar where bag `bag` is, in teaching round `round`: joint -> degrees.

    Recorded by the game since step 2 names its children: `rule` "median" (Kaspar
    points with the median of every pose shown for the bag; absent in older
    sessions, where the last round's pose was used), who moved the arm and who
    pressed, and `check_again` when the pose was far from where the bag was shown
    before and Kaspar asked for it once more (it counts, the bag is asked again).
    """

    bag: int
    round: int
    pose: dict[str, float]
    at: float
    rule: str | UnsetType = UNSET
    mover: str | UnsetType = UNSET
    presser: str | UnsetType = UNSET
    check_again: bool | UnsetType = UNSET


class StepRecord(Record, tag="step", kw_only=True, frozen=True):
    """The game entered `to`: one of the steps, "finished" or "stopped"."""

    to: str


class UndoRecord(Record, tag="undo", kw_only=True, frozen=True):
    """The researcher took back the answer to trial `trial` (the last one)."""

    trial: int


class QuestionRecord(Record, tag="question", kw_only=True, frozen=True):
    """Kaspar is about to ask a question of step 4: where it points, whose turn, how sure it is.

    Written when the trial is planned, before Kaspar speaks, so a reader (the
    researcher's live view, `kasparctl watch`) sees the open question; history
    only, it changes no state. The trial record of the same number answers it and
    repeats these fields; a question asked again (after a pause, a fault or a
    resume) is recorded again, with the same values.
    """

    trial: int
    problem_trial: int
    target: str
    target_index: int
    child: str
    child_index: int
    candidates: list[str]
    # Over every toy, as in the trial record: 0 for those no longer offered.
    probabilities: list[float]
    entropy: float
    band: str | None
    choice: str
    choice_index: int


class TrialRecord(Record, tag="trial", kw_only=True, frozen=True):
    """One guess: the question Kaspar asked, the answer, and what the learner made of it.

    docs/research-data.md documents every field (as the trials CSV's columns).
    """

    trial: int
    problem_trial: int
    step: str
    target: str
    target_index: int
    child: str
    child_index: int
    candidates: list[str]
    probabilities: list[float]
    entropy: float
    band: str | None
    spoken: list[str]
    choice: str
    choice_index: int
    feedback: Button
    question_end: float
    feedback_at: float
    reaction_time: float
    reward: float
    q_before: list[float]
    q_after: list[float]
    # The learner's generator after this guess's draw (numpy's bit_generator.state).
    learner_rng: dict[str, Any]
    perseverative: bool
    win_shift: bool
    correct: bool | None
    feedback_right: bool | None
    learned: bool
    # Pressed in the question's last words (before question_end, so the reaction time
    # is negative) and taken as the answer; absent otherwise.
    in_question: bool | UnsetType = UNSET
    # Sessions planned with recovery (kasparctl.game.recovery): the labels (indices)
    # whose last answer on this target is red, after this answer. Absent before.
    rejected: list[int] | UnsetType = UNSET
    # One keyfob per child: the seat (from 1) and device that answered, and the child
    # credited with the answer (the seat's child: `child` unless an answer out of turn
    # was taken, game.answer_out_of_turn = "take"). Absent with one shared keyfob.
    seat: int | UnsetType = UNSET
    device: str | UnsetType = UNSET
    credited: str | UnsetType = UNSET
    credited_index: int | UnsetType = UNSET

    @property
    def green(self) -> bool:
        """Whether the children said yes."""
        return self.feedback == "green"


class ConfusedRecord(Record, tag="confused", kw_only=True, frozen=True):
    """Kaspar is confused about `target` after trial `trial`, says so and asks the researcher.

    `reason` "all_rejected": every name still offered was answered red on this
    target; "learned_elsewhere": `name`, learned for another target (`learned_for`),
    was answered green here. `reopen_target` and `reopen_name` are what the
    researcher's re-open would re-open (the name learned last), None if nothing is
    learned. Changes the state: Kaspar says it once per target until a re-open.
    """

    trial: int
    target: str
    target_index: int
    reason: str
    rejected: list[str]
    reopen_target: str | None
    reopen_name: str | None
    name: str | UnsetType = UNSET
    learned_for: str | UnsetType = UNSET


class ReopenRecord(Record, tag="reopen", kw_only=True, frozen=True):
    """The researcher re-opened `name`, learned last, for `target`: it is learned no more,
    offered again, and the target is asked again once the current one is done.

    `trial` is the number of trials recorded before it. `taken_back` when the
    researcher's undo took that re-open back (the name is learned again).
    """

    trial: int
    target: str
    target_index: int
    name: str
    name_index: int
    taken_back: bool | UnsetType = UNSET


class ButtonCheckRecord(Record, tag="button_check", kw_only=True, frozen=True):
    """At the start of a session Kaspar asked for the button `asked` (kasparctl.game.buttons):
    `pressed` is the button that answered and `at` its key-down, or `skipped` when the
    researcher's "next" skipped the rest of the check. No trial, no answer: history only."""

    asked: Button
    pressed: str | UnsetType = UNSET
    at: float | UnsetType = UNSET
    skipped: bool | UnsetType = UNSET


class AlertRecord(Record, tag="alert", kw_only=True, frozen=True):
    """Something the researcher should know, found with the plan's answer key.

    `alert` "right_toy_withdrawn": after trial `trial`, `toy`, the right toy of the
    open target `target` (per the answer key), is no longer offered, because it
    was learned for `learned_for`. History only: the learner never sees the key.
    """

    alert: str
    trial: int
    target: str
    target_index: int
    toy: str
    learned_for: str


class RotationRecord(Record, tag="rotation", kw_only=True, frozen=True):
    """Whose turn it is in step 4 changed without an answer (kasparctl.game.rotation).

    `event` "away": the researcher took `child` out of the rotation; "back": brought
    them back; "skipped": their turn was passed over, for `reason` ("away", or "keyfob
    absent": their seat's keyfob is not connected). `turn` is the rotation's turn
    (GameState.turn) after it. Changes the state.
    """

    event: Literal["away", "back", "skipped"]
    child: str
    child_index: int
    turn: int
    reason: str | UnsetType = UNSET
    seat: int | UnsetType = UNSET


class ClockRecord(Record, tag="clock", kw_only=True, frozen=True):
    """The wall clock's state (kasparctl.game.wallclock): at the session's start or resume,
    and whenever the daemon saw the wall clock jump against the monotonic one.

    `synchronised` whether it can be trusted (systemd-timesyncd says NTPSynchronized),
    `source` "timesyncd" or "unsynchronised"; `offset` the wall clock minus the
    monotonic one (s) and `step` how far that moved since the last reading (0.0 at a
    start); `boot` the kernel's boot id, the monotonic clock's reference. History only:
    every order and age is taken from seq and `clock`, never from `time`.
    """

    synchronised: bool
    source: str
    offset: float
    step: float
    boot: str = ""


AnyRecord = (
    SessionRecord
    | CommandRecord
    | PressRecord
    | PromptRecord
    | FaultRecord
    | HalRecord
    | PoseRecord
    | StepRecord
    | UndoRecord
    | QuestionRecord
    | TrialRecord
    | ConfusedRecord
    | ReopenRecord
    | AlertRecord
    | RotationRecord
    | ButtonCheckRecord
    | ClockRecord
)

# Records that change GameState when applied; every other kind is history only.
STATE_CHANGING = (
    StepRecord,
    PoseRecord,
    TrialRecord,
    UndoRecord,
    CommandRecord,
    ConfusedRecord,
    ReopenRecord,
    RotationRecord,
)
