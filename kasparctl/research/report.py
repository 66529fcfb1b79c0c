"""A report on recorded sessions: the paper's figures and statistics, with intervals.

Into one private directory: entropy_by_trial, final_q, trials_to_learn,
feedback_by_child and contrasts (kasparctl.research.figures, each as PNG and
PDF, and SVG on request), summary.md and summary.json (kasparctl.research.summary) and children.csv
(each child's teaching measures, joined to participants.csv when given).
Sessions of different conditions are shown side by side; every interval is a 95 %
cluster bootstrap (kasparctl.research.inference) over the chosen unit.
"""

from __future__ import annotations

import csv
import io
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from kasparctl.config import Config
from kasparctl.game.phrases import load_phrasebook
from kasparctl.research.catalogue import SessionData
from kasparctl.research.children import Children
from kasparctl.research.conditions import by_condition, by_uncertainty, learner_split, pooled
from kasparctl.research.figures import FORMATS, SVG, FigureData, draw_all
from kasparctl.research.inference import (
    attribute_contrasts,
    condition_contrasts,
    holm,
    intervals,
)
from kasparctl.research.output import atomic_file, private_directory, write_bytes
from kasparctl.research.participants import Participants
from kasparctl.research.source import Source
from kasparctl.research.summary import Method, build_summary, markdown, write_json
from kasparctl.research.tidy import cell


@dataclass(frozen=True)
class Written:
    """What a report wrote: the conditions shown and the figures drawn."""

    conditions: list[str]
    figures: list[str]


def write_report(
    sessions: Sequence[SessionData],
    source: Source,
    participants: Participants,
    participants_file: str | None,
    out: Path,
    method: Method,
    svg: bool = False,
    workers: int = 1,
) -> Written:
    """Draw the figures and write the summaries and children.csv into `out` (made 0700).

    `participants_file` is the participants.csv as the researcher named it (the summary
    says so). Each figure is written as PNG and PDF, and as SVG too when `svg`,
    by up to `workers` processes at once. A figure
    that could not be drawn is a warning on stderr; the rest is written.
    """
    children = Children()
    conditions = by_condition(sessions, source.params, children, method.unit)
    everything = pooled(conditions)
    bands = load_phrasebook(*_language(source.config)).bands
    replicates, seed = method.replicates, method.seed
    found = {c.label: intervals(c, replicates, seed) for c in [*conditions, everything]}
    contrasts = condition_contrasts(conditions, method.unit, replicates, seed)
    measured = list(children.by_key.values())
    contrasts += attribute_contrasts(measured, participants, replicates, seed)
    contrasts = holm(contrasts)  # one family: every contrast of the report

    def joined(coded_only: bool) -> Iterator[dict[str, Any]]:
        for row in children.rows(coded_only):
            attributes = participants.attributes(row["participant"])
            yield {**row, **{f"participant_{c}": v for c, v in attributes.items()}}

    private_directory(out)
    data = FigureData(conditions, found, bands, measured, participants, contrasts)
    drawn = draw_all(data, out, (*FORMATS, SVG) if svg else FORMATS, workers)
    for note in drawn.notes:
        if note.split(":")[0] in drawn.failed:
            print(f"warning: {note}", file=sys.stderr)
    summary = build_summary(
        conditions,
        everything,
        found,
        method,
        contrasts,
        list(joined(coded_only=True)),
        participants_file,
        by_uncertainty(conditions),
    )
    summary["figures"] = drawn.names
    summary["notes"] = [*_learner_notes(sessions), *drawn.notes]
    write_json(out / "summary.json", summary)
    text = markdown(summary, drawn.names, summary["notes"], drawn.formats)
    write_bytes(out / "summary.md", text.encode("utf-8"))
    with atomic_file(out / "children.csv") as stream:
        _write_children(stream, joined(coded_only=False))
    return Written([c.label for c in conditions], list(drawn.names))


def _learner_notes(sessions: Sequence[SessionData]) -> list[str]:
    """A note per profile name whose sessions had different learners (not pooled)."""
    marks = learner_split(sessions)
    split = sorted({s.profile for s in sessions if marks.get(s.uid)})
    return [
        f"learner profile {profile!r}: its sessions were recorded with different "
        "parameters (plan.json's learner), so each set is a condition of its own, labelled "
        "with its alpha and beta"
        for profile in split
    ]


def _language(config: Config | None) -> tuple[str, str | None]:
    """The phrase book whose bands the figures draw: the configuration's, else English."""
    if config is None:
        return "en", None
    return config.language, config.phrases_dir


def _write_children(stream: BinaryIO, rows: Iterator[dict[str, Any]]) -> None:
    """children.csv: every child's measures, one row at a time."""
    text = io.TextIOWrapper(stream, encoding="utf-8", newline="")
    writer = csv.writer(text, lineterminator="\n")
    header: list[str] | None = None
    for row in rows:
        if header is None:
            header = list(row)
            writer.writerow(header)
        writer.writerow([cell(row.get(column)) for column in header])
    if header is None:
        writer.writerow(["child"])
    text.flush()
    text.detach()
