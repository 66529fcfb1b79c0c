"""The battery between trials: "my battery is low" once per fall, recorded; STATUS= and the view.

The game is the demo's, on the simulated robot in simulated time: its battery is a
LiFePO4 pack read through head_yaw's servo ([servos.battery] in kasparctl/sim/demo.toml).
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from tomllib import loads

from rig_events import on_event
from test_game import play, records_of

from hal.servos.api import BatteryReading
from kasparctl.game.battery import HYSTERESIS_V, BatteryWatch, Crossing
from kasparctl.game.records import HalEvent, HalRecord, StepRecord
from kasparctl.service.status import battery_words, status_line
from kasparctl.sim.demo import DemoRig

PHRASES = Path(__file__).resolve().parents[1] / "phrases"
LOW_LINE = loads((PHRASES / "en.toml").read_text())["fault"]["battery_low"][0]


def test_a_crossing_is_one_fall_below_the_line_until_it_is_back_above_with_margin():
    watch = BatteryWatch()
    readings = [12.4, 11.9, 11.7, 11.6, 11.9, 11.7, 11.8 + HYSTERESIS_V, 12.5, 11.5]
    crossings = [watch.reading(volts, 11.8) for volts in readings]
    assert crossings == [None, None, Crossing.LOW, None, None, None, Crossing.OK, None,
                         Crossing.LOW]


def _set_battery(rig: DemoRig, volts: float) -> None:
    for driver in rig.servos.drivers.values():
        driver.battery_full_v = volts  # falls from here with the clock, slowly


def test_kaspar_says_its_battery_is_low_once_per_fall_between_trials(tmp_path: Path) -> None:
    async def scenario(rig: DemoRig) -> None:
        await on_event(rig, "question", lambda info: info["trial"] == 2)
        _set_battery(rig, 11.5)
        await on_event(rig, "question", lambda info: info["trial"] == 5)
        _set_battery(rig, 13.2)  # the pack swapped for a charged one
        await on_event(rig, "question", lambda info: info["trial"] == 7)
        _set_battery(rig, 11.4)
        await asyncio.sleep(3600)

    result, _, out = play(tmp_path, scenario=scenario, seed=1)
    records = records_of(result)
    battery = [r for r in records if r["kind"] == "hal" and r["event"].startswith("battery")]
    assert [r["event"] for r in battery] == ["battery_low", "battery_ok", "battery_low"]
    assert battery[0]["voltage_v"] < 11.8 and battery[0]["warn_below_v"] == 11.8
    assert battery[0]["joint"] == "head_yaw" and battery[1]["voltage_v"] > 13.0
    # Said once per fall, between trials: not during a question, not every trial.
    assert out.count(f"Kaspar: {LOW_LINE}") == 2
    kinds = [r["kind"] for r in records]
    first = kinds.index("hal", kinds.index("trial"))
    assert records[first]["event"] == "battery_low" and records[first + 1]["kind"] != "trial"
    assert result.finished


def test_the_live_view_shows_the_battery_as_last_recorded():
    from test_view_frame import picture

    low = HalRecord(event=HalEvent.BATTERY_LOW, voltage_v=11.62, warn_below_v=11.8,
                    joint="torso_yaw")
    lines, view, _ = picture(StepRecord(to="guessing"), low)
    assert view.session.battery == "LOW 11.6 V (below 11.8 V)" and view.session.battery_low
    (daemon,) = [line for line in lines if line.startswith("daemon ")]
    assert "robot ok  battery LOW 11.6 V (below 11.8 V)" in daemon
    ok = HalRecord(event=HalEvent.BATTERY_OK, voltage_v=13.1, warn_below_v=11.8, joint="torso_yaw")
    lines, view, _ = picture(StepRecord(to="guessing"), low, ok)
    assert view.session.battery == "ok 13.1 V" and not view.session.battery_low
    assert not view.session.faults  # a battery record is not a line unheard


def test_status_shows_the_battery():
    reading = BatteryReading("torso_yaw", 11.62, 11.8)
    assert battery_words(reading) == "battery LOW: 11.6 V, below 11.8 V"
    assert battery_words(BatteryReading("torso_yaw", 12.96, 11.8)) == "battery 13.0 V"
    assert battery_words(BatteryReading("torso_yaw", None, 11.8)) == "battery not read yet"
    assert battery_words(None) is None
    line = status_line("guessing", battery=battery_words(reading))
    assert line == "step 4: Kaspar guesses the names | battery LOW: 11.6 V, below 11.8 V"
    # Last, after the problems and the notice: a line's beginning stays as it was.
    line = status_line("idle", notice="session x abandoned", battery="battery 13.0 V")
    assert line == "waiting: 'next' starts the session | session x abandoned | battery 13.0 V"
