"""The real voice with real espeak-ng (command and library), writing WAV files.

Needs the Debian packages espeak-ng and libespeak-ng1 (and sox for soxi).
"""

from __future__ import annotations

import asyncio
import io
import shutil
import subprocess
import threading
import wave
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import structlog

from hal.errors import InvalidArgument, VoiceError
from hal.voice.api import SpokenStatus
from hal.voice.settings import VoiceSettings
from hal.voice.sinks import PlayerSink, WavSink
from hal.voice.speaker import Voice
from kasparctl.log import configure_logging

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng not installed")

WAIT = 60.0  # generous: never a timing assertion, only a bound against a real hang


@pytest.fixture
def quiet_logs():
    """Log lines into a buffer, so the fd-level stdout check sees only what the engines print."""
    buffer = io.StringIO()
    configure_logging("debug", "json", stream=buffer)
    yield buffer
    structlog.reset_defaults()


def frames(path: str | Path) -> np.ndarray:
    with wave.open(str(path), "rb") as audio:
        assert audio.getsampwidth() == 2 and audio.getnchannels() == 1
        return np.frombuffer(audio.readframes(audio.getnframes()), dtype="<i2")


def voice_for(tmp_path: Path, **settings) -> Voice:
    values = {"wav_dir": str(tmp_path / "out"), **settings}
    return Voice(VoiceSettings(**values))


async def say(voice: Voice, text: str, key: str | None = None):
    return await asyncio.wait_for(voice.say(text, key), WAIT)


async def test_200_utterances_in_a_row_on_pyttsx3_and_nothing_on_stdout(tmp_path, capfd, quiet_logs):
    voice = voice_for(tmp_path, engine="pyttsx3")
    try:
        for number in range(200):
            spoken = await say(voice, f"Line {number}.")
            assert spoken.status is SpokenStatus.FINISHED, spoken
            assert spoken.via == "pyttsx3", spoken.error
            assert len(frames(spoken.wav)) > 1000
    finally:
        await voice.close()
    written = sorted((tmp_path / "out").iterdir())
    assert len(written) == 200
    out, _ = capfd.readouterr()
    assert out == ""
    assert "Audio saved" in quiet_logs.getvalue()  # the driver's print, caught and logged


async def test_espeak_ng_many_in_a_row(tmp_path):
    voice = voice_for(tmp_path, engine="espeak-ng")
    try:
        results = [await say(voice, f"Number {n}") for n in range(30)]
    finally:
        await voice.close()
    assert {(r.status, r.via) for r in results} == {(SpokenStatus.FINISHED, "espeak-ng")}
    duration = subprocess.run(
        ["soxi", "-D", results[0].wav], capture_output=True, text=True, check=True
    ).stdout
    assert float(duration) > 0.2


@pytest.fixture
def hang_marker(monkeypatch):
    """Make pyttsx3 hang inside synthesis for any text containing HANG, until released."""
    import pyttsx3.drivers.espeak as espeak_driver

    release = threading.Event()
    original = espeak_driver.EspeakDriver._start_synthesis

    def start_synthesis(self, text):
        if "HANG" in str(text):
            release.wait(60)
        return original(self, text)

    monkeypatch.setattr(espeak_driver.EspeakDriver, "_start_synthesis", start_synthesis)
    yield release
    release.set()


async def test_hung_utterance_is_cut_and_the_next_one_plays(tmp_path, hang_marker):
    voice = voice_for(tmp_path, engine="pyttsx3", timeout=1.0)
    try:
        assert (await say(voice, "warm up")).via == "pyttsx3"
        hung = await say(voice, "HANG here please")
        assert hung.status is SpokenStatus.TIMED_OUT
        # The old thread is still stuck: the fallback speaks rather than a second engine.
        after = await say(voice, "the next line")
        assert (after.status, after.via) == (SpokenStatus.FINISHED, "espeak-ng")
        assert len(frames(after.wav)) > 1000

        hang_marker.set()  # the stuck thread comes back, finds itself retired, ends
        for _ in range(200):
            recovered = await say(voice, "and pyttsx3 again")
            if recovered.via == "pyttsx3":
                break
            await asyncio.sleep(0.05)
        assert (recovered.status, recovered.via) == (SpokenStatus.FINISHED, "pyttsx3")
        assert len(frames(recovered.wav)) > 1000
    finally:
        await voice.close()
    assert not [p for p in (tmp_path / "out").iterdir() if "HANG" in p.name]


