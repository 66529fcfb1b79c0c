"""docs/research-data.md's column tables, generated from kasparctl.research.codebook.

    .venv/bin/python tests/codebook_table.py          # rewrites the tables in the doc

tests/test_data_package.py fails when the doc and the codebook disagree: the codebook
is the one source of the exported columns (the CSV headers, datapackage.json, Psych-DS),
and the doc shows it.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from kasparctl.research import codebook  # noqa: E402

DOC = ROOT / "docs" / "research-data.md"


def markers(table: str) -> tuple[str, str]:
    """The lines around one table in the doc."""
    return (
        f"<!-- {table} columns: generated from kasparctl/research/codebook.py by "
        "tests/codebook_table.py, do not edit by hand -->",
        f"<!-- end of {table} columns -->",
    )


def block(table: str) -> str:
    """One table between its markers."""
    begin, end = markers(table)
    return f"{begin}\n{codebook.markdown(codebook.TABLES[table])}\n{end}"


def current(doc: str, table: str) -> str:
    """The table as the doc has it now (empty without markers)."""
    begin, end = markers(table)
    start, stop = doc.find(begin), doc.find(end)
    return doc[start : stop + len(end)] if start >= 0 and stop > start else ""


def main() -> None:
    """Rewrite every table of the doc from the codebook."""
    doc = DOC.read_text(encoding="utf-8")
    for table in codebook.TABLES:
        old = current(doc, table)
        if not old:
            raise SystemExit(f"{DOC}: no markers for the {table} table: {markers(table)}")
        doc = doc.replace(old, block(table))
    DOC.write_text(doc, encoding="utf-8")


if __name__ == "__main__":
    main()
