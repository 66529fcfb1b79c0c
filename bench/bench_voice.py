"""say() call to first audio sample, pyttsx3 and espeak-ng side by side; memory over 1000 lines.

There is no sound card on a CI machine, so the player is replaced by a sink
inside this process that notes when the first audio sample after the WAV
header reaches it: for espeak-ng that is the first chunk on the pipe (it
streams), for pyttsx3 the moment its rendered file is handed over (it
renders the whole line first). Both go through Voice.say(): the queue, the
worker task, and for pyttsx3 the hop to its thread and back. A real player
(aplay) adds its own start-up, the same for both.

Memory: resident set size over 1000 lines after a warm-up of 500, and the
Python heap (tracemalloc) over 300 more, scaled to 1000, per engine.
Target: no growth (within allocator noise).
Run: .venv/bin/python bench/bench_voice.py
"""

from __future__ import annotations

import asyncio
import gc
import os
import statistics
import time
import tracemalloc
from pathlib import Path

from hal.voice.processes import spawn, stop
from hal.voice.settings import VoiceSettings
from hal.voice.speaker import Voice

LINE = "I think the lion is in this bag."  # 8 words, typical of the game
RUNS = 40
MEMORY_LINES = 1000
WARM_UP_LINES = 500
HEAP_LINES = 300  # scaled to MEMORY_LINES in the report
FIRST_SAMPLE_TARGET_MS = 100.0  # heard as immediate after a child's press
GROWTH_TARGET_KB = 256.0
WAV_HEADER = 44


class FirstSampleSink:
    """Records when the first audio sample would reach a player."""

    def __init__(self, directory: Path) -> None:
        self._directory = directory
        self.first_sample: float | None = None

    def target(self, via: str) -> tuple[Path, bool]:
        return self._directory / f"{via}.wav", False

    async def play_file(self, path: Path, via: str) -> str | None:
        with path.open("rb") as wav:
            wav.seek(WAV_HEADER)
            if wav.read(2):
                self.first_sample = time.monotonic()
        return None

    async def espeak(self, argv: list[str], text: str) -> str | None:
        process = await spawn([*argv, "--stdout"], stdin=True, stdout=asyncio.subprocess.PIPE)
        try:
            process.stdin.write(text.encode())
            process.stdin.close()
            await process.stdout.readexactly(WAV_HEADER + 2)
            self.first_sample = time.monotonic()
            await process.stdout.read()
            await process.wait()
        finally:
            await stop(process)
        return None

    def close(self) -> None:
        pass


async def first_sample_ms(engine: str, directory: Path) -> list[float]:
    sink = FirstSampleSink(directory)
    voice = Voice(VoiceSettings(engine=engine), sink=sink)
    latencies = []
    try:
        await voice.say("warm up")
        for _ in range(RUNS):
            sink.first_sample = None
            start = time.monotonic()
            spoken = await voice.say(LINE)
            assert spoken.via == engine, spoken
            assert sink.first_sample is not None
            latencies.append((sink.first_sample - start) * 1000)
    finally:
        await voice.close()
    return latencies


def rss_kb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1024


async def memory_growth(engine: str, directory: Path) -> tuple[float, float]:
    voice = Voice(VoiceSettings(engine=engine), sink=FirstSampleSink(directory))
    try:
        # The allocator and asyncio's child watcher settle over the first few
        # hundred lines (about 0.7 MiB, once); growth is measured after that.
        for number in range(WARM_UP_LINES):
            await voice.say(f"Warming up, line {number}.")
        gc.collect()
        rss_before = rss_kb()
        for number in range(MEMORY_LINES):
            spoken = await voice.say(f"This is line number {number} of the memory test.")
            assert spoken.via == engine, spoken
        gc.collect()
        rss_after = rss_kb()
        # The Python heap separately: tracemalloc's own bookkeeping would inflate the RSS.
        tracemalloc.start()
        heap_before = tracemalloc.get_traced_memory()[0]
        for number in range(HEAP_LINES):
            await voice.say(f"This is line number {number} of the heap test.")
        gc.collect()
        heap_after = tracemalloc.get_traced_memory()[0]
        tracemalloc.stop()
    finally:
        await voice.close()
    return rss_after - rss_before, (heap_after - heap_before) / 1024 * MEMORY_LINES / HEAP_LINES


def describe(values: list[float]) -> str:
    ordered = sorted(values)
    p90 = ordered[round(0.9 * (len(ordered) - 1))]
    return f"p50 {statistics.median(values):6.1f} ms  p90 {p90:6.1f} ms  max {max(values):6.1f} ms"


async def main() -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as directory:
        work = Path(directory)
        print(f"say() -> first audio sample, {LINE!r} ({RUNS} runs each)")
        results = {}
        for engine in ("pyttsx3", "espeak-ng"):
            results[engine] = await first_sample_ms(engine, work)
            target = f"target p90 < {FIRST_SAMPLE_TARGET_MS:.0f} ms"
            print(f"  {engine:<10} {describe(results[engine])}   {target}")
        faster = min(results, key=lambda name: statistics.median(results[name]))
        print(f"  faster: {faster}")
        print(f"memory over {MEMORY_LINES} utterances (after {WARM_UP_LINES} to warm up)")
        for engine in ("pyttsx3", "espeak-ng"):
            rss, heap = await memory_growth(engine, work)
            print(
                f"  {engine:<10} RSS {rss:+8.0f} KiB  Python heap {heap:+8.1f} KiB"
                f"   target < {GROWTH_TARGET_KB:.0f} KiB"
            )


if __name__ == "__main__":
    asyncio.run(main())
