"""The paper's figures per condition, with intervals: JSON for scripts, Markdown for people.

The statistics are kasparctl.learning.study_stats' (the simulator's own), so a report
on recorded sessions and `kasparctl simulate` measure the same things. Added
here: how often the children's feedback was wrong, what preceded Kaspar's
perseverative errors and win-shifts, 95 % cluster-bootstrap intervals
(kasparctl.research.inference), contrasts between conditions and between
groups of participants, and each child's teaching measures.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec

from kasparctl.learning.study_stats import summarise
from kasparctl.research.conditions import Condition
from kasparctl.research.inference import MEASURES, MIN_CLUSTERS, Contrast, Intervals
from kasparctl.research.output import write_bytes
from kasparctl.research.sessions_table import session_rows


@dataclass(frozen=True)
class Method:
    """How the intervals were made: resamples, seed, unit."""

    replicates: int
    seed: int
    unit: str
    level: float = 0.95


def feedback_counts(condition: Condition) -> dict[str, Any]:
    """Children's answers checked against the answer key, where the plan has one."""
    total = condition.feedback
    return {
        "feedback_checked": total.checked,
        # A green for a wrong guess teaches the wrong toy; a red for a right one delays it.
        "wrong_green": total.wrong_green,
        "wrong_red": total.wrong_red,
        "wrong_guesses": total.wrong_guesses,
        "right_guesses": total.right_guesses,
        "feedback_by_child": [
            {"child": child, "checked": counts.checked, "right": counts.right}
            for child, counts in sorted(condition.feedback_by_position.items())
            if counts.checked
        ],
    }


def with_a_choice(condition: Condition) -> dict[str, Any]:
    """The first-guess and entropy statistics over the problems with a choice: in the names
    game a learned name is withdrawn from the later bags, so the last bag is offered one
    toy, its first guess forced (no choice) and its entropy 0 bits. Left out,
    the figures compare with the pilot's, where every problem offers every toy."""
    chosen = [p.record for p in condition.problems if p.record.candidates != 1]
    stats = summarise(chosen) if chosen else None
    with_key = sum(1 for p in chosen if p.trials[0].correct is not None)
    return {
        "problems_forced": len(condition.problems) - len(chosen),
        "problems_with_a_choice": len(chosen),
        "problems_with_a_choice_and_answer_key": with_key,
        "first_guess_correct_with_a_choice": 0 if stats is None else stats.first_guess_correct,
        "first_guess_correct_rate_with_a_choice": (
            None if stats is None or not with_key else stats.first_guess_correct / with_key
        ),
        "initial_entropy_with_a_choice": None if stats is None else stats.initial_entropy,
        "final_entropy_mean_with_a_choice": None if stats is None else stats.final_entropy_mean,
    }


def condition_summary(condition: Condition, found: Intervals) -> dict[str, Any]:
    """One condition's column of the summary: sessions, problems, statistics, intervals."""
    sessions = condition.sessions
    stats = msgspec.to_builtins(condition.stats)
    return {
        "condition": condition.label,
        "sessions": len(sessions),
        "session_ids": [s.uid for s in sessions],
        "robots": sorted({s.robot for s in sessions if s.robot}),
        "groups": sorted({s.group for s in sessions}),
        "variants": sorted({s.variant for s in sessions}),
        "clusters": len(condition.clusters),
        "finished": sum(1 for s in sessions if s.status == "finished"),
        "stopped": sum(1 for s in sessions if s.status == "stopped"),
        "interrupted": sum(1 for s in sessions if s.status == "interrupted"),
        "undone": condition.undone,
        "problems_with_answer_key": sum(
            1 for p in condition.problems if p.record.trials[0].correct is not None
        ),
        **stats,
        **with_a_choice(condition),
        "entropy_by_trial_low": [e.low for e in found.entropy_by_trial],
        "entropy_by_trial_high": [e.high for e in found.entropy_by_trial],
        **feedback_counts(condition),
        "intervals": {name: estimate.plain() for name, estimate in found.measures.items()},
        "trials_to_learn_shares": [
            {"trials": found.trials_bins_start + index, **estimate.plain()}
            for index, estimate in enumerate(found.trials_share)
        ],
    }


def _ratio(numerator: float, denominator: float) -> float | None:
    return numerator / denominator if denominator else None


