"""`kasparctl report`: the paper's figures and statistics for recorded sessions, with intervals.

Writes to --out: entropy_by_trial, final_q, trials_to_learn, feedback_by_child
and contrasts, each as 300-dpi PNG and PDF (and SVG with --svg), summary.md,
summary.json and children.csv (each child's teaching measures, joined to
participants.csv when given).
Sessions of different conditions are shown side by side; every interval is a
95 % cluster bootstrap over groups of children (--cluster session: over
sessions). --state-dir may be repeated to pool robots or days. The figures
need matplotlib: pip install 'kasparctl[report]'.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from kasparctl.commands.arguments import add_sources, path, seed, whole
from kasparctl.research.conditions import CLUSTER_UNITS
from kasparctl.research.figures import require_matplotlib
from kasparctl.research.inference import DEFAULT_REPLICATES, DEFAULT_SEED
from kasparctl.research.output import check_outputs
from kasparctl.research.participants import NO_PARTICIPANTS, load_participants
from kasparctl.research.report import write_report
from kasparctl.research.source import (
    SourceError,
    input_files,
    read_sessions,
    report_unknown_codes,
)
from kasparctl.research.summary import Method

MAX_REPLICATES = 100_000


def register(subparsers: Any) -> None:
    """Add the `report` subcommand."""
    parser = subparsers.add_parser(
        "report", help="figures and a summary like the paper's", description=__doc__
    )
    add_sources(parser)
    add = parser.add_argument
    add("--out", required=True, type=path, metavar="DIR", help="where to write the report")
    add("--participants", metavar="FILE", type=path,
        help="participants.csv: the children's attributes by code (contrasts by each category)")
    add("--cluster", choices=CLUSTER_UNITS, default="group",
        help="what the intervals resample (default: group, the paper's unit)")
    add("--bootstrap", type=whole(100, MAX_REPLICATES), default=DEFAULT_REPLICATES, metavar="N",
        help=f"bootstrap resamples (default {DEFAULT_REPLICATES})")
    add("--seed", type=seed, default=DEFAULT_SEED, help="seed of the resampling (default 0)")
    add("--workers", type=whole(1, 64), default=1, metavar="N",
        help="processes drawing the figures at once, one figure each (default 1: each "
             "worker takes up to about 200 MB at 720 sessions)")
    add("--svg", action="store_true",
        help="also write each figure as SVG (text as <text>); PNG and PDF are always written")
    parser.set_defaults(run=run)  # fmt: skip


def run(arguments: argparse.Namespace) -> int:
    """Draw the paper's figures and write the summary for every session."""
    require_matplotlib()  # before reading a thousand sessions, not after
    participants = (
        load_participants(Path(arguments.participants))
        if arguments.participants
        else NO_PARTICIPANTS
    )
    source, catalogue = read_sessions(arguments)
    sessions = catalogue.sessions
    if not sessions:
        raise SourceError("no sessions to report on")
    check_outputs(
        [("--out", arguments.out)],
        source.state_dirs,
        [s.directory for s in sessions] + [d.directory for d in catalogue.damaged],
        input_files(arguments),
    )
    report_unknown_codes(sessions, participants)
    out = Path(arguments.out)
    method = Method(arguments.bootstrap, arguments.seed, arguments.cluster)
    try:
        written = write_report(
            sessions, source, participants, arguments.participants, out, method, arguments.svg,
            arguments.workers,
        )
    except OSError as error:
        where = f"{error.filename}: " if error.filename else ""
        print(f"error: cannot write the report: {where}{error.strerror or error}", file=sys.stderr)
        return 1
    print(
        f"report on {len(sessions)} sessions ({', '.join(written.conditions)}): "
        f"{len(written.figures)} figures, summary.md, summary.json and children.csv in {out}"
    )
    return 0
