"""The paper's figures per condition, as JSON (for scripts) and Markdown (for people).

The statistics are kasparctl.learning.study_stats' (the simulator's own), so a report
on recorded sessions and `kasparctl simulate` measure the same things. Added
here only what needs the answer key and the children's turns: how often the
children's feedback was wrong, and how often each child's was right.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgspec

from kasparctl.research.conditions import Condition, pooled


def feedback_counts(condition: Condition) -> dict[str, Any]:
    """Children's answers checked against the answer key, where the plan has one."""
    checked = [t for t in condition.trials if t.feedback_right is not None]
    by_child: dict[int, list[bool]] = {}
    for trial in checked:
        by_child.setdefault(trial.child_index + 1, []).append(bool(trial.feedback_right))
    return {
        "feedback_checked": len(checked),
        # A green for a wrong guess teaches the wrong toy; a red for a right one delays it.
        "wrong_green": sum(1 for t in checked if t.green and not t.correct),
        "wrong_red": sum(1 for t in checked if not t.green and t.correct),
        "feedback_by_child": [
            {"child": child, "checked": len(rights), "right": sum(rights)}
            for child, rights in sorted(by_child.items())
        ],
    }


def condition_summary(condition: Condition) -> dict[str, Any]:
    """One condition's column of the summary: sessions, problems, statistics, feedback."""
    sessions = condition.sessions
    return {
        "condition": condition.label,
        "sessions": len(sessions),
        "groups": sorted({s.group for s in sessions}),
        "variants": sorted({s.variant for s in sessions}),
        "finished": sum(1 for s in sessions if s.status == "finished"),
        "stopped": sum(1 for s in sessions if s.status == "stopped"),
        "interrupted": sum(1 for s in sessions if s.status == "interrupted"),
        "undone": condition.undone,
        "problems_with_answer_key": sum(
            1 for p in condition.problems if p.record.trials[0].correct is not None
        ),
        **msgspec.to_builtins(condition.stats),
        **feedback_counts(condition),
    }


def build_summary(conditions: Sequence[Condition]) -> dict[str, Any]:
    """The report's summary.json: every condition, and all of them pooled."""
    return {
        "sessions": [s.id for c in conditions for s in c.sessions],
        "conditions": [condition_summary(c) for c in conditions],
        "all": condition_summary(pooled(conditions)),
    }


def write_json(path: Path, summary: dict[str, Any]) -> None:
    """Write the summary as indented JSON."""
    path.write_bytes(msgspec.json.format(msgspec.json.encode(summary), indent=2) + b"\n")


# -- Markdown ---------------------------------------------------------------------


def _number(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _mean_sd(mean: float | None, sd: float | None, digits: int = 2) -> str:
    return "-" if mean is None else f"{mean:.{digits}f} ± {_number(sd, digits)}"


def _share(count: int, total: int | None) -> str:
    if not total:
        return f"{count}"
    return f"{count} of {total} ({100 * count / total:.0f} %)"


def _rows(summary: dict[str, Any]) -> list[tuple[str, str]]:
    s = summary
    return [
        (
            "Sessions (finished / stopped / interrupted)",
            f"{s['sessions']} ({s['finished']} / {s['stopped']} / {s['interrupted']})",
        ),
        ("Groups", ", ".join(s["groups"])),
        (
            "Problems (learned / not learned)",
            f"{s['problems']} ({s['problems_learned']} / {s['problems_given_up']})",
        ),
        ("Problems learned with a wrong toy", str(s["problems_learned_wrong"])),
        ("Trials", str(s["trials_total"])),
        ("Trials to learn, mean ± sd", _mean_sd(s["trials_mean"], s["trials_sd"])),
        (
            "Trials to learn, min - max",
            "-" if s["trials_min"] is None else f"{s['trials_min']} - {s['trials_max']}",
        ),
        (
            "First guess correct",
            _share(s["first_guess_correct"], s["problems_with_answer_key"])
            if s["problems_with_answer_key"]
            else "no answer key",
        ),
        ("Perseverative errors", _share(s["perseverative_errors"], s["trials_total"])),
        ("Win-shifts", _share(s["win_shifts"], s["trials_total"])),
        ("Entropy before the first guess (bits)", _number(s["initial_entropy"], 3)),
        (
            "Final entropy, before the last guess (bits)",
            _mean_sd(s["final_entropy_mean"], s["final_entropy_sd"]),
        ),
        (
            "Final entropy, after the last update (bits)",
            _mean_sd(s["final_entropy_after_mean"], s["final_entropy_after_sd"]),
        ),
        ("Answers checked against the answer key", str(s["feedback_checked"])),
        ("Wrong greens (green for a wrong guess)", str(s["wrong_green"])),
        ("Wrong reds (red for a right guess)", str(s["wrong_red"])),
        (
            "Feedback right, per child",
            ", ".join(
                f"{c['child']}: {_share(c['right'], c['checked'])}" for c in s["feedback_by_child"]
            )
            or "-",
        ),
        ("Undone answers (not counted)", str(s["undone"])),
    ]


def markdown(summary: dict[str, Any], figures: Sequence[str], notes: Sequence[str]) -> str:
    """The report's summary.md: the conditions side by side, then the figures and notes."""
    columns = list(summary["conditions"])
    if len(columns) > 1:
        columns.append(summary["all"])
    header = ["", *(c["condition"] for c in columns)]
    table = [header, ["---"] * len(header)]
    rows_by_column = [_rows(c) for c in columns]
    for index, (name, _) in enumerate(rows_by_column[0]):
        table.append([name, *(rows[index][1] for rows in rows_by_column)])
    lines = [
        "# Kaspar sessions: summary",
        "",
        f"{len(summary['sessions'])} sessions, {summary['all']['trials_total']} trials, "
        f"{summary['all']['problems']} problems. Trials to learn and final entropies are over "
        "learned problems; undone answers are not trials. Definitions: docs/research-data.md.",
        "",
        *("| " + " | ".join(row) + " |" for row in table),
        "",
    ]
    if figures:
        lines += ["## Figures", ""]
        lines += [f"- [{name}]({name}.svg) ([PNG]({name}.png))" for name in figures]
        lines.append("")
    if notes:
        lines += ["## Notes", "", *(f"- {note}" for note in notes), ""]
    return "\n".join(lines)
