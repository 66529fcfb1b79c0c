"""Settings of Kaspar's voice (the `[voice]` table of kaspar.toml)."""

from __future__ import annotations

import msgspec


class VoiceSettings(msgspec.Struct, forbid_unknown_fields=True, frozen=True, kw_only=True):
    """Placeholder until the voice HAL defines engine, voice, rate, volume and clips."""
