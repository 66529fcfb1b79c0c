"""What the live view shows: the picture of a session, as plain frozen data.

kasparctl.view.fold makes it from a session's records; kasparctl.view.frame
lays it out for a screen. Nothing here reads a file or a clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from kasparctl.game.stages import ENDS, STEPS


def step_number(stage: str) -> int | None:
    """The paper's number of a step (placing 1 ... farewell 5); None for other stages."""
    return STEPS.index(stage) + 1 if stage in STEPS else None


@dataclass(frozen=True, slots=True)
class Bar:
    """One toy of a question: the learner's probability of it, and whether it is still offered."""

    toy: str
    probability: float
    offered: bool
    chosen: bool


@dataclass(frozen=True, slots=True)
class Question:
    """A question of step 4: asked (open), or answered green or red (or undone)."""

    trial: int
    problem_trial: int
    target: str
    child: str
    bars: tuple[Bar, ...]
    entropy: float
    # log2 of the number of toys offered: Kaspar has no idea at all.
    max_entropy: float
    band: str | None
    choice: str
    asked_at: str  # UTC, ISO 8601
    answer: str | None = None  # "green" or "red"; None while the question is open
    reaction_time: float | None = None
    prompts: int = 0  # times nobody answered and Kaspar prompted
    early_presses: int = 0  # presses before the question was finished
    undone: bool = False
    # Left unanswered when the daemon stopped: a resumed game asks it again.
    interrupted: bool = False

    @property
    def open(self) -> bool:
        """Whether the children have yet to answer (and the question still stands)."""
        return self.answer is None and not self.interrupted


@dataclass(frozen=True, slots=True)
class Answer:
    """One trial as recorded: the guess, the children's answer and what it meant."""

    trial: int
    problem_trial: int
    target: str
    child: str
    choice: str
    feedback: str
    reaction_time: float
    # None where the plan has no answer key.
    correct: bool | None
    feedback_right: bool | None
    learned: bool
    perseverative: bool
    win_shift: bool
    time: str
    undone: bool = False

    @property
    def wrong(self) -> str | None:
        """ "wrong green" or "wrong red" when the answer key says the children erred."""
        if self.feedback_right is False:
            return f"wrong {self.feedback}"
        return None


@dataclass(frozen=True, slots=True)
class Learned:
    """A target whose toy Kaspar learned, and in how many guesses (kasparctl.game.fold)."""

    target: str
    toy: str
    trials: int
    trial: int  # the session's trial that taught it


@dataclass(frozen=True, slots=True)
class CommandSeen:
    """A researcher's command: applied (what it did) or ignored (why)."""

    time: str
    gesture: str
    command: str
    applied: bool
    outcome: str  # the confirmation, or the reason it was ignored
    stage: str


@dataclass(frozen=True, slots=True)
class FaultSeen:
    """A failure: of a part, of the software, or the daemon's own, with its reason."""

    time: str
    source: str  # servo, keyfob, voice, software, or daemon
    detail: str
    joint: str | None = None
    # Whether the game stopped for it (the fault stage), and still waits for a resume.
    stopped_game: bool = False
    pending: bool = False
    # Its monotonic seconds and the daemon's run they count in (kasparctl.view.ages).
    clock: float | None = None
    run: str = ""


@dataclass(frozen=True, slots=True)
class Teaching:
    """Step 2's progress: poses logged, and the round and bag Kaspar asks for next."""

    poses: int = 0
    round: int = 0
    bag: int = 0
    retries: int = 0


@dataclass(frozen=True, slots=True)
class SessionView:
    """Everything the view shows about one session."""

    session: str
    group: str
    condition: str
    variant: str
    profile: str
    speak_uncertainty: bool | None
    answer_key: bool
    stage: str = "idle"  # a stage of kasparctl.game.stages.STATES
    step: str | None = None  # the step the session is on; kept while paused or faulted
    resumes: int = 0
    # Why the daemon stopped, when nothing was recorded since: the session waits to be resumed.
    shutdown: str | None = None
    question: Question | None = None
    answers: tuple[Answer, ...] = ()
    learned: tuple[Learned, ...] = ()
    targets: tuple[str, ...] = ()  # every target seen in a question or trial, in order
    toys: tuple[str, ...] = ()  # every toy, in the game's order, once a question shows them
    teaching: Teaching = field(default_factory=Teaching)
    commands: tuple[CommandSeen, ...] = ()
    faults: tuple[FaultSeen, ...] = ()
    keyfob_lost: bool = False
    # The battery as last recorded (a crossing of its warning line): "LOW 11.6 V (below
    # 11.8 V)" or "ok 12.2 V"; None until a crossing is recorded.
    battery: str | None = None
    battery_low: bool = False
    # The targets given up (not learned in the session's limit of guesses), in order.
    given_up: tuple[str, ...] = ()
    # Kaspar is confused and asks the researcher (kasparctl.game.recovery): what to tell
    # them, until a name is re-opened or the target is done (learned or given up; the
    # rule of kasparctl.game.fold); None otherwise.
    confused: str | None = None
    # Right toys no longer offered (with the answer key), until re-opened: one line each.
    alerts: tuple[str, ...] = ()
    reopens: int = 0  # names the researcher re-opened (less those taken back)
    records: int = 0
    last_seq: int = 0
    last_time: str | None = None
    warnings: tuple[str, ...] = ()
    # The last record's monotonic seconds; the daemon's run they count in (a start or a
    # resume begins the next) and the boot its clock record named ("" if none yet).
    last_clock: float | None = None
    run: str = ""
    boot: str = ""
    # What the last clock record said (kasparctl.game.wallclock); None without one.
    clock_synchronised: bool | None = None

    @property
    def trials(self) -> int:
        """Trials that count: recorded and not undone."""
        return sum(not answer.undone for answer in self.answers)

    @property
    def undone(self) -> int:
        """Answers the researcher took back."""
        return sum(answer.undone for answer in self.answers)

    @property
    def ended(self) -> bool:
        """Finished or stopped: nothing more will be recorded in this session."""
        return self.stage in ENDS

    @property
    def pending_faults(self) -> tuple[FaultSeen, ...]:
        """The faults the game is stopped for, waiting for the researcher's resume."""
        return tuple(fault for fault in self.faults if fault.pending)

    @property
    def whose_turn(self) -> str | None:
        """The child the open question is for."""
        question = self.question
        return question.child if question is not None and question.open else None


@dataclass(frozen=True, slots=True)
class DaemonEvent:
    """One line of the daemon's events.jsonl, as far as it can be read."""

    time: str
    name: str
    detail: str
    fault: bool
    # The researcher chose a planned session in idle, or marked its group absent:
    # "group B2, session 1" (and ", marked absent").
    chosen: str = ""


@dataclass(frozen=True, slots=True)
class WatchView:
    """The whole picture: the state directory, its live session, the daemon, and a footer."""

    state_dir: str
    exists: bool = True
    session: SessionView | None = None
    sessions: int = 0  # sessions in the state directory
    daemon: tuple[DaemonEvent, ...] = ()
    # The process holding the state directory's writer lock, where the kernel tells.
    writer: int | None = None
    footer: str = ""
    # Why part of the state directory cannot be followed (permission denied...), if so.
    problem: str = ""

    @property
    def chosen(self) -> str | None:
        """The planned session the researcher chose last in idle, while no session is open
        since (the daemon's events after the live session's last record)."""
        choices = [event for event in self.daemon if event.chosen]
        if not choices:
            return None
        last = choices[-1]
        session = self.session
        if session is not None and not session.ended:
            return None
        if session is not None and session.last_time and last.time <= session.last_time:
            return None
        return last.chosen
