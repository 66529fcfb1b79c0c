"""The mouth follows real espeak-ng speech, through the voice's envelope hook."""

from __future__ import annotations

import asyncio
import shutil
from pathlib import Path

import pytest

from hal.clock import MonotonicClock
from hal.voice.envelope import StreamMeter, rms_levels
from hal.voice.settings import VoiceSettings
from hal.voice.sinks import PlayerSink, WavSink
from hal.voice.speaker import Voice
from kasparctl.body.mouth import Mouth, player_latency

pytestmark = pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="needs espeak-ng")


class Heard:
    """Keeps every envelope and end, and passes them to a mouth."""

    def __init__(self, mouth: Mouth) -> None:
        self.mouth = mouth
        self.pieces: list[tuple[float, float, list[float]]] = []
        self.ends: list[bool] = []

    def on_envelope(self, start, frame_s, levels) -> None:
        self.pieces.append((start, frame_s, list(levels)))
        self.mouth.on_envelope(start, frame_s, levels)

    def on_end(self, cut: bool) -> None:
        self.ends.append(cut)
        self.mouth.on_end(cut)


def openings(mouth: Mouth, begin: float, end: float, step: float = 0.02) -> list[float | None]:
    return [mouth.opening(begin + k * step) for k in range(round((end - begin) / step))]


def test_rms_levels_of_silence_and_of_a_full_square_wave():
    assert rms_levels(b"\x00\x00" * 440, 2, 1, 22050) == [0.0, 0.0]  # 220-sample frames
    loud = (b"\xff\x7f" + b"\x00\x80") * 110
    assert rms_levels(loud, 2, 1, 22050)[0] == pytest.approx(1.0, abs=1e-3)


async def test_the_mouth_is_closed_in_silence_opens_with_speech_and_closes_at_the_end(tmp_path):
    clock = MonotonicClock()
    mouth = Mouth(clock, latency_s=0.0, full_level=0.2, window_s=0.02)
    heard = Heard(mouth)
    voice = Voice(VoiceSettings(engine="espeak-ng"), clock, sink=WavSink(file=tmp_path / "a.wav"))
    assert voice.listen(heard)
    assert mouth.opening(clock.now()) is None  # before a line: not even claimed
    spoken = await voice.say("Hello, I am Kaspar. Shall we play?")
    await voice.close()
    assert spoken.finished and heard.ends == [False]
    ((start, frame, levels),) = heard.pieces
    speech_end = start + len(levels) * frame
    shape = openings(mouth, start, speech_end)
    assert shape[0] == 0.0  # espeak's lead-in is silence: closed
    assert max(o or 0.0 for o in shape) > 0.5  # open during speech
    assert sum(1 for o in shape if o == 0.0) >= 3  # closed again in the pauses
    assert mouth.opening(speech_end + 0.05) == 0.0  # closed at the end of the line
    assert mouth.opening(speech_end + 1.0) is None  # then left to the other layers


async def test_a_cut_line_closes_the_mouth_at_once(tmp_path):
    clock = MonotonicClock()
    mouth = Mouth(clock, latency_s=player_latency("aplay"), full_level=0.2, window_s=0.02)
    heard = Heard(mouth)
    # A player that takes the stream slowly: the line is still playing when it is cut.
    player = ("sh", "-c", "exec sleep 30")  # reads nothing: the pipe fills, the line plays on
    voice = Voice(VoiceSettings(engine="espeak-ng"), clock, sink=PlayerSink(player))
    voice.listen(heard)
    line = asyncio.ensure_future(
        voice.say("This is a long line that will be cut before its end, by the researcher."))
    while not heard.pieces:
        await asyncio.sleep(0.01)
    (_, _, levels) = heard.pieces[0]
    assert levels  # the samples passed through us on their way to the player
    voice.cancel()
    spoken = await line
    await voice.close()
    assert spoken.status.value == "cancelled" and heard.ends == [True]
    now = clock.now()
    assert set(openings(mouth, now, now + 0.25)) == {0.0}  # closed, and nothing still to come
    assert mouth.opening(now + 1.0) is None


def test_a_stream_meter_reads_espeaks_header_and_times_frames_by_samples(tmp_path):
    import subprocess

    wav = tmp_path / "s.wav"
    subprocess.run(["espeak-ng", "-w", str(wav), "Hello there"], check=True)
    data = Path(wav).read_bytes()

    class Clock:
        t = 5.0

        def now(self) -> float:
            return self.t

        async def sleep(self, seconds: float) -> None:  # pragma: no cover - not used
            self.t += seconds

    got: list[tuple[float, int]] = []

    class Listener:
        def on_envelope(self, start, frame_s, levels) -> None:
            got.append((start, len(levels)))

        def on_end(self, cut: bool) -> None:
            got.append((-1.0, int(cut)))

    meter = StreamMeter(Listener(), Clock())
    for index in range(0, len(data), 1000):
        meter.feed(data[index:index + 1000])
    meter.end(cut=False)
    starts = [start for start, _ in got[:-1]]
    assert starts[0] == 5.0
    counts = [n for _, n in got[:-1]]
    assert starts[1] == pytest.approx(5.0 + counts[0] * 220 / 22050)  # placed by samples, not arrival
    assert got[-1] == (-1.0, 0)
