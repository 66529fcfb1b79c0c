"""pyttsx3 (over libespeak-ng) confined to one thread that owns the engine.

pyttsx3 is not thread-safe and its run loop cannot be re-entered, so one
thread builds the engine and renders every line, one at a time, with
save_to_file; the WAV is then played like any other, never with engine.say().

pyttsx3 traps handled here (pyttsx3 2.99, espeak driver):
- after save_to_file, later say() calls go to that file (`_save_file` is never
  cleared): say() is never used, every line has its own save_to_file;
- only the last save_to_file before runAndWait is rendered: one per runAndWait;
- pyttsx3.init() hands back a cached engine, the hung one too: engines are built
  with pyttsx3.engine.Engine directly;
- libespeak-ng keeps one synth callback for the whole process, so two engines
  at once either race in C or the older one renders nothing: the voice builds a
  new engine only after the previous thread has ended (hal.voice.speaker);
- a runAndWait that raised leaves `_inLoop` set and every later one raises
  "run loop already started": the thread ends and the voice builds another;
- the driver print()s "Audio saved to ..." on stdout, which would corrupt the
  JSON log lines: its module-level print is replaced by a debug log (the fd is
  left alone: redirecting fd 1 would swallow our own logs too);
- runAndWait does not wait for a save_to_file: libespeak-ng is started in its
  asynchronous mode (AUDIO_OUTPUT_RETRIEVAL), runAndWait returns once Synth is
  queued, and the WAV is written later on libespeak-ng's own thread, followed by
  a "finished-utterance" notice. The render waits for that notice; read at once,
  the file was missing or empty on a loaded machine;
- espeak_Cancel, which runAndWait's endLoop calls when libespeak-ng is still
  busy, empties its queue: the voice, rate and volume of a new engine, queued
  with setProperty, were lost now and then (its first line at the default
  rate). They are set on the library directly once it is idle, and each line
  starts only when it is idle;
- a render that returns without a file (the silent failure) counts as a failure.
"""

from __future__ import annotations

import asyncio
import contextlib
import queue
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Protocol

import structlog

from hal.errors import EmptyRender, VoiceError
from hal.voice.settings import VoiceSettings
from hal.voice.sinks import check_wav, wav_frames

log = structlog.get_logger("kaspar.voice")

RENDER_ATTEMPTS = 2
# How often a render waiting for libespeak-ng's "finished-utterance" looks whether the
# engine was retired meanwhile (the voice's utterance timeout decides when it hangs).
FINISH_POLL_S = 0.05


class Pyttsx3Voice(Protocol):
    """One of the voices a pyttsx3 engine lists."""

    @property
    def id(self) -> str:
        """The driver's voice id; for libespeak-ng a file name such as "gmw/en"."""
        ...

    @property
    def name(self) -> str | None:
        """A readable name, when the driver gives one."""
        ...

    @property
    def languages(self) -> Sequence[str] | None:
        """Languages the voice speaks ("en-gb"), when the driver gives them."""
        ...


class Pyttsx3Engine(Protocol):
    """The part of pyttsx3.engine.Engine the thread uses (pyttsx3 ships no types)."""

    def setProperty(self, name: str, value: str | float) -> None:
        """Set "voice" (an id), "rate" (words per minute) or "volume" (0.0 to 1.0)."""
        ...

    def getProperty(self, name: Literal["voices"]) -> Sequence[Pyttsx3Voice]:
        """The voices the driver offers."""
        ...

    def connect(self, topic: str, cb: Callable[..., None]) -> object:
        """Call `cb` on each `topic` event ("error", "finished-utterance"), with keyword
        arguments only; returns the token for disconnect."""
        ...

    def disconnect(self, token: object) -> None:
        """Stop the callback registered under `token`."""
        ...

    def save_to_file(self, text: str, filename: str) -> None:
        """Queue rendering `text` into the WAV file `filename` (done by runAndWait)."""
        ...

    def runAndWait(self) -> None:
        """Run the queued commands to their end, on the calling thread."""
        ...


def _quiet_print(*args: object, **_: object) -> None:
    log.debug("pyttsx3 said", text=" ".join(map(str, args)))


