"""Build the three hardware parts from their settings: the real drivers or the twins."""

from __future__ import annotations

import sys
from typing import TextIO

import msgspec

from hal import Hardware
from hal.clock import Clock
from hal.keyfob.api import KeyfobInput
from hal.keyfob.settings import KeyfobSettings
from hal.servos.api import ServoApi
from hal.servos.settings import ServoSettings
from hal.voice.api import VoiceOutput
from hal.voice.settings import VoiceSettings


def build_servos(settings: ServoSettings, clock: Clock) -> ServoApi:
    """The configured backend: the real buses, or the simulated servos."""
    if settings.backend == "real":
        from hal.servos.joints import Joints

        return Joints.from_settings(settings, clock)
    from hal.servos.sim import SimServos

    return SimServos(settings, clock)


def build(
    servos: ServoSettings,
    keyfob: KeyfobSettings,
    voice: VoiceSettings,
    clock: Clock,
    *,
    sim: bool = False,
    sim_keys: TextIO | None = None,
    sim_lines: TextIO | None = None,
) -> Hardware:
    """Each part as its `backend` says, or every part simulated when `sim`.

    A simulated keyfob reads keys from `sim_keys` (standard input by default:
    g green, r red, G long green, ...); a simulated voice prints to `sim_lines`.
    """
    if sim:
        servos = msgspec.structs.replace(servos, backend="sim")
    built_servos = build_servos(servos, clock)
    if sim or keyfob.backend == "sim":
        from hal.keyfob.sim import TerminalKeyfob

        built_keyfob: KeyfobInput = TerminalKeyfob(clock, stream=sim_keys or sys.stdin)
    else:
        from hal.keyfob.reader import Keyfob

        built_keyfob = Keyfob(keyfob, clock)
    if sim or voice.backend == "sim":
        from hal.voice.sim import SimVoice

        built_voice: VoiceOutput = SimVoice(sim_lines or sys.stderr, clock, rate=voice.rate)
    else:
        from hal.voice.speaker import Voice

        built_voice = Voice(voice, clock)
    return Hardware(built_servos, built_keyfob, built_voice)