def mode_summary(mode: Condition) -> dict[str, Any]:
    """One uncertainty mode's column: its sessions pooled over profiles and variants, and
    the main outcome measures (kasparctl.research.conditions.by_uncertainty)."""
    stats = mode.stats
    feedback = mode.feedback
    answers = len(mode.reaction_times) + mode.answers_in_question
    with_key = sum(1 for p in mode.problems if p.record.trials[0].correct is not None)
    return {
        "uncertainty": mode.label,
        "conditions": sorted({s.condition for s in mode.sessions}),
        "sessions": len(mode.sessions),
        "groups": sorted({s.group for s in mode.sessions}),
        "trials_total": stats.trials_total,
        "problems": stats.problems,
        "problems_learned": stats.problems_learned,
        "problems_learned_rate": _ratio(stats.problems_learned, stats.problems),
        "trials_mean": stats.trials_mean,
        "trials_sd": stats.trials_sd,
        "problems_with_answer_key": with_key,
        "first_guess_correct": stats.first_guess_correct,
        "first_guess_correct_rate": _ratio(stats.first_guess_correct, with_key),
        "perseverative_error_rate": stats.perseverative_error_rate,
        "win_shift_rate": stats.win_shift_rate,
        "final_entropy_mean": stats.final_entropy_mean,
        "wrong_green": feedback.wrong_green,
        "wrong_guesses": feedback.wrong_guesses,
        "wrong_red": feedback.wrong_red,
        "right_guesses": feedback.right_guesses,
        # Over the answers after the question; those in its last words counted apart.
        "reaction_time_median": (
            statistics.median(mode.reaction_times) if mode.reaction_times else None
        ),
        "answers_in_question": mode.answers_in_question,
        "prompts_per_answer": _ratio(mode.prompts, answers),
    }


def build_summary(
    conditions: Sequence[Condition],
    everything: Condition,
    intervals: dict[str, Intervals],
    method: Method,
    contrasts: Sequence[Contrast] = (),
    children: Sequence[dict[str, Any]] = (),
    participants_file: str | None = None,
    modes: Sequence[Condition] = (),
) -> dict[str, Any]:
    """The report's summary.json: every condition, all of them pooled, the uncertainty
    modes side by side, contrasts, children."""
    sessions = everything.sessions
    return {
        "sessions": [s.uid for s in sessions],
        # One row per session (research.codebook.SESSIONS), as sessions.csv has them.
        "sessions_table": session_rows(sessions),
        "session_names": [s.name for s in sessions],
        "robots": sorted({s.robot for s in sessions if s.robot}),
        "intervals": {
            "method": "cluster bootstrap, percentile",
            "level": method.level,
            "replicates": method.replicates,
            "seed": method.seed,
            "unit": method.unit,
        },
        "conditions": [condition_summary(c, intervals[c.label]) for c in conditions],
        "all": condition_summary(everything, intervals["all"]),
        "uncertainty_modes": [mode_summary(mode) for mode in modes],
        "contrasts": [c.plain() for c in contrasts],
        "participants_file": participants_file,
        "children": list(children),
    }


def write_json(path: Path, summary: dict[str, Any]) -> None:
    """Write the summary as indented JSON (atomically)."""
    write_bytes(path, msgspec.json.format(msgspec.json.encode(summary), indent=2) + b"\n")


# -- Markdown ---------------------------------------------------------------------


