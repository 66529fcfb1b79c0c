"""The exported tables described for machines: datapackage.json and a Psych-DS layout.

datapackage.json is a Frictionless Data Package (Table Schema v1): a resource per
CSV with its fields' types, constraints (required, enumerations, ranges), NA as
the missing value, TRUE/FALSE as the booleans, primary keys (trials: session and
trial; events: session and seq; sessions: session) and the foreign keys that join
trials and events to their session. Every description is the codebook's
(kasparctl.research.codebook), as are the columns, so the package, the CSVs and
docs/research-data.md say one thing. The Psych-DS layout puts the same CSVs under
data/ with Psych-DS's names and a dataset_description.json whose variableMeasured
lists every column with its description.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from kasparctl.research import codebook
from kasparctl.research.tidy import MISSING

_TYPES = {
    "string": "string",
    "list": "string",  # values joined by ";": Table Schema v1 has no list type
    "integer": "integer",
    "number": "number",
    "boolean": "boolean",
    "timestamp": "datetime",
}
_KEYS = {"trials": ["session", "trial"], "events": ["session", "seq"], "sessions": ["session"]}


@dataclass(frozen=True)
class Table:
    """One exported CSV: which codebook table, where it is (relative), its header."""

    table: str
    path: str
    header: Sequence[str]


def field(name: str, column: codebook.Column) -> dict[str, Any]:
    """A column as a Table Schema field."""
    described: dict[str, Any] = {
        "name": name,
        "type": _TYPES[column.type],
        "description": codebook.description(column),
    }
    if column.type == "boolean":
        described.update(trueValues=["TRUE"], falseValues=["FALSE"])
    if column.type == "list":
        described["format"] = "default"
        described["description"] += " Values joined by ';'."
    constraints: dict[str, Any] = {}
    if column.required:
        constraints["required"] = True
    if column.enum:
        constraints["enum"] = list(column.enum)
    if column.minimum is not None:
        constraints["minimum"] = column.minimum
    if column.maximum is not None:
        constraints["maximum"] = column.maximum
    if constraints:
        described["constraints"] = constraints
    return described


def columns_of(table: Table) -> list[tuple[str, codebook.Column]]:
    """The header's columns, each with its codebook entry (a per-toy or per-attribute
    column by its pattern)."""
    patterns = codebook.TABLES[table.table]
    exact = {c.name: c for c in patterns}
    found = []
    for name in table.header:
        column = exact.get(name) or next(
            c
            for c in patterns
            if "<" in c.name
            and name.startswith(c.name.split("<")[0])
            and name.endswith(c.name.split(">")[-1])
        )
        found.append((name, column))
    return found


def schema(table: Table, with_sessions: bool) -> dict[str, Any]:
    """A table's Table Schema."""
    described: dict[str, Any] = {
        "fields": [field(name, column) for name, column in columns_of(table)],
        "missingValues": [MISSING],
        "primaryKey": _KEYS[table.table],
    }
    if with_sessions and table.table != "sessions":
        described["foreignKeys"] = [
            {"fields": ["session"], "reference": {"resource": "sessions", "fields": ["session"]}}
        ]
    return described


def datapackage(tables: Sequence[Table], title: str) -> dict[str, Any]:
    """datapackage.json for the exported tables."""
    with_sessions = any(t.table == "sessions" for t in tables)
    return {
        "profile": "tabular-data-package",
        "name": "kaspar-sessions",
        "title": title,
        "description": (
            "Sessions of the children-as-teachers game with the Kaspar robot, exported by "
            "kasparctl. Columns are described in codebook.md and docs/research-data.md."
        ),
        "resources": [
            {
                "name": table.table,
                "path": table.path,
                "profile": "tabular-data-resource",
                "format": "csv",
                "mediatype": "text/csv",
                "encoding": "utf-8",
                "dialect": {"delimiter": ",", "quoteChar": '"', "header": True},
                "schema": schema(table, with_sessions),
            }
            for table in tables
        ],
    }


# Psych-DS: data files are keyword-value pairs ending in _data.csv, under data/.
PSYCH_DS_NAMES = {
    "trials": "data/study-kaspar_description-trials_data.csv",
    "events": "data/study-kaspar_description-events_data.csv",
    "sessions": "data/study-kaspar_description-sessions_data.csv",
}


def dataset_description(tables: Sequence[Table], title: str) -> dict[str, Any]:
    """Psych-DS's dataset_description.json: schema.org's Dataset, every column measured."""
    measured: dict[str, dict[str, Any]] = {}
    for table in tables:
        for name, column in columns_of(table):
            measured.setdefault(
                name,
                {
                    "@type": "PropertyValue",
                    "name": name,
                    "description": codebook.description(column),
                },
            )
    return {
        "@context": "https://schema.org/",
        "@type": "Dataset",
        "name": title,
        "description": (
            "Sessions of the children-as-teachers game with the Kaspar robot: a row per "
            "trial, per other event and per session (see codebook.md). Missing values: NA."
        ),
        "variableMeasured": list(measured.values()),
    }


def codebook_markdown(tables: Sequence[Table]) -> str:
    """codebook.md: each exported table's columns, as docs/research-data.md shows them."""
    parts = [
        "# Codebook",
        "",
        "Plain CSV (UTF-8, comma, `\"` quoting). Missing values are `NA` (base R's read.csv, "
        "readr and pandas all read it as missing); booleans `TRUE`/`FALSE`; times UTC ISO "
        "8601. A text cell starting with `'` had the mark added so that a spreadsheet does "
        "not evaluate it or a reader take it for missing: `sub(\"^'\", \"\", x)` removes it. "
        "`<toy>` is each toy's name in snake_case.",
        "",
    ]
    for table in tables:
        parts += [f"## {table.path}", "", codebook.markdown(codebook.TABLES[table.table]), ""]
    return "\n".join(parts)
