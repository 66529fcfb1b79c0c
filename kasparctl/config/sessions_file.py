"""The planned sessions in a file of their own: `sessions_file` in kaspar.toml.

`kasparctl plan` writes one such file per robot of a study; the robot's
kaspar.toml names it, and its `[[sessions]]` are the robot's, checked by every
rule kaspar.toml's own are (kasparctl.config.rules). The file holds
`[[sessions]]` tables and nothing else; kaspar.toml then has none of its own
(two lists would leave their order, and which one a reader meant, to a guess).
Every error names the sessions file and the key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import msgspec

from kasparctl.config.errors import ConfigError, read_toml
from kasparctl.config.explain import explain_validation_error
from kasparctl.config.schema import Config, SessionPlan


class _SessionsFile(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    sessions: tuple[SessionPlan, ...] = ()


def read_sessions(path: str | Path) -> tuple[SessionPlan, ...]:
    """The planned sessions of a sessions file; ConfigError names the file and the key."""
    source = str(path)
    raw = read_toml(path)
    unknown = sorted(set(raw) - {"sessions"})
    if unknown:
        raise ConfigError(
            source, unknown[0], "expected only [[sessions]] tables in a sessions file, found "
            f"{unknown[0]!r} (the robot's other settings belong in kaspar.toml)"
        )
    try:
        return msgspec.convert(raw, type=_SessionsFile).sessions
    except msgspec.ValidationError as error:
        key, message = explain_validation_error(str(error), raw)
        raise ConfigError(source, key, message) from None


def apply_sessions_file(
    config: Config, raw: dict[str, Any], source: str, base_dir: Path | None
) -> tuple[Config, str | None]:
    """The configuration with its sessions file's sessions, and that file's path (None
    without one); ConfigError if kaspar.toml also plans sessions of its own."""
    if config.sessions_file is None:
        return config, None
    if raw.get("sessions"):
        raise ConfigError(
            source,
            "sessions_file",
            f"expected the planned sessions in [[sessions]] here or in sessions_file, not "
            f"both: found {len(raw['sessions'])} [[sessions]] and sessions_file = "
            f"{config.sessions_file!r}",
        )
    path = Path(config.sessions_file)
    if base_dir is not None:
        path = base_dir / path
    sessions = read_sessions(path)
    return msgspec.structs.replace(config, sessions=sessions, sessions_file=str(path)), str(path)
