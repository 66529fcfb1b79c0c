"""What `kasparctl simulate` is asked, checked, and answered: a study, a sweep or a power curve.

The command parses its options into a Request (values; nothing read yet).
`answer` reads the game and the learner profiles (the configuration's, else the
pilot with the built-in profiles), checks every option against them and against
each other, and runs one of three simulations:

- a study: kasparctl.sim.simulate, one guess at a time, summarised in constant memory;
- a sweep of alpha and beta: kasparctl.sim.sweep, vectorised pilot problems;
- a power curve of two arms: kasparctl.sim.power.

An option's value that cannot be used raises OptionError, naming the option (a
usage error on the command line); a configuration or teacher file that cannot
be used raises its own error. Each answer is JSON-ready data (`plain`) or a
table (`text`, kasparctl.sim.tables).
"""

from __future__ import annotations

import dataclasses
import io
import math
import secrets
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import msgspec

from kasparctl.config import BUILTIN_PROFILES, GameSettings, ProfileSettings, load_config
from kasparctl.learning.learner import LearnerError, LearnerParams
from kasparctl.learning.study_stats import ProblemRecord, StudyStats
from kasparctl.sim import tables
from kasparctl.sim.design import DEFAULT_DESIGN_GROUPS, DesignAnswer, design
from kasparctl.sim.power import DEFAULT_GROUPS, DEFAULT_STUDIES, Arm, PowerPoint, draw_power
from kasparctl.sim.power import power_curve as simulate_power
from kasparctl.sim.simulate import (
    OptionError,
    SimulationError,
    iter_groups,
    playable,
    summarise_groups,
)
from kasparctl.sim.studies import GROUP_MEASURES
from kasparctl.sim.sweep import PilotShape, sweep
from kasparctl.sim.teacher import Teacher, TeacherError, TeacherModel, load_teacher

SWEEPABLE = ("alpha", "beta")
MAX_SWEEP_VALUES = 1000
# The scalar path plays about 8,000 pilot groups a second and holds only totals: a million
# groups is two minutes, the most a question about one setting needs.
MAX_GROUPS = 1_000_000
SCALAR_GROUPS_PER_SECOND = 8000
# The sweep holds about 150 bytes per problem: 20 million problems is about 3 GB.
MAX_SWEEP_PROBLEMS = 20_000_000
EXCLUDE_RULES = ("names", "always", "never")
COMPARABLE = (
    "profile",
    "teacher",
    "p_wrong_green",
    "p_wrong_red",
    "p_no_answer",
    "alpha",
    "beta",
    "exclude_learned",
)

# Between a study's groups and their summary, e.g. a progress bar: (the groups, how many).
Watch = Callable[[Iterator[list[ProblemRecord]], int], Iterable[list[ProblemRecord]]]


@dataclass(frozen=True)
class Design:
    """A power study's design: each group's measure, the designs tried, the test's level."""

    measure: str = "trials_mean"
    groups_per_arm: tuple[int, ...] = DEFAULT_GROUPS
    studies: int = DEFAULT_STUDIES
    level: float = 0.05


@dataclass(frozen=True)
class Request:
    """One `kasparctl simulate`'s options as values; None: the configuration's, else the default."""

    groups: int = 16
    seed: int | None = None
    profile: str | None = None
    # alpha, beta or gamma given on the command line, over the profile's.
    learner: dict[str, float] = field(default_factory=dict)
    variant: str | None = None
    rates: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the --p-* options
    teacher: str | None = None  # a teacher model file
    exclude_learned: str | None = None
    recover: bool = False
    config: str | None = None
    sweep: tuple[tuple[str, list[float]], ...] = ()
    power: bool = False
    compare: tuple[str, tuple[str, str]] | None = None  # NAME and its two values
    design: Design = Design()
    # --design TARGET: a profile for this many guesses per game, over this many groups each.
    design_for: float | None = None
    design_groups: int = DEFAULT_DESIGN_GROUPS


@dataclass(frozen=True)
class Setup:
    """What the simulation plays: the game, learner and children, and how it is described."""

    game: GameSettings
    params: LearnerParams
    profiles: dict[str, ProfileSettings]
    teacher: Teacher | TeacherModel
    seed: int
    context: dict[str, Any]
    # The game before the profile's greens to learn: what another profile's arm starts from.
    base_game: GameSettings | None = None