async def test_hung_player_is_killed_at_the_timeout(tmp_path):
    first = tmp_path / "first-done"
    out = tmp_path / "played.wav"
    # The first play hangs (exec: the process killed is the one that hangs); later ones copy.
    script = f'if [ -e {first} ]; then cat -- "$0" > {out}; else touch {first}; exec sleep 120; fi'
    voice = Voice(
        VoiceSettings(engine="espeak-ng", timeout=1.0),
        sink=PlayerSink(("sh", "-c", script)),
    )
    try:
        assert (await say(voice, "this one hangs")).status is SpokenStatus.TIMED_OUT
        spoken = await say(voice, "this one plays")
        assert (spoken.status, spoken.via) == (SpokenStatus.FINISHED, "espeak-ng")
    finally:
        await voice.close()
    # Streamed through the pipe: a RIFF header and audio after it.
    data = out.read_bytes()
    assert data[:4] == b"RIFF" and len(data) > 10_000


@pytest.mark.parametrize("breakage", ["engine_will_not_start", "synthesis_raises"])
async def test_fallback_to_espeak_ng_when_pyttsx3_is_broken(tmp_path, monkeypatch, breakage):
    if breakage == "engine_will_not_start":

        def factory():
            raise RuntimeError("could not initialize espeak")

        voice = Voice(VoiceSettings(engine="pyttsx3", wav_dir=str(tmp_path)), engine_factory=factory)
    else:
        import pyttsx3.drivers._espeak as espeak_library

        def synth(*args, **kwargs):
            raise OSError("synthesis broken")

        monkeypatch.setattr(espeak_library, "Synth", synth)
        voice = voice_for(tmp_path, engine="pyttsx3")
    try:
        for text in ("first line", "second line"):
            spoken = await say(voice, text)
            assert (spoken.status, spoken.via) == (SpokenStatus.FINISHED, "espeak-ng")
            assert "pyttsx3" in (spoken.error or "")
            assert len(frames(spoken.wav)) > 1000
    finally:
        await voice.close()


class DroppingEngine:
    """A pyttsx3 engine that renders no audio for its first `drops` lines, as libespeak-ng
    now and then does, then a short tone.

    As pyttsx3 2.99 over libespeak-ng does, runAndWait returns before the WAV exists: it
    is written `delay` seconds later on another thread, then "finished-utterance" is sent.
    """

    def __init__(self, drops: int, delay: float = 0.0) -> None:
        self.drops = drops
        self.delay = delay
        self.renders: list[str] = []
        self._job: tuple[str, str] | None = None
        self._callbacks: dict[str, list] = {}

    def setProperty(self, name, value) -> None:
        pass

    def getProperty(self, name):
        return [SimpleNamespace(id="gmw/en-GB", name="English", languages=["en-gb"])]

    def connect(self, topic, cb):
        self._callbacks.setdefault(topic, []).append(cb)
        return (topic, cb)

    def disconnect(self, token) -> None:
        topic, cb = token
        self._callbacks[topic].remove(cb)

    def save_to_file(self, text: str, filename: str) -> None:
        self._job = (text, filename)

    def runAndWait(self) -> None:
        assert self._job is not None
        text, filename = self._job
        self.renders.append(text)
        samples = b"" if len(self.renders) <= self.drops else b"\x10\x00" * 4000

        def synthesise() -> None:
            with wave.open(filename, "wb") as audio:
                audio.setnchannels(1)
                audio.setsampwidth(2)
                audio.setframerate(22050)
                audio.writeframes(samples)
            for cb in list(self._callbacks.get("finished-utterance", [])):
                cb(name=None, completed=True)

        threading.Timer(self.delay, synthesise).start()


async def say_with(engine: DroppingEngine, tmp_path: Path, text: str):
    """`text` said by a pyttsx3 voice whose engine is `engine`."""
    voice = Voice(
        VoiceSettings(engine="pyttsx3", wav_dir=str(tmp_path)), engine_factory=lambda: engine
    )
    try:
        return await say(voice, text)
    finally:
        await voice.close()


async def test_a_line_written_after_run_and_wait_returns_is_waited_for(tmp_path):
    # Read at once, this file was missing (or empty) and the line fell back to
    # espeak-ng: seen on a loaded machine with the real pyttsx3.
    engine = DroppingEngine(drops=0, delay=0.3)
    spoken = await say_with(engine, tmp_path, "written late")
    assert (spoken.status, spoken.via, spoken.error) == (SpokenStatus.FINISHED, "pyttsx3", None)
    assert len(frames(spoken.wav)) == 4000


