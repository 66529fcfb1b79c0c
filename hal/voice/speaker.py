"""Kaspar's voice: a queue of utterances, two engines, clips, timeouts and cancellation.

Engines:
- espeak-ng as a child process (text on stdin, WAV on stdout piped into the
  player, or written to a file). Nothing shared with this process, and a hung
  one is killed.
- pyttsx3 (over libespeak-ng), confined to one thread that owns the engine:
  pyttsx3 is not thread-safe and its run loop cannot be re-entered. It
  renders every line with save_to_file and the WAV is then played like any
  other, never with engine.say().

The configured engine is tried first and the other is the fallback when it fails.

pyttsx3 traps handled here (pyttsx3 2.99, espeak driver):
- after save_to_file, later say() calls go to that file (`_save_file` is never
  cleared): say() is never used, every line has its own save_to_file;
- only the last save_to_file before runAndWait is rendered: one per runAndWait;
- pyttsx3.init() hands back a cached engine, the hung one too: engines are built
  with pyttsx3.engine.Engine directly;
- libespeak-ng keeps one synth callback for the whole process, so two engines
  at once either race in C or the older one renders nothing: a new engine is
  built only after the previous thread has ended; until then the fallback speaks;
- a runAndWait that raised leaves `_inLoop` set and every later one raises
  "run loop already started": the thread and engine are replaced;
- the driver print()s "Audio saved to ..." on stdout, which would corrupt the
  JSON log lines: its module-level print is replaced by a debug log (the fd is
  left alone: redirecting fd 1 would swallow our own logs too);
- a render that returns without a file (the silent failure) counts as a failure.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import queue
import shutil
import subprocess
import tempfile
import threading
import wave
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import structlog

from hal.clock import Clock, MonotonicClock
from hal.errors import HalError
from hal.voice.api import Spoken, SpokenStatus
from hal.voice.settings import VoiceSettings

log = structlog.get_logger("kaspar.voice")

# How long close() waits for a retired pyttsx3 thread to end.
CLOSE_GRACE_S = 2.0
# How often a retired pyttsx3 thread is checked for having ended; until it
# has, no new engine is built and the fallback engine speaks.
THREAD_EXIT_POLL = 0.05


class VoiceError(HalError):
    """An engine or the player failed for one utterance (the fallback is tried)."""


# -- where the sound goes ----------------------------------------------------


class Sink(Protocol):
    def target(self, via: str) -> tuple[Path, bool]:
        """A path to render a WAV into, and whether that file is already the output."""
        ...

    async def play_file(self, path: Path, via: str) -> str | None:
        """Play (or store) a WAV; returns the stored file, if any."""
        ...

    async def espeak(self, argv: list[str], text: str) -> str | None:
        """Run espeak-ng (argv without an output option) into the sink."""
        ...

    def close(self) -> None: ...


class PlayerSink:
    """Plays through a player command (aplay, or sox's play)."""

    def __init__(self, player: tuple[str, ...]) -> None:
        self._player = list(player)
        self._tmp = Path(tempfile.mkdtemp(prefix="kaspar-voice-"))
        self._count = 0

    def target(self, via: str) -> tuple[Path, bool]:
        self._count += 1
        return self._tmp / f"{self._count}-{via}.wav", False

    async def play_file(self, path: Path, via: str) -> str | None:
        await _run([*self._player, str(path)], what="player")
        return None

    def close(self) -> None:
        shutil.rmtree(self._tmp, ignore_errors=True)

    async def espeak(self, argv: list[str], text: str) -> str | None:
        # espeak-ng streams into the player, so the first words are heard while
        # the rest is still being synthesised.
        read_end, write_end = os.pipe()
        try:
            synth = await _spawn([*argv, "--stdout"], stdin=True, stdout=write_end)
            try:
                player = await _spawn([*self._player, "-"], stdin=read_end)
            except BaseException:
                await _stop(synth)
                raise
        finally:
            os.close(read_end)
            os.close(write_end)
        try:
            await asyncio.gather(
                _finish(synth, "espeak-ng", text.encode()), _finish(player, "player", None)
            )
        finally:
            await _stop(synth)
            await _stop(player)
        return None


class WavSink:
    """Writes each utterance as a WAV file: numbered files in a directory, or one file."""

    def __init__(self, directory: str | Path | None = None, file: str | Path | None = None) -> None:
        if (directory is None) == (file is None):
            raise ValueError("give a directory or a file")
        self._directory = Path(directory) if directory is not None else None
        self._file = Path(file) if file is not None else None
        if self._directory is not None:
            self._directory.mkdir(parents=True, exist_ok=True)
        self._count = 0

    def target(self, via: str) -> tuple[Path, bool]:
        if self._file is not None:
            return self._file, True
        assert self._directory is not None
        self._count += 1
        return self._directory / f"{self._count:05d}-{via}.wav", True

    def close(self) -> None:
        pass  # the files are the output

    async def play_file(self, path: Path, via: str) -> str | None:
        target, _ = self.target(via)
        if path != target:
            await asyncio.to_thread(shutil.copyfile, path, target)
        return str(target)

    async def espeak(self, argv: list[str], text: str) -> str | None:
        target, _ = self.target("espeak-ng")
        process = await _spawn([*argv, "-w", str(target)], stdin=True)
        try:
            await _finish(process, "espeak-ng", text.encode())
        finally:
            await _stop(process)
        _check_wav(target, "espeak-ng")
        return str(target)


def sink_for(settings: VoiceSettings) -> Sink:
    if settings.wav_dir is not None:
        return WavSink(directory=settings.wav_dir)
    return PlayerSink(settings.player)


# -- child processes -----------------------------------------------------------


async def _spawn(argv: list[str], *, stdin: bool | int = False, stdout: int | None = None) -> Any:
    try:
        return await asyncio.create_subprocess_exec(
            *argv,
            stdin=asyncio.subprocess.PIPE if stdin is True else (stdin or subprocess.DEVNULL),
            # Never our stdout: that is where the JSON log lines go.
            stdout=stdout if stdout is not None else subprocess.DEVNULL,
            stderr=asyncio.subprocess.PIPE,
        )
    except OSError as error:
        raise VoiceError(f"cannot run {argv[0]}: {error.strerror}") from error


async def _finish(process: Any, what: str, text: bytes | None) -> None:
    _, errors = await process.communicate(text)
    if process.returncode != 0:
        detail = errors.decode(errors="replace").strip()[-300:]
        raise VoiceError(f"{what} exited with {process.returncode}: {detail}")


async def _run(argv: list[str], what: str) -> None:
    process = await _spawn(argv)
    try:
        await _finish(process, what, None)
    finally:
        await _stop(process)


async def _stop(process: Any) -> None:
    """Kill a process still running (timeout or cancel) and reap it."""
    if process.returncode is None:
        with contextlib.suppress(ProcessLookupError):
            process.kill()
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.shield(process.wait())


def _check_wav(path: Path, what: str) -> None:
    try:
        with wave.open(str(path), "rb") as audio:
            frames = audio.getnframes()
    except (OSError, EOFError, wave.Error) as error:
        raise VoiceError(f"{what} wrote no usable WAV: {error}") from error
    if frames == 0:
        raise VoiceError(f"{what} wrote an empty WAV")


def espeak_argv(settings: VoiceSettings) -> list[str]:
    return [
        settings.espeak_ng,
        "-v",
        settings.voice,
        "-s",
        str(settings.rate),
        "-a",
        str(round(settings.volume * 100)),
        "--stdin",
    ]


# -- pyttsx3 on its own thread -----------------------------------------------


def _quiet_print(*args: object, **_: object) -> None:
    log.debug("pyttsx3 said", text=" ".join(map(str, args)))


def default_engine_factory() -> Any:
    import pyttsx3.drivers.espeak as espeak_driver
    import pyttsx3.engine

    espeak_driver.print = _quiet_print  # type: ignore[attr-defined]
    # Not pyttsx3.init(): its cache would return the previous engine, hung or not.
    return pyttsx3.engine.Engine("espeak")


@dataclass(eq=False)
class _Job:
    text: str
    path: Path
    loop: asyncio.AbstractEventLoop
    future: asyncio.Future[None]
    abandoned: bool = False

    def settle(self, error: BaseException | None) -> None:
        def settle_on_loop() -> None:
            if self.future.done():
                return
            if error is None:
                self.future.set_result(None)
            else:
                self.future.set_exception(error)

        with contextlib.suppress(RuntimeError):  # the loop is closed: nobody waits
            self.loop.call_soon_threadsafe(settle_on_loop)


class Pyttsx3Thread:
    """One thread, one pyttsx3 engine, one job at a time; jobs come through a queue."""

    def __init__(self, settings: VoiceSettings, factory: Callable[[], Any]) -> None:
        self._settings = settings
        self._factory = factory
        self._jobs: queue.SimpleQueue[_Job | None] = queue.SimpleQueue()
        self._engine: Any = None
        self._retired = False
        self.failure: str | None = None
        # Guards the moment the thread stops taking jobs, so none is left unanswered.
        self._taking = threading.Lock()
        self._ended = False
        self._thread = threading.Thread(target=self._run, name="kaspar-pyttsx3", daemon=True)
        self._thread.start()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def join(self, timeout: float) -> None:
        self._thread.join(timeout)

    @property
    def usable(self) -> bool:
        return self.alive and not self._retired and self.failure is None

    async def render(self, text: str, path: Path) -> None:
        loop = asyncio.get_running_loop()
        job = _Job(text, path, loop, loop.create_future())
        with self._taking:
            if self._ended or self._retired:
                raise VoiceError(self.failure or "pyttsx3 engine retired")
            self._jobs.put(job)
        try:
            await job.future
        except asyncio.CancelledError:
            job.abandoned = True
            raise

    def retire(self) -> None:
        """Stop taking jobs and try to end a run loop that is spinning."""
        self._retired = True
        self._jobs.put(None)
        driver = getattr(getattr(self._engine, "proxy", None), "_driver", None)
        if driver is not None:
            # The espeak driver's loop polls this flag every 10 ms; a thread
            # stuck inside the C library is not helped, hence the fallback.
            driver._looping = False

    def _run(self) -> None:
        try:
            engine = self._factory()
            engine.setProperty("voice", _voice_id(engine, self._settings.voice))
            engine.setProperty("rate", self._settings.rate)
            engine.setProperty("volume", self._settings.volume)
            self._engine = engine
        except Exception as error:
            self.failure = f"pyttsx3 could not start: {error!r}"
            self._drain(VoiceError(self.failure))
            return
        while True:
            job = self._jobs.get()
            if job is None or self._retired:
                if job is not None:
                    job.settle(VoiceError("pyttsx3 engine retired"))
                self._drain(VoiceError("pyttsx3 engine retired"))
                return
            if job.abandoned:
                continue
            try:
                self._render(engine, job)
                if job.abandoned:
                    job.path.unlink(missing_ok=True)  # nobody will play it
            except Exception as error:
                # The engine's state is unknown now (a raised runAndWait leaves
                # it "in loop" for ever): this thread ends and a new one is built.
                self.failure = f"pyttsx3 failed: {error}"
                job.settle(error if isinstance(error, VoiceError) else VoiceError(self.failure))
                self._drain(VoiceError(self.failure))
                return
            job.settle(None)

    def _render(self, engine: Any, job: _Job) -> None:
        errors: list[BaseException] = []
        token = engine.connect("error", lambda name=None, exception=None: errors.append(exception))
        try:
            with contextlib.suppress(FileNotFoundError):
                job.path.unlink()
            engine.save_to_file(job.text, str(job.path))
            engine.runAndWait()
        finally:
            engine.disconnect(token)
        if errors:
            raise VoiceError(f"pyttsx3 reported {errors[0]!r}")
        _check_wav(job.path, "pyttsx3")

    def _drain(self, error: VoiceError) -> None:
        with self._taking:
            self._ended = True
        while True:
            try:
                job = self._jobs.get_nowait()
            except queue.Empty:
                return
            if job is not None:
                job.settle(error)


def _voice_id(engine: Any, wanted: str) -> str:
    """The pyttsx3 voice id for a name the espeak-ng command accepts ("en-gb").

    libespeak-ng's SetVoiceByName knows only file names ("gmw/en"), while the
    command line also takes languages; one setting serves both engines.
    """
    wanted = wanted.lower()
    voices = engine.getProperty("voices")
    for match in (
        lambda v: v.id.lower() == wanted,
        lambda v: wanted in [language.lower() for language in v.languages or ()],
        lambda v: v.id.lower().rsplit("/", 1)[-1] == wanted,
        lambda v: (v.name or "").lower() == wanted,
    ):
        for voice in voices:
            if match(voice):
                return str(voice.id)
    raise VoiceError(f"pyttsx3 has no voice {wanted!r}")


# -- the voice ---------------------------------------------------------------


@dataclass(eq=False)
class _Request:
    text: str
    key: str | None
    future: asyncio.Future[Spoken]
    timed_out: bool = False
    wav: str | None = None
    via: str | None = None


class Voice:
    """The real voice; satisfies hal.voice.api.VoiceOutput."""

    def __init__(
        self,
        settings: VoiceSettings,
        clock: Clock | None = None,
        *,
        sink: Sink | None = None,
        engine_factory: Callable[[], Any] = default_engine_factory,
    ) -> None:
        self._settings = settings
        self._clock = clock or MonotonicClock()
        self._sink = sink or sink_for(settings)
        self._factory = engine_factory
        self._espeak = espeak_argv(settings)
        self._queue: asyncio.Queue[_Request] = asyncio.Queue()
        self._worker: asyncio.Task[None] | None = None
        self._current: tuple[_Request, asyncio.Task[Spoken]] | None = None
        self._pyttsx3: Pyttsx3Thread | None = None
        self._retiring: Pyttsx3Thread | None = None
        self._exit_watch: asyncio.Task[None] | None = None
        self._closed = False

    @property
    def engine(self) -> str:
        return self._settings.engine

    async def say(self, text: str, key: str | None = None) -> Spoken:
        if self._closed:
            raise VoiceError("the voice is closed")
        if self._worker is None:
            self._worker = asyncio.get_running_loop().create_task(self._work())
        request = _Request(text, key, asyncio.get_running_loop().create_future())
        self._queue.put_nowait(request)
        try:
            return await asyncio.shield(request.future)
        except asyncio.CancelledError:
            # The caller gave up on this line: it must not be heard later.
            self._cancel_request(request)
            raise

    def cancel(self) -> None:
        while not self._queue.empty():
            self._resolve(self._queue.get_nowait(), SpokenStatus.CANCELLED, None)
        if self._current is not None:
            self._current[1].cancel()

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.cancel()
        if self._worker is not None:
            self._worker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._worker
        engines = [engine for engine in (self._pyttsx3, self._retiring) if engine is not None]
        for engine in engines:
            engine.retire()
        # libespeak-ng is one library state per process: let a retiring engine end
        # before another can start, or its teardown resets the new one's settings.
        # A thread stuck in the library is not waited for beyond the grace.
        for engine in engines:
            await asyncio.to_thread(engine.join, CLOSE_GRACE_S)
        if self._exit_watch is not None:
            self._exit_watch.cancel()
        self._sink.close()

    # -- the queue -----------------------------------------------------------

    def _cancel_request(self, request: _Request) -> None:
        if self._current is not None and self._current[0] is request:
            self._current[1].cancel()
        self._resolve(request, SpokenStatus.CANCELLED, None)

    def _resolve(self, request: _Request, status: SpokenStatus, error: str | None) -> None:
        if not request.future.done():
            now = self._clock.now()
            request.future.set_result(
                Spoken(status, request.text, request.via, now, now, request.wav, error)
            )

    async def _work(self) -> None:
        while True:
            request = await self._queue.get()
            if request.future.done():
                continue  # cancelled while queued
            started = self._clock.now()
            task = asyncio.get_running_loop().create_task(self._speak(request))
            self._current = (request, task)
            timeout = self._clock.sleep(self._settings.timeout)
            timer = asyncio.get_running_loop().create_task(timeout)
            try:
                await asyncio.wait({task, timer}, return_when=asyncio.FIRST_COMPLETED)
            except asyncio.CancelledError:
                self._resolve(request, SpokenStatus.CANCELLED, "the voice was closed")
                raise
            finally:
                timer.cancel()
                if not task.done():
                    request.timed_out = not self._closed
                    task.cancel()
                # _speak cleans up (kills processes) before it ends; its result
                # or exception is read by _outcome, not raised here.
                await asyncio.wait({task})
                self._current = None
            spoken = self._outcome(request, task, started)
            if spoken.status in (SpokenStatus.TIMED_OUT, SpokenStatus.FAILED):
                log.warning(
                    "voice fault", status=spoken.status.value, text=request.text, error=spoken.error
                )
            if not request.future.done():
                request.future.set_result(spoken)

    def _outcome(self, request: _Request, task: asyncio.Task[Spoken], started: float) -> Spoken:
        ended = self._clock.now()
        if task.cancelled():
            status = SpokenStatus.TIMED_OUT if request.timed_out else SpokenStatus.CANCELLED
            error = f"no end after {self._settings.timeout} s" if request.timed_out else None
            return Spoken(status, request.text, request.via, started, ended, request.wav, error)
        error = task.exception()
        if error is not None:
            return Spoken(
                SpokenStatus.FAILED, request.text, None, started, ended, None, str(error)
            )
        spoken = task.result()
        return Spoken(
            spoken.status, spoken.text, spoken.via, started, ended, spoken.wav, spoken.error
        )

    # -- one utterance -------------------------------------------------------

    async def _speak(self, request: _Request) -> Spoken:
        errors: list[str] = []
        clip = self._settings.clips.get(request.key or "")
        if clip is not None:
            try:
                request.via = "clip"
                request.wav = await self._play_clip(Path(clip))
                return self._spoken(request)
            except VoiceError as error:
                log.warning("clip failed, speaking the text", key=request.key, error=str(error))
                errors.append(str(error))
        order = ["pyttsx3", "espeak-ng"]
        if self._settings.engine == "espeak-ng":
            order.reverse()
        for engine in order:
            request.via = engine
            try:
                if engine == "pyttsx3":
                    request.wav = await self._speak_pyttsx3(request)
                else:
                    request.wav = await self._sink.espeak(self._espeak, request.text)
                return self._spoken(request, "; ".join(errors) or None)
            except VoiceError as error:
                log.warning("voice engine failed", engine=engine, error=str(error))
                errors.append(f"{engine}: {error}")
        raise VoiceError("; ".join(errors))

    def _spoken(self, request: _Request, error: str | None = None) -> Spoken:
        now = self._clock.now()
        via, wav = request.via, request.wav
        return Spoken(SpokenStatus.FINISHED, request.text, via, now, now, wav, error)

    async def _play_clip(self, clip: Path) -> str | None:
        if not clip.is_file():
            raise VoiceError(f"clip {clip} is missing")
        return await self._sink.play_file(clip, "clip")

    async def _speak_pyttsx3(self, request: _Request) -> str | None:
        engine = self._engine_thread()
        path, final = self._sink.target("pyttsx3")
        try:
            await engine.render(request.text, path)
        except asyncio.CancelledError:
            if request.timed_out:
                self._retire(engine, "the utterance timed out")
            raise
        except VoiceError:
            path.unlink(missing_ok=True)  # no half-written line among the outputs
            raise
        if final:
            return str(path)
        try:
            return await self._sink.play_file(path, "pyttsx3")
        finally:
            path.unlink(missing_ok=True)

    def _engine_thread(self) -> Pyttsx3Thread:
        engine = self._pyttsx3
        if engine is not None and engine.usable:
            return engine
        if engine is not None:
            self._retire(engine, engine.failure or "engine thread ended")
        if self._retiring is not None:
            # Building an engine while the old thread may still be inside
            # libespeak-ng would share its global state between two threads.
            raise VoiceError("pyttsx3 is recovering from a hung utterance")
        self._pyttsx3 = Pyttsx3Thread(self._settings, self._factory)
        return self._pyttsx3

    def _retire(self, engine: Pyttsx3Thread, reason: str) -> None:
        log.warning("pyttsx3 engine replaced", reason=reason)
        engine.retire()
        if self._pyttsx3 is engine:
            self._pyttsx3 = None
        if engine.alive:
            self._retiring = engine
            self._exit_watch = asyncio.get_running_loop().create_task(self._await_exit(engine))

    async def _await_exit(self, engine: Pyttsx3Thread) -> None:
        while engine.alive:
            # Real time, not the injected clock: this waits on a real thread,
            # and a virtual clock would turn the poll into a busy loop.
            await asyncio.sleep(THREAD_EXIT_POLL)
        if self._retiring is engine:
            self._retiring = None
        log.info("pyttsx3 thread ended; a new engine will be built")