@dataclass(frozen=True)
class StudyAnswer:
    """A simulated study's statistics, with what was simulated."""

    context: dict[str, Any]
    stats: StudyStats
    toys: int
    targets: int

    def plain(self) -> dict[str, Any]:
        """One JSON object: the context and the statistics."""
        return {**self.context, **msgspec.to_builtins(self.stats)}

    def text(self) -> str:
        """The statistics beside the paper's (pilot variant)."""
        return tables.study(self.stats, self.context, self.toys, self.targets)


@dataclass(frozen=True)
class SweepAnswer:
    """Each (alpha, beta) setting's statistics over the same pilot problems."""

    context: dict[str, Any]
    rows: list[dict[str, Any]]
    problems: int
    params: LearnerParams
    teacher: Teacher

    def plain(self) -> list[dict[str, Any]]:
        """A JSON list: one object per setting, each with the context."""
        return [{**self.context, **row} for row in self.rows]

    def text(self) -> str:
        """One line per setting."""
        return tables.sweep(self.rows, self.context, self.problems, self.params, self.teacher)


@dataclass(frozen=True)
class PowerAnswer:
    """The power curve of a comparison: one point per number of groups per arm."""

    name: str
    values: tuple[str, str]
    design: Design
    seed: int
    game: GameSettings
    title: str
    points: list[PowerPoint]

    def plain(self) -> dict[str, Any]:
        """One JSON object: the comparison, the design and the points."""
        return {
            "compare": {"name": self.name, "a": self.values[0], "b": self.values[1]},
            "measure": self.design.measure,
            "level": self.design.level,
            "studies": self.design.studies,
            "seed": self.seed,
            "variant": self.game.variant,
            "points": [point.plain() for point in self.points],
        }

    def text(self) -> str:
        """The table of power against groups per arm, and where it reaches 80 %."""
        measure = GROUP_MEASURES[self.design.measure]
        return tables.power(self.title, self.points, self.design.studies, self.seed, self.game,
                            measure)  # fmt: skip

    def figure(self, kind: str) -> bytes:
        """The power curve drawn as `kind` (png or svg); needs matplotlib."""
        try:
            figure = draw_power(self.points, self.title, self.design.studies)
        except ImportError:
            raise SimulationError(
                "--figure: needs matplotlib, which is not installed: "
                "pip install 'kasparctl[report]'"
            ) from None
        buffer = io.BytesIO()
        figure.savefig(buffer, format=kind, dpi=120)
        return buffer.getvalue()


def answer(
    request: Request, watch: Watch | None = None
) -> StudyAnswer | SweepAnswer | PowerAnswer | DesignAnswer:
    """Check the request against the settings and run the simulation it asks for."""
    setup = prepare(request)
    if request.design_for is not None:
        base_game = setup.base_game or setup.game
        return design(request.design_for, base_game, setup.params, setup.teacher,
                      request.design_groups, setup.seed)  # fmt: skip
    if request.power:
        return _power(request, setup)
    if request.sweep:
        return _sweep(request, setup)
    groups = iter_groups(
        request.groups, setup.game, setup.params, setup.teacher, setup.seed,
        recover=request.recover,
    )  # fmt: skip
    stats = summarise_groups(watch(groups, request.groups) if watch else groups)
    return StudyAnswer(setup.context, stats, len(setup.game.toys), len(setup.game.targets))


