"""A reload between sessions changes the voice Kaspar speaks with, as a fresh start would.

The daemon runs in this process on simulated servos and keyfobs, with the real voice:
espeak-ng writing each line as a WAV file. The greeting of a session is measured
(duration, RMS) at [voice] rate 150, volume 1.0; after SIGHUP with rate 90, volume 0.2;
and at a fresh start with rate 90, volume 0.2.
"""

from __future__ import annotations

import asyncio
import gc
import os
import shutil
import signal
import wave
from pathlib import Path

import numpy as np
import pytest

from hal import Hardware
from hal.clock import LoopClock
from hal.keyfob.sim import SimKeyfob
from hal.servos.sim import SimServos
from hal.voice.speaker import Voice
from kasparctl.config import load_config, parse_config
from kasparctl.service.applying import restart_only
from kasparctl.service.daemon import Daemon, DaemonOptions
from kasparctl.service.sdnotify import Notifier

needs_espeak = pytest.mark.skipif(
    shutil.which("espeak-ng") is None, reason="espeak-ng not installed"
)

DEMO_CONFIG = Path(__file__).resolve().parents[1] / "kasparctl" / "sim" / "demo.toml"
DEADLINE_S = 60.0
COMMANDS = ("next", "pause", "undo", "stop", "away", "choose", "absent")


def write_config(path: Path, wav_dir: Path, rate: int, volume: float) -> None:
    voice = f'[voice]\nrate = {rate}\nvolume = {volume}\nwav_dir = "{wav_dir}"\n'
    path.write_text(DEMO_CONFIG.read_text(encoding="utf-8") + "\n" + voice, encoding="utf-8")


def measure(path: Path) -> tuple[float, float]:
    """A WAV file's duration (s) and RMS (of int16 samples)."""
    with wave.open(str(path), "rb") as audio:
        samples = np.frombuffer(audio.readframes(audio.getnframes()), dtype="<i2")
        seconds = audio.getnframes() / audio.getframerate()
    return seconds, float(np.sqrt(np.mean(samples.astype(np.float64) ** 2)))


async def until(what: str, condition) -> None:  # type: ignore[no-untyped-def]
    async with asyncio.timeout(DEADLINE_S):
        while not condition():
            await asyncio.sleep(0.02)


async def greeting(tmp_path: Path, name: str, rate: int, volume: float, reload_to=None):  # type: ignore[no-untyped-def]
    """The greeting's WAV of a daemon started at (rate, volume), reloaded to `reload_to`
    (rate, volume) while idle if given."""
    wav_dir = tmp_path / name / "wav"
    wav_dir.mkdir(parents=True)
    config_path = tmp_path / name / "kaspar.toml"
    write_config(config_path, wav_dir, rate, volume)
    config = load_config(config_path)
    clock = LoopClock()
    researcher = SimKeyfob(clock, commands=COMMANDS)
    hardware = Hardware(
        SimServos(config.servos, clock), SimKeyfob(clock), Voice(config.voice, clock), researcher
    )
    options = DaemonOptions(str(config_path), sim=True, state_dir=str(tmp_path / name / "state"))
    daemon = Daemon(options, Notifier(""), hardware=hardware)
    running = asyncio.create_task(daemon.run())
    try:
        await until("idle", lambda: daemon.game is not None and daemon.game.stage == "idle")
        if reload_to is not None:
            idle = daemon.game
            write_config(config_path, wav_dir, *reload_to)
            os.kill(os.getpid(), signal.SIGHUP)
            await until(
                "reloaded",
                lambda: daemon.config.voice.rate == reload_to[0]
                and daemon.game is not idle
                and daemon.game is not None
                and daemon.game.stage == "idle",
            )
        assert list(wav_dir.iterdir()) == []
        await researcher.perform("command next")
        # The greeting is whole once the next line has begun.
        await until("two lines", lambda: len(list(wav_dir.iterdir())) >= 2)
        return sorted(wav_dir.iterdir())[0]
    finally:
        daemon.request_stop("the test is over")
        await asyncio.wait_for(running, timeout=DEADLINE_S)


@needs_espeak
def test_a_reload_changes_rate_and_volume_as_a_fresh_start_would(tmp_path: Path) -> None:
    async def all_three() -> list[Path]:
        paths = [
            await greeting(tmp_path, "before", 150, 1.0),
            await greeting(tmp_path, "reloaded", 150, 1.0, (90, 0.2)),
            await greeting(tmp_path, "fresh", 90, 0.2),
        ]
        # The line cut by each stop left its espeak-ng transport to the collector: closed
        # while the loop still runs.
        gc.collect()
        await asyncio.sleep(0.1)
        return paths

    before, reloaded, fresh = (measure(path) for path in asyncio.run(all_three()))
    print(
        f"greeting: before {before[0]:.2f} s RMS {before[1]:.0f}; after reload "
        f"{reloaded[0]:.2f} s RMS {reloaded[1]:.0f}; fresh start {fresh[0]:.2f} s RMS "
        f"{fresh[1]:.0f}"
    )
    # Slower and quieter than before the reload...
    assert reloaded[0] > 1.4 * before[0]
    assert reloaded[1] < 0.4 * before[1]
    # ...and the very voice a fresh start with those settings gives.
    assert reloaded[0] == pytest.approx(fresh[0], rel=0.02)
    assert reloaded[1] == pytest.approx(fresh[1], rel=0.05)


def test_a_reload_names_each_setting_that_waits_for_a_restart(tmp_path: Path) -> None:
    running = parse_config("", "kaspar.toml")
    text = (
        'state_dir = "elsewhere"\n[body]\nenabled = true\n[logging]\nlevel = "debug"\n'
        '[voice]\nrate = 90\nplayer = ["paplay"]\n[game]\ncorrect_answers_to_learn = 3\n'
        '[robot]\nname = "Robin"\n'
    )
    loaded = parse_config(text, "kaspar.toml")
    applied, kept = restart_only(running, loaded, Path(running.state_dir))
    assert kept == ["body", "logging", "state_dir", "voice.player"]
    # What waits keeps its running value; everything else is the new file's.
    assert applied.body == running.body and applied.voice.player == running.voice.player
    assert applied.state_dir == running.state_dir and applied.logging == running.logging
    assert applied.voice.rate == 90 and applied.game.correct_answers_to_learn == 3
    assert applied.robot_settings.name == "Robin"


def test_configure_changes_how_kaspar_sounds_never_where_the_sound_goes(tmp_path: Path) -> None:
    from hal.voice.settings import VoiceSettings

    voice = Voice(VoiceSettings(wav_dir=str(tmp_path)))
    voice.configure(VoiceSettings(rate=90, volume=0.2, pitch=30, voice="de", player=("paplay",)))
    settings = voice.settings
    assert (settings.rate, settings.volume, settings.pitch, settings.voice) == (90, 0.2, 30, "de")
    assert settings.wav_dir == str(tmp_path) and settings.player == VoiceSettings().player
    fixed = Voice(VoiceSettings(engine="pyttsx3", wav_dir=str(tmp_path)), keep=("wav_dir", "engine"))
    fixed.configure(VoiceSettings(engine="espeak-ng", rate=100))
    assert (fixed.settings.engine, fixed.settings.rate) == ("pyttsx3", 100)
