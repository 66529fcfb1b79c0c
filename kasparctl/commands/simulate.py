"""`kasparctl simulate`: replicate the pilot study, sweep the learner, or plan a study's size.

Without --config it plays the paper's pilot (3 locations, 6 toys) with the
built-in profiles; with --config the game and profiles come from kaspar.toml.
--alpha, --beta and --gamma override the chosen profile's values; --teacher
gives the children of a teacher model (`kasparctl fit-teacher` fits one from
recorded sessions). --power compares two arms (--compare NAME=A,B) and gives
the power to detect their difference against the number of groups.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import secrets
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgspec

from kasparctl.config import (
    BUILTIN_PROFILES,
    ConfigError,
    GameSettings,
    ProfileSettings,
    load_config,
)
from kasparctl.learning.learner import LearnerError, LearnerParams
from kasparctl.learning.study_stats import StudyStats
from kasparctl.research.output import OutputError, check_outputs, closed_pipe, write_bytes
from kasparctl.sim.fit import PAPER
from kasparctl.sim.power import (
    DEFAULT_GROUPS,
    DEFAULT_STUDIES,
    Arm,
    PowerError,
    PowerPoint,
    draw_power,
    power_curve,
)
from kasparctl.sim.simulate import SimulationError, playable, summarise_study
from kasparctl.sim.studies import GROUP_MEASURES
from kasparctl.sim.sweep import PilotShape, sweep
from kasparctl.sim.teacher import Teacher, TeacherError, TeacherModel, load_teacher

__all__ = ["PAPER", "register", "run"]

SWEEPABLE = ("alpha", "beta")
# Below this many groups the scalar simulation takes about a second; no bar.
PROGRESS_MIN_GROUPS = 2000
MAX_SWEEP_VALUES = 1000
# The scalar path plays about 8,000 pilot groups a second and holds only totals: a million
# groups is two minutes, the most a question about one setting needs.
MAX_GROUPS = 1_000_000
SCALAR_GROUPS_PER_SECOND = 8000
# The sweep holds about 150 bytes per problem: 20 million problems is about 3 GB.
MAX_SWEEP_PROBLEMS = 20_000_000
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


def register(subparsers: Any) -> None:
    """Add `simulate` and its options to the command line."""
    parser = subparsers.add_parser(
        "simulate",
        help="simulate groups of children teaching Kaspar (the pilot study), or sweep the learner",
        description=__doc__,
    )
    parser.add_argument(
        "--groups",
        type=_positive_int,
        default=16,
        help="groups of children (default 16, as in the pilot)",
    )
    parser.add_argument(
        "--seed",
        type=_seed,
        default=None,
        help="random seed (default: the config's game.seed, else fresh)",
    )
    parser.add_argument(
        "--profile",
        default=None,
        help="learner profile (default: the config's default, else 'paper')",
    )
    parser.add_argument(
        "--alpha",
        type=_finite_float,
        default=None,
        help="learning rate, overrides the profile",
    )
    parser.add_argument(
        "--beta",
        type=_finite_float,
        default=None,
        help="inverse temperature, overrides the profile",
    )
    parser.add_argument(
        "--gamma",
        type=_finite_float,
        default=None,
        help="discount factor, overrides the profile",
    )
    parser.add_argument(
        "--variant",
        choices=("pilot", "names"),
        default=None,
        help="game variant (default: the config's, else pilot)",
    )
    parser.add_argument(
        "--p-wrong-green",
        type=_probability,
        default=0.0,
        help="chance of a green for a wrong guess",
    )
    parser.add_argument(
        "--p-wrong-red", type=_probability, default=0.0, help="chance of a red for a right guess"
    )
    parser.add_argument(
        "--p-no-answer", type=_probability, default=0.0, help="chance nobody answers a guess"
    )
    parser.add_argument(
        "--teacher",
        metavar="FILE",
        default=None,
        help="a teacher model (TOML; `kasparctl fit-teacher` writes one): each child's rates",
    )
    parser.add_argument(
        "--exclude-learned",
        choices=("names", "always", "never"),
        default=None,
        help="withdraw a learned toy from later targets (default: the config's, else names)",
    )
    parser.add_argument(
        "--recover",
        action="store_true",
        help="a researcher re-opens a wrongly learned name when Kaspar is confused "
        "(kasparctl.game.recovery); the scalar simulator only",
    )
    parser.add_argument(
        "--config", default=None, help="kaspar.toml to take the game settings and profiles from"
    )
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object (a list with --sweep)"
    )
    parser.add_argument(
        "--sweep",
        action="append",
        type=_sweep_range,
        default=[],
        metavar="NAME=START:STOP:STEP",
        help="sweep alpha or beta over an inclusive range (repeatable; vectorised pilot problems)",
    )
    power = parser.add_argument_group("study design (--power)")
    power.add_argument(
        "--power",
        action="store_true",
        help="the power to detect the --compare difference, against the number of groups",
    )
    power.add_argument(
        "--compare",
        type=_comparison,
        metavar="NAME=A,B",
        help=f"the two arms: NAME one of {', '.join(COMPARABLE)} (teacher: two model files)",
    )
    power.add_argument(
        "--measure",
        choices=tuple(GROUP_MEASURES),
        default="trials_mean",
        help="each group's value the arms are compared on (default trials_mean)",
    )
    power.add_argument(
        "--groups-per-arm",
        type=_group_list,
        default=DEFAULT_GROUPS,
        metavar="N,N,...",
        help=f"designs to try (default {','.join(map(str, DEFAULT_GROUPS))})",
    )
    power.add_argument(
        "--studies",
        type=_positive_int,
        default=DEFAULT_STUDIES,
        help=f"simulated studies per design (default {DEFAULT_STUDIES})",
    )
    power.add_argument(
        "--level", type=_probability, default=0.05, help="the test's level (default 0.05)"
    )
    power.add_argument(
        "--figure", metavar="FILE", default=None, help="also draw the power curve (.png or .svg)"
    )
    parser.set_defaults(run=run)


class UsageError(Exception):
    """A bad option value found after parsing; the message names the option."""


def run(arguments: argparse.Namespace) -> int:
    """Simulate, sweep or plan, print the result (JSON with --json); 1 on a bad option."""
    try:
        return _run(arguments)
    except BrokenPipeError:
        return closed_pipe()


def _run(arguments: argparse.Namespace) -> int:
    try:
        game, profiles, default_profile, config_seed = _settings(arguments.config)
        params, profile_name = _params(arguments, profiles, default_profile)
        teacher = _teacher(arguments)
        if arguments.variant is not None:
            game = msgspec.structs.replace(game, variant=arguments.variant)
        if arguments.exclude_learned is not None:
            game = msgspec.structs.replace(game, exclude_learned_rule=arguments.exclude_learned)
        game = playable(game)
        _check_size(arguments, game)
    except (ConfigError, UsageError, SimulationError, TeacherError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    seed = arguments.seed if arguments.seed is not None else config_seed
    if seed is None:
        # Drawn here and printed, so any run can be repeated; from the OS's entropy,
        # as numpy's own SeedSequence() draws it.
        seed = secrets.randbits(63)
    simple = teacher if isinstance(teacher, Teacher) else teacher.pooled(prompts_as_silence=False)
    context = {
        "variant": game.variant,
        "exclude_learned": game.exclude_learned_rule,
        "groups": arguments.groups,
        "seed": seed,
        "profile": profile_name,
        "alpha": params.alpha,
        "beta": params.beta,
        "gamma": params.gamma,
        "p_wrong_green": simple.p_wrong_green,
        "p_wrong_red": simple.p_wrong_red,
        "p_no_answer": simple.p_no_answer,
        "recover": arguments.recover,
    }
    if isinstance(teacher, TeacherModel):
        context["teacher"] = arguments.teacher
    if arguments.power:
        return _run_power(arguments, game, params, profiles, teacher, seed)
    if arguments.sweep:
        if isinstance(teacher, TeacherModel):
            print(
                "error: --sweep: expected one teacher for every child, not a model", file=sys.stderr
            )
            return 1
        return _run_sweep(arguments, game, params, teacher, seed, context)

    with _progress(arguments.groups) as on_group:
        stats = summarise_study(
            arguments.groups, game, params, teacher, seed, on_group, recover=arguments.recover
        )
    if arguments.json:
        print(json.dumps({**context, **msgspec.to_builtins(stats)}, allow_nan=False))
    else:
        print(_stats_table(stats, context, len(game.toys), len(game.targets)))
    return 0


def _teacher(arguments: argparse.Namespace) -> Teacher | TeacherModel:
    """The children: a teacher model file, or the --p-* rates (not both)."""
    rates = (arguments.p_wrong_green, arguments.p_wrong_red, arguments.p_no_answer)
    if arguments.teacher is None:
        return Teacher(*rates)
    if any(rates):
        raise UsageError(
            "--teacher: the model gives the children's rates; drop --p-wrong-green, "
            "--p-wrong-red and --p-no-answer"
        )
    return load_teacher(arguments.teacher)


def _check_size(arguments: argparse.Namespace, game: GameSettings) -> None:
    """Refuse work no run should take hours or gigabytes for, saying what to do instead."""
    if arguments.recover and (arguments.power or arguments.sweep):
        raise UsageError("--recover: only the scalar simulator plays it, not --power or --sweep")
    if arguments.power:
        if arguments.compare is None:
            raise UsageError("--power: expected --compare NAME=A,B (the two arms to compare)")
        return
    if arguments.compare is not None:
        raise UsageError("--compare: only with --power")
    if arguments.sweep:
        settings = math.prod(len(values) for _, values in arguments.sweep)
        problems = arguments.groups * (len(game.locations) or 3) * settings
        if problems > MAX_SWEEP_PROBLEMS:
            raise UsageError(
                f"--groups {arguments.groups} x {settings} settings = {problems:,} pilot problems; "
                f"expected at most {MAX_SWEEP_PROBLEMS:,} (about 3 GB): fewer groups or settings"
            )
        return
    if arguments.groups > MAX_GROUPS:
        minutes = arguments.groups / SCALAR_GROUPS_PER_SECOND / 60
        raise UsageError(
            f"--groups: expected at most {MAX_GROUPS:,}, found {arguments.groups:,} (about "
            f"{minutes:,.0f} minutes of simulation); the figures of a million groups are already "
            "exact to three decimals. For a study's size use --power; to place a cohort among "
            "simulated studies, `kasparctl replicate`"
        )


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


def _params(
    arguments: argparse.Namespace, profiles: dict[str, ProfileSettings], default_profile: str
) -> tuple[LearnerParams, str]:
    name = arguments.profile or default_profile
    if name not in profiles:
        raise UsageError(
            f"--profile: expected one of {', '.join(sorted(profiles))}, found {name!r}"
        )
    overrides = {
        key: getattr(arguments, key)
        for key in ("alpha", "beta", "gamma")
        if getattr(arguments, key) is not None
    }
    try:
        params = dataclasses.replace(profiles[name].params(), **overrides)
    except LearnerError as error:
        option = f"--{error.key}" if error.key in overrides else f"profile {name!r}: {error.key}"
        raise UsageError(f"{option}: {error}") from error
    label = name + (
        " with " + ", ".join(f"{k} {v:g}" for k, v in overrides.items()) if overrides else ""
    )
    return params, label


def _run_power(
    arguments: argparse.Namespace,
    game: GameSettings,
    params: LearnerParams,
    profiles: dict[str, ProfileSettings],
    teacher: Teacher | TeacherModel,
    seed: int,
) -> int:
    name, values = arguments.compare
    try:
        arms = tuple(_arm(name, value, game, params, profiles, teacher) for value in values)
        if arguments.figure is not None:
            check_outputs([("--figure", arguments.figure)], [], [], _inputs(arguments))
        points = power_curve(
            (arms[0], arms[1]),
            arguments.measure,
            arguments.groups_per_arm,
            arguments.studies,
            arguments.level,
            seed,
        )
        title = (
            f"{arms[0].label} vs {arms[1].label}: {arguments.measure} "
            f"(Welch t-test on groups, level {arguments.level:g})"
        )
        if arguments.figure is not None:
            _write_figure(Path(arguments.figure), points, title, arguments.studies)
    except (UsageError, PowerError, ConfigError, TeacherError, LearnerError, OutputError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"error: cannot write {arguments.figure}: {error.strerror or error}", file=sys.stderr)
        return 1
    if arguments.json:
        print(
            json.dumps(
                {
                    "compare": {"name": name, "a": values[0], "b": values[1]},
                    "measure": arguments.measure,
                    "level": arguments.level,
                    "studies": arguments.studies,
                    "seed": seed,
                    "variant": game.variant,
                    "points": [point.plain() for point in points],
                },
                allow_nan=False,
            )
        )
        return 0
    print(f"power: {title}")
    print(
        f"{arguments.studies} simulated studies per design, seed {seed}; {game.variant}, "
        f"{len(game.targets)} targets, {len(game.toys)} toys; measure: "
        f"{GROUP_MEASURES[arguments.measure]}"
    )
    print(f"{'groups per arm':>15} {'power':>7} {'MC error':>9} {'mean difference (A - B)':>24}")
    for point in points:
        print(
            f"{point.groups:>15} {point.power:>7.3f} {point.mc_error:>9.3f} "
            f"{point.difference:>24.4f}"
        )
    enough = next((p.groups for p in points if p.power >= 0.8), None)
    print(
        f"80 % power from {enough} groups per arm"
        if enough is not None
        else "80 % power not reached: try more groups (--groups-per-arm)"
    )
    return 0


def _inputs(arguments: argparse.Namespace) -> list[tuple[str, str]]:
    files = [("--config", arguments.config)] if arguments.config else []
    if arguments.teacher:
        files.append(("--teacher", arguments.teacher))
    name, values = arguments.compare
    if name == "teacher":
        files += [("--compare", value) for value in values]
    return files


def _write_figure(path: Path, points: list[PowerPoint], title: str, studies: int) -> None:
    import io

    try:
        figure = draw_power(points, title, studies)
    except ImportError:
        raise UsageError(
            "--figure: needs matplotlib, which is not installed: pip install 'kasparctl[report]'"
        ) from None
    kind = "svg" if path.suffix.lower() == ".svg" else "png"
    buffer = io.BytesIO()
    figure.savefig(buffer, format=kind, dpi=120)
    write_bytes(path, buffer.getvalue())


def _arm(
    name: str,
    value: str,
    game: GameSettings,
    params: LearnerParams,
    profiles: dict[str, ProfileSettings],
    teacher: Teacher | TeacherModel,
) -> Arm:
    """One arm of the comparison: the base settings with NAME set to `value`."""
    label = f"{name} {value}"
    if name == "profile":
        if value not in profiles:
            known = ", ".join(sorted(profiles))
            raise UsageError(f"--compare: profile: expected one of {known}, found {value!r}")
        chosen = profiles[value].params()
        return Arm(label, game, dataclasses.replace(chosen, gamma=params.gamma), teacher)
    if name == "teacher":
        return Arm(label, game, params, load_teacher(value))
    if name == "exclude_learned":
        if value not in ("names", "always", "never"):
            raise UsageError(
                f"--compare: exclude_learned: expected names, always or never, found {value!r}"
            )
        return Arm(
            label, msgspec.structs.replace(game, exclude_learned_rule=value), params, teacher
        )
    number = _float(value)
    if number is None:
        raise UsageError(f"--compare: {name}: expected a number, found {value!r}")
    if name in ("alpha", "beta"):
        try:
            return Arm(label, game, dataclasses.replace(params, **{name: number}), teacher)
        except LearnerError as error:
            raise UsageError(f"--compare: {name}: {error}") from None
    if isinstance(teacher, TeacherModel):
        raise UsageError(f"--compare: {name}: expected the --p-* rates, not a --teacher model")
    try:
        return Arm(label, game, params, dataclasses.replace(teacher, **{name: number}))
    except TeacherError as error:
        raise UsageError(f"--compare: {name}: {error}") from None


def _run_sweep(
    arguments: argparse.Namespace,
    game: GameSettings,
    params: LearnerParams,
    teacher: Teacher,
    seed: int,
    context: dict[str, Any],
) -> int:
    if game.variant != "pilot":
        print(
            "error: --sweep: expected the pilot variant (the vectorised path plays pilot "
            f"problems), found variant {game.variant!r}",
            file=sys.stderr,
        )
        return 1
    ranges = dict(arguments.sweep)
    if len(ranges) != len(arguments.sweep):
        print(
            "error: --sweep: expected each of alpha, beta at most once, found one twice",
            file=sys.stderr,
        )
        return 1
    alphas = ranges.get("alpha", [params.alpha])
    betas = ranges.get("beta", [params.beta])
    settings = [(a, b) for a in alphas for b in betas]
    shape = PilotShape.from_game(game)
    problems = arguments.groups * shape.problems_per_group
    results = sweep(settings, problems, seed, params, teacher, shape)
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
    if arguments.json:
        print(json.dumps([{**context, **row} for row in rows], allow_nan=False))
        return 0
    print(
        f"pilot problems per setting: {problems} ({arguments.groups} groups), seed {seed}, "
        f"gamma {params.gamma:g}, teacher {_teacher_text(teacher)}"
    )
    print(
        f"{'alpha':>6} {'beta':>6} {'trials mean':>12} {'sd':>6} {'max':>4} {'given up':>9} "
        f"{'persev/trial':>13} {'win-shift/trial':>16}"
    )
    for row in rows:
        print(
            f"{row['alpha']:>6g} {row['beta']:>6g} {_num(row['trials_mean'], 2):>12} "
            f"{_num(row['trials_sd'], 2):>6} {_num(row['trials_max'], 0):>4} "
            f"{row['problems_given_up']:>9} {_num(row['perseverative_error_rate'], 4):>13} "
            f"{_num(row['win_shift_rate'], 4):>16}"
        )
    return 0


def _stats_table(stats: StudyStats, context: dict[str, Any], n_toys: int, n_targets: int) -> str:
    pilot = context["variant"] == "pilot"
    paper = PAPER if pilot else {}
    lines = [
        f"{context['groups']} groups x {n_targets} problems ({context['variant']}, {n_toys} toys), "
        f"seed {context['seed']}",
        f"learner: {context['profile']} (alpha {context['alpha']:g}, beta {context['beta']:g}, "
        f"gamma {context['gamma']:g}); teacher: {_teacher_text_from(context)}",
        "",
        f"{'':34} {'simulated':>16} {'paper' if pilot else '':>14}".rstrip(),
    ]

    def row(label: str, simulated: str, published: str = "") -> None:
        lines.append(f"{label:34} {simulated:>16} {published if pilot else '':>14}".rstrip())

    def with_rate(count: int, rate: float | None) -> str:
        return f"{count} ({_num(None if rate is None else 100 * rate, 2)}%)"

    trials = stats.trials_total
    row(
        "problems (learned)",
        f"{stats.problems} ({stats.problems_learned})",
        str(paper.get("problems", "")),
    )
    row("trials", str(trials), "202")
    row(
        "trials to learn, mean ± sd",
        f"{_num(stats.trials_mean, 2)} ± {_num(stats.trials_sd, 2)}",
        "4.21 ± 1.46",
    )
    row(
        "trials to learn, min-max",
        f"{_num(stats.trials_min, 0)}-{_num(stats.trials_max, 0)}",
        "2-7",
    )
    row(
        "given up / learned wrong",
        f"{stats.problems_given_up} / {stats.problems_learned_wrong}",
        "0 / 0",
    )
    row(
        "first guess correct",
        with_rate(stats.first_guess_correct, stats.first_guess_correct_rate),
        "7 (14.58%)",
    )
    row(
        "perseverative errors (per trial)",
        with_rate(stats.perseverative_errors, stats.perseverative_error_rate),
        "1 (0.50%)",
    )
    row("win-shifts (per trial)", with_rate(stats.win_shifts, stats.win_shift_rate), "1 (0.50%)")
    row("initial entropy (bits)", _num(stats.initial_entropy, 3), "2.585")
    row(
        "final entropy, before last guess",
        f"{_num(stats.final_entropy_mean, 2)} ± {_num(stats.final_entropy_sd, 2)}",
        "0.73 ± 0.58",
    )
    row(
        "final entropy, after last update",
        f"{_num(stats.final_entropy_after_mean, 3)} ± {_num(stats.final_entropy_after_sd, 3)}",
        "",
    )
    lines.append("")
    lines.append("entropy before guess k (bits), problems with a k-th guess:")
    for k, (entropy, n) in enumerate(
        zip(stats.entropy_by_trial, stats.entropy_by_trial_n, strict=True), 1
    ):
        lines.append(f"  {k:>3}  {entropy:6.3f}  (n={n})")
    return "\n".join(lines)


def _teacher_text(teacher: Teacher) -> str:
    if teacher.honest:
        return "honest"
    return (
        f"wrong green {teacher.p_wrong_green:g}, wrong red {teacher.p_wrong_red:g}, "
        f"no answer {teacher.p_no_answer:g}"
    )


def _teacher_text_from(context: dict[str, Any]) -> str:
    if "teacher" in context:
        return f"model {context['teacher']} (its children's rates, in turn)"
    return _teacher_text(
        Teacher(context["p_wrong_green"], context["p_wrong_red"], context["p_no_answer"])
    )


def _num(value: float | None, decimals: int) -> str:
    return "-" if value is None else f"{value:.{decimals}f}"


@contextmanager
def _progress(groups: int) -> Iterator[Callable[[int], None] | None]:
    """A tqdm bar on stderr for long runs at a terminal; nothing otherwise (tqdm is optional)."""
    if groups < PROGRESS_MIN_GROUPS or not sys.stderr.isatty():
        yield None
        return
    try:
        from tqdm import tqdm  # type: ignore[import-untyped]  # tqdm ships no type hints
    except ImportError:
        yield None
        return
    with tqdm(total=groups, unit="group", file=sys.stderr, leave=False) as bar:
        yield lambda _group: bar.update(1)


# Option value types: argparse reports their ArgumentTypeError as
# "argument --NAME: <message>", which names the option.


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, found {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, found {text!r}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, found {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, found {text!r}")
    return value


def _float(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _finite_float(text: str) -> float:
    value = _float(text)
    if value is None:
        raise argparse.ArgumentTypeError(f"expected a finite number, found {text!r}")
    return value


def _probability(text: str) -> float:
    value = _float(text)
    if value is None or not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a probability in [0, 1], found {text!r}")
    return value


def _comparison(text: str) -> tuple[str, tuple[str, str]]:
    """NAME=A,B: the setting the two arms differ in, and its two values."""
    name, equals, spec = text.partition("=")
    values = [value.strip() for value in spec.split(",")]
    if not equals or name.strip() not in COMPARABLE or len(values) != 2 or not all(values):
        raise argparse.ArgumentTypeError(
            f"expected NAME=A,B with NAME one of {', '.join(COMPARABLE)}, found {text!r}"
        )
    return name.strip(), (values[0], values[1])


def _group_list(text: str) -> tuple[int, ...]:
    """N,N,...: numbers of groups per arm, each >= 2."""
    try:
        values = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected numbers of groups separated by commas, found {text!r}"
        ) from None
    if not values or min(values) < 2:
        raise argparse.ArgumentTypeError(f"expected numbers >= 2, found {text!r}")
    return values


def _sweep_range(text: str) -> tuple[str, list[float]]:
    """NAME=START:STOP:STEP (inclusive) or NAME=VALUE, checked against the learner's limits."""
    expected = f"expected NAME=START:STOP:STEP with NAME one of {', '.join(SWEEPABLE)}"
    name, equals, spec = text.partition("=")
    name = name.strip()
    if not equals or name not in SWEEPABLE:
        raise argparse.ArgumentTypeError(f"{expected}, found {text!r}")
    parts = [_float(part) for part in spec.split(":")]
    if len(parts) not in (1, 3) or any(part is None for part in parts):
        raise argparse.ArgumentTypeError(f"{expected} (finite numbers), found {text!r}")
    if len(parts) == 1:
        values = [float(parts[0])]  # type: ignore[arg-type]
    else:
        start, stop, step = (float(part) for part in parts)  # type: ignore[arg-type]
        if step <= 0.0 or stop < start:
            raise argparse.ArgumentTypeError(
                f"{expected} with STEP > 0 and STOP >= START, found {text!r}"
            )
        # The small allowance keeps STOP in the range despite decimal steps (0.1 * 9).
        count = math.floor((stop - start) / step + 1e-9) + 1
        if count > MAX_SWEEP_VALUES:
            raise argparse.ArgumentTypeError(
                f"expected at most {MAX_SWEEP_VALUES} values, found {count} in {text!r}"
            )
        # Rounded so that 0.1 + 2 * 0.1 prints and compares as 0.3.
        values = [round(start + i * step, 12) for i in range(count)]
    for value in values:
        try:
            LearnerParams(**{name: value})
        except LearnerError as error:
            raise argparse.ArgumentTypeError(f"{name}: {error} (in {text!r})") from None
    return name, values