def prepare(request: Request) -> Setup:
    """The game, learner and children the request names, its seed, and its description."""
    game, profiles, default_profile, config_seed = _settings(request.config)
    name = request.profile or default_profile
    params = learner(profiles, name, request.learner)
    teacher = _children(request)
    if request.variant is not None:
        game = msgspec.structs.replace(game, variant=request.variant)
    if request.exclude_learned is not None:
        game = msgspec.structs.replace(game, exclude_learned_rule=request.exclude_learned)
    base_game = playable(game)
    # The profile's greens to learn over the game's (name is known: learner() checked it).
    game = playable(profiles[name].shaped(game))
    _check_size(request, game)
    seed = request.seed if request.seed is not None else config_seed
    if seed is None:
        # Drawn here and printed, so any run can be repeated; from the OS's entropy,
        # as numpy's own SeedSequence() draws it.
        seed = secrets.randbits(63)
    simple = teacher if isinstance(teacher, Teacher) else teacher.pooled(prompts_as_silence=False)
    overrides = ", ".join(f"{k} {v:g}" for k, v in request.learner.items())
    context: dict[str, Any] = {
        "variant": game.variant,
        "exclude_learned": game.exclude_learned_rule,
        "groups": request.groups,
        "seed": seed,
        "profile": name + (f" with {overrides}" if overrides else ""),
        "alpha": params.alpha,
        "beta": params.beta,
        "gamma": params.gamma,
        "correct_answers_to_learn": game.correct_answers_to_learn,
        "p_wrong_green": simple.p_wrong_green,
        "p_wrong_red": simple.p_wrong_red,
        "p_no_answer": simple.p_no_answer,
        "recover": request.recover,
    }
    if isinstance(teacher, TeacherModel):
        context["teacher"] = request.teacher
    return Setup(game, params, profiles, teacher, seed, context, base_game)


def learner(
    profiles: dict[str, ProfileSettings], name: str, overrides: dict[str, float] | None = None
) -> LearnerParams:
    """Profile `name`'s learner with `overrides`; OptionError names --profile or the value."""
    if name not in profiles:
        raise OptionError(
            f"--profile: expected one of {', '.join(sorted(profiles))}, found {name!r}"
        )
    overrides = overrides or {}
    try:
        return dataclasses.replace(profiles[name].params(), **overrides)
    except LearnerError as error:
        if error.key in overrides:
            raise OptionError(f"--{error.key}: {error}") from error
        raise SimulationError(f"profile {name!r}: {error.key}: {error}") from error


def _settings(
    config_path: str | None,
) -> tuple[GameSettings, dict[str, ProfileSettings], str, int | None]:
    if config_path is None:
        return GameSettings(variant="pilot"), dict(BUILTIN_PROFILES), "paper", None
    config = load_config(config_path)
    return (
        config.game,
        config.learner.all_profiles(),
        config.learner.default_profile,
        config.game.seed,
    )


def _children(request: Request) -> Teacher | TeacherModel:
    """The children: a teacher model file, or the --p-* rates (not both)."""
    if request.teacher is None:
        return Teacher(*request.rates)
    if any(request.rates):
        raise OptionError(
            "--teacher: the model gives the children's rates; drop --p-wrong-green, "
            "--p-wrong-red and --p-no-answer"
        )
    return load_teacher(request.teacher)


def _check_size(request: Request, game: GameSettings) -> None:
    """Refuse work no run should take hours or gigabytes for, saying what to do instead."""
    if request.design_for is not None:
        given = [name for name, value in (("--power", request.power), ("--sweep", request.sweep),
                 ("--recover", request.recover), ("--compare", request.compare)) if value]
        if given:
            raise OptionError(f"--design: cannot be combined with {', '.join(given)}")
        return
    if request.recover and (request.power or request.sweep):
        raise OptionError("--recover: only the scalar simulator plays it, not --power or --sweep")
    if request.power:
        if request.compare is None:
            raise OptionError("--power: expected --compare NAME=A,B (the two arms to compare)")
        return
    if request.compare is not None:
        raise OptionError("--compare: only with --power")
    if request.sweep:
        settings = math.prod(len(values) for _, values in request.sweep)
        problems = request.groups * (len(game.locations) or 3) * settings
        if problems > MAX_SWEEP_PROBLEMS:
            raise OptionError(
                f"--groups {request.groups} x {settings} settings = {problems:,} pilot problems; "
                f"expected at most {MAX_SWEEP_PROBLEMS:,} (about 3 GB): fewer groups or settings"
            )
        return
    if request.groups > MAX_GROUPS:
        minutes = request.groups / SCALAR_GROUPS_PER_SECOND / 60
        raise OptionError(
            f"--groups: expected at most {MAX_GROUPS:,}, found {request.groups:,} (about "
            f"{minutes:,.0f} minutes of simulation); the figures of a million groups are already "
            "exact to three decimals. For a study's size use --power; to place a cohort among "
            "simulated studies, `kasparctl replicate`"
        )


