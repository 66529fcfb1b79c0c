"""`kasparctl report`: the paper's figures and statistics for recorded sessions, with intervals.

Writes to --out: entropy_by_trial, final_q, trials_to_learn, feedback_by_child
and contrasts, each as PNG and SVG, summary.md, summary.json and children.csv
(each child's teaching measures, joined to participants.csv when given).
Sessions of different conditions are shown side by side; every interval is a
95 % cluster bootstrap over groups of children (--cluster session: over
sessions). --state-dir may be repeated to pool robots or days. The figures
need matplotlib: pip install 'kasparctl[report]'.
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

from kasparctl.game.phrases import PhraseError, load_phrasebook
from kasparctl.research.children import Children
from kasparctl.research.conditions import CLUSTER_UNITS, by_condition, by_uncertainty, pooled
from kasparctl.research.figures import FigureData, FiguresUnavailable, draw_all, require_matplotlib
from kasparctl.research.inference import (
    DEFAULT_REPLICATES,
    DEFAULT_SEED,
    attribute_contrasts,
    condition_contrasts,
    intervals,
)
from kasparctl.research.output import (
    OutputError,
    atomic_file,
    check_outputs,
    private_directory,
    write_bytes,
)
from kasparctl.research.participants import (
    NO_PARTICIPANTS,
    ParticipantsError,
    load_participants,
)
from kasparctl.research.source import (
    SourceError,
    add_source_arguments,
    input_files,
    read_sessions,
    report_unknown_codes,
)
from kasparctl.research.summary import Method, build_summary, markdown, write_json
from kasparctl.research.tidy import cell

MAX_REPLICATES = 100_000


def register(subparsers: Any) -> None:
    """Add the `report` subcommand."""
    parser = subparsers.add_parser(
        "report", help="figures and a summary like the paper's", description=__doc__
    )
    add_source_arguments(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="where to write the report")
    parser.add_argument(
        "--participants",
        metavar="FILE",
        help="participants.csv: the children's attributes by code (contrasts by each category)",
    )
    parser.add_argument(
        "--cluster",
        choices=CLUSTER_UNITS,
        default="group",
        help="what the intervals resample (default: group, the paper's unit)",
    )
    parser.add_argument(
        "--bootstrap",
        type=_replicates,
        default=DEFAULT_REPLICATES,
        metavar="N",
        help=f"bootstrap resamples (default {DEFAULT_REPLICATES})",
    )
    parser.add_argument(
        "--seed", type=int, default=DEFAULT_SEED, help="seed of the resampling (default 0)"
    )
    parser.set_defaults(run=run)


def _replicates(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, found {text!r}") from None
    if not 100 <= value <= MAX_REPLICATES:
        raise argparse.ArgumentTypeError(
            f"expected 100 to {MAX_REPLICATES} resamples, found {value}"
        )
    return value


def run(arguments: argparse.Namespace) -> int:
    """Draw the paper's figures and write the summary for every session."""
    try:
        # Before reading a thousand sessions, not after.
        require_matplotlib()
        participants = (
            load_participants(Path(arguments.participants))
            if arguments.participants
            else NO_PARTICIPANTS
        )
        source, catalogue = read_sessions(arguments)
        sessions = catalogue.sessions
        if not sessions:
            raise SourceError("no sessions to report on")
        out = Path(arguments.out)
        check_outputs(
            [("--out", arguments.out)],
            source.state_dirs,
            [s.directory for s in sessions] + [d.directory for d in catalogue.damaged],
            input_files(arguments),
        )
        report_unknown_codes(sessions, participants)
        children = Children()
        conditions = by_condition(sessions, source.params, children, arguments.cluster)
        everything = pooled(conditions)
        config = source.config
        bands = load_phrasebook(
            config.language if config else "en", config.phrases_dir if config else None
        ).bands
        replicates, seed = arguments.bootstrap, arguments.seed
        found = {c.label: intervals(c, replicates, seed) for c in [*conditions, everything]}
        contrasts = condition_contrasts(conditions, arguments.cluster, replicates, seed)
        measured = list(children.by_key.values())
        contrasts += attribute_contrasts(measured, participants, replicates, seed)

        def joined(coded_only: bool) -> Iterator[dict[str, Any]]:
            for row in children.rows(coded_only):
                attributes = participants.attributes(row["participant"])
                yield {**row, **{f"participant_{c}": v for c, v in attributes.items()}}

        private_directory(out)
        data = FigureData(conditions, found, bands, measured, participants, contrasts)
        drawn = draw_all(data, out)
        for note in drawn.notes:
            if note.split(":")[0] in drawn.failed:
                print(f"warning: {note}", file=sys.stderr)
        summary = build_summary(
            conditions,
            everything,
            found,
            Method(replicates, seed, arguments.cluster),
            contrasts,
            list(joined(coded_only=True)),
            arguments.participants,
            by_uncertainty(conditions),
        )
        summary["figures"] = drawn.names
        summary["notes"] = drawn.notes
        write_json(out / "summary.json", summary)
        write_bytes(out / "summary.md", markdown(summary, drawn.names, drawn.notes).encode("utf-8"))
        with atomic_file(out / "children.csv") as stream:
            _write_children(stream, joined(coded_only=False))
    except (
        SourceError,
        FiguresUnavailable,
        PhraseError,
        OutputError,
        ParticipantsError,
    ) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        where = f"{error.filename}: " if error.filename else ""
        print(f"error: cannot write the report: {where}{error.strerror or error}", file=sys.stderr)
        return 1
    labels = ", ".join(c.label for c in conditions)
    print(
        f"report on {len(sessions)} sessions ({labels}): {len(drawn.names)} figures, "
        f"summary.md, summary.json and children.csv in {out}"
    )
    return 0


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
