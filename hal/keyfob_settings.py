"""Settings of the keyfob (the `[keyfob]` table of kaspar.toml)."""

from __future__ import annotations

import msgspec


class KeyfobSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Placeholder until the keyfob HAL defines its device, key map and gesture timings."""