def _sweep(request: Request, setup: Setup) -> SweepAnswer:
    """Every (alpha, beta) of the ranges over the same pilot problems, vectorised."""
    if isinstance(setup.teacher, TeacherModel):
        raise OptionError("--sweep: expected one teacher for every child, not a model")
    if setup.game.variant != "pilot":
        raise OptionError(
            "--sweep: expected the pilot variant (the vectorised path plays pilot problems), "
            f"found variant {setup.game.variant!r}"
        )
    ranges = dict(request.sweep)
    if len(ranges) != len(request.sweep):
        raise OptionError("--sweep: expected each of alpha, beta at most once, found one twice")
    for name, values in request.sweep:
        for value in values:
            try:
                LearnerParams(**{name: value})
            except LearnerError as error:
                raise OptionError(f"--sweep: {name}: {error}") from None
    params = setup.params
    settings = [
        (alpha, beta)
        for alpha in ranges.get("alpha", [params.alpha])
        for beta in ranges.get("beta", [params.beta])
    ]
    shape = PilotShape.from_game(setup.game)
    problems = request.groups * shape.problems_per_group
    results = sweep(settings, problems, setup.seed, params, setup.teacher, shape)
    rows = [
        {
            "alpha": alpha,
            "beta": beta,
            "problems": stats.problems,
            "trials_mean": stats.trials_mean,
            "trials_sd": stats.trials_sd,
            "trials_min": stats.trials_min,
            "trials_max": stats.trials_max,
            "problems_given_up": stats.problems_given_up,
            "first_guess_correct_rate": stats.first_guess_correct_rate,
            "perseverative_error_rate": stats.perseverative_error_rate,
            "win_shift_rate": stats.win_shift_rate,
            "final_entropy_mean": stats.final_entropy_mean,
        }
        for (alpha, beta), stats in zip(settings, results, strict=True)
    ]
    return SweepAnswer(setup.context, rows, problems, params, setup.teacher)


def _power(request: Request, setup: Setup) -> PowerAnswer:
    """The power to tell the two arms apart, against the number of groups per arm."""
    assert request.compare is not None  # _check_size saw to it
    name, values = request.compare
    a, b = (arm(name, value, setup) for value in values)
    design = request.design
    points = simulate_power(
        (a, b), design.measure, design.groups_per_arm, design.studies, design.level, setup.seed
    )
    title = (
        f"{a.label} vs {b.label}: {design.measure} "
        f"(Welch t-test on groups, level {design.level:g})"
    )
    return PowerAnswer(name, values, design, setup.seed, setup.game, title, points)


def arm(name: str, value: str, setup: Setup) -> Arm:
    """One arm of the comparison: the base settings with NAME set to `value`."""
    label = f"{name} {value}"
    game, params, teacher = setup.game, setup.params, setup.teacher
    if name == "profile":
        if value not in setup.profiles:
            known = ", ".join(sorted(setup.profiles))
            raise OptionError(f"--compare: profile: expected one of {known}, found {value!r}")
        profile = setup.profiles[value]
        chosen = dataclasses.replace(profile.params(), gamma=params.gamma)
        return Arm(label, playable(profile.shaped(setup.base_game or game)), chosen, teacher)
    if name == "teacher":
        return Arm(label, game, params, load_teacher(value))
    if name == "exclude_learned":
        if value not in EXCLUDE_RULES:
            raise OptionError(
                f"--compare: exclude_learned: expected names, always or never, found {value!r}"
            )
        return Arm(
            label, msgspec.structs.replace(game, exclude_learned_rule=value), params, teacher
        )
    number = _finite(value)
    if number is None:
        raise OptionError(f"--compare: {name}: expected a number, found {value!r}")
    if name in SWEEPABLE:
        try:
            return Arm(label, game, dataclasses.replace(params, **{name: number}), teacher)
        except LearnerError as error:
            raise OptionError(f"--compare: {name}: {error}") from None
    if isinstance(teacher, TeacherModel):
        raise OptionError(f"--compare: {name}: expected the --p-* rates, not a --teacher model")
    try:
        return Arm(label, game, params, dataclasses.replace(teacher, **{name: number}))
    except TeacherError as error:
        raise OptionError(f"--compare: {name}: {error}") from None


def _finite(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None
