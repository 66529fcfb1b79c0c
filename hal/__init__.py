"""Hardware abstraction: the robot's servos, keyfob and voice, each with a simulated twin.

The game sees only these three interfaces; drivers live in their own modules
and are chosen by each table's `backend` in the configuration. The HAL knows
nothing of the game.

- ServoApi (hal.servo_api): named joints, groups, degrees; safety enforced below it.
- KeyfobInput (hal.input_api): a stream of gestures and keyfob-lost/back events.
- VoiceOutput (hal.voice_api): say, cancel, close; failures are results, not exceptions.
"""

from hal.input_api import InputEvent, KeyfobBack, KeyfobInput, KeyfobLost
from hal.servo_api import Fault, FaultKind, ServoApi
from hal.voice_api import Spoken, SpokenStatus, VoiceOutput

__all__ = [
    "Fault",
    "FaultKind",
    "InputEvent",
    "KeyfobBack",
    "KeyfobInput",
    "KeyfobLost",
    "ServoApi",
    "Spoken",
    "SpokenStatus",
    "VoiceOutput",
]
