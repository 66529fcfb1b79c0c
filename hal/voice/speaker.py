"""Kaspar's voice: a queue of utterances, clips, two engines, timeouts and cancellation.

Voice satisfies hal.voice.api.VoiceOutput. Utterances are spoken one at a
time, in order, by a worker task on the event loop; each is tried as its
recorded clip (if the phrase key has one), then the configured engine, then
the other engine, and is cut at the utterance timeout.

Engines (each in its own module):
- espeak-ng as a child process (hal.voice.espeak), run by the sink so that it
  can stream into the player (hal.voice.sinks);
- pyttsx3 over libespeak-ng on a thread that owns the engine
  (hal.voice.pyttsx3_thread). A hung pyttsx3 engine is retired; a new one is
  built only after the old thread has ended, because libespeak-ng keeps one
  state per process. Until then the fallback engine speaks.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import msgspec
import structlog

from hal.clock import Clock, MonotonicClock
from hal.errors import VoiceError
from hal.voice.api import Spoken, SpokenStatus
from hal.voice.envelope import EnvelopeListener
from hal.voice.espeak import espeak_argv
from hal.voice.pyttsx3_thread import Pyttsx3Engine, Pyttsx3Thread, default_engine_factory
from hal.voice.settings import VoiceSettings
from hal.voice.sinks import Listened, Sink, WavSink, sink_for

log = structlog.get_logger("kaspar.voice")

# How long close() waits for a retired pyttsx3 thread to end.
CLOSE_GRACE_S = 2.0
# How often a retired pyttsx3 thread is checked for having ended; until it
# has, no new engine is built and the fallback engine speaks.
THREAD_EXIT_POLL = 0.05


@dataclass(eq=False)
class _Request:
    text: str
    key: str | None
    future: asyncio.Future[Spoken]
    timed_out: bool = False
    wav: str | None = None
    via: str | None = None


# What configure() keeps by default: where the sound goes, chosen when the voice is built.
WHERE_SOUND_GOES = ("backend", "player", "wav_dir", "espeak_ng")


class Voice:
    """The real voice; satisfies hal.voice.api.VoiceOutput."""

    def __init__(
        self,
        settings: VoiceSettings,
        clock: Clock | None = None,
        *,
        sink: Sink | None = None,
        engine_factory: Callable[[], Pyttsx3Engine] = default_engine_factory,
        keep: tuple[str, ...] = WHERE_SOUND_GOES,
    ) -> None:
        """The voice of `settings`; `clock` stamps each Spoken and times out utterances.

        `sink` replaces the one the settings name (a WAV file, a bench's probe);
        `engine_factory` builds each pyttsx3 engine, on its own thread. No worker
        or engine starts until the first say() (a player sink makes its temporary
        directory now). `keep` names the settings configure() never changes.
        """
        self._keep = keep
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
        """The configured engine, tried first ("espeak-ng" or "pyttsx3")."""
        return self._settings.engine

    @property
    def settings(self) -> VoiceSettings:
        """The settings the next line is spoken with."""
        return self._settings

    def configure(self, settings: VoiceSettings) -> None:
        """Speak with `settings` from the next line on: a session's own voice, a reload's.

        The engine, voice, rate, volume, pitch, timeout and clips change; what `keep`
        names does not (by default where the sound goes: the mouth listens to that sink,
        and a reload names it as waiting for a restart). A pyttsx3 engine built with the
        old settings is replaced.
        """
        old = self._settings
        settings = msgspec.structs.replace(
            settings, **{key: getattr(old, key) for key in self._keep}
        )
        if settings == old:
            return
        self._settings = settings
        self._espeak = espeak_argv(settings)
        engine = self._pyttsx3
        if engine is not None:
            self._retire(engine, "the voice's settings changed")

    def listen(self, listener: EnvelopeListener | None) -> bool:
        """Tell `listener` the levels of every line as its audio reaches the player (the
        body's mouth follows them); None stops. False when the sink cannot be listened to."""
        if not isinstance(self._sink, Listened):
            return False
        self._sink.listen(listener, self._clock)
        return True

    @property
    def player(self) -> str | None:
        """The player program the sound goes to; None when lines are written to WAV files."""
        return getattr(self._sink, "player", None)

    async def say(self, text: str, key: str | None = None) -> Spoken:
        """Speak `text` (or the clip of phrase `key`) after what is queued; returns when it ends.

        Failures are results, not exceptions (SpokenStatus FAILED or TIMED_OUT with
        the error). A caller cancelled while waiting also drops its line, queued or
        playing. Raises VoiceError only when the voice is closed.
        """
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
        """Stop the current line and drop everything queued (each resolves CANCELLED)."""
        while not self._queue.empty():
            self._resolve(self._queue.get_nowait(), SpokenStatus.CANCELLED, None)
        if self._current is not None:
            self._current[1].cancel()

    async def close(self) -> None:
        """Cancel, stop the worker, retire the pyttsx3 threads and close the sink; idempotent.

        Waits up to CLOSE_GRACE_S per thread (off the loop); a thread stuck in
        libespeak-ng is left behind (it is a daemon thread).
        """
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
        failure = task.exception()
        if failure is not None:
            return Spoken(
                SpokenStatus.FAILED, request.text, None, started, ended, None, str(failure)
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
            if isinstance(self._sink, WavSink):
                await self._sink.written(path)
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
