"""Build the hardware parts from their settings: the real drivers or the twins."""

from __future__ import annotations

import sys
from typing import TextIO

import msgspec

from hal import Hardware
from hal.clock import Clock
from hal.keyfob.api import KeyfobInput
from hal.keyfob.settings import KeyfobSettings, ResearcherSettings
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
    researcher: ResearcherSettings | None = None,
    sim: bool = False,
    sim_keys: TextIO | None = None,
    sim_keys_fifo: str | None = None,
    sim_lines: TextIO | None = None,
) -> Hardware:
    """Each part as its `backend` says, or every part simulated when `sim`.

    The researcher's own device is built when `researcher.source` is "device" (the
    default table when none is given). A simulated keyfob reads keys from `sim_keys`
    (standard input by default), or from the fifo `sim_keys_fifo` (which may come
    late): g and r are the children's green and red, G, R, d and b the researcher's
    next, pause, undo and stop (docs/keyfob-and-voice.md). A simulated voice prints
    to `sim_lines`.
    """
    researcher = researcher if researcher is not None else ResearcherSettings()
    if sim:
        servos = msgspec.structs.replace(servos, backend="sim")
    built_servos = build_servos(servos, clock)
    own_device = researcher.source == "device"
    built_researcher: KeyfobInput | None = None
    simulated = sim or keyfob.backend == "sim" or sim_keys_fifo is not None
    if simulated:
        from hal.keyfob.sim import FifoKeyfob, ResearcherKeys, SimKeyfob, TerminalKeyfob

        # The researcher's keys typed beside the children's reach a simulated device, or
        # the keypad's own command keys; on one keyfob they are its holds.
        twin = SimKeyfob(clock, commands=researcher.command_names())
        if own_device:
            built_researcher = twin
        device = twin if own_device else None
        keypad = sorted(set(keyfob.commands.values())) if researcher.source == "keypad" else []
        if sim_keys_fifo is not None:
            fifo = FifoKeyfob(sim_keys_fifo, clock, researcher=device, commands=keypad)
            built_keyfob: KeyfobInput = fifo
            if keypad:
                fifo.researcher = ResearcherKeys(fifo, fifo)
        else:
            stream = sim_keys or sys.stdin
            terminal = TerminalKeyfob(clock, stream=stream, researcher=device, commands=keypad)
            built_keyfob = terminal
            if keypad:
                terminal.researcher = ResearcherKeys(terminal, terminal)
    else:
        from hal.keyfob.reader import Keyfob

        built_keyfob = Keyfob(keyfob, clock)
        if own_device:
            if researcher.backend == "sim":
                from hal.keyfob.sim import SimKeyfob

                built_researcher = SimKeyfob(clock, commands=researcher.command_names())
            else:
                built_researcher = Keyfob(
                    researcher, clock, role="researcher", needs=researcher.gesture_needs()
                )
    if keyfob.children:
        built_keyfob = _seats(keyfob, clock, built_keyfob, simulated)
    if sim or voice.backend == "sim":
        from hal.voice.sim import SimVoice

        built_voice: VoiceOutput = SimVoice(sim_lines or sys.stderr, clock, rate=voice.rate)
    else:
        from hal.voice.speaker import Voice

        built_voice = Voice(voice, clock)
    return Hardware(built_servos, built_keyfob, built_voice, built_researcher)


def _seats(
    keyfob: KeyfobSettings, clock: Clock, first: KeyfobInput, simulated: bool
) -> KeyfobInput:
    """One keyfob per child ([[keyfob.children]]) as one stream. Simulated, the terminal's
    (or the fifo's) keyfob is the first seat's, the others are silent twins."""
    from hal.keyfob.seats import Seats

    devices = [seat.where for seat in keyfob.children]
    if simulated:
        from hal.keyfob.sim import SimKeyfob

        others = [SimKeyfob(clock) for _ in devices[1:]]
        return Seats([first, *others], devices)
    from hal.keyfob.reader import Keyfob

    keyfobs = [Keyfob(keyfob.seat(index), clock) for index in range(len(devices))]
    return Seats(keyfobs, devices)