def default_engine_factory() -> Pyttsx3Engine:
    """A new pyttsx3 engine on the espeak driver, its stdout prints turned into debug logs.

    Called on the engine's own thread; raises whatever pyttsx3 raises when
    libespeak-ng is missing or cannot start.
    """
    import pyttsx3.drivers.espeak as espeak_driver
    import pyttsx3.engine

    espeak_driver.print = _quiet_print
    # Not pyttsx3.init(): its cache would return the previous engine, hung or not.
    engine: Pyttsx3Engine = pyttsx3.engine.Engine("espeak")
    return engine


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
    """One thread, one pyttsx3 engine, one job at a time; jobs come through a queue.

    The thread owns the engine: nothing else touches it, except retire(), which
    only flips the driver's loop flag. Once the engine has failed or been
    retired the thread ends and this object is not used again: the voice builds
    a new one (after this thread has ended, see the module docstring).
    """

    def __init__(self, settings: VoiceSettings, factory: Callable[[], Pyttsx3Engine]) -> None:
        """Start the thread; it builds the engine with `factory` and sets voice, rate and volume."""
        self._settings = settings
        self._factory = factory
        self._jobs: queue.SimpleQueue[_Job | None] = queue.SimpleQueue()
        self._engine: Pyttsx3Engine | None = None
        self._retired = False
        self.failure: str | None = None
        # Guards the moment the thread stops taking jobs, so none is left unanswered.
        self._taking = threading.Lock()
        self._ended = False
        self._thread = threading.Thread(target=self._run, name="kaspar-pyttsx3", daemon=True)
        self._thread.start()

    @property
    def alive(self) -> bool:
        """True until the thread has ended (a thread stuck in libespeak-ng stays alive)."""
        return self._thread.is_alive()

    def join(self, timeout: float) -> None:
        """Wait up to `timeout` seconds for the thread to end; blocking (run it off the loop)."""
        self._thread.join(timeout)

    @property
    def usable(self) -> bool:
        """True while new jobs can be given: alive, not retired and never failed."""
        return self.alive and not self._retired and self.failure is None

    async def render(self, text: str, path: Path) -> None:
        """Render `text` into the WAV file `path` on the engine's thread.

        Raises VoiceError when the engine is retired, failed or wrote no audio.
        If the caller is cancelled the job is abandoned: its file is removed
        once rendered, as nobody will play it.
        """
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
            _configure(engine, self._settings)
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

    def _render(self, engine: Pyttsx3Engine, job: _Job) -> None:
        # libespeak-ng now and then drops a line at once (a lone end-of-message event,
        # no samples; seen on the second line after an engine starts): rendering the
        # same text again on the same engine gives the audio. Twice empty is a failure.
        for attempt in range(RENDER_ATTEMPTS):
            try:
                self._render_once(engine, job)
                return
            except EmptyRender:
                if attempt + 1 == RENDER_ATTEMPTS:
                    raise
                log.info("pyttsx3 rendered no audio; rendering the line again", text=job.text)

    def _render_once(self, engine: Pyttsx3Engine, job: _Job) -> None:
        errors: list[BaseException | None] = []
        finished = threading.Event()
        endings: list[bool] = []  # "completed" of each finished-utterance

        def on_error(name: object = None, exception: BaseException | None = None) -> None:
            errors.append(exception)
            finished.set()

        def on_finished(name: object = None, completed: bool = True) -> None:
            endings.append(completed)
            finished.set()

        tokens = [engine.connect("error", on_error),
                  engine.connect("finished-utterance", on_finished)]
        _wait_for_libespeak(engine)
        try:
            with contextlib.suppress(FileNotFoundError):
                job.path.unlink()
            engine.save_to_file(job.text, str(job.path))
            engine.runAndWait()
            while not finished.wait(FINISH_POLL_S):
                if self._retired:
                    raise VoiceError("pyttsx3 engine retired before the line was rendered")
        finally:
            for token in tokens:
                engine.disconnect(token)
        if errors:
            raise VoiceError(f"pyttsx3 reported {errors[0]!r}")
        if not all(endings):
            raise VoiceError("pyttsx3 stopped the line before its end")
        if wav_frames(job.path) == 0:
            raise EmptyRender("pyttsx3 wrote an empty WAV")
        check_wav(job.path, "pyttsx3")

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


def _espeak_driver(engine: Pyttsx3Engine) -> Any | None:
    """pyttsx3's espeak driver under `engine`; None for any other engine (the tests' own)."""
    driver = getattr(getattr(engine, "proxy", None), "_driver", None)
    return driver if type(driver).__module__ == "pyttsx3.drivers.espeak" else None


def _wait_for_libespeak(engine: Pyttsx3Engine) -> None:
    """Return once libespeak-ng's own thread has done every command queued so far.

    runAndWait's endLoop cancels libespeak-ng's queue when it is still busy
    (espeak_Cancel), dropping what waits in it: the rate a new engine had just set
    was lost, and its first line came out at the default rate. Blocks this thread
    only (a hung library is the voice's utterance timeout's to handle).
    """
    if _espeak_driver(engine) is not None:
        from pyttsx3.drivers import _espeak

        _espeak.Synchronize()


def _configure(engine: Pyttsx3Engine, settings: VoiceSettings) -> None:
    """The voice, rate and volume, in force before the first line is rendered."""
    properties = (
        ("voice", _voice_id(engine, settings.voice)),
        ("rate", settings.rate),
        ("volume", settings.volume),
    )
    driver = _espeak_driver(engine)
    if driver is None:
        for name, value in properties:
            engine.setProperty(name, value)  # queued, applied by the first runAndWait
        return
    # engine.setProperty would queue them for runAndWait, whose endLoop can cancel them
    # (see _wait_for_libespeak): set on libespeak-ng directly, after what came before.
    _wait_for_libespeak(engine)
    for name, value in properties:
        driver.setProperty(name, value)
    _wait_for_libespeak(engine)


def _voice_id(engine: Pyttsx3Engine, wanted: str) -> str:
    """The pyttsx3 voice id for a name the espeak-ng command accepts ("en-gb").

    libespeak-ng's SetVoiceByName knows only file names ("gmw/en"), while the
    command line also takes languages; one setting serves both engines.
    """
    wanted = wanted.lower()
    voices = engine.getProperty("voices")
    matches: list[Callable[[Pyttsx3Voice], bool]] = [
        lambda v: v.id.lower() == wanted,
        lambda v: wanted in [language.lower() for language in v.languages or ()],
        lambda v: v.id.lower().rsplit("/", 1)[-1] == wanted,
        lambda v: (v.name or "").lower() == wanted,
    ]
    for match in matches:
        for voice in voices:
            if match(voice):
                return str(voice.id)
    raise VoiceError(f"pyttsx3 has no voice {wanted!r}")
