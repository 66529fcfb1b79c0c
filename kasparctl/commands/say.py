"""`kasparctl say`: being built (owned by the say work in progress)."""

from __future__ import annotations

from typing import Any


def register(subparsers: Any) -> None:
    del subparsers
