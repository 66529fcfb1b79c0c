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

The body rests whenever it can. A goal that would not change a servo's count is not
sent (the joints layer's stream), and the loop does not even wake for the ticks that
would send nothing: after each step it looks ahead, tick by tick on the same schedule,
at what the layers would ask (a pure peek: blinks and idle movements are planned whole
when they begin, the mouth's levels are known once the voice hands them over), and
sleeps to the first tick that would change a count or the body's own state (a layer
beginning or ending, life due, the game moving a joint). Anything the game asks wakes
it at the next tick. The servos receive the same goals at the same moments as a loop
that computes every tick (`rests = False`, tests/test_body_rest.py), for a fraction of
the work: on the robot, the battery's; in simulated time, whole games.
"""

from __future__ import annotations

import asyncio
import bisect
import contextlib
import math
import random
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import structlog

from hal.clock import Alarm, Clock
from hal.errors import HalError, KasparError
from hal.servos.api import Fault, Goal, ServoApi
from hal.servos.settings import ServoSettings
from kasparctl.body.api import Gaze, GazeKind
from kasparctl.body.behaviours import Behaviour, in_real_joints, minimum_jerk
from kasparctl.body.mouth import Mouth
from kasparctl.config import BodySettings

log = structlog.get_logger("kasparctl.body")

# Seconds a gaze shift takes (slower if a joint's speed limit says so).
GAZE_MOVE_S = 0.6
# A joint further than this from where the body last sent it was moved by someone else.
HOME_EPSILON_DEG = 0.05
# A joint left away from home goes this share of the way each tick (within its count: home).
HOME_PULL = 0.2
# Ticks looked ahead at once before sleeping to the last of them and looking further: a
# bounded piece of arithmetic on the event loop (a fraction of a millisecond).
LOOKAHEAD_TICKS = 25
# A tick runs this long after its moment: after anything else due then (a line begun, a
# move ended), whichever was scheduled first, so a resting loop and a ticking one see the
# game's news at the same tick.
TIE_S = 1e-9
# News this close to a tick's moment came at that moment (floating point's sums differ).
SAME_MOMENT_S = 1e-7
BLINK = "blink"
IDLE = "idle"
# The layers, as each goal's source names them (a gesture's adds the behaviour's name).
GAZE_LAYER = "gaze"
IDLE_LAYER = "idle"
BLINK_LAYER = "blink"
MOUTH_LAYER = "mouth"
GESTURE_LAYER = "gesture"
HOME_LAYER = "home"
OWN_LAYERS = frozenset({GAZE_LAYER, IDLE_LAYER, BLINK_LAYER, MOUTH_LAYER, GESTURE_LAYER,
                        HOME_LAYER})


@dataclass(eq=False)
class _Playback:
    """A behaviour being played: from its first tick, offsets from `base`."""

    behaviour: Behaviour
    strength: float
    layer: str
    done: asyncio.Future[None] | None = None
    started: float | None = None
    base: dict[str, float] = field(default_factory=dict)
    # The whole trajectory, planned at its first tick: the offsets at each tick from there.
    plan: list[dict[str, float]] = field(default_factory=list)
    period: float = 0.0
    # The ticks (from its first) at which one of its joints' servo counts changes, when
    # played alone over still joints (None: not foreseen so, the loop looks tick by tick).
    changes: list[int] | None = None
    # At each of those ticks, the goals of the joints whose count changes there.
    change_goals: dict[int, dict[str, float]] = field(default_factory=dict)

    def begin(self, now: float, base: dict[str, float], period: float) -> None:
        """Its first tick, at `now`: offsets from `base`, every tick's planned at once."""
        self.started = now
        self.base = base
        self.period = period
        ticks = math.ceil(self.behaviour.duration / period - 1e-9) + 1
        self.plan = [self.behaviour.offsets(k * period, self.strength) for k in range(ticks)]

    def offsets(self, now: float) -> dict[str, float]:
        """Each joint's offset at `now`: planned at the loop's ticks, else (a late tick on the
        robot, a test's own moment) the curve evaluated there."""
        assert self.started is not None
        elapsed = now - self.started
        index = round(elapsed / self.period)
        if 0 <= index < len(self.plan) and abs(index * self.period - elapsed) < 1e-7:
            return self.plan[index]
        return self.behaviour.offsets(elapsed, self.strength)

    def foresee(
        self, counter: Callable[[str], Callable[[float], int]],
        within: Callable[[str, float], float], reach: Callable[[str], float],
    ) -> None:
        """Plan the ticks at which a servo count changes, if its goals are its own: from its
        base, each tick's step within its joint's reach (nothing slewed behind the plan).
        `counter(joint)` gives the joint's degrees-to-count function."""
        assert self.started is not None
        base = self.base
        counts = {joint: counter(joint) for joint in base}
        last = {joint: counts[joint](within(joint, value)) for joint, value in base.items()}
        before = dict(base)
        changes = []
        goals: dict[int, dict[str, float]] = {}
        for index, offsets in enumerate(self.plan):
            changed: dict[str, float] = {}
            for joint, offset in offsets.items():
                if joint not in base:
                    continue
                value = within(joint, base[joint] + offset)
                if abs(value - before[joint]) > reach(joint):
                    return  # faster than its limit somewhere: the stream would lag the plan
                before[joint] = value
                count = counts[joint](value)
                if count != last[joint]:
                    last[joint] = count
                    changed[joint] = value
            if changed:
                changes.append(index)
                goals[index] = changed
        self.changes = changes
        self.change_goals = goals

    def next_change(self, index: int) -> int | None:
        """The first planned tick after `index` (from its first) with a change, if any."""
        assert self.changes is not None
        at = bisect.bisect_right(self.changes, index)
        return self.changes[at] if at < len(self.changes) else None

    def finish(self) -> None:
        if self.done is not None and not self.done.done():
            self.done.set_result(None)


class _MustStep(KasparError):
    """A look ahead met a tick that changes the body's own state (a layer begins or ends,
    life is due, the game moved a joint): the loop steps there."""


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
        self._joint_settings = {j.name: j for j in servo_settings.joints}
        self._coupled = {c.joint for c in servo_settings.couplings}
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
        # False: compute and stream every tick (the reference the resting loop must equal).
        self.rests = True
        # The goals of the next tick when only planned life changes counts there (a light
        # step), and the layer of each.
        self._light: dict[str, float] | None = None
        self._light_layers: dict[str, str] = {}
        # Each home's raw count, as the servo would be sent it (a joint within it is home).
        self._home_counts: dict[str, int] = {}
        # Each joint's last position found within its home's count.
        self._found_home: dict[str, float] = {}
        # A latched fault ends every behaviour at once, loop running or not.
        servos.on_fault(self._on_fault)
        # A goal of the game's (a move, torque on, rest) wakes a resting loop at once.
        servos.on_goals(self._on_goal)

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
        self._servos.off_goals(self._on_goal)
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
        self._home_counts.clear()
        self._found_home.clear()
        self._sent.clear()
        self._poke()

    # --- the loop -----------------------------------------------------------------------

    async def _run(self) -> None:
        period = self.period
        begin = self._clock.now()
        stepped = 0  # the last tick stepped, counted from `begin`
        next_tick = 1  # the tick the loop wakes at
        looking = False  # woken there only to look further ahead (nothing is sent there)
        while True:
            due = begin + next_tick * period
            if due - self._clock.now() < -period:  # far behind: start again, no burst
                begin, stepped, next_tick, looking = self._clock.now(), 0, 0, False
                due, self._light = begin, None
            if await self._alarm.sleep_until(due + TIE_S):
                next_tick, looking, self._light = self._tick_for_news(begin, stepped), False, None
                continue
            if looking:
                next_tick, looking = self._plan_rest(begin, next_tick, self._servos.commanded())
                continue
            now = self._clock.now()
            if self.lateness is not None:
                self.lateness.append(now - due)
            light, self._light = self._light, None  # planned for this tick alone
            sent = await (self._light_step(light) if light is not None else self.step(now))
            stepped = next_tick
            if not sent and self.quiet():
                # Nothing moves: no goal to send until a layer has something to do. The
                # joints layer holds every goal meanwhile; waking costs nothing on the
                # robot and keeps whole games in simulated time as fast as without a body.
                await self._rest_until(self._next_life())
                begin, stepped, next_tick, looking = self._clock.now(), 0, 1, False
            elif self.rests:
                next_tick, looking = self._plan_rest(begin, stepped, self._servos.commanded())
            else:
                next_tick = stepped + 1

    def _tick_for_news(self, begin: float, stepped: int) -> int:
        """The tick that sees what was just asked: the next one, or the one of this very
        moment (stepped again if it has run). In simulated time the game's news often comes
        at a tick's own moment (its timers began at a tick: a gesture's end); which of the
        two then runs first is the event loop's choice, so the news is seen at that tick
        either way, by the resting loop and the ticking one alike."""
        ticks = (self._clock.now() - TIE_S - begin) / self.period
        nearest = round(ticks)
        if abs(ticks - nearest) * self.period < SAME_MOMENT_S and nearest >= stepped:
            return nearest
        return max(stepped + 1, math.floor(ticks) + 1)

    def _plan_rest(self, begin: float, tick: int, held: Mapping[str, float]) -> tuple[int, bool]:
        """The tick to wake at after `tick`, skipping those that would send nothing and change
        nothing, and whether it is only to look further (nothing to send as far as looked).
        Sets `_light` when that tick only changes counts of planned life."""
        self._light = None
        self._light_layers.clear()
        foreseen = self._foreseen_step(begin, tick, held)
        if foreseen is not None:
            return foreseen, False  # life alone, planned whole: no tick looked at
        index = tick
        for _ in range(LOOKAHEAD_TICKS):
            if self._must_step(begin + (index + 1) * self.period + TIE_S, held):
                return index + 1, False
            index += 1
        return index, True

    def _foreseen_step(self, begin: float, tick: int, held: Mapping[str, float]) -> int | None:
        """The next tick that steps, when only blinks and idle movements play (each over
        joints of its own, every other joint home) and both were foreseen whole; else None
        (the loop looks ahead tick by tick)."""
        if self._gesture is not None or self.mouth.claimed or self._moved_by_others(held):
            return None
        if self._gaze is not None and not self._gaze.settled:
            return None
        playing = [p for p in (self._idle, self._blink) if p is not None]
        claimed: set[str] = set()
        for playback in playing:
            if playback.changes is None or claimed & playback.base.keys():
                return None
            claimed |= playback.base.keys()
        for joint in self._home:
            if joint not in claimed and joint in held and not self._is_home(joint, held[joint]):
                return None  # on its way home: tick by tick
        period = self.period
        changes: list[tuple[int, _Playback, int]] = []
        events = []  # ticks that change the body's state: a full step
        for playback in playing:
            assert playback.started is not None and playback.changes is not None
            first = round((playback.started - begin) / period)
            change = playback.next_change(tick - first)
            if change is not None:
                changes.append((first + change, playback, change))
            # Its end (the tick its last offsets are sent and it finishes).
            events.append(first + math.ceil(playback.behaviour.duration / period - 1e-9))
        for due, allowed in ((self._next_blink, self._blinking), (self._next_idle, self._alive)):
            if allowed:
                if due is None:
                    return None  # drawn at the next tick
                events.append(math.ceil((due - TIE_S - begin) / period - 1e-9))
        if not changes and not events:
            return None
        at = max(tick + 1, min([c for c, _, _ in changes] + events))
        if not events or min(events) > at:
            # Only counts change there: the light step sends those joints' planned goals
            # (the packets a whole step would send), by the layer that plays each.
            light: dict[str, float] = {}
            for moment, playback, change in changes:
                if moment == at:
                    for joint, value in playback.change_goals[change].items():
                        if joint in playback.base:  # not one the game has taken since
                            light[joint] = value
                            self._light_layers[joint] = playback.layer
            if light:
                self._light = light
        return at

    def _must_step(self, moment: float, held: Mapping[str, float]) -> bool:
        """Whether the tick at `moment` would send a servo a new count or change the body's
        state; nothing is changed."""
        try:
            pose = self._compose(moment, held, peek=True)
        except _MustStep:
            return True
        if not pose and self.quiet():
            return True  # the loop's own rest begins there
        return self._servos.sends(pose, moment, self.period)

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
        self._alarm.interrupt()

    async def _light_step(self, goals: dict[str, float]) -> dict[str, float]:
        """A step at a tick where only planned life changes counts: those joints' goals,
        without composing every layer again (what a whole step would send there)."""
        return await self._send(goals, dict(self._light_layers))

    async def step(self, now: float) -> dict[str, float]:
        """One tick: blend the layers for `now` and send the goals; the goals sent."""
        pose = self.compose(now)
        if not pose:
            return {}
        return await self._send(pose, dict(self.layers))

    async def _send(self, pose: dict[str, float], sources: dict[str, str]) -> dict[str, float]:
        """Stream `pose` as one step; a refusal (a fault, a pause) stills the body, once told."""
        try:
            sent = await self._servos.stream(pose, self.period, sources)
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
        return self._compose(now, self._servos.commanded(), peek=False)

    def _compose(
        self, now: float, held: Mapping[str, float], *, peek: bool
    ) -> dict[str, float]:
        """compose() at `now` with the joints held at `held`. `peek`: change nothing, and
        raise _MustStep where the tick would change the body's state (one code path for
        the step and the look ahead, so the two cannot disagree)."""
        if peek:
            if self._moved_by_others(held):
                raise _MustStep
        else:
            self._learn_home(held)
        home = self._home
        out: dict[str, float] = {}
        layers: dict[str, str] = {}
        self._gaze_layer(now, held, out, layers, peek)
        if self._blinking:
            self._schedule_life(now, peek)
            if self._idle is not None:
                idle = self._played(self._idle, now, home, out, layers, peek, additive=True)
                if not peek:
                    self._idle = idle
            if self._blink is not None:
                blink = self._played(self._blink, now, home, out, layers, peek, additive=False)
                if not peek:
                    self._blink = blink
        if self._mouth_joint is not None and self._mouth_joint in held:
            if peek and self.mouth.ends_by(now):
                raise _MustStep
            opening = self.mouth.level_at(now) if peek else self.mouth.opening(now)
            if opening is not None:
                span = self._settings.mouth_open_deg
                out[self._mouth_joint] = self._mouth_closed + opening * span
                layers[self._mouth_joint] = MOUTH_LAYER
        if self._gesture is not None:
            gesture = self._played(self._gesture, now, home, out, layers, peek,
                                   additive=False)
            if not peek:
                self._gesture = gesture
        found = self._found_home
        for joint, rest in home.items():
            # A joint a behaviour left away from home (cut short) goes back to it gently,
            # and the last counts of the way at once (a pull shorter than a count is never
            # sent, so it would never arrive).
            now_at = held.get(joint)
            if now_at is None or now_at == rest or found.get(joint) == now_at or joint in out:
                continue
            if self._is_home(joint, now_at):
                continue
            pulled = now_at + (rest - now_at) * HOME_PULL
            if self._servos.count_of(joint, pulled) == self._servos.count_of(joint, now_at):
                pulled = rest
            out[joint] = pulled
            layers[joint] = HOME_LAYER
        if not peek:
            self.layers = layers
        return {
            joint: self._within(joint, value) for joint, value in out.items() if joint in held
        }

    def _counter(self, joint: str) -> Callable[[float], int]:
        """`joint`'s degrees (in its range) to the count its servo is sent: the servo model's
        own arithmetic for a joint of its own, the joints layer's for a coupled one."""
        settings = self._joint_settings.get(joint)
        if settings is None or joint in self._coupled:
            return lambda degrees: self._servos.count_of(joint, degrees)
        model, direction, offset = settings.servo, settings.direction, settings.offset_deg
        return lambda degrees: model.to_raw(degrees, direction, offset)

    def _reach(self, joint: str) -> float:
        """How far `joint` may go in one tick at its speed limit."""
        return self._servos.speed_limit(joint) * self.period

    def _within(self, joint: str, degrees: float) -> float:
        low, high = self._ranges.get(joint, (degrees, degrees))
        return min(max(degrees, low), high)

    def _is_home(self, joint: str, degrees: float) -> bool:
        """Whether `degrees` is `joint`'s home: the same count as the servo would be sent."""
        if degrees == self._home[joint] or self._found_home.get(joint) == degrees:
            return True
        count = self._home_counts.get(joint)
        if count is None:
            count = self._home_counts[joint] = self._servos.count_of(joint, self._home[joint])
        if self._servos.count_of(joint, degrees) != count:
            return False
        self._found_home[joint] = degrees  # asked again every tick while it stays there
        return True

    def _set_home(self, joint: str, degrees: float) -> None:
        self._home[joint] = degrees
        self._home_counts.pop(joint, None)
        self._found_home.pop(joint, None)

    def _moved_by_others(self, held: Mapping[str, float]) -> bool:
        """Whether a joint is not where the body last sent it (what _learn_home acts on)."""
        sent = self._sent
        for joint, value in held.items():
            last = sent.get(joint)
            if last is None or abs(value - last) > HOME_EPSILON_DEG:
                return True
        return False

    def _learn_home(self, held: Mapping[str, float]) -> None:
        """A joint not where the body last sent it was moved by someone else: its new home."""
        for joint, value in held.items():
            sent = self._sent.get(joint)
            if sent is None or abs(value - sent) > HOME_EPSILON_DEG:
                self._set_home(joint, value)
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
            not self._is_home(joint, held[joint]) for joint in self._home if joint in held
        )

    def _schedule_life(self, now: float, peek: bool) -> None:
        settings = self._settings
        undrawn = self._next_blink is None or (self._next_idle is None and self._alive)
        if undrawn and peek:
            raise _MustStep
        if self._next_blink is None:
            self._next_blink = now + self._rng.uniform(*settings.blink_interval_s)
        if self._next_idle is None and self._alive:
            self._next_idle = now + self._rng.uniform(*settings.idle_interval_s)
        blink_due = now >= self._next_blink
        idle_due = self._next_idle is not None and now >= self._next_idle
        if peek:
            if blink_due or idle_due:
                raise _MustStep
            return
        if blink_due:
            self._next_blink = None
            if self._blink is None and BLINK in self._library:
                self._blink = _Playback(self._library[BLINK], 1.0, BLINK_LAYER)
        if idle_due:
            self._next_idle = None
            if self._idle is None and IDLE in self._library and settings.idle_amplitude > 0:
                self._idle = _Playback(self._library[IDLE], settings.idle_amplitude, IDLE_LAYER)

    def _gaze_layer(
        self,
        now: float,
        held: Mapping[str, float],
        out: dict[str, float],
        layers: dict[str, str],
        peek: bool,
    ) -> None:
        move = self._gaze
        if move is None:
            return
        if move.began is None:
            if peek:
                raise _MustStep
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
        if now - move.began >= GAZE_MOVE_S:
            if peek:
                raise _MustStep
            move.settled = True
            for joint, target in move.target.items():
                if joint in move.start:
                    self._set_home(joint, target)

    def _played(
        self,
        playback: _Playback,
        now: float,
        held: Mapping[str, float],
        out: dict[str, float],
        layers: dict[str, str],
        peek: bool,
        *,
        additive: bool,
    ) -> _Playback | None:
        """Write `playback`'s goals at `now` into `out`; None once it has ended there.

        Its offsets are from where each joint was at its first tick (`held`). `additive`
        (idle): added to what the layers below want; else (blink, gesture) overriding
        them, from what they wanted at that first tick."""
        if playback.started is None:
            if peek:
                raise _MustStep
            joints = [j for j in playback.behaviour.joints if j in held]
            base = {j: held[j] for j in joints} if additive else {
                j: out.get(j, held[j]) for j in joints}
            playback.begin(now, base, self.period)
            # Life is foreseen whole when its goals are its own: a blink overrides what is
            # below it; an idle movement adds to it, so only over joints nothing else moves.
            if playback.layer == BLINK_LAYER or (
                playback.layer == IDLE_LAYER and not out.keys() & base.keys()
            ):
                playback.foresee(self._counter, self._within, self._reach)
        assert playback.started is not None
        ends = now - playback.started >= playback.behaviour.duration
        if ends and peek:
            raise _MustStep
        base = playback.base
        for joint, offset in playback.offsets(now).items():
            if joint in base:
                out[joint] = (out.get(joint, base[joint]) if additive else base[joint]) + offset
                layers[joint] = playback.layer
        if ends:
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

    def _on_goal(self, goal: Goal) -> None:
        # The body's own goals are named by its layers; any other is the game's.
        if goal.source.split(":", 1)[0] not in OWN_LAYERS:
            self._poke()

    def _note_once(self, behaviour: str, joint: str, message: str) -> None:
        if (behaviour, joint) not in self._noted:
            self._noted.add((behaviour, joint))
            log.info(message, behaviour=behaviour, joint=joint or None)
