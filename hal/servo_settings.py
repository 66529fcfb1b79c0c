"""Settings of the servo buses and named joints (the `[servos]` table of kaspar.toml)."""

from __future__ import annotations

import msgspec


class ServoSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Placeholder until the servo HAL defines buses and joints."""
