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
import math
import random
from collections.abc import Mapping
from dataclasses import dataclass, field

import structlog

from hal.clock import Alarm, Clock
from hal.errors import HalError, KasparError
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
# The longest the loop sleeps through ticks that change no servo's count before it
# looks ahead again (a lookahead costs a tick's arithmetic, no packet and no wake-up).
MAX_STILL_S = 10.0


@dataclass(eq=False)
class _Playback:
    """A behaviour being played: from its first tick, offsets from `base`."""

    behaviour: Behaviour
    strength: float
    layer: str
    done: asyncio.Future[None] | None = None
    started: float | None = None
    base: dict[str, float] = field(default_factory=dict)

    # The whole trajectory, planned at its first tick: each joint's offset at every tick
    # of the loop from there. A tick on the loop's schedule reads it; a late one (the
    # robot's loop, a few ms) evaluates the curve at its own moment.
    plan: list[dict[str, float]] = field(default_factory=list)
    period: float = 0.0

    def begin(self, now: float, base: dict[str, float], period: float) -> None:
        """Its first tick: offsets from `base`, every tick's planned at once."""
        self.started = now
        self.base = base
        self.period = period
        ticks = math.ceil(self.behaviour.duration / period - 1e-9) + 1
        self.plan = [self.behaviour.offsets(k * period, self.strength) for k in range(ticks)]

    def offsets(self, now: float) -> dict[str, float]:
        """Each joint's offset at `now` (planned when `now` is one of the loop's ticks)."""
        assert self.started is not None
        elapsed = now - self.started
        index = round(elapsed / self.period)
        if index < len(self.plan) and abs(index * self.period - elapsed) < 1e-6:
            return self.plan[index]
        return self.behaviour.offsets(elapsed, self.strength)

    @property
    def ends(self) -> float:
        """When its last tick is due (its first must have come)."""
        assert self.started is not None
        return self.started + self.behaviour.duration

    def finish(self) -> None:
        if self.done is not None and not self.done.done():
            self.done.set_result(None)


