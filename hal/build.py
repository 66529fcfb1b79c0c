"""Build the three hardware parts from their settings: the real drivers or the twins."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import TextIO

import msgspec

from hal.clock import Clock
from hal.input_api import KeyfobInput
from hal.keyfob_settings import KeyfobSettings
from hal.servo_api import ServoApi, build_servos
from hal.servo_settings import ServoSettings
from hal.voice_api import VoiceOutput
from hal.voice_settings import VoiceSettings


@dataclass
class BuiltHardware:
    servos: ServoApi
    keyfob: KeyfobInput
    voice: VoiceOutput


def build(
    servos: ServoSettings,
    keyfob: KeyfobSettings,
    voice: VoiceSettings,
    clock: Clock,
    *,
    sim: bool = False,
    sim_keys: TextIO | None = None,
    sim_lines: TextIO | None = None,
) -> BuiltHardware:
    """Each part as its `backend` says, or every part simulated when `sim`.

    A simulated keyfob reads keys from `sim_keys` (standard input by default:
    g green, r red, G long green, ...); a simulated voice prints to `sim_lines`.
    """
    if sim:
        servos = msgspec.structs.replace(servos, backend="sim")
    built_servos = build_servos(servos, clock)
    if sim or keyfob.backend == "sim":
        from hal.sim_keyfob import TerminalKeyfob

        built_keyfob: KeyfobInput = TerminalKeyfob(clock, stream=sim_keys or sys.stdin)
    else:
        from hal.keyfob import Keyfob

        built_keyfob = Keyfob(keyfob, clock)
    if sim or voice.backend == "sim":
        from hal.sim_voice import SimVoice

        built_voice: VoiceOutput = SimVoice(sim_lines or sys.stderr, clock)
    else:
        from hal.voice import Voice

        built_voice = Voice(voice, clock)
    return BuiltHardware(built_servos, built_keyfob, built_voice)
