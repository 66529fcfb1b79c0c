"""When the battery crosses its warning line: Kaspar says it is low once per fall (pure).

The servos layer reads the battery through one servo's voltage register
(`[servos.battery]`); between two guesses step 4 (game.steps) compares the last reading with
`warn_below_v`. Falling below it is one crossing: recorded (a "hal" record,
battery_low, with the voltage) and said once ("battery.low"). It is said again only
after the battery has come back above the line by HYSTERESIS_V (charged or swapped:
recorded as battery_ok, silently), so a reading that wavers around the line is not
a warning every trial. The watch outlives a game (game.machine.Lasting): the battery
does not recharge between sessions.
"""

from __future__ import annotations

import enum

# Above the line by this much before a later fall is a new crossing: a LiFePO4 pack's
# voltage moves by tenths of a volt with the load of a move.
HYSTERESIS_V = 0.3


class Crossing(enum.Enum):
    """Which way a reading crossed the warning line."""

    LOW = "low"
    OK = "ok"


class BatteryWatch:
    """Whether the battery is below its line now, and when that changes (pure)."""

    def __init__(self) -> None:
        """Not low until a reading says so."""
        self.low = False

    def reading(self, volts: float, warn_below_v: float) -> Crossing | None:
        """The crossing this reading makes, if any."""
        if not self.low and volts < warn_below_v:
            self.low = True
            return Crossing.LOW
        if self.low and volts >= warn_below_v + HYSTERESIS_V:
            self.low = False
            return Crossing.OK
        return None