def _number(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _mean_sd(mean: float | None, sd: float | None, digits: int = 2) -> str:
    return "-" if mean is None else f"{mean:.{digits}f} ± {_number(sd, digits)}"


def plural(unit: str) -> str:
    """A cluster unit in the plural: groups, sessions, children."""
    return "children" if unit == "child" else unit + "s"


def percent(value: float) -> str:
    """A share as a percentage to 0.1 % (1 of 440 is 0.2 %, never 0 %)."""
    return f"{100 * value:.1f} %"


def _share(count: int, total: int | None) -> str:
    if not total:
        return f"{count}"
    return f"{count} of {total} ({percent(count / total)})"


def _interval(estimate: dict[str, Any], digits: int = 2, share: bool = False) -> str:
    low, high = estimate.get("low"), estimate.get("high")
    if low is None or high is None:
        return ""
    if share:
        return f" [{100 * low:.1f}, {100 * high:.1f}]"
    return f" [{low:.{digits}f}, {high:.{digits}f}]"


def _rows(summary: dict[str, Any]) -> list[tuple[str, str]]:
    s = summary
    ci = s["intervals"]

    def attributed(wrong: int, explore: int) -> str:
        return f"; after wrong feedback {wrong}, exploratory {explore}" if wrong or explore else ""

    return [
        (
            "Sessions (finished / stopped / interrupted)",
            f"{s['sessions']} ({s['finished']} / {s['stopped']} / {s['interrupted']})",
        ),
        ("Groups", ", ".join(s["groups"])),
        ("Clusters resampled", str(s["clusters"])),
        (
            "Problems (learned / not learned)",
            f"{s['problems']} ({s['problems_learned']} / {s['problems_given_up']})"
            + _interval(ci["problems_learned_rate"], share=True),
        ),
        ("Problems learned with a wrong toy", str(s["problems_learned_wrong"])),
        ("Trials", str(s["trials_total"])),
        (
            "Trials to learn, mean ± sd",
            _mean_sd(s["trials_mean"], s["trials_sd"]) + _interval(ci["trials_mean"]),
        ),
        (
            "Trials to learn, min - max",
            "-" if s["trials_min"] is None else f"{s['trials_min']} - {s['trials_max']}",
        ),
        (
            "First guess correct, all problems",
            _share(s["first_guess_correct"], s["problems_with_answer_key"])
            + _interval(ci["first_guess_correct_rate"], share=True)
            if s["problems_with_answer_key"]
            else "no answer key",
        ),
        (
            "First guess correct, problems with a choice (forced ones left out)",
            _share(
                s["first_guess_correct_with_a_choice"],
                s["problems_with_a_choice_and_answer_key"],
            )
            + f"; {s['problems_forced']} forced"
            if s["problems_with_a_choice_and_answer_key"]
            else f"no answer key; {s['problems_forced']} forced",
        ),
        (
            "Perseverative errors",
            _share(s["perseverative_errors"], s["trials_total"])
            + _interval(ci["perseverative_error_rate"], share=True)
            + attributed(s["perseverative_after_wrong_feedback"], s["perseverative_exploratory"]),
        ),
        (
            "Win-shifts",
            _share(s["win_shifts"], s["trials_total"])
            + _interval(ci["win_shift_rate"], share=True)
            + attributed(s["win_shifts_after_wrong_feedback"], s["win_shifts_exploratory"]),
        ),
        ("Entropy before the first guess (bits), all problems", _number(s["initial_entropy"], 3)),
        (
            "Entropy before the first guess (bits), problems with a choice",
            _number(s["initial_entropy_with_a_choice"], 3),
        ),
        (
            "Final entropy, before the last guess (bits)",
            _mean_sd(s["final_entropy_mean"], s["final_entropy_sd"])
            + _interval(ci["final_entropy_mean"]),
        ),
        (
            "Final entropy, after the last update (bits)",
            _mean_sd(s["final_entropy_after_mean"], s["final_entropy_after_sd"])
            + _interval(ci["final_entropy_after_mean"]),
        ),
        ("Answers checked against the answer key", str(s["feedback_checked"])),
        (
            "Wrong greens (green for a wrong guess)",
            _share(s["wrong_green"], s["wrong_guesses"])
            + _interval(ci["wrong_green_rate"], share=True),
        ),
        (
            "Wrong reds (red for a right guess)",
            _share(s["wrong_red"], s["right_guesses"])
            + _interval(ci["wrong_red_rate"], share=True),
        ),
        (
            "Feedback right, per place in the turn order",
            ", ".join(
                f"{c['child']}: {_share(c['right'], c['checked'])}" for c in s["feedback_by_child"]
            )
            or "-",
        ),
        ("Undone answers (not counted)", str(s["undone"])),
    ]


_MEASURE_LABELS = {m.name: m.label for m in MEASURES}
_MEASURE_LABELS.update(
    false_green_rate="False greens, of wrong guesses",
    false_red_rate="False reds, of right guesses",
    reaction_time_mean="Reaction time, mean (s)",
    prompts_per_answer="Prompts per answer",
    extra_presses_per_answer="Extra presses per answer",
    undos_per_answer="Undos per answer",
)
_SHARES = {m.name for m in MEASURES if m.unit == "share"} | {
    "false_green_rate",
    "false_red_rate",
}


def _value(measure: str, value: float | None) -> str:
    if value is None:
        return "-"
    return percent(value) if measure in _SHARES else f"{value:.3f}"


def _contrast_table(contrasts: Sequence[dict[str, Any]]) -> list[str]:
    lines = [
        "| factor | A - B | measure | A | B | difference [95 % CI] | Hedges' g [95 % CI] "
        "| p | p (Holm) | design | clusters |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for c in contrasts:
        measure = c["measure"]
        share = measure in _SHARES
        difference = (
            "-"
            if c["difference"] is None
            else (f"{100 * c['difference']:+.1f} points" if share else f"{c['difference']:+.3f}")
            + _interval(
                {"low": c["difference_low"], "high": c["difference_high"]},
                digits=3,
                share=share,
            )
        )
        g = (
            "-"
            if c["hedges_g"] is None
            else f"{c['hedges_g']:+.2f}"
            + _interval({"low": c["hedges_g_low"], "high": c["hedges_g_high"]})
        )
        lines.append(
            f"| {c['factor']} | {c['a']} - {c['b']} | {_MEASURE_LABELS.get(measure, measure)} "
            f"| {_value(measure, c['a_value'])} | {_value(measure, c['b_value'])} "
            f"| {difference} | {g} | {_p(c.get('p'))} | {_p(c.get('p_holm'))}"
            f"{' *' if c.get('significant_holm') else ''} | {_design(c)} "
            f"| {c['clusters_a']} / {c['clusters_b']} {plural(c['unit'])} |"
        )
    return lines


def _p(value: float | None) -> str:
    return "-" if value is None else ("< 0.001" if value < 0.001 else f"{value:.3f}")


def _design(contrast: dict[str, Any]) -> str:
    """Paired (groups met both sides: how many, in which order) or independent."""
    if not contrast.get("paired"):
        return "independent"
    shared = contrast.get("shared_clusters") or 0
    first_a, first_b = contrast.get("order_a_first"), contrast.get("order_b_first")
    order = "" if first_a is None else f"; A first {first_a}, B first {first_b}"
    return f"paired ({shared} shared{order})"


CHILD_COLUMNS = (
    ("child", "child"),
    ("sessions", "sessions"),
    ("answers", "answers"),
    ("wrong feedback", "wrong_feedback_rate"),
    ("false greens", "false_greens"),
    ("false reds", "false_reds"),
    ("reaction time, median (s)", "reaction_time_median"),
    ("prompts", "prompts"),
    ("extra presses", "extra_presses"),
    ("undos", "undos"),
)
MAX_CHILD_ROWS = 60


def _children_table(children: Sequence[dict[str, Any]]) -> list[str]:
    lines = [
        "| " + " | ".join(name for name, _ in CHILD_COLUMNS) + " |",
        "| " + " | ".join("---" for _ in CHILD_COLUMNS) + " |",
    ]
    for row in children[:MAX_CHILD_ROWS]:
        cells = []
        for _, key in CHILD_COLUMNS:
            value = row.get(key)
            if key == "wrong_feedback_rate":
                cells.append(
                    "-" if value is None else _share(row["checked"] - row["right"], row["checked"])
                )
            elif isinstance(value, float):
                cells.append(f"{value:.2f}")
            else:
                cells.append("-" if value is None else str(value))
        lines.append("| " + " | ".join(cells) + " |")
    if len(children) > MAX_CHILD_ROWS:
        lines.append("")
        lines.append(f"{len(children) - MAX_CHILD_ROWS} more children in children.csv.")
    return lines


def _mode_rows(m: dict[str, Any]) -> list[tuple[str, str]]:
    def share(count: int, total: int | None, rate: float | None) -> str:
        return "-" if rate is None else _share(count, total)

    return [
        ("Conditions", ", ".join(m["conditions"])),
        ("Sessions", str(m["sessions"])),
        ("Groups", str(len(m["groups"]))),
        ("Trials", str(m["trials_total"])),
        (
            "Problems learned",
            share(m["problems_learned"], m["problems"], m["problems_learned_rate"]),
        ),
        ("Trials to learn, mean ± sd", _mean_sd(m["trials_mean"], m["trials_sd"])),
        (
            "First guess correct",
            share(
                m["first_guess_correct"],
                m["problems_with_answer_key"],
                m["first_guess_correct_rate"],
            ),
        ),
        ("Perseverative errors, of trials", _rate(m["perseverative_error_rate"])),
        ("Win-shifts, of trials", _rate(m["win_shift_rate"])),
        ("Final entropy, before the last guess (bits)", _number(m["final_entropy_mean"], 3)),
        ("Wrong greens (green for a wrong guess)", _share(m["wrong_green"], m["wrong_guesses"])),
        ("Wrong reds (red for a right guess)", _share(m["wrong_red"], m["right_guesses"])),
        ("Reaction time, median (s)", _number(m["reaction_time_median"])),
        ("Prompts per answer", _number(m["prompts_per_answer"])),
    ]


def _rate(value: float | None) -> str:
    return "-" if value is None else percent(value)


def _modes_table(modes: Sequence[dict[str, Any]]) -> list[str]:
    """The uncertainty modes side by side: a column per mode, a row per measure."""
    header = ["", *(m["uncertainty"] for m in modes)]
    rows_by_mode = [_mode_rows(m) for m in modes]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    for index, (name, _) in enumerate(rows_by_mode[0]):
        lines.append("| " + " | ".join([name, *(rows[index][1] for rows in rows_by_mode)]) + " |")
    return lines


def _forced_caveat(summary: dict[str, Any]) -> list[str]:
    """Why the names game's first-guess and entropy figures are not the paper's pilot's."""
    if not summary["all"].get("problems_forced"):
        return []
    return [
        "**Forced choices.** In the names game a learned name is no longer offered for the "
        "other bags, so the last bag has one candidate: its first guess is no choice (right "
        "by elimination, unless a name learned wrongly withdrew the right toy) and its "
        f"entropy 0 bits ({summary['all']['problems_forced']} such "
        "problems here). The figures over all problems are therefore not comparable with the "
        "paper's pilot, where every toy was offered for every location (2.585 bits before "
        "each first guess with six toys); the rows *problems with a choice* leave the forced "
        "problems out and are the comparable ones. Even with a choice the later bags offer "
        "fewer toys, so their \"no idea\" is log2 of fewer (entropy_by_trial draws a line for "
        "each number of toys offered).",
        "",
    ]


def markdown(
    summary: dict[str, Any],
    figures: Sequence[str],
    notes: Sequence[str],
    formats: Sequence[str] = ("png", "pdf"),
) -> str:
    """The report's summary.md: the conditions side by side, contrasts, children, figures."""
    columns = list(summary["conditions"])
    if len(columns) > 1:
        columns.append(summary["all"])
    header = ["", *(c["condition"] for c in columns)]
    table = [header, ["---"] * len(header)]
    rows_by_column = [_rows(c) for c in columns]
    for index, (name, _) in enumerate(rows_by_column[0]):
        table.append([name, *(rows[index][1] for rows in rows_by_column)])
    method = summary["intervals"]
    lines = [
        "# Kaspar sessions: summary",
        "",
        f"{len(summary['sessions'])} sessions, {summary['all']['trials_total']} trials, "
        f"{summary['all']['problems']} problems. Trials to learn and final entropies are over "
        "learned problems; undone answers are not trials. In brackets: 95 % intervals, "
        f"cluster bootstrap over {plural(method['unit'])} ({method['replicates']} resamples, seed "
        f"{method['seed']}); none with fewer than {MIN_CLUSTERS} a side. Definitions: "
        "docs/research-data.md.",
        "",
        *_forced_caveat(summary),
        *("| " + " | ".join(row) + " |" for row in table),
        "",
    ]
    modes = summary.get("uncertainty_modes", [])
    if len(modes) > 1:
        lines += [
            "## Uncertainty modes",
            "",
            "How Kaspar showed how sure it was before each guess (spoken: said; body: its "
            "thinking behaviour and the way it pointed; both; none), each mode's sessions "
            "pooled over profiles and variants. Intervals and tests: the conditions and "
            "contrasts.",
            "",
            *_modes_table(modes),
            "",
        ]
    if summary["contrasts"]:
        lines += [
            "## Contrasts",
            "",
            "A - B with 95 % cluster-bootstrap intervals: paired (one set of weights for "
            "both sides) where groups met both conditions, else each side's clusters "
            "resampled on their own; Hedges' g over the clusters' own values, with the "
            "difference's sign. p: two-sided bootstrap; p (Holm): corrected over every "
            "contrast of this report (one family), * where below 0.05. Read p (Holm), not "
            "whether an interval excludes 0.",
            "",
        ]
        lines += [*_contrast_table(summary["contrasts"]), ""]
    if summary["children"]:
        lines += [
            "## Children",
            "",
            "By participant code (the plans' codes). Every measure and attribute, and the "
            "children of sessions without codes (by session and place), are in children.csv.",
            "",
        ]
        lines += [*_children_table(summary["children"]), ""]
    if figures:
        lines += ["## Figures", ""]
        lines += [_figure_links(name, formats) for name in figures]
        lines.append("")
    if notes:
        lines += ["## Notes", "", *(f"- {note}" for note in notes), ""]
    return "\n".join(lines)


def _figure_links(name: str, formats: Sequence[str]) -> str:
    """A figure's line in summary.md: a link to each file that was written, PDF first."""
    order = [kind for kind in ("pdf", "png", "svg") if kind in formats]
    if not order:
        return f"- {name}"
    first, *rest = order
    others = "".join(f" ([{kind.upper()}]({name}.{kind}))" for kind in rest)
    return f"- [{name}]({name}.{first}){others}"