class _Unplanned(KasparError):
    """The moment ahead cannot be foreseen: a layer begins or pulls home at the next tick."""


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
        skipping: bool = True,
    ) -> None:
        """The body of `servos` as `settings` say, playing behaviours of `library`.

        `latency_s` is the player's output latency (the mouth waits as long);
        `rng` draws the blink and idle intervals. Nothing moves until start().
        `skipping`: the loop sleeps through the ticks at which no servo's count would
        change (False: it wakes at every tick, as it used to; the goals sent are the same).
        """
        self.skipping = skipping
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
        # Set while the loop rests or sleeps through still ticks: a poke ends that wait.
        self._resting = False
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
        # The joints that may be away from home: those the body moved (or whose home a
        # gaze changed) since each was last seen there. Only these are looked at for the
        # way home, not every joint at every tick.
        self._unsettled: set[str] = set()
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
        self._unsettled.clear()

    # --- the loop -----------------------------------------------------------------------

    async def _run(self) -> None:
        begin = self._clock.now()
        tick = 0
        period = self.period
        arrived = False  # woken at this tick's moment already (the end of a still stretch)
        while True:
            tick += 1
            due = begin + tick * period
            if due - self._clock.now() < -period:  # far behind: start again, no burst
                begin, tick = self._clock.now(), 0
                due = begin
            if not arrived:
                await self._alarm.sleep_until(due)
            arrived = False
            now = self._clock.now()
            if self.lateness is not None:
                self.lateness.append(now - due)
            sent = await self.step(now)
            # A resting loop knows the next tick would send nothing once no layer is left:
            # it rests now, as the ticking loop does one tick later (either wakes then at
            # the same moment, the next life or a poke, and ticks from there).
            held = self._servos.commanded()  # once, for the questions below
            if (not sent or self.skipping) and self.quiet(held):
                # Nothing moves: no goal to send until a layer has something to do. The
                # joints layer holds every goal meanwhile; waking costs nothing on the
                # robot and keeps whole games in simulated time as fast as without a body.
                await self._rest_until(self._next_life())
                begin, tick = self._clock.now(), 0
                continue
            # While a line is heard the mouth changes its count at nearly every tick: no
            # look ahead then (it would find the very next tick), only in its pauses.
            speaking = self.layers.get(self._mouth_joint or "") == MOUTH_LAYER and bool(
                self.mouth.peek(now))
            still = self.still_ticks(due, held) if self.skipping and not speaking else 0
            if still:
                # The ticks ahead would send no servo a new count: sleep through them to
                # the next that does, on the schedule; a poke wakes the loop for the tick
                # after it.
                if await self._rest_until(due + (still + 1) * period):
                    tick = math.floor((self._clock.now() - begin) / period + 1e-9)
                else:
                    tick += still
                    arrived = True

    def still_ticks(self, due: float, held: Mapping[str, float] | None = None) -> int:
        """How many ticks after the one `due` would send no servo a new count: the layers'
        trajectories looked at ahead, up to the next moment a layer begins or ends."""
        if HOME_LAYER in self.layers.values():
            return 0
        period = self.period
        try:
            horizon = self._horizon()
            if held is None:
                held = self._servos.commanded()
            if self._pulled_home(held):
                return 0
            limit = max(1, round(MAX_STILL_S / period))
            life = self._life_still_ticks(due, horizon, limit)
            if life is not None:
                return life
            for ahead in range(1, limit + 1):
                moment = due + ahead * period
                if moment >= horizon - 1e-9:
                    return ahead - 1
                pose = self._blend(moment, held, self._home, {}, live=False)
                if pose and self._servos.moves_servo(pose):
                    return ahead - 1
            return limit
        except _Unplanned:
            return 0

    def _life_still_ticks(self, due: float, horizon: float, limit: int) -> int | None:
        """still_ticks when only blinks and idle movements play: each joint's planned
        trajectory read against the targets its servo would not be sent (still_band),
        without composing a pose a tick; None when other layers play too."""
        if (self._gesture is not None or self.mouth.until is not None
                or (self._gaze is not None and not self._gaze.settled)):
            return None
        tracks: dict[str, _Playback] = {}
        for playback in (self._idle, self._blink):  # the blink above the idle
            if playback is not None:
                if playback.started is None:
                    raise _Unplanned
                tracks.update(dict.fromkeys(playback.base, playback))
        period = self.period
        still = limit
        for ahead in range(1, limit + 1):
            if due + ahead * period >= horizon - 1e-9:
                still = ahead - 1
                break
        for joint, playback in tracks.items():
            low, high = self._servos.still_band(joint)
            base = playback.base[joint]
            assert playback.started is not None
            first = round((due - playback.started) / period)
            plan = playback.plan
            for ahead in range(1, still + 1):
                index = first + ahead
                if index >= len(plan):
                    break  # its end is the horizon
                value = self._within(joint, base + plan[index].get(joint, 0.0))
                if not low <= value <= high:
                    still = ahead - 1
                    break
        return still

    def _pulled_home(self, held: Mapping[str, float]) -> bool:
        """Whether a joint away from home is left to the home layer by every other layer."""
        claimed: set[str] = set()
        for playback in (self._idle, self._blink, self._gesture):
            if playback is not None:
                claimed.update(playback.base)
        if self._gaze is not None and not self._gaze.settled:
            claimed.update(self._gaze.start)
        if self._mouth_joint is not None and self.mouth.claimed:
            claimed.add(self._mouth_joint)
        home = self._home
        return any(
            joint not in claimed and abs(held[joint] - home[joint]) > HOME_EPSILON_DEG
            for joint in self._unsettled
            if joint in held and joint in home
        )

    def _horizon(self) -> float:
        """The next moment a layer begins or ends (a tick at or after it is never slept
        through); _Unplanned when one begins at the next tick."""
        moments = [math.inf]
        if self._blinking:
            if self._next_blink is None or (self._alive and self._next_idle is None):
                raise _Unplanned
            moments.append(self._next_blink)
            if self._alive and self._next_idle is not None:
                moments.append(self._next_idle)
        for playback in (self._idle, self._blink, self._gesture):
            if playback is not None:
                if playback.started is None:
                    raise _Unplanned
                moments.append(playback.ends)
        move = self._gaze
        if move is not None and not move.settled:
            if move.began is None:
                raise _Unplanned
            moments.append(move.began + GAZE_MOVE_S)
        until = self.mouth.until
        if until is not None:
            moments.append(until)
        return min(moments)

    def quiet(self, held: Mapping[str, float] | None = None) -> bool:
        """Whether no layer has anything to send (blinks and idle may still be scheduled)."""
        gaze_moving = self._gaze is not None and not self._gaze.settled
        return (
            self._gesture is None
            and self._blink is None
            and self._idle is None
            and not gaze_moving
            and not self.mouth.claimed
            and not self.away_from_home(held)
        )

    def _next_life(self) -> float | None:
        """When the next blink or idle movement is due, if Kaspar is alive."""
        allowed = ((self._next_blink, self._blinking), (self._next_idle, self._alive))
        due = [moment for moment, allowed_now in allowed if moment is not None and allowed_now]
        return min(due) if due else None

    async def _rest_until(self, moment: float | None) -> bool:
        """Wait for a poke (a behaviour, a gaze, alive again, a line's sound) or `moment`
        (None: a poke only); whether a poke came."""
        self._resting = True
        try:
            return await self._alarm.sleep_until(moment)
        finally:
            self._resting = False

    def _poke(self) -> None:
        if self._resting:
            self._alarm.interrupt()

    async def step(self, now: float) -> dict[str, float]:
        """One tick: blend the layers for `now` and send the goals; the goals sent."""
        composed = self.compose(now)
        # A joint held where the body last put it would be skipped by the joints layer
        # too (its goal is its target): only the joints that move are sent to stream.
        last = self._sent
        pose = {joint: value for joint, value in composed.items() if last.get(joint) != value}
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
        self._unsettled.update(sent)
        return sent

    def compose(self, now: float) -> dict[str, float]:
        """The blended target of every claimed joint at `now` (layers by priority)."""
        held = self._servos.commanded()
        self._learn_home(held)
        layers = self.layers
        layers.clear()
        return self._blend(now, held, self._home, layers, live=True)

    def _blend(
        self,
        now: float,
        held: Mapping[str, float],
        home: Mapping[str, float],
        layers: dict[str, str],
        *,
        live: bool,
    ) -> dict[str, float]:
        """The layers at `now`. Live, a tick: layers begin, end and settle. Not live, a
        look ahead that changes nothing (_Unplanned where a layer would begin)."""
        out: dict[str, float] = {}
        self._gaze_layer(now, held, out, layers, live)
        if self._blinking:
            if live:
                self._schedule_life(now)
            if self._idle is not None:
                idle = self._additive(self._idle, now, home, out, layers, live)
                if live:
                    self._idle = idle
            if self._blink is not None:
                blink = self._relative(self._blink, now, home, out, layers, live)
                if live:
                    self._blink = blink
        if self._mouth_joint is not None and self._mouth_joint in held:
            opening = self.mouth.opening(now) if live else self.mouth.peek(now)
            if opening is not None:
                span = self._settings.mouth_open_deg
                out[self._mouth_joint] = self._mouth_closed + opening * span
                layers[self._mouth_joint] = MOUTH_LAYER
        if self._gesture is not None:
            gesture = self._relative(self._gesture, now, home, out, layers, live)
            if live:
                self._gesture = gesture
        if live:
            # A joint a behaviour left away from home (cut short) goes back to it gently.
            # (A look ahead has asked _pulled_home once: held does not change meanwhile.)
            for joint in list(self._unsettled):
                if joint in out:
                    continue
                now_at, rest = held.get(joint), home.get(joint)
                if now_at is not None and rest is not None and abs(now_at - rest) > (
                        HOME_EPSILON_DEG):
                    out[joint] = now_at + (rest - now_at) * HOME_PULL
                    layers[joint] = HOME_LAYER
                else:
                    self._unsettled.discard(joint)  # home: nothing to look at until it moves
        return {
            joint: self._within(joint, value) for joint, value in out.items() if joint in held
        }

    def _within(self, joint: str, degrees: float) -> float:
        low, high = self._ranges.get(joint, (degrees, degrees))
        return min(max(degrees, low), high)

    def _learn_home(self, held: Mapping[str, float]) -> None:
        """A joint not where the body last sent it was moved by someone else: its new home."""
        last = self._sent
        for joint, value in held.items():
            sent = last.get(joint)
            if sent == value:
                continue  # where the body left it: most joints, most ticks
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

    def away_from_home(self, held: Mapping[str, float] | None = None) -> bool:
        """Whether a joint still has its way home to go (`held`: commanded(), if read)."""
        if held is None:
            held = self._servos.commanded()
        home = self._home
        return any(
            abs(held[joint] - home[joint]) > HOME_EPSILON_DEG
            for joint in self._unsettled
            if joint in held and joint in home
        )

    def _schedule_life(self, now: float) -> None:
        settings = self._settings
        if self._next_blink is not None and now >= self._next_blink:
            self._next_blink = None
            if self._blink is None and BLINK in self._library:
                self._blink = _Playback(self._library[BLINK], 1.0, BLINK_LAYER)
        if self._next_idle is not None and now >= self._next_idle:
            self._next_idle = None
            if self._idle is None and IDLE in self._library and settings.idle_amplitude > 0:
                self._idle = _Playback(self._library[IDLE], settings.idle_amplitude, IDLE_LAYER)
        # The next ones drawn at once: the loop knows when to wake for them.
        if self._next_blink is None:
            self._next_blink = now + self._rng.uniform(*settings.blink_interval_s)
        if self._next_idle is None and self._alive:
            self._next_idle = now + self._rng.uniform(*settings.idle_interval_s)

    def _gaze_layer(
        self,
        now: float,
        held: Mapping[str, float],
        out: dict[str, float],
        layers: dict[str, str],
        live: bool,
    ) -> None:
        move = self._gaze
        if move is None:
            return
        if move.began is None:
            if not live:
                raise _Unplanned
            move.began = now
            move.start = {j: held[j] for j in move.target if j in held}
        if move.settled:
            return  # held by the joints layer at its target
        fraction = minimum_jerk((now - move.began) / GAZE_MOVE_S)
        for joint, target in move.target.items():
            start = move.start.get(joint)
            if start is not None:
                out[joint] = start + (target - start) * fraction
                layers[joint] = GAZE_LAYER
        if live:
            move.settled = now - move.began >= GAZE_MOVE_S
            if move.settled:
                settled = {j: v for j, v in move.target.items() if j in move.start}
                self._home.update(settled)
                self._unsettled.update(settled)

    def _additive(
        self,
        playback: _Playback,
        now: float,
        held: Mapping[str, float],
        out: dict[str, float],
        layers: dict[str, str],
        live: bool,
    ) -> _Playback | None:
        """Offsets added to what the layers below want (else to where the joint was)."""
        if playback.started is None:
            if not live:
                raise _Unplanned
            playback.begin(
                now, {j: held[j] for j in playback.behaviour.joints if j in held}, self.period)
        base = playback.base
        for joint, offset in playback.offsets(now).items():
            if joint in base:
                out[joint] = out.get(joint, base[joint]) + offset
                layers[joint] = playback.layer
        return self._ended(playback, now, live)

    def _relative(
        self,
        playback: _Playback,
        now: float,
        held: Mapping[str, float],
        out: dict[str, float],
        layers: dict[str, str],
        live: bool,
    ) -> _Playback | None:
        """Offsets from where each joint was (or was wanted) at the first tick; overrides."""
        if playback.started is None:
            if not live:
                raise _Unplanned
            playback.begin(
                now,
                {j: out.get(j, held[j]) for j in playback.behaviour.joints if j in held},
                self.period,
            )
        base = playback.base
        for joint, offset in playback.offsets(now).items():
            if joint in base:
                out[joint] = base[joint] + offset
                layers[joint] = playback.layer
        return self._ended(playback, now, live)

    @staticmethod
    def _ended(playback: _Playback, now: float, live: bool) -> _Playback | None:
        """The playback, or None at its last tick (a live one is finished there)."""
        assert playback.started is not None
        if live and now - playback.started >= playback.behaviour.duration:
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
