"""Hardware abstraction: the robot's servos, keyfob and voice, each with a simulated twin.

The game sees only these three interfaces; drivers live in their own modules
and are chosen by each table's `backend` in the configuration. The HAL knows
nothing of the game.

- ServoApi (hal.servos.api): named joints, groups, degrees; safety enforced below it.
- KeyfobInput (hal.keyfob.api): a stream of gestures and keyfob-lost/back events; the
  children's keyfob, and the researcher's own device when there is one.
- VoiceOutput (hal.voice.api): say, cancel, close; failures are results, not exceptions.
"""

from dataclasses import dataclass

from hal.keyfob.api import InputEvent, KeyfobBack, KeyfobInput, KeyfobLost
from hal.servos.api import Fault, FaultKind, ServoApi
from hal.voice.api import Spoken, SpokenStatus, VoiceOutput


@dataclass
class Hardware:
    """The robot's parts, as the game sees them: built by hal.build, or by a test rig.

    `researcher` is the researcher's own device (a keypad of command keys), or None
    when their commands come from the children's keypad or keyfob.
    """

    servos: ServoApi
    keyfob: KeyfobInput
    voice: VoiceOutput
    researcher: KeyfobInput | None = None


__all__ = [
    "Fault",
    "FaultKind",
    "Hardware",
    "InputEvent",
    "KeyfobBack",
    "KeyfobInput",
    "KeyfobLost",
    "ServoApi",
    "Spoken",
    "SpokenStatus",
    "VoiceOutput",
]
