"""Named joints over the bus drivers: limits, offsets, groups, safe moves, latched faults.

Safety rules, enforced here whatever a pose file or a caller says:
- every goal is clamped to the joint's safe range, and each clamp is logged;
- no goal step exceeds the joint's speed limit (the profile is planned so that
  its steepest step is within the limit, and late steps do not catch up);
- torque goes on only after the goal has been set to the present position,
  and not at all for a joint found outside its range (it stays limp);
- a servo that overheats, is overloaded, has a bad supply or stops answering
  latches a fault naming the joint; the faulty servo is freed and the
  configured safe action (hold or torque_off) is applied to the rest;
- while a fault is latched every motion is refused until clear_faults();
- the same error repeating is logged once, then once with its count when it ends.

One arbiter of motion (hal.servos.claims): a move claims only the joints it moves, for
as long as it runs; stream steps go on for every other joint (the mouth while the arm
points) and are dropped for the claimed ones; set_compliant and rest claim the joints
they touch. Every goal, by any path, is told to the goal listeners (on_goals).

Virtual joints and couplings (ServoSettings.realise): a pose may name a virtual joint
(eyes_yaw) for the real joints it drives, and a joint that follows another (a lid
following its eyeball's pitch) moves with its leader. A move or stream claims, clamps
and speed-limits the real joints, followers included; commanded() and a stream's
return give a follower's own value (its goal without its leader's share), the value a
caller asks for.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import math
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import TypeVar

import structlog

from hal.clock import Clock
from hal.errors import (
    BusError,
    PortUnavailable,
    RepeatFilter,
    ServoFaultError,
    ServoSilent,
    SettingsError,
    UnknownJoint,
    UnsafeCommand,
)
from hal.servos.api import (
    MOVE,
    STREAM,
    BatteryReading,
    Fault,
    FaultKind,
    Goal,
    Health,
    JointStatus,
    Pose,
    ServoDriver,
)
from hal.servos.claims import JointClaims
from hal.servos.settings import CouplingSettings, JointSettings, ServoModel, ServoSettings

log = structlog.get_logger("hal.servos.joints")

T = TypeVar("T")

# A joint pushed this far outside its range by hand is not grabbed back by torque-on.
RANGE_TOLERANCE_DEG = 2.0
# The motion profile's steepest slope relative to a constant-speed move (smoothstep).
PROFILE_PEAK = 1.5
# A servo this close to max_temperature_c is logged (once) before the fault latches.
TEMPERATURE_WARNING_MARGIN_C = 5.0
NEAR_TEMPERATURE_LIMIT = "NEAR_TEMPERATURE_LIMIT"
# The sources of the goals the joints layer writes on its own account.
TORQUE_ON = "torque_on"  # the hold written just before torque goes on
INTO_RANGE = "into_range"  # a joint found a little outside its range, brought in
REST = "rest"
# Readings outside these are no servo's: `servos read` and `check` name them.
PLAUSIBLE_TEMPERATURE_C = (-20.0, 120.0)
PLAUSIBLE_VOLTAGE_V = (4.0, 20.0)


def impossible_reading(joint: JointSettings, raw: int) -> str:
    """Why a reading cannot be trusted, naming what the joint's servo can report."""
    model = joint.servo
    return (
        f"position reading {raw} is impossible for a {joint.model} "
        f"(it reports {model.sensor_min} to {model.sensor_max})"
    )


def smoothstep(t: float) -> float:
    """Eases in and out: gentler on the gears and on the child beside the arm."""
    return t * t * (3.0 - 2.0 * t)


@dataclass
class _Joint:
    settings: JointSettings
    driver: ServoDriver
    commanded: float | None = None  # the last goal sent, in degrees
    present: float | None = None
    torque: bool | None = None  # None until we have set it
    last_sent: float | None = None  # the last goal before torque went off (hobby servos)
    sent_at: float | None = None  # Clock.now() of the last goal written (stream's speed limit)

    @property
    def name(self) -> str:
        return self.settings.name

    @property
    def servo_id(self) -> int:
        return self.settings.id

    def clamp(self, degrees: float) -> float:
        low, high = self.settings.range_deg
        return min(high, max(low, degrees))

    @functools.cached_property
    def servo(self) -> ServoModel:
        # Built from the settings on each read there: every tick asks it of every joint.
        return self.settings.servo

    def to_raw(self, degrees: float) -> int:
        s = self.settings
        return self.servo.to_raw(self.clamp(degrees), s.direction, s.offset_deg)

    def to_raw_unclamped(self, degrees: float) -> int:
        """Raw goal without the range clamp: only for a joint being brought into range."""
        s = self.settings
        return self.servo.to_raw(degrees, s.direction, s.offset_deg)

    def to_degrees(self, raw: int) -> float:
        s = self.settings
        return self.servo.to_degrees(raw, s.direction, s.offset_deg)


