"""The live body: layers blended per joint, one control loop, every goal through the joints layer.

Layers, lowest priority first; each claims some joints at each tick, and a higher
one overrides a lower one on the joints it claims:

1. gaze: head and eyes to where Kaspar looks (absolute poses, minimum-jerk moves);
2. idle: the idle behaviour's small offsets, *added* to the gaze (life on top of
   attention, so Kaspar looks at the child and still breathes);
3. blink: the eyelids, from where they were when the blink began;
4. mouth: the voice's envelope (kasparctl.body.mouth);
5. gesture: a behaviour the game performs (nod, thinking, ...), offsets from
   where each joint was when it began (a nod wherever Kaspar looks).

A gesture is above the mouth: a behaviour that moves the mouth (a smile, a gasp)
means it, and a line said meanwhile shows on the other joints; speech is above
blinks and gaze because the mouth joint is its own. Joints no layer claims are
not sent anything (the arm the children move while teaching stays limp and free).

Every tick sends one `stream` step through the joints layer: its clamps, its speed
limits (a jump between layers is slewed, never sent), its torque rules and
latched faults, and its arbitration: the joints a move of the game holds (the arm
pointing, the listening pose) are left to the move, and every other joint streams
on (the mouth says the line while the arm points). Each goal is named by the layer
that won its joint (gaze, idle, blink, mouth, gesture:<behaviour>, home). A fault,
a pause or a stop calls cancel(): every layer ends at once and nothing more is sent
until the game asks again.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import structlog

from hal.clock import Alarm, Clock
from hal.errors import HalError
from hal.servos.api import Fault, ServoApi
from hal.servos.settings import ServoSettings
from kasparctl.body.api import Gaze, GazeKind
from kasparctl.body.behaviours import Behaviour, in_real_joints, minimum_jerk
from kasparctl.body.mouth import Mouth
from kasparctl.config import BodySettings

log = structlog.get_logger("kasparctl.body")

# Seconds a gaze shift takes (slower if a joint's speed limit says so).
GAZE_MOVE_S = 0.6
# Closer than this to home is home; a joint left away goes this share of the way each tick.
HOME_EPSILON_DEG = 0.05
HOME_PULL = 0.2
BLINK = "blink"
IDLE = "idle"
# The layers, as each goal's source names them (a gesture's adds the behaviour's name).
GAZE_LAYER = "gaze"
IDLE_LAYER = "idle"
BLINK_LAYER = "blink"
MOUTH_LAYER = "mouth"
GESTURE_LAYER = "gesture"
HOME_LAYER = "home"


@dataclass(eq=False)
class _Playback:
    """A behaviour being played: from its first tick, offsets from `base`."""

    behaviour: Behaviour
    strength: float
    layer: str
    done: asyncio.Future[None] | None = None
    started: float | None = None
    base: dict[str, float] = field(default_factory=dict)

    def finish(self) -> None:
        if self.done is not None and not self.done.done():
            self.done.set_result(None)


@dataclass
class _GazeMove:
    start: dict[str, float]
    target: dict[str, float]
    began: float | None = None
    # The target reached and sent: the joints layer holds it from here on.
    settled: bool = False


class LiveBody:
    """Kaspar's body language on the servos; satisfies kasparctl.body.api.Body."""

    def __init__(
        self,
        servos: ServoApi,
        settings: BodySettings,
        servo_settings: ServoSettings,
        library: Mapping[str, Behaviour],
        clock: Clock,
        *,
        latency_s: float = 0.0,
        rng: random.Random | None = None,
    ) -> None:
        """The body of `servos` as `settings` say, playing behaviours of `library`.

        `latency_s` is the player's output latency (the mouth waits as long);
        `rng` draws the blink and idle intervals. Nothing moves until start().
        """
        self._servos = servos
        self._settings = settings
        # Virtual joints (eyes_yaw, eyelids) played as the real joints they drive.
        self._library = {n: in_real_joints(b, servo_settings) for n, b in library.items()}
        self._virtual = servo_settings.virtual
        self._clock = clock
        self._rng = rng or random.Random()
        self.period = 1.0 / settings.rate_hz
        self._present = set(servos.joints)
        rests = {j.name: j.rest_deg for j in servo_settings.joints}
        # A behaviour played near a joint's limit is squashed against it here, quietly: the
        # joints layer would clamp it too, but warns of every goal it clamps.
        self._ranges = {j.name: j.range_deg for j in servo_settings.joints}
        mouth = settings.mouth_joint
        self._mouth_joint = mouth if mouth and mouth in self._present else None
        self._mouth_closed = rests.get(mouth, 0.0)
        self.mouth = Mouth(clock, latency_s, settings.mouth_full_level, self.period)
        # A line's sound wakes a quiet loop at once (the mouth must not wait for a poll).
        self.mouth.on_news = self._poke
        self._wake = asyncio.Event()
        self._alive = False
        self._blinking = False  # blinks on in a body otherwise still (pointing)
        self._gesture: _Playback | None = None
        self._blink: _Playback | None = None
        self._idle: _Playback | None = None
        self._gaze: _GazeMove | None = None
        self._next_blink: float | None = None
        self._next_idle: float | None = None
        self._task: asyncio.Task[None] | None = None
        # Wakes the loop on its schedule to the microsecond on the robot (hal.clock.Alarm).
        self._alarm = Alarm(clock)
        self._noted: set[tuple[str, str]] = set()
        self._fault_seen = False
        # Where each joint rests between behaviours: wherever the game (or anyone but the
        # body) last put it, or where a gaze settled. Behaviours are offsets from here, so
        # one cut short leaves nothing behind for the next to add to.
        self._home: dict[str, float] = {}
        # What the body itself last sent, to tell its own goals from the game's moves.
        self._sent: dict[str, float] = {}
        # The layer that won each joint at the last compose (the goals' sources).
        self.layers: dict[str, str] = {}
        # Set to a list to collect each tick's lateness in seconds (bench/bench_body_loop.py).
        self.lateness: list[float] | None = None
        # A latched fault ends every behaviour at once, loop running or not.
        servos.on_fault(self._on_fault)

    # --- the Body interface -------------------------------------------------------------

    async def start(self) -> None:
        """Begin the control loop; the body is not alive until set_alive(True)."""
        if self._task is not None:
            return
        self._task = asyncio.get_running_loop().create_task(self._run(), name="body loop")

    async def close(self) -> None:
        """Cancel everything and stop the loop; idempotent."""
        self.cancel()
        self._servos.off_fault(self._on_fault)
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._alarm.close()

    def set_alive(self, alive: bool, *, blinking: bool = False) -> None:
        """Allow or forbid blinks, idle movements and gaze shifts.

        Forbidden, idle movements end at once and no gaze is taken, and blinks too unless
        `blinking`; the gaze asked last still turns the head there and holds it (the game
        looks at the bag, then keeps the head still while the arm points, the eyelids
        blinking on: the move claims only the arm).
        """
        self._alive = alive
        self._blinking = alive or blinking
        if not alive:
            self._idle = self._next_idle = None
        if not self._blinking:
            self._blink = self._next_blink = None
        if self._blinking:
            self._poke()

    def look_at(self, gaze: Gaze) -> None:
        """Turn head and eyes to the configured pose for `gaze`, when alive; returns at once."""
        if not self._alive:
            return
        target = {j: v for j, v in self._gaze_pose(gaze).items() if j in self._present}
        if not target:
            return
        self._gaze = _GazeMove({}, target)
        self._poke()

    async def perform(self, behaviour: str, strength: float = 1.0) -> None:
        """Play `behaviour` to its end (or until cancelled or replaced); never raises for it.

        An unknown behaviour, or one played before start(), is logged once and skipped.
        """
        chosen = self._library.get(behaviour)
        if chosen is None or self._task is None:
            self._note_once(behaviour, "", "behaviour not played: "
                            + ("unknown" if chosen is None else "the body is not started"))
            return
        playback = self.play(chosen, strength)
        assert playback.done is not None
        await asyncio.shield(playback.done)

    def play(self, behaviour: Behaviour, strength: float = 1.0) -> _Playback:
        """Start `behaviour` in the gesture layer now (replacing one playing); its playback."""
        for joint in behaviour.joints:
            if joint not in self._present:
                self._note_once(behaviour.name, joint, "joint not on this robot: skipped")
        if self._gesture is not None:
            self._gesture.finish()
        playback = _Playback(behaviour, strength, f"{GESTURE_LAYER}:{behaviour.name}",
                             asyncio.get_running_loop().create_future())
        self._gesture = playback
        self._poke()
        return playback

    def cancel(self) -> None:
        """End every layer at once: no goal is sent after this returns, until the game asks
        again (set_alive(True), look_at, perform, or the next line's sound)."""
        if self._gesture is not None:
            self._gesture.finish()
        self._gesture = self._blink = self._idle = self._gaze = None
        self._alive = self._blinking = False
        self._next_blink = self._next_idle = None
        self.mouth.silence()
        # Every joint is home where it stands: not even the way home is sent after a cancel.
        self._home.clear()
        self._sent.clear()

    # --- the loop -----------------------------------------------------------------------

    async def _run(self) -> None:
        begin = self._clock.now()
        tick = 0
        while True:
            tick += 1
            due = begin + tick * self.period
            if due - self._clock.now() < -self.period:  # far behind: start again, no burst
                begin, tick = self._clock.now(), 0
                due = begin
            await self._alarm.sleep_until(due)
            now = self._clock.now()
            if self.lateness is not None:
                self.lateness.append(now - due)
            sent = await self.step(now)
            if not sent and self.quiet():
                # Nothing moves: no goal to send until a layer has something to do. The
                # joints layer holds every goal meanwhile; waking costs nothing on the
                # robot and keeps whole games in simulated time as fast as without a body.
                await self._rest_until(self._next_life())
                begin, tick = self._clock.now(), 0

    def quiet(self) -> bool:
        """Whether no layer has anything to send (blinks and idle may still be scheduled)."""
        gaze_moving = self._gaze is not None and not self._gaze.settled
        return (
            self._gesture is None
            and self._blink is None
            and self._idle is None
            and not gaze_moving
            and not self.mouth.claimed
            and not self.away_from_home()
        )

    def _next_life(self) -> float | None:
        """When the next blink or idle movement is due, if Kaspar is alive."""
        allowed = ((self._next_blink, self._blinking), (self._next_idle, self._alive))
        due = [moment for moment, allowed_now in allowed if moment is not None and allowed_now]
        return min(due) if due else None

    async def _rest_until(self, moment: float | None) -> None:
        """Wait for a poke (a behaviour, a gaze, alive again, a line's sound) or `moment`."""
        self._wake.clear()
        waits: list[asyncio.Future[Any]] = [asyncio.ensure_future(self._wake.wait())]
        if moment is not None:
            delay = max(0.0, moment - self._clock.now())
            waits.append(asyncio.ensure_future(self._clock.sleep(delay)))
        try:
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for waiting in waits:
                waiting.cancel()
            await asyncio.gather(*waits, return_exceptions=True)

    def _poke(self) -> None:
        self._wake.set()

    async def step(self, now: float) -> dict[str, float]:
        """One tick: blend the layers for `now` and send the goals; the goals sent."""
        pose = self.compose(now)
        if not pose:
            return {}
        try:
            sent = await self._servos.stream(pose, self.period, dict(self.layers))
        except HalError as error:
            if not self._fault_seen:
                log.warning("body paused: the servos refuse motion", error=str(error))
                self._fault_seen = True
            self.cancel()
            return {}
        self._fault_seen = False
        self._sent.update(sent)
        return sent

    def compose(self, now: float) -> dict[str, float]:
        """The blended target of every claimed joint at `now` (layers by priority)."""
        held = self._servos.commanded()
        self._learn_home(held)
        home = self._home
        out: dict[str, float] = {}
        layers = self.layers
        layers.clear()
        self._gaze_layer(now, held, out)
        if self._blinking:
            self._schedule_life(now)
            if self._idle is not None:
                self._idle = self._additive(self._idle, now, home, out)
            if self._blink is not None:
                self._blink = self._relative(self._blink, now, home, out)
        if self._mouth_joint is not None and self._mouth_joint in held:
            opening = self.mouth.opening(now)
            if opening is not None:
                span = self._settings.mouth_open_deg
                out[self._mouth_joint] = self._mouth_closed + opening * span
                layers[self._mouth_joint] = MOUTH_LAYER
        if self._gesture is not None:
            self._gesture = self._relative(self._gesture, now, home, out)
        for joint, rest in home.items():
            # A joint a behaviour left away from home (cut short) goes back to it gently.
            now_at = held.get(joint)
            if now_at is not None and joint not in out and abs(now_at - rest) > HOME_EPSILON_DEG:
                out[joint] = now_at + (rest - now_at) * HOME_PULL
                layers[joint] = HOME_LAYER
        return {
            joint: self._within(joint, value) for joint, value in out.items() if joint in held
        }

    def _within(self, joint: str, degrees: float) -> float:
        low, high = self._ranges.get(joint, (degrees, degrees))
        return min(max(degrees, low), high)

    def _learn_home(self, held: Mapping[str, float]) -> None:
        """A joint not where the body last sent it was moved by someone else: its new home."""
        for joint, value in held.items():
            sent = self._sent.get(joint)
            if sent is None or abs(value - sent) > HOME_EPSILON_DEG:
                self._home[joint] = value
                self._sent[joint] = value
                if sent is not None:
                    self._yield_joint(joint)

    def _yield_joint(self, joint: str) -> None:
        """The game moved `joint` (its listening pose, a point): what the body was doing
        with it ends there, and the rest of each behaviour goes on."""
        for playback in (self._gesture, self._blink, self._idle):
            if playback is not None and playback.base is not None:
                playback.base.pop(joint, None)
        if self._gaze is not None:
            self._gaze.target.pop(joint, None)
            self._gaze.start.pop(joint, None)

    def away_from_home(self) -> bool:
        """Whether a joint still has its way home to go."""
        held = self._servos.commanded()
        return any(
            abs(held[joint] - rest) > HOME_EPSILON_DEG
            for joint, rest in self._home.items()
            if joint in held
        )

    def _schedule_life(self, now: float) -> None:
        settings = self._settings
        if self._next_blink is None:
            self._next_blink = now + self._rng.uniform(*settings.blink_interval_s)
        if self._next_idle is None and self._alive:
            self._next_idle = now + self._rng.uniform(*settings.idle_interval_s)
        if now >= self._next_blink:
            self._next_blink = None
            if self._blink is None and BLINK in self._library:
                self._blink = _Playback(self._library[BLINK], 1.0, BLINK_LAYER)
        if self._next_idle is not None and now >= self._next_idle:
            self._next_idle = None
            if self._idle is None and IDLE in self._library and settings.idle_amplitude > 0:
                self._idle = _Playback(self._library[IDLE], settings.idle_amplitude, IDLE_LAYER)

    def _gaze_layer(self, now: float, held: Mapping[str, float], out: dict[str, float]) -> None:
        move = self._gaze
        if move is None:
            return
        if move.began is None:
            move.began = now
            move.start = {j: held[j] for j in move.target if j in held}
        if move.settled:
            return  # held by the joints layer at its target
        fraction = minimum_jerk((now - move.began) / GAZE_MOVE_S)
        for joint, target in move.target.items():
            start = move.start.get(joint)
            if start is not None:
                out[joint] = start + (target - start) * fraction
                self.layers[joint] = GAZE_LAYER
        move.settled = now - move.began >= GAZE_MOVE_S
        if move.settled:
            self._home.update({j: v for j, v in move.target.items() if j in move.start})

    def _additive(
        self, playback: _Playback, now: float, held: Mapping[str, float], out: dict[str, float]
    ) -> _Playback | None:
        """Offsets added to what the layers below want (else to where the joint was)."""
        if playback.started is None:
            playback.started = now
            playback.base = {j: held[j] for j in playback.behaviour.joints if j in held}
        elapsed = now - playback.started
        for joint, offset in playback.behaviour.offsets(elapsed, playback.strength).items():
            if joint in playback.base:
                out[joint] = out.get(joint, playback.base[joint]) + offset
                self.layers[joint] = playback.layer
        if elapsed >= playback.behaviour.duration:
            playback.finish()
            return None
        return playback

    def _relative(
        self, playback: _Playback, now: float, held: Mapping[str, float], out: dict[str, float]
    ) -> _Playback | None:
        """Offsets from where each joint was (or was wanted) at the first tick; overrides."""
        if playback.started is None:
            playback.started = now
            playback.base = {
                j: out.get(j, held[j]) for j in playback.behaviour.joints if j in held
            }
        elapsed = now - playback.started
        for joint, offset in playback.behaviour.offsets(elapsed, playback.strength).items():
            if joint in playback.base:
                out[joint] = playback.base[joint] + offset
                self.layers[joint] = playback.layer
        if elapsed >= playback.behaviour.duration:
            playback.finish()
            return None
        return playback

    # --- helpers ------------------------------------------------------------------------

    def _gaze_pose(self, gaze: Gaze) -> dict[str, float]:
        table = self._settings.gaze
        if gaze.kind is GazeKind.CHILD and 0 <= gaze.index < len(table.children):
            pose = table.children[gaze.index]
        elif gaze.kind is GazeKind.BAG and 0 <= gaze.index < len(table.bags):
            pose = table.bags[gaze.index]
        elif gaze.kind is GazeKind.RESEARCHER and table.researcher:
            pose = table.researcher
        else:
            pose = table.ahead
        # A virtual joint (eyes_yaw) as the real joints it drives (the rules checked the pose).
        real: dict[str, float] = {}
        for name, degrees in pose.items():
            for joint, ratio in self._virtual.get(name, {name: 1.0}).items():
                real[joint] = ratio * degrees
        return real

    def _on_fault(self, fault: Fault) -> None:
        self.cancel()

    def _note_once(self, behaviour: str, joint: str, message: str) -> None:
        if (behaviour, joint) not in self._noted:
            self._noted.add((behaviour, joint))
            log.info(message, behaviour=behaviour, joint=joint or None)
