"""`kasparctl report`: the paper's figures and statistics for recorded sessions.

Writes to --out: entropy_by_trial, final_q, trials_to_learn and
feedback_by_child, each as PNG and SVG, and summary.md and summary.json.
Sessions of different conditions are shown side by side. The figures need
matplotlib: pip install 'kasparctl[report]'.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from kasparctl.game.phrases import PhraseError, load_phrasebook
from kasparctl.research.conditions import by_condition
from kasparctl.research.figures import FiguresUnavailable, draw_all, require_matplotlib
from kasparctl.research.source import SourceError, add_source_arguments, read_sessions
from kasparctl.research.summary import build_summary, markdown, write_json


def register(subparsers: Any) -> None:
    """Add the `report` subcommand."""
    parser = subparsers.add_parser(
        "report", help="figures and a summary like the paper's", description=__doc__
    )
    add_source_arguments(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="where to write the report")
    parser.set_defaults(run=run)


def run(arguments: argparse.Namespace) -> int:
    """Draw the paper's figures and write the summary for every session."""
    try:
        # Before reading a thousand sessions, not after.
        require_matplotlib()
        source, sessions = read_sessions(arguments)
        if not sessions:
            raise SourceError("no sessions to report on")
        conditions = by_condition(sessions, source.params)
        config = source.config
        bands = load_phrasebook(
            config.language if config else "en", config.phrases_dir if config else None
        ).bands
        out = Path(arguments.out)
        out.mkdir(parents=True, exist_ok=True)
        drawn = draw_all(conditions, bands, out)
        summary = build_summary(conditions)
        summary["figures"] = drawn.names
        summary["notes"] = drawn.notes
        write_json(out / "summary.json", summary)
        (out / "summary.md").write_text(
            markdown(summary, drawn.names, drawn.notes), encoding="utf-8"
        )
    except (SourceError, FiguresUnavailable, PhraseError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    except OSError as error:
        print(f"error: cannot write the report: {error}", file=sys.stderr)
        return 1
    labels = ", ".join(c.label for c in conditions)
    print(
        f"report on {len(sessions)} sessions ({labels}): {len(drawn.names)} figures, "
        f"summary.md and summary.json in {out}"
    )
    return 0
