"""The codebook: every column of the exported tables, written once, as data.

The export's headers (kasparctl.research.tidy), the column tables of
docs/research-data.md (tests/codebook_table.py writes them; a test fails when
they differ), the Frictionless table schemas of datapackage.json and the
Psych-DS variableMeasured (kasparctl.research.package) all read these
tables, so a column cannot be documented one way and written another.

A column's `type` is the docs' word: string, integer, number, boolean,
timestamp (UTC ISO 8601) or list (values joined by ";"). `empty_when` says
when the cell is missing (written NA); "never" columns are required.
A name with "<toy>" is one column per toy, "<attribute>" one per column of
participants.csv.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Column:
    """One column: its name, type, when it is missing, what it means, its constraints."""

    name: str
    type: str
    empty_when: str
    meaning: str
    enum: tuple[str, ...] = ()
    minimum: float | None = None
    maximum: float | None = None

    @property
    def required(self) -> bool:
        """Never missing."""
        return self.empty_when == "never"


C = Column

ROBOT_NAME = C(
    "robot_name",
    "string",
    "recorded before robot names",
    "the robot's name (`[robot] name`, the name it says in its greeting; plan.json's `robot.name`)",
)
SESSION_NUMBER = C(
    "session_number",
    "integer",
    "recorded before session numbers",
    "the group's session: 1 for its first, 2 for the one more it had... (plan.json's `number`)",
    minimum=1,
)
SESSION_CLOCK = C(
    "session_clock",
    "number",
    "never",
    "seconds since the session's first record on a clock that runs on across resumes: "
    "`clock` within a run of the robot, and from a resume on the time the last record "
    "before it plus the wall-clock gap to the resume (none if the wall clock went back)",
    minimum=0,
)
LEARNER_FIELDS = (
    ("alpha", "the learning rate (Eq. 1)"),
    ("beta", "the softmax's inverse temperature (Eq. 2)"),
    ("gamma", "the discount (Eq. 1)"),
    ("reward_green", "the reward of a green"),
    ("reward_red", "the reward of a red"),
    ("initial_q", "every Q-value at the start"),
)
LEARNER_COLUMNS = tuple(
    C(
        f"learner_{name}",
        "number",
        "recorded before learners were frozen in plan.json",
        f"the session's learner as frozen in plan.json at its start: {meaning}",
    )
    for name, meaning in LEARNER_FIELDS
)

TRIALS: tuple[Column, ...] = (
    C(
        "session",
        "string",
        "never",
        "the session's unique id (a ULID: no two sessions of any robot share one; derived from plan.json for sessions recorded before ids)",
    ),
    C(
        "session_name",
        "string",
        "never",
        "its readable id: its start time (UTC) and group code, the directory's name (not unique across robots or state directories)",
    ),
    C(
        "robot",
        "string",
        "recorded before robot ids",
        "the robot that recorded it (`robot_id`, or a hash of its machine id)",
    ),
    ROBOT_NAME,
    C("group", "string", "never", "the group's code, from the plan"),
    SESSION_NUMBER,
    C(
        "condition",
        "string",
        "never",
        "`<profile>/<spoken\\|body\\|both\\|silent>`, from the plan: the profile and the uncertainty mode (`silent` for `none`, the word sessions had before modes, so they pool)",
    ),
    C(
        "profile",
        "string",
        "never",
        "learner profile: `paper`, `fast`, `slow` or the configuration's own",
    ),
    C(
        "speak_uncertainty",
        "boolean",
        "never",
        "whether Kaspar said how sure it was before each guess (modes `spoken` and `both`)",
    ),
    C(
        "uncertainty",
        "string",
        "never",
        "the uncertainty mode: `spoken` (the line), `body` (the thinking behaviour and the way Kaspar points), `both` or `none`; sessions from before modes: `spoken` or `none` from `speak_uncertainty`",
    ),
    C(
        "variant",
        "string",
        "never",
        "`names` (children teach toy names) or `pilot` (toys to locations)",
    ),
    C(
        "script",
        "string",
        "never",
        "how Kaspar said how sure it was: `paper` (the paper's three levels, fixed words) or `varied`; `varied` for sessions planned before scripts existed",
    ),
    C(
        "script_version",
        "integer",
        "never",
        "the script's version (plan.json's `script_version`); 0 for sessions planned before scripts existed",
    ),
    C(
        "language",
        "string",
        "never",
        "the language Kaspar spoke (plan.json's `language`: en, nl, de, it, fr...); en for sessions planned before it was recorded",
    ),
    *LEARNER_COLUMNS,
    C(
        "trial",
        "integer",
        "never",
        "the trial number within the session, from 1; carries on over a resume, never repeats",
    ),
    C(
        "seq",
        "integer",
        "never",
        "the trial record's number in the session (the events CSV's `seq`: a prompt, a press or a question joins its trial by `trial`, and falls between trials by `seq`)",
        minimum=1,
    ),
    C("problem_trial", "integer", "never", "the guess number within this problem (target), from 1"),
    C("target", "string", "never", "what Kaspar pointed at: `bag N`, or the pilot's location"),
    C(
        "answer",
        "string",
        "no answer key",
        "the correct toy for the target, from the plan's answer key",
    ),
    C(
        "child",
        "string",
        "never",
        "whose turn: first name from the plan, or `child one`...; `child N` with `--anonymise`",
    ),
    C("child_number", "integer", "never", "whose turn as a number: 1 for the plan's first child"),
    C(
        "participant",
        "string",
        "the plan has no codes",
        "the pseudonymous code of the child who answered (the plan's `participants`, by turn)",
    ),
    C(
        "participant_<attribute>",
        "string",
        "no `--participants`, or no row for the code",
        "one column per column of participants.csv (`participant_group`, `participant_age`...), joined by code",
    ),
    C(
        "seat",
        "integer",
        "one shared keyfob",
        "with one keyfob per child (`[[keyfob.children]]`): the seat (from 1) whose keyfob answered",
    ),
    C(
        "device",
        "string",
        "one shared keyfob",
        "that seat's keyfob, as configured (its path or name)",
    ),
    C(
        "credited_child_number",
        "integer",
        "never",
        'the child credited with the answer, as a number: the seat\'s child with one keyfob per child (another than `child_number` only when a press out of turn was taken, `answer_out_of_turn = "take"`), else the child whose turn it was',
    ),
    C("credited_participant", "string", "the plan has no codes", "that child's pseudonymous code"),
    C(
        "candidates",
        "list",
        "never",
        "the toys offered (a learned name is withdrawn from later bags in the names game)",
    ),
    C("n_candidates", "integer", "never", 'how many toys were offered: "no idea" is log2 of this'),
    C(
        "p_<toy>",
        "number",
        "toy not in the session",
        "probability of choosing the toy (softmax, Eq. 2); 0 when not a candidate",
    ),
    C(
        "entropy",
        "number",
        "never",
        "entropy of those probabilities in bits (Eq. 3), before the guess",
    ),
    C(
        "band",
        "string",
        "uncertainty not spoken",
        "the phrase band Kaspar's line came from (`no_idea`, `unsure`, `idea_not_sure`, `fairly_sure`, `sure`)",
    ),
    C(
        "spoken",
        "string",
        "never",
        "Kaspar's lines for the guess: the uncertainty (if spoken) and the guess",
    ),
    C("choice", "string", "never", "the toy Kaspar guessed"),
    C("feedback", "string", "never", "the children's answer: `green` or `red`"),
    C(
        "reaction_time",
        "number",
        "never",
        "seconds from the end of Kaspar's question (when the voice finished its last words) to the answer the game took; negative when the children pressed during the question's last words, where the toy is named (`in_question`): a press counts from the guess itself",
    ),
    C(
        "in_question",
        "boolean",
        "never",
        "the answer came during the question's last words (where the toy is named) and was taken: its `reaction_time` is negative; TRUE also for a negative time recorded before the flag existed",
    ),
    C("reward", "number", "never", "the reward the learner got for the answer"),
    C(
        "q_before_<toy>",
        "number",
        "toy not in the session",
        "the target's Q-value for the toy before the answer",
    ),
    C("q_after_<toy>", "number", "toy not in the session", "the same after the update (Eq. 1)"),
    C(
        "perseverative",
        "boolean",
        "never",
        "same toy chosen again right after a red on this target (the answer it follows: the last one on this target not undone; none for a target's first guess, nor for its first after the researcher re-opened its name)",
    ),
    C(
        "win_shift",
        "boolean",
        "never",
        "another toy chosen right after a green on this target (the answer it follows, as for `perseverative`: the first guess after a re-open is no win-shift, the green that taught the name was taken back)",
    ),
    C(
        "error_cause",
        "string",
        "neither perseverative nor a win-shift",
        "`after_wrong_feedback` (the children's answer it follows was wrong: a red for the right toy, a green for a wrong one), `exploratory` (that answer was right: Kaspar's own exploration) or `unknown` (no answer key)",
    ),
    C("correct", "boolean", "no answer key", "whether the guess was the answer key's toy"),
    C(
        "feedback_right",
        "boolean",
        "no answer key",
        "whether the children's answer agreed with the answer key",
    ),
    C(
        "learned",
        "boolean",
        "never",
        "this answer completed the target (two greens in a row for the same toy)",
    ),
    C(
        "undone",
        "boolean",
        "never",
        "the researcher took this answer back (double red); not a trial of the problem",
    ),
    C(
        "right_toy_offered",
        "boolean",
        "no answer key",
        "whether the answer key's toy of this target was among the candidates (FALSE: a name learned wrongly for another target withdrew it; see Recovery in interaction.md)",
    ),
    C(
        "confused",
        "boolean",
        "never",
        "asked while Kaspar was confused about this target (after a `confused` event, until the target was done (learned, or given up), a name was re-opened, or the answer that showed it was undone; a re-open taken back puts it back)",
    ),
    C(
        "reopened",
        "boolean",
        "never",
        "the target's learned name had been re-opened by the researcher before this trial (its guesses after learning it wrongly)",
    ),
    C(
        "time",
        "timestamp",
        "never",
        "when the trial was recorded (UTC), by the robot's wall clock: trust it only where `clock_synchronised` is TRUE; in the demo (simulated time) the computer's wall clock when the record was written, not the game's time: durations are `session_clock`'s",
    ),
    SESSION_CLOCK,
    C(
        "clock_synchronised",
        "boolean",
        "the session has no clock record (older sessions, the demo)",
        "whether the robot's wall clock was synchronised (systemd-timesyncd) at the session's start and at every jump it made; FALSE: `time` may be hours or years off (the order of sessions and records is not: see docs/install.md, a good clock)",
    ),
)

EVENTS: tuple[Column, ...] = (
    C("session", "string", "never", "the session's unique id"),
    C("session_name", "string", "never", "its readable id (start time and group code)"),
    C("robot", "string", "recorded before robot ids", "the robot that recorded it"),
    ROBOT_NAME,
    C("group", "string", "never", "group code"),
    SESSION_NUMBER,
    C("condition", "string", "never", "`<profile>/<spoken\\|body\\|both\\|silent>`"),
    C("uncertainty", "string", "never", "the uncertainty mode (as in the trials CSV)"),
    C("script", "string", "never", "the session's uncertainty script (as in the trials CSV)"),
    C("script_version", "integer", "never", "its version (as in the trials CSV)"),
    C("language", "string", "never", "the language Kaspar spoke (as in the trials CSV)"),
    C("seq", "integer", "never", "the record's number in the session, from 1"),
    C("time", "timestamp", "never", "when it was recorded (UTC; as the trials' `time`)"),
    C(
        "clock",
        "number",
        "never",
        "the robot's monotonic clock when it was recorded, seconds: it starts again when the robot (or the demo) restarts, so across a resume use `session_clock`",
    ),
    SESSION_CLOCK,
    C(
        "kind",
        "string",
        "never",
        "`command`, `press`, `prompt`, `fault`, `hal`, `step`, `pose`, `undo`, `question`, `confused`, `reopen`, `alert`, `rotation`, `button_check`, `clock` or `session`",
    ),
    C(
        "name",
        "string",
        "pose, undo, question",
        "what happened: the command (`pause`...), the button, the prompt line, the fault kind, the HAL event, the step entered, the session event (`start`, `resumed`, `absent`, `present`), why Kaspar is confused (`all_rejected`, `learned_elsewhere`), the name re-opened, the alert, the rotation's change (`away`, `back`, `skipped`)",
    ),
    C(
        "trial",
        "integer",
        "not about a trial",
        "the trial an undo, an extra press or a question refers to; for a prompt while guessing the trial of the question it repeated (the trials CSV's `trial`); for `confused` and `alert` the trial whose answer showed it, for `reopen` the trials recorded before it",
    ),
    C(
        "participant",
        "string",
        "not about one child, or no codes",
        "the child concerned: whose question a prompt repeated (while guessing; a prompt of the check of the buttons is nobody's), whose answer an extra press followed or an undo took back, who pressed a seat's own keyfob, who a `rotation` record took out, brought back or passed over",
    ),
    C(
        "detail",
        "string",
        "nothing more",
        "every other field of the record, as a JSON object (the start record's plan is left out: it is plan.json)",
    ),
)

_SETTING = "recorded before settings were (plan.json's `settings`)"


def _setting(
    name: str,
    kind: str,
    meaning: str,
    minimum: float | None = None,
    maximum: float | None = None,
) -> Column:
    key = name.replace("voice_", "voice.")
    return C(name, kind, _SETTING, f"plan.json's `settings.{key}`: {meaning}", (), minimum, maximum)


# One row per session: what every trial and event of it shares, joined by `session`.
SESSIONS: tuple[Column, ...] = (
    C("session", "string", "never", "the session's unique id (the trials' and events' `session`)"),
    C("session_name", "string", "never", "its readable id: its start time (UTC) and group code"),
    C(
        "robot",
        "string",
        "recorded before robot ids",
        "the robot's stable id (plan.json's `robot.id`, or `robot` in sessions before robot names)",
    ),
    ROBOT_NAME,
    C("group", "string", "never", "the group's code, from the plan"),
    SESSION_NUMBER,
    C(
        "condition",
        "string",
        "never",
        "`<profile>/<spoken\\|body\\|both\\|silent>`, as in the trials CSV",
    ),
    C("profile", "string", "never", "the learner profile's name"),
    C(
        "uncertainty",
        "string",
        "never",
        "the uncertainty mode",
        enum=("spoken", "body", "both", "none"),
    ),
    C("variant", "string", "never", "`names` or `pilot`"),
    C("script", "string", "never", "the uncertainty script (as in the trials CSV)"),
    C("script_version", "integer", "never", "its version (as in the trials CSV)", minimum=0),
    C("language", "string", "never", "the language Kaspar spoke"),
    C("created", "timestamp", "never", "when the session was opened (UTC, the robot's wall clock)"),
    C("date", "string", "never", "the day it was opened, YYYY-MM-DD (UTC)"),
    C(
        "status",
        "string",
        "never",
        "`finished`, `stopped`, `interrupted`, `absent` or `absent, taken back` (see kasparctl sessions)",
        enum=("finished", "stopped", "interrupted", "absent", "absent, taken back"),
    ),
    C(
        "resumed",
        "integer",
        "never",
        "how many times the robot carried the session on after a restart",
        minimum=0,
    ),
    C("trials", "integer", "never", "answers that count (undone ones are not)", minimum=0),
    C("undone", "integer", "never", "answers the researcher took back", minimum=0),
    C(
        "clock_synchronised",
        "boolean",
        "the session has no clock record (older sessions, the demo)",
        "whether the robot's wall clock was synchronised at every clock record",
    ),
    C(
        "kasparctl_version",
        "string",
        "recorded before versions were",
        "the version of kasparctl that opened the session (plan.json's `kasparctl_version`)",
    ),
    *LEARNER_COLUMNS,
    _setting("correct_answers_to_learn", "integer", "greens in a row that teach a name", minimum=1),
    _setting("max_trials_per_target", "integer", "guesses before a target is given up", minimum=1),
    _setting("toys", "list", "the toys, in the game's order"),
    _setting("locations", "list", "the pilot's locations"),
    _setting(
        "prompt_after_s",
        "list",
        "seconds of silence before each prompt after a question (first, second, then the "
        "call for help)",
    ),
    _setting("step_prompt_after_s", "number", "the same in the other steps", minimum=0),
    _setting("reactions", "string", "Kaspar's happy and sad reactions: `paper`, `all` or `none`"),
    _setting("alive", "boolean", "gaze and life on"),
    _setting("speed_scale", "number", "the scale of Kaspar's movement speed", minimum=0),
    _setting("voice_engine", "string", "the speech engine"),
    _setting("voice_voice", "string", "the voice"),
    _setting("voice_rate", "number", "the speech rate, words per minute", minimum=0),
    _setting("voice_volume", "number", "the volume, 0 to 1", minimum=0, maximum=1),
    _setting("voice_pitch", "number", "the pitch"),
    C("settings", "string", _SETTING, "every setting of plan.json's `settings`, as a JSON object"),
)

TABLES = {"trials": TRIALS, "events": EVENTS, "sessions": SESSIONS}


def expanded(
    columns: tuple[Column, ...], toys: tuple[str, ...] = (), attributes: tuple[str, ...] = ()
) -> list[tuple[str, Column]]:
    """Each concrete column name with its Column: "<toy>" written out for every toy
    suffix, "<attribute>" for every participants.csv column."""
    names: list[tuple[str, Column]] = []
    for column in columns:
        if "<toy>" in column.name:
            names += [(column.name.replace("<toy>", toy), column) for toy in toys]
        elif "<attribute>" in column.name:
            names += [(column.name.replace("<attribute>", a), column) for a in attributes]
        else:
            names.append((column.name, column))
    return names


def markdown(columns: tuple[Column, ...]) -> str:
    """A table of the docs: column, type, empty when, meaning."""
    lines = ["| column | type | empty when | meaning |", "|---|---|---|---|"]
    for column in columns:
        name = column.name.replace("<", "\\<").replace(">", "\\>")
        lines.append(f"| {name} | {column.type} | {column.empty_when} | {column.meaning} |")
    return "\n".join(lines)


def description(column: Column) -> str:
    """The column's meaning as plain text (for datapackage.json and Psych-DS)."""
    text = column.meaning.replace("\\|", "|").replace("`", "")
    return text if column.required else f"{text}. Missing (NA) when {column.empty_when}."