async def test_a_line_rendered_empty_once_is_rendered_again_on_pyttsx3(tmp_path):
    engine = DroppingEngine(drops=1)
    spoken = await say_with(engine, tmp_path, "the second line")
    assert (spoken.status, spoken.via, spoken.error) == (SpokenStatus.FINISHED, "pyttsx3", None)
    assert engine.renders == ["the second line", "the second line"]
    assert len(frames(spoken.wav)) == 4000


async def test_a_line_rendered_empty_twice_falls_back_to_espeak_ng(tmp_path):
    engine = DroppingEngine(drops=2)
    spoken = await say_with(engine, tmp_path, "never heard from pyttsx3")
    assert (spoken.status, spoken.via) == (SpokenStatus.FINISHED, "espeak-ng")
    assert "empty WAV" in (spoken.error or "")
    assert engine.renders == ["never heard from pyttsx3"] * 2


async def test_fallback_to_pyttsx3_when_espeak_ng_is_missing(tmp_path):
    voice = voice_for(tmp_path, engine="espeak-ng", espeak_ng=str(tmp_path / "no-such-espeak"))
    try:
        spoken = await say(voice, "still speaking")
    finally:
        await voice.close()
    assert (spoken.status, spoken.via) == (SpokenStatus.FINISHED, "pyttsx3")
    assert "cannot run" in (spoken.error or "")


async def test_failed_when_every_engine_fails(tmp_path):
    def factory():
        raise RuntimeError("no engine")

    voice = Voice(
        VoiceSettings(engine="espeak-ng", espeak_ng=str(tmp_path / "none"), wav_dir=str(tmp_path)),
        engine_factory=factory,
    )
    try:
        spoken = await say(voice, "nobody hears this")
    finally:
        await voice.close()
    assert spoken.status is SpokenStatus.FAILED
    assert "espeak-ng" in spoken.error and "pyttsx3" in spoken.error


@pytest.fixture
def clip(tmp_path) -> Path:
    path = tmp_path / "clips" / "hello.wav"
    path.parent.mkdir()
    with wave.open(str(path), "wb") as audio:
        audio.setnchannels(1)
        audio.setsampwidth(2)
        audio.setframerate(22050)
        tone = (8000 * np.sin(np.arange(11025) * 2 * np.pi * 440 / 22050)).astype("<i2")
        audio.writeframes(tone.tobytes())
    return path


async def test_recorded_clip_plays_instead_of_the_text(tmp_path, clip):
    voice = voice_for(tmp_path, clips={"hello": str(clip), "gone": str(tmp_path / "gone.wav")})
    try:
        played = await say(voice, "Hello everyone", key="hello")
        spoken = await say(voice, "Hello everyone", key="other")
        missing = await say(voice, "A missing clip", key="gone")
    finally:
        await voice.close()
    assert played.via == "clip"
    assert Path(played.wav).read_bytes() == clip.read_bytes()
    assert spoken.via == "espeak-ng"
    assert (missing.status, missing.via) == (SpokenStatus.FINISHED, "espeak-ng")
    assert "missing" in missing.error


async def test_cancel_stops_the_current_line_and_drops_the_queue(tmp_path):
    script = "exec sleep 120"
    voice = Voice(VoiceSettings(engine="espeak-ng"), sink=PlayerSink(("sh", "-c", script)))
    try:
        first = asyncio.create_task(voice.say("a long line that is playing"))
        second = asyncio.create_task(voice.say("a queued line"))
        await asyncio.sleep(0.3)
        voice.cancel()
        results = await asyncio.wait_for(asyncio.gather(first, second), WAIT)
        assert [r.status for r in results] == [SpokenStatus.CANCELLED] * 2
    finally:
        await voice.close()


async def test_caller_cancelled_while_queued_is_never_heard(tmp_path):
    voice = voice_for(tmp_path, engine="espeak-ng")
    try:
        first = asyncio.create_task(voice.say("first"))
        doomed = asyncio.create_task(voice.say("doomed"))
        third = asyncio.create_task(voice.say("third"))
        await asyncio.sleep(0)
        doomed.cancel()
        done = await asyncio.wait_for(asyncio.gather(first, third), WAIT)
        with pytest.raises(asyncio.CancelledError):
            await doomed
    finally:
        await voice.close()
    assert [r.status for r in done] == [SpokenStatus.FINISHED] * 2
    assert len(list((tmp_path / "out").iterdir())) == 2


