"""ConfigError, the one error of a configuration: the file, the key, what is wrong.

Every part of kasparctl.config raises it the same way, `SOURCE: KEY: MESSAGE`,
the message saying what was expected and what was found.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from hal.errors import KasparError


class ConfigError(KasparError):
    """A configuration that cannot be used, with where and why."""

    def __init__(self, source: str, key: str, message: str) -> None:
        """Say `SOURCE: KEY: MESSAGE`; the three parts stay readable on their own."""
        super().__init__(f"{source}: {key}: {message}")
        self.source = source
        self.key = key
        self.message = message


def utf8_text(data: bytes, source: str) -> str:
    """The file's text; a byte that is not UTF-8 is an error naming where it is, never
    replaced (a name said aloud and kept in the records must be what the file says)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        column = error.start - (data.rfind(b"\n", 0, error.start) + 1) + 1
        byte = data[error.start : error.start + 1].hex()
        raise ConfigError(
            source,
            "(file)",
            f"expected UTF-8 text, found byte 0x{byte} at line {line}, column {column} "
            f"(byte offset {error.start}): save the file as UTF-8",
        ) from None



def read_toml(path: str | Path) -> dict[str, Any]:
    """A side file's TOML (poses, centres): ConfigError names the file for one that cannot
    be read, is not UTF-8 or is not TOML."""
    source = str(path)
    try:
        text = utf8_text(Path(path).read_bytes(), source)
    except OSError as error:
        raise ConfigError(source, "(file)", f"cannot read it: {error.strerror}") from error
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(source, "(syntax)", f"not valid TOML: {error}") from error