class Joints:
    """The ServoApi over real (or simulated) bus drivers."""

    def __init__(
        self,
        settings: ServoSettings,
        drivers: Mapping[str, ServoDriver],
        clock: Clock,
    ) -> None:
        """The joints of `settings` over `drivers` (bus name -> driver), timed by `clock`.

        Nothing is opened or read until start(); every method is called from the
        event loop that start() ran on.
        """
        self.settings = settings
        self.clock = clock
        self._drivers = dict(drivers)
        self._joints = {j.name: _Joint(j, self._drivers[j.bus]) for j in settings.joints}
        self._groups = settings.groups
        self._faults: list[Fault] = []
        self._fault_listeners: list[Callable[[Fault], None]] = []
        self._claims = JointClaims()
        self._goal_listeners: list[Callable[[Goal], None]] = []
        self._repeats = RepeatFilter()
        self._poll_task: asyncio.Task[None] | None = None
        self._last_status: dict[str, JointStatus] = {}
        self._retried_seen: dict[str, int] = {}  # bus name -> replies retried, as last logged
        self._bits: dict[tuple[str, str], int] = {}  # (joint, error bit) -> polls seen in a row
        self._battery_v: float | None = None  # the battery joint's last voltage reading
        self.step = 1.0 / settings.control_hz
        # Every joint's speed limit times this (a session's slower robot); never above 1.
        self._speed_scale = 1.0
        # Each coupled joint's own value, as last asked (ServoSettings.realise adds its
        # leader's share): a lid keeps it while its eye moves.
        self._own: dict[str, float] = {}
        # Real joints no coupling joins: a pose of these alone is its own goals.
        coupled = {c.joint for c in settings.couplings} | {c.follows for c in settings.couplings}
        self._plain = frozenset(self._joints) - coupled
        self._leaders: dict[str, list[CouplingSettings]] = {}
        for coupling in settings.couplings:
            self._leaders.setdefault(coupling.joint, []).append(coupling)

    @property
    def speed_scale(self) -> float:
        """What every joint's speed limit is multiplied by now (1: the configured limits)."""
        return self._speed_scale

    def scale_speeds(self, scale: float) -> None:
        """Every joint's speed limit times `scale` (0 < scale <= 1) from the next goal on:
        moves and streams go slower, never faster than the configured limits."""
        if not 0.0 < scale <= 1.0:
            raise UnsafeCommand(f"speed scale: expected more than 0 and at most 1, found {scale}")
        self._speed_scale = scale

    def _limit(self, joint: _Joint) -> float:
        return joint.settings.max_speed_dps * self._speed_scale

    @classmethod
    def from_settings(cls, settings: ServoSettings, clock: Clock) -> Joints:
        """The real joints: a bus driver per configured bus (not started)."""
        from hal.servos.drivers import driver_for

        return cls(settings, {bus.name: driver_for(bus) for bus in settings.buses}, clock)

    # --- what the game sees -------------------------------------------------------------

    @property
    def joints(self) -> tuple[str, ...]:
        """Every configured joint name, in configuration order."""
        return tuple(self._joints)

    @property
    def groups(self) -> Mapping[str, tuple[str, ...]]:
        """Group name -> its joints."""
        return self._groups

    @property
    def faults(self) -> tuple[Fault, ...]:
        """The latched faults, oldest first; empty when all is well."""
        return tuple(self._faults)

    def on_fault(self, listener: Callable[[Fault], None]) -> None:
        """Call `listener` with every newly latched fault (the robot says so aloud)."""
        self._fault_listeners.append(listener)

    def off_fault(self, listener: Callable[[Fault], None]) -> None:
        """Stop calling a listener given to on_fault; an unknown one is ignored."""
        with contextlib.suppress(ValueError):
            self._fault_listeners.remove(listener)

    def on_goals(self, listener: Callable[[Goal], None]) -> None:
        """Call `listener` with every goal written, by any path, once its packet is sent
        (`kasparctl demo --motion` writes them down)."""
        self._goal_listeners.append(listener)

    def off_goals(self, listener: Callable[[Goal], None]) -> None:
        """Stop calling a listener given to on_goals; an unknown one is ignored."""
        with contextlib.suppress(ValueError):
            self._goal_listeners.remove(listener)

    def battery(self) -> BatteryReading | None:
        """The battery as the health poll last read it; None when no battery is watched."""
        battery = self.settings.battery
        if battery is None:
            return None
        return BatteryReading(battery.joint, self._battery_v, battery.warn_below_v)

    def claimed(self) -> frozenset[str]:
        """The joints a move, set_compliant or rest holds now (stream steps leave them be)."""
        return self._claims.held()

    async def start(self, poll: bool = True, read: bool = True) -> None:
        """Open the buses; with `read`, learn where every joint is; with `poll`, watch health.

        Nothing is written: torque stays as found, so a restart neither slumps nor
        jerks the robot. A servo that does not answer here is latched as a fault
        without the safe action, for the same reason.
        """
        for driver in self._drivers.values():
            await driver.start()
        if read:
            for driver, members in self._by_driver(self._joints.values()).items():
                by_id = {j.servo_id: j for j in members}
                try:
                    raw = await driver.read_positions(list(by_id))
                except ServoSilent as error:
                    joint = by_id.get(error.servo_id, members[0])
                    await self._latch(joint.name, FaultKind.SILENT, str(error), act=False)
                    continue
                except PortUnavailable as error:
                    await self._bus_lost(members, error, act=False)
                    continue
                impossible = self._take_readings(by_id, raw)
                for joint, detail in impossible:
                    await self._latch(joint.name, FaultKind.IMPOSSIBLE, detail, act=False)
                for joint in members:
                    if joint.present is not None:
                        joint.commanded = joint.clamp(joint.present)
            self._warn_outside(list(self._joints.values()))
        if poll:
            self._poll_task = asyncio.create_task(self._poll_forever(), name="servo health poll")

    async def close(self) -> None:
        """Stop the health poll and close the buses; torque is left as it is (no slump)."""
        if self._poll_task is not None:
            self._poll_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._poll_task
            self._poll_task = None
        for driver in self._drivers.values():
            await driver.close()

    async def read_positions(self, group: str | None = None) -> dict[str, float]:
        """Present positions in degrees of a group's (or one joint's) joints; all if None.

        Raises UnknownJoint for an unknown name, and ServoFaultError when a servo
        is silent or the bus is lost (the fault is latched).
        """
        selected = [self._joints[name] for name in self._select(group)]
        await self._read_present(selected)
        return {j.name: j.present for j in selected if j.present is not None}

    async def move(
        self,
        pose: Pose,
        duration: float | None = None,
        speed: float | None = None,
        *,
        source: str = MOVE,
    ) -> None:
        """Move the joints in `pose` together, within their ranges and speed limits.

        See ServoApi.move: the joints of `pose` are claimed (after any earlier move,
        set_compliant or rest holding one of them), clamped targets are logged, and the
        profile takes at least `duration` seconds; its goals are told as `source`.
        Raises UnknownJoint, UnsafeCommand or ServoFaultError.
        """
        pose = self._realise(pose)
        if duration is not None and not (duration >= 0 and math.isfinite(duration)):
            raise UnsafeCommand(f"duration must be a finite number >= 0, found {duration}")
        if speed is not None and not (speed > 0 and math.isfinite(speed)):
            raise UnsafeCommand(f"speed must be a finite number > 0, found {speed}")
        async with self._claims.claim(pose, source):
            self._refuse_if_faulted()
            joints = [self._joints[name] for name in pose]
            # Torque goes on only through set_compliant(group, False), which sets the goal to
            # the present position first and refuses a joint found outside its range.
            limp = [j.name for j in joints if j.torque is not True]
            if limp:
                raise UnsafeCommand(
                    f"torque is off or not yet turned on by set_compliant for: {', '.join(limp)}"
                )
            targets = {j.name: self._clamped(j, pose[j.name]) for j in joints}
            await self._run_profile(joints, targets, duration, speed, source)

    def commanded(self) -> dict[str, float]:
        """The last goal of every joint whose torque is on (where it is being held), in degrees
        (a follower's own value, without its leader's share)."""
        return self._own_values({
            name: j.commanded for name, j in self._joints.items()
            if j.torque is True and j.commanded is not None
        })

    async def stream(
        self, pose: Pose, period: float, sources: Mapping[str, str] | None = None
    ) -> dict[str, float]:
        """One control step toward `pose`, for a loop that sends a goal every `period` seconds.

        Each joint's goal is clamped to its range (logged), and moves from its last
        goal by at most its speed limit times the time since that goal was written
        (at most `period`, or one count's time at the limit if longer: a late step
        does not catch up; after a move, from the move's last goal). A goal the servo
        would not notice (the same raw count as
        the last one) is not sent, and the last goal stays: packets only for change.
        One packet per bus, no waiting beyond it. Joints whose
        torque is off (teaching) are left alone, and so are the joints a move,
        set_compliant or rest holds (their goals are dropped: the claim owns them);
        the others go out at once. `sources` names each joint's layer in the goals
        told to the listeners (STREAM when unnamed). Returns the goals sent.
        Raises UnknownJoint, UnsafeCommand (NaN target, bad period) and
        ServoFaultError while a fault is latched (or one is latched by this write).
        """
        pose = self._realise(pose)
        if not (period > 0 and math.isfinite(period)):
            raise UnsafeCommand(f"period must be a finite number > 0, found {period}")
        self._refuse_if_faulted()
        now = self.clock.now()
        sent: dict[str, float] = {}
        for driver, members in self._by_driver(pose).items():
            # Asked again for each bus: a claim, a torque change or a fault may have come
            # while the last packet was on its way. A claimed joint's goals come from its
            # claim alone, so two writers never interleave on one joint.
            self._refuse_if_faulted()
            claimed = self._claims.held()
            goals = {}
            for joint in members:
                start = joint.commanded
                if start is None or not self._takes_stream(joint, claimed):
                    continue
                goal = self._stream_goal(joint, start, self._clamped(joint, pose[joint.name]),
                                         now, period)
                if goal is None:
                    continue
                joint.commanded = goal
                joint.sent_at = now
                goals[joint.servo_id] = (joint.to_raw(goal), self._limit(joint))
                sent[joint.name] = goal
            if goals:
                await self._guarded(members[0], driver.write_goals(goals, period))
                self._tell(
                    now,
                    {j.name: sent[j.name] for j in members if j.servo_id in goals},
                    sources,
                    STREAM,
                )
        return self._own_values(sent)

    @staticmethod
    def _takes_stream(joint: _Joint, claimed: frozenset[str]) -> bool:
        """Whether a stream step may move `joint`: torque on, and no move, set_compliant or
        rest holding it (a claimed joint's goals come from its claim alone)."""
        return joint.torque is True and joint.name not in claimed

    def _stream_goal(
        self, joint: _Joint, start: float, target: float, now: float, period: float
    ) -> float | None:
        """The goal a stream step at `now` sends `joint` (last goal `start`) toward `target`;
        None when it would not change the servo's count: nothing is sent and nothing changes.

        The step is at most the joint's speed limit times the time since its last goal,
        counting no more than a period (a late loop does not catch up) or, if longer, the
        time one count takes at the limit (so a joint slower than a count a period still
        moves, a count at a time, at its limit).
        """
        limit = self._limit(joint)
        if joint.sent_at is None:  # never written: what the servo holds is not known
            return max(start - limit * period, min(start + limit * period, target))
        count_s = joint.servo.degrees_per_unit / limit
        reach = limit * min(max(0.0, now - joint.sent_at), max(period, count_s))
        goal = max(start - reach, min(start + reach, target))
        if joint.to_raw(goal) == joint.to_raw(start):
            return None  # the servo would do nothing with it: no packet, the goal unchanged
        return goal

    def sends(self, pose: Pose, at: float, period: float) -> bool:
        """Whether stream(pose, period) at `at` would send any servo a new count (True while
        a fault is latched: stream would raise). Nothing is sent or changed: a loop asks it
        to rest through the steps that would change nothing a servo does."""
        if self._faults:
            return True
        try:
            pose = self._realise(pose, dict(self._own))
        except (UnknownJoint, UnsafeCommand):
            return True
        claimed = self._claims.held()
        for name, degrees in pose.items():
            joint = self._joints[name]
            start = joint.commanded
            if start is None or not self._takes_stream(joint, claimed):
                continue
            if not math.isfinite(degrees):
                return True
            if self._stream_goal(joint, start, joint.clamp(degrees), at, period) is not None:
                return True
        return False

    def count_of(self, joint: str, degrees: float) -> int:
        """The raw count `joint`'s servo would be sent for `degrees` as its own value (a
        follower's leader's share added, as the leader stands), clamped to its range."""
        for coupling in self._leaders.get(joint, ()):
            leader = self._joints[coupling.follows]
            lead = leader.commanded if leader.commanded is not None else leader.settings.rest_deg
            degrees += coupling.ratio * (lead - leader.settings.rest_deg)
        return self._joints[joint].to_raw(degrees)

    def speed_limit(self, joint: str) -> float:
        """`joint`'s speed limit now, degrees per second (the session's scale applied)."""
        return self._limit(self._joints[joint])

    def _realise(self, pose: Pose, own: dict[str, float] | None = None) -> dict[str, float]:
        """`pose` as the real joints' goals (virtual joints expanded, followers moved); each
        follower's own value is kept in `own` (the joints' own record when None)."""
        if own is None:
            own = self._own
        if self._plain.issuperset(pose):
            return dict(pose)
        virtual = self.settings.virtual
        unknown = [name for name in pose if name not in self._joints and name not in virtual]
        if unknown:
            raise UnknownJoint(f"unknown joints: {', '.join(unknown)}")
        if not virtual and not self.settings.couplings:
            return dict(pose)
        for name, degrees in pose.items():
            if not math.isfinite(degrees):
                raise UnsafeCommand(f"{name}: target {degrees} is not a number")
        try:
            expanded = self.settings.expand(pose)
        except SettingsError as error:
            raise UnsafeCommand(str(error)) from None
        for coupling in self.settings.couplings:
            if coupling.joint in expanded:
                # Its own value, as asked (within its range): what it keeps when only its
                # leader moves, and what commanded() gives.
                own[coupling.joint] = self._joints[coupling.joint].clamp(
                    expanded[coupling.joint])
        where = self._own_values(
            {n: j.commanded for n, j in self._joints.items() if j.commanded is not None}, own
        )
        for coupling in self.settings.couplings:
            if coupling.follows in expanded and coupling.joint in where:
                # From here on its own value is kept, not re-read through a clamped goal.
                own.setdefault(coupling.joint, where[coupling.joint])
        return self.settings.realise(pose, where)

    def _own_values(
        self, goals: dict[str, float], own: Mapping[str, float] | None = None
    ) -> dict[str, float]:
        """`goals` with each follower's own value (its goal without its leader's share), as
        `own` records them (the joints' own record when None)."""
        owned = self._own if own is None else own
        for coupling in self.settings.couplings:
            if coupling.joint not in goals:
                continue
            own_value = owned.get(coupling.joint)
            if own_value is None:
                # Never asked: what it was found at, less its leader's share.
                leader = self._joints[coupling.follows]
                if leader.commanded is None:
                    continue
                own_value = goals[coupling.joint] - coupling.ratio * (
                    leader.commanded - leader.settings.rest_deg)
            goals[coupling.joint] = own_value
        return goals

    async def set_compliant(self, group: str, compliant: bool) -> None:
        """Torque off for `group` (or one joint), or back on holding where each joint is.

        Raises UnknownJoint for an unknown name; turning on raises ServoFaultError
        while a fault is latched and UnsafeCommand for a joint outside its range.
        """
        joints = [self._joints[name] for name in self._select(group)]
        async with self._claims.claim([j.name for j in joints], "set_compliant"):
            if compliant:
                await self._torque(joints, False)
                return
            self._refuse_if_faulted()
            await self._power_on(joints, strict=True)

    async def rest(self, duration: float | None = None) -> None:
        """Move every powered joint to rest; first power, safely, those never turned on.

        Joints made compliant on purpose (teaching, a safe action) stay limp. A joint
        whose torque state is unknown (just after start) is turned on as by
        set_compliant, or left limp with a warning if it sits outside its range.
        """
        unknown = [j for j in self._joints.values() if j.torque is None]
        if unknown:
            async with self._claims.claim([j.name for j in unknown], REST):
                self._refuse_if_faulted()
                await self._power_on(unknown, strict=False)
        pose = {name: j.settings.rest_deg for name, j in self._joints.items() if j.torque is True}
        await self.move(pose, duration, source=REST)

    async def _power_on(self, joints: list[_Joint], strict: bool) -> None:
        """Goal := present position, then torque on; never for a joint outside its range.

        A joint up to RANGE_TOLERANCE_DEG outside its range is held where it is,
        then brought into range at its own speed limit (never snapped there in
        one step). A joint whose servo cannot report its position (a hobby servo
        without pulses) starts from where it was last commanded, or its rest.
        """
        await self._read_present(joints)
        outside = [j for j in joints if self._outside_by(j) > RANGE_TOLERANCE_DEG]
        if outside:
            # Torque on here would snap the joint back into range: leave it limp and say so.
            described = self._describe_outside(outside)
            if strict:
                raise UnsafeCommand(f"outside the safe range, left compliant: {described}")
            log.warning("joints outside their safe range left compliant", joints=described)
            joints = [j for j in joints if j not in outside]
        for driver, members in self._by_driver(joints).items():
            goals = {}
            for joint in members:
                if joint.present is None:
                    last = joint.commanded if joint.commanded is not None else joint.last_sent
                    joint.present = last if last is not None else joint.settings.rest_deg
                    log.info(
                        "no position feedback: joint starts from its last or rest position",
                        joint=joint.name, degrees=round(joint.present, 2),
                    )
                joint.commanded = joint.present  # hold where it is, even a little outside
                s = joint.settings
                raw = s.servo.to_raw(joint.commanded, s.direction, s.offset_deg)
                goals[joint.servo_id] = (raw, s.max_speed_dps)
            await self._guarded(members[0], driver.write_goals(goals, self.step))
            self._tell(self.clock.now(), {j.name: j.present for j in members
                                          if j.present is not None}, None, TORQUE_ON)
        await self._torque(joints, True)
        held_at = self.clock.now()
        for joint in joints:
            joint.commanded = joint.present
            joint.sent_at = held_at  # the hold is a goal: a stream step counts from it
        edging = [j for j in joints if self._outside_by(j) > 0]
        if edging:
            # Into range at each joint's own speed limit, not in one control step.
            log.info("joints brought into their safe range", joints=self._describe_outside(edging))
            targets = {j.name: j.clamp(j.present) for j in edging}  # type: ignore[arg-type]
            await self._run_profile(edging, targets, None, None, INTO_RANGE)

    @staticmethod
    def _outside_by(joint: _Joint) -> float:
        """Degrees the joint's present position lies outside its range (0 inside or unknown)."""
        if joint.present is None:
            return 0.0
        return abs(joint.clamp(joint.present) - joint.present)

    @staticmethod
    def _describe_outside(joints: Iterable[_Joint]) -> str:
        return "; ".join(
            f"{j.name} at {j.present:.1f} deg (range {j.settings.range_deg[0]} to "
            f"{j.settings.range_deg[1]})"
            for j in joints
        )

    def _warn_outside(self, joints: list[_Joint]) -> None:
        """One warning naming every joint found outside its range, whatever its group."""
        outside = [j for j in joints if self._outside_by(j) > 0]
        if outside:
            log.warning(
                "joints found outside their safe range",
                joints=self._describe_outside(outside),
                count=len(outside),
                groups=sorted({j.settings.group for j in outside}),
            )

    async def clear_faults(self) -> None:
        """Reset the faulty servos' error state and forget every latched fault.

        A reset that fails is logged, not raised: the next poll latches the fault
        again if it persists.
        """
        faulty = [self._joints[f.joint] for f in self._faults if f.joint in self._joints]
        for driver, members in self._by_driver(faulty).items():
            try:
                await driver.reset_errors([j.servo_id for j in members])
            except BusError as error:
                # Still clear: the next poll latches the fault again if it persists.
                log.warning("servo errors could not be reset", error=str(error))
        if self._faults:
            log.info("servo faults cleared", faults=[str(f) for f in self._faults])
        self._faults.clear()

    # --- inspection (check, `servos read`) -----------------------------------------------

    def unavailable_buses(self) -> dict[str, str]:
        """Each bus whose adapter is not open now, and why, naming the adapter (the joints
        behind it cannot answer: one message for them all). Simulated buses are always open."""
        from hal.servos.drivers import BusDriver

        return {
            name: driver.bus.unavailable()
            for name, driver in self._drivers.items()
            if isinstance(driver, BusDriver) and not driver.bus.connected
        }

    async def ping_all(self) -> dict[str, int | None]:
        """Every joint's servo model number (0 where the protocol has none), None if silent."""
        found: dict[str, int | None] = {}
        for joint in self._joints.values():
            try:
                found[joint.name] = await joint.driver.ping(joint.servo_id)
            except BusError:
                found[joint.name] = None
        return found

    async def survey(self) -> list[JointStatus]:
        """Every joint's position and health, without latching anything.

        Each status names what is impossible or unsafe in its readings (`problems`)
        and the error bits its servo reported (`flags`).
        """
        statuses = []
        for joint in self._joints.values():
            fault = next((f for f in self._faults if f.joint == joint.name), None)
            try:
                raw = (await joint.driver.read_positions([joint.servo_id]))[joint.servo_id]
                health = await joint.driver.read_health(joint.servo_id)
            except BusError as error:
                lost = isinstance(error, PortUnavailable)
                kind = FaultKind.BUS_LOST if lost else FaultKind.SILENT
                fault = fault or Fault(joint.name, kind, str(error), self.clock.now())
                statuses.append(JointStatus(joint.name, None, bool(joint.torque), fault=fault))
                continue
            if health.kind is not None and fault is None:
                detail = health.detail or ", ".join(health.flags)
                fault = Fault(joint.name, health.kind, detail, self.clock.now())
            position, problems = self._judge(joint, raw, health)
            statuses.append(
                JointStatus(
                    joint.name,
                    position,
                    bool(joint.torque),
                    health.temperature_c,
                    health.voltage_v,
                    health.load,
                    fault,
                    raw_position=raw,
                    flags=health.flags,
                    problems=tuple(problems),
                    stored_limits=health.stored_limits,
                    active_limits=health.active_limits,
                )
            )
        return statuses

    def _judge(self, joint: _Joint, raw: int, health: Health) -> tuple[float | None, list[str]]:
        """The joint's position in degrees (None if unknown) and what is wrong with its readings."""
        model = joint.settings.servo
        problems = []
        position = None
        if not model.readable(raw):
            problems.append(impossible_reading(joint.settings, raw))
        elif raw != model.off_reading:
            position = joint.to_degrees(raw)
            low, high = joint.settings.range_deg
            if not low <= position <= high:
                problems.append(f"outside its safe range: {position:.1f} deg ({low} to {high})")
        temperature, voltage = health.temperature_c, health.voltage_v
        if temperature is not None:
            if not PLAUSIBLE_TEMPERATURE_C[0] <= temperature <= PLAUSIBLE_TEMPERATURE_C[1]:
                problems.append(f"temperature {temperature:.0f} C is impossible")
            elif temperature >= self.settings.max_temperature_c:
                problems.append(
                    f"too hot: {temperature:.0f} C >= max_temperature_c "
                    f"{self.settings.max_temperature_c:.0f} C"
                )
        if voltage is not None and not PLAUSIBLE_VOLTAGE_V[0] <= voltage <= PLAUSIBLE_VOLTAGE_V[1]:
            problems.append(f"voltage {voltage:.1f} V is impossible")
        return position, problems

    # --- health polling -----------------------------------------------------------------

    async def _poll_forever(self) -> None:
        while True:
            try:
                await self.poll_health()
            except Exception:  # the poll must outlive any one failure; it is logged
                log.exception("servo health poll failed")
            await self.clock.sleep(self.settings.poll_interval_s)

    async def poll_health(self) -> None:
        """One round of temperature, load, voltage and error bits for every joint."""
        lost_drivers: set[int] = set()
        for joint in self._joints.values():
            if id(joint.driver) in lost_drivers:
                continue
            try:
                health = await joint.driver.read_health(joint.servo_id)
            except ServoSilent as error:
                if self.settings.battery is not None and joint.name == self.settings.battery.joint:
                    self._battery_v = None  # a silent servo reads no battery
                self._repeat(joint.name, "silent", str(error))
                await self._latch(joint.name, FaultKind.SILENT, str(error))
                continue
            except PortUnavailable as error:
                lost_drivers.add(id(joint.driver))
                await self._bus_lost(self._on_driver(joint.driver), error)
                continue
            self._recovered(joint.name)
            if self.settings.battery is not None and joint.name == self.settings.battery.joint:
                self._battery_v = health.voltage_v
            self._note_bits(joint.name, health)
            position = health.position
            if position is not None and not joint.settings.servo.readable(position):
                detail = impossible_reading(joint.settings, position)
                self._repeat(joint.name, FaultKind.IMPOSSIBLE.value, detail)
                await self._latch(joint.name, FaultKind.IMPOSSIBLE, detail)
            kind, detail = health.kind, health.detail or ", ".join(health.flags)
            limit = self.settings.max_temperature_c
            hot = health.temperature_c
            if kind is None and hot is not None and hot >= limit:
                kind, detail = FaultKind.OVERHEATING, f"{hot:.0f} C >= {limit:.0f} C"
            if kind is not None:
                self._repeat(joint.name, kind.value, detail)
                await self._latch(joint.name, kind, detail or kind.value)
        self._log_retries()

    def _note_bits(self, joint: str, health: Health) -> None:
        """Log each error bit (and a servo nearing its temperature limit) once, then its count.

        The servo's LED blinks for a latched bit; without this the controller would
        ignore it silently. Bits the driver cleared at once say so.
        """
        seen = set(health.flags)
        limit = self.settings.max_temperature_c
        hot = health.temperature_c
        if hot is not None and limit - TEMPERATURE_WARNING_MARGIN_C <= hot < limit:
            seen.add(NEAR_TEMPERATURE_LIMIT)
        for bit in sorted(seen):
            key = (joint, bit)
            count = self._bits.get(key, 0)
            self._bits[key] = count + 1
            if count:
                continue
            if bit == NEAR_TEMPERATURE_LIMIT:
                log.warning("servo temperature near its limit", joint=joint,
                            temperature_c=round(hot or 0.0, 1), max_temperature_c=limit)
            else:
                log.warning("servo error bit", joint=joint, bit=bit,
                            cleared=bit in health.cleared)
        for key in [k for k in self._bits if k[0] == joint and k[1] not in seen]:
            log.info("servo error bit no longer seen", joint=joint, bit=key[1],
                     times=self._bits.pop(key))

    def _log_retries(self) -> None:
        """Replies the bus had to retry since the last poll: one line per poll at most.

        A retried reply never reaches the game, so without this a failing cable or a
        noisy bus would leave no trace until it stopped a session.
        """
        for name, driver in self._drivers.items():
            total = driver.retried()
            seen = self._retried_seen.get(name, 0)
            if total > seen:
                log.warning("bus replies retried", bus=name, count=total - seen, total=total)
            self._retried_seen[name] = total

    # --- internals ----------------------------------------------------------------------

    def _select(self, group: str | None) -> list[str]:
        if group is None:
            return list(self._joints)
        if group in self._groups:
            return list(self._groups[group])
        if group in self._joints:
            return [group]
        raise UnknownJoint(f"unknown group or joint {group!r}")

    def _by_driver(self, joints: Iterable[_Joint | str]) -> dict[ServoDriver, list[_Joint]]:
        grouped: dict[ServoDriver, list[_Joint]] = {}
        for item in joints:
            joint = self._joints[item] if isinstance(item, str) else item
            grouped.setdefault(joint.driver, []).append(joint)
        return grouped

    def _refuse_if_faulted(self) -> None:
        if self._faults:
            raise ServoFaultError(
                "motion refused while faults are latched: " + "; ".join(map(str, self._faults))
            )

    def _clamped(self, joint: _Joint, degrees: float) -> float:
        if not math.isfinite(degrees):
            raise UnsafeCommand(f"{joint.name}: target {degrees} is not a number")
        clamped = joint.clamp(degrees)
        if clamped != degrees:
            log.warning(
                "joint target clamped to its safe range",
                joint=joint.name,
                asked_deg=degrees,
                clamped_deg=clamped,
                range_deg=list(joint.settings.range_deg),
            )
        return clamped

    async def _run_profile(
        self,
        joints: list[_Joint],
        targets: dict[str, float],
        duration: float | None,
        speed: float | None,
        source: str,
    ) -> None:
        starts = {}
        for joint in joints:
            if joint.commanded is None:  # never guess a start: a guess can be a jump
                raise UnsafeCommand(f"{joint.name}: no known position to start from")
            starts[joint.name] = joint.commanded
        limits = {j.name: min(self._limit(j), speed or math.inf) for j in joints}
        # Long enough that the profile's steepest step keeps every joint within its limit.
        needed = max(
            (PROFILE_PEAK * abs(targets[n] - starts[n]) / limits[n] for n in targets), default=0.0
        )
        total = max(duration or 0.0, needed)
        steps = max(1, math.ceil(total / self.step - 1e-9))
        begin = self.clock.now()
        by_driver = self._by_driver(joints)
        for k in range(1, steps + 1):
            self._refuse_if_faulted()
            fraction = smoothstep(k / steps)
            for driver, members in by_driver.items():
                goals = {}
                written = self.clock.now()
                for joint in members:
                    start, end = starts[joint.name], targets[joint.name]
                    # Clamped to the range, widened only to include a start found outside it
                    # (a joint being brought into range): never a step beyond either.
                    low, high = joint.settings.range_deg
                    low, high = min(low, start), max(high, start)
                    joint.commanded = max(low, min(high, start + (end - start) * fraction))
                    goals[joint.servo_id] = (joint.to_raw_unclamped(joint.commanded),
                                             limits[joint.name])
                    joint.sent_at = written
                await self._guarded(members[0], driver.write_goals(goals, self.step))
                self._tell(written, {j.name: j.commanded for j in members
                                     if j.commanded is not None}, None, source)
            # Absolute schedule: a late step is not followed by a catch-up burst.
            delay = begin + k * self.step - self.clock.now()
            await self.clock.sleep(max(0.0, delay) if k < steps else 0.0)

    def _tell(
        self,
        time: float,
        goals: Mapping[str, float],
        sources: Mapping[str, str] | None,
        default: str,
    ) -> None:
        """Each goal just written, to every goal listener."""
        if not self._goal_listeners:
            return
        for joint, degrees in goals.items():
            source = sources.get(joint, default) if sources is not None else default
            goal = Goal(time, joint, degrees, source)
            for listener in self._goal_listeners:
                listener(goal)

    async def _guarded(self, joint: _Joint, operation: Awaitable[T]) -> T:
        try:
            return await operation
        except ServoSilent as error:
            await self._latch(joint.name, FaultKind.SILENT, str(error))
            raise ServoFaultError(str(error)) from error
        except PortUnavailable as error:
            await self._bus_lost(self._on_driver(joint.driver), error)
            raise ServoFaultError(str(error)) from error

    def _on_driver(self, driver: ServoDriver) -> list[_Joint]:
        return [j for j in self._joints.values() if j.driver is driver]

    async def _read_present(self, joints: list[_Joint]) -> None:
        for driver, members in self._by_driver(joints).items():
            by_id = {j.servo_id: j for j in members}
            try:
                raw = await driver.read_positions(list(by_id))
            except ServoSilent as error:
                joint = by_id.get(error.servo_id, members[0])
                await self._latch(joint.name, FaultKind.SILENT, str(error))
                raise ServoFaultError(str(error)) from error
            except PortUnavailable as error:
                await self._bus_lost(self._on_driver(driver), error)
                raise ServoFaultError(str(error)) from error
            impossible = self._take_readings(by_id, raw)
            for joint, detail in impossible:
                await self._latch(joint.name, FaultKind.IMPOSSIBLE, detail)
            if impossible:
                raise ServoFaultError("; ".join(f"{j.name}: {d}" for j, d in impossible))

    def _take_readings(
        self, by_id: Mapping[int, _Joint], raw: Mapping[int, int]
    ) -> list[tuple[_Joint, str]]:
        """Store each reading as the joint's present position; return the impossible ones.

        A reading the servo cannot give is never turned into degrees (it would be a
        plausible-looking nonsense angle); an off reading (no feedback) leaves the
        position unknown.
        """
        impossible = []
        for servo_id, value in raw.items():
            joint = by_id[servo_id]
            model = joint.settings.servo
            if not model.readable(value):
                joint.present = None
                impossible.append((joint, impossible_reading(joint.settings, value)))
            elif value == model.off_reading:
                joint.present = None
            else:
                joint.present = joint.to_degrees(value)
        return impossible

    async def _torque(self, joints: list[_Joint], on: bool) -> None:
        for driver, members in self._by_driver(joints).items():
            await self._guarded(members[0], driver.set_torque([j.servo_id for j in members], on))
            for joint in members:
                joint.torque = on
                if not on:
                    if joint.commanded is not None:
                        joint.last_sent = joint.commanded
                    joint.commanded = None

    async def _bus_lost(self, joints: list[_Joint], error: BaseException, act: bool = True) -> None:
        """Every joint behind an adapter that went away: one fault each, one log line for all
        (it names the adapter, not each servo behind it)."""
        new = [
            j.name for j in joints
            if not any(f.joint == j.name and f.kind is FaultKind.BUS_LOST for f in self._faults)
        ]
        if new:
            log.error("servo bus lost: its joints' faults latched", detail=str(error),
                      joints=new, safe_action=self.settings.safe_action)
        for joint in joints:
            await self._latch(joint.name, FaultKind.BUS_LOST, str(error), act=False, logged=True)
        if act:
            await self._safe_action(None)

    async def _latch(
        self, joint: str, kind: FaultKind, detail: str, act: bool = True, logged: bool = False
    ) -> None:
        if any(f.joint == joint and f.kind is kind for f in self._faults):
            return
        fault = Fault(joint, kind, detail, self.clock.now())
        self._faults.append(fault)
        if not logged:
            log.error("servo fault latched", joint=joint, kind=kind.value, detail=detail,
                      safe_action=self.settings.safe_action)
        for listener in self._fault_listeners:
            listener(fault)
        if act:
            await self._safe_action(self._joints[joint])

    async def _safe_action(self, faulty: _Joint | None) -> None:
        """Free the faulty servo; then hold everything else, or free it all."""
        targets = list(self._joints.values()) if self.settings.safe_action == "torque_off" else []
        if faulty is not None and faulty not in targets:
            targets.append(faulty)
        # "hold" needs no packet: moves stop at their next step (faults are latched) and
        # every servo keeps its last goal.
        for driver, members in self._by_driver(targets).items():
            try:
                await driver.set_torque([j.servo_id for j in members], False)
            except BusError as error:
                self._repeat("safe-action", "failed", str(error))
                continue
            for joint in members:
                joint.torque = False
                if joint.commanded is not None:
                    joint.last_sent = joint.commanded
                joint.commanded = None

    def _repeat(self, key: str, kind: str, detail: str) -> None:
        if self._repeats.first(key, f"{kind}: {detail}"):
            log.warning("servo error", joint=key, kind=kind, detail=detail)

    def _recovered(self, key: str) -> None:
        repeated = self._repeats.end(key)
        if repeated is not None:
            log.info("servo error no longer seen", joint=key, error=repeated[0], times=repeated[1])