async def test_queue_keeps_order(tmp_path):
    voice = voice_for(tmp_path, engine="espeak-ng")
    try:
        texts = ["one", "two two two two", "three"]
        results = await asyncio.wait_for(asyncio.gather(*(voice.say(t) for t in texts)), WAIT)
    finally:
        await voice.close()
    assert [r.text for r in results] == texts
    assert [Path(r.wav).name[:5] for r in results] == ["00001", "00002", "00003"]
    assert results[0].ended <= results[1].started


@pytest.mark.parametrize("engine", ["pyttsx3", "espeak-ng"])
async def test_rate_and_volume_reach_the_engine(tmp_path, engine):
    line = "The lion is in the first bag, I think."
    outputs = {}
    for name, rate, volume in (("slow", 100, 1.0), ("fast", 300, 1.0), ("soft", 100, 0.2)):
        voice = voice_for(tmp_path / name, engine=engine, rate=rate, volume=volume)
        try:
            spoken = await say(voice, line)
        finally:
            await voice.close()
        assert spoken.via == engine
        outputs[name] = frames(spoken.wav)
    assert len(outputs["slow"]) > 1.5 * len(outputs["fast"])
    peak = {name: int(np.abs(samples.astype(np.int32)).max()) for name, samples in outputs.items()}
    assert peak["soft"] < 0.5 * peak["slow"]


async def test_player_sink_plays_pyttsx3_renders_and_cleans_up(tmp_path):
    out = tmp_path / "played.wav"
    sink = PlayerSink(("sh", "-c", f'cat -- "$0" > {out}'))
    voice = Voice(VoiceSettings(engine="pyttsx3"), sink=sink)
    try:
        spoken = await say(voice, "through the player")
    finally:
        await voice.close()
    assert (spoken.status, spoken.via) == (SpokenStatus.FINISHED, "pyttsx3")
    assert len(frames(out)) > 1000
    assert not sink._tmp.exists()


async def test_single_file_sink(tmp_path):
    target = tmp_path / "line.wav"
    voice = Voice(VoiceSettings(engine="espeak-ng"), sink=WavSink(file=target))
    try:
        spoken = await say(voice, "one file")
    finally:
        await voice.close()
    assert spoken.wav == str(target) and len(frames(target)) > 1000


def test_a_wav_sink_needs_a_directory_or_a_file(tmp_path):
    for arguments in ({}, {"directory": tmp_path, "file": tmp_path / "x.wav"}):
        with pytest.raises(InvalidArgument, match="give a directory or a file"):
            WavSink(**arguments)


async def test_a_closed_voice_refuses_to_speak(tmp_path):
    voice = voice_for(tmp_path, engine="espeak-ng")
    await voice.close()
    with pytest.raises(VoiceError, match="the voice is closed"):
        await voice.say("too late")


@pytest.fixture
def reset_logging():
    yield
    structlog.reset_defaults()


def test_say_command_writes_a_wav(tmp_path, capsys, monkeypatch, reset_logging):
    from kasparctl.cli import main

    monkeypatch.delenv("KASPAR_CONFIG", raising=False)
    target = tmp_path / "line.wav"
    config = tmp_path / "kaspar.toml"
    config.write_text('[voice]\nengine = "pyttsx3"\nrate = 120\n')
    assert main(["say", "Hello children", "--wav", str(target), "--config", str(config)]) == 0
    assert capsys.readouterr().out == f"wrote {target} (pyttsx3)\n"
    assert len(frames(target)) > 1000
    assert main(["say", "Hello children", "--wav", str(target), "--engine", "espeak-ng"]) == 0
    assert capsys.readouterr().out == f"wrote {target} (espeak-ng)\n"


def test_say_command_reports_a_bad_configuration(tmp_path, capsys, reset_logging):
    from kasparctl.cli import main

    config = tmp_path / "kaspar.toml"
    config.write_text("[voice]\nrate = 5\n")
    assert main(["say", "Hello", "--wav", str(tmp_path / "x.wav"), "--config", str(config)]) == 1
    assert "voice.rate: expected 80 to 450 words per minute, found 5" in capsys.readouterr().err
