"""Behaviours against the configured robot: every joint exists, nothing clamped, nothing too fast.

Offsets are relative, so a behaviour is checked from each joint's rest position at
full strength (the largest it is ever played): a keyframe that would leave the
joint's safe range would be clamped by the joints layer, and a move between
keyframes whose minimum-jerk peak speed exceeds the joint's limit would be slowed,
so that the behaviour would not look as written. Each is an error naming the
file, the behaviour, the keyframe and the joint.

Virtual joints are checked as the real joints they drive. A joint that follows
another (a lid following its eyeball's pitch) moves by its own offset and its
leader's share together: such joints are checked along the whole behaviour, sampled,
where the two may add up between keyframes.
"""

from __future__ import annotations

from collections.abc import Mapping

from hal.servos.settings import ServoSettings
from kasparctl.body.behaviours import MINIMUM_JERK_PEAK, Behaviour, BehaviourError, in_real_joints

# Coupled joints are sampled this often (s): a blink's fastest stretch lasts 0.17 s.
SAMPLE_S = 0.002


def absent_joints(library: Mapping[str, Behaviour], servos: ServoSettings) -> list[str]:
    """The joints the behaviours move that this robot does not have (sorted)."""
    present = {joint.name for joint in servos.joints} | set(servos.virtual)
    named = {name for behaviour in library.values() for _, pose in behaviour.keyframes
             for name in pose}
    return sorted(named - present)


def problems(
    library: Mapping[str, Behaviour], servos: ServoSettings, *, absent_is_problem: bool = True
) -> list[str]:
    """Every problem of every behaviour on this robot, one line each; empty when all fit.

    A joint the robot lacks is skipped when played: a problem for `behaviour check`,
    which shows what an engineer's file does, not for a smaller robot's `check`
    (absent_is_problem=False; absent_joints names them).
    """
    joints = {joint.name: joint for joint in servos.joints}
    found: list[str] = []
    for named in library.values():
        where = f"{named.source}: behaviour {named.name!r}"
        try:
            behaviour = in_real_joints(named, servos)
        except BehaviourError as error:
            found.append(str(error))
            continue
        missing: set[str] = set()
        for number, (time, pose) in enumerate(named.keyframes, 1):
            for name in pose:
                absent = name not in joints and name not in servos.virtual
                # Once per behaviour, at its first keyframe.
                if absent and absent_is_problem and name not in missing:
                    missing.add(name)
                    at = f"{where}, keyframe {number} (at {time:g} s), joint {name}"
                    found.append(f"{at}: not a joint of this robot (skipped when played)")
        for number, (time, pose) in enumerate(behaviour.keyframes, 1):
            for name, offset in pose.items():
                joint = joints.get(name)
                if joint is None:
                    continue
                at = f"{where}, keyframe {number} (at {time:g} s), joint {name}"
                low, high = joint.range_deg
                value = joint.rest_deg + offset
                if not low <= value <= high:
                    found.append(
                        f"{at}: would be clamped: rest {joint.rest_deg:g} + offset {offset:g} "
                        f"= {value:g} deg, outside its safe range [{low:g}, {high:g}]"
                    )
        for number, name, t0, v0, t1, v1 in behaviour.segments():
            joint = joints.get(name)
            if joint is None:
                continue
            peak = MINIMUM_JERK_PEAK * abs(v1 - v0) / (t1 - t0)
            if peak > joint.max_speed_dps + 1e-9:
                found.append(
                    f"{where}, keyframe {number} (at {t1:g} s), joint {name}: too fast: "
                    f"{abs(v1 - v0):g} deg in {t1 - t0:g} s peaks at {peak:.0f} deg/s, "
                    f"above its limit of {joint.max_speed_dps:g} deg/s"
                )
        found.extend(_coupled(behaviour, servos, where))
    return found


def _coupled(behaviour: Behaviour, servos: ServoSettings, where: str) -> list[str]:
    """The followers' problems: range and speed of own offset plus the leader's share."""
    joints = {joint.name: joint for joint in servos.joints}
    moved = set(behaviour.joints)
    followers = [c for c in servos.couplings
                 if c.joint in joints and c.follows in moved and c.follows in joints]
    if not followers:
        return []
    rests = {name: joint.rest_deg for name, joint in joints.items()}
    found: list[str] = []
    steps = max(1, round(behaviour.duration / SAMPLE_S))
    previous: dict[str, float] = {}
    # The worst excess of each follower past its range, and its fastest speed: (amount, at).
    worst: dict[str, tuple[float, float, float]] = {}
    fastest: dict[str, tuple[float, float]] = {}
    for step in range(steps + 1):
        time = behaviour.duration * step / steps
        offsets = behaviour.offsets(time)
        pose = {name: rests[name] + offset for name, offset in offsets.items() if name in rests}
        goals = servos.realise(pose, rests)
        for coupling in followers:
            name = coupling.joint
            value = goals.get(name, joints[name].rest_deg)
            low, high = joints[name].range_deg
            excess = max(low - value, value - high)
            if excess > 1e-6 and excess > worst.get(name, (0.0, 0.0, 0.0))[0]:
                worst[name] = (excess, time, value)
            if name in previous and step:
                speed = abs(value - previous[name]) / (behaviour.duration / steps)
                if speed > fastest.get(name, (0.0, 0.0))[0]:
                    fastest[name] = (speed, time)
            previous[name] = value
    for coupling in followers:
        name, joint = coupling.joint, joints[coupling.joint]
        what = f"{where}, joint {name} (following {coupling.follows})"
        if name in worst:
            _, time, value = worst[name]
            low, high = joint.range_deg
            found.append(f"{what}, at {time:.2f} s: would be clamped: {value:.3g} deg, "
                         f"outside its safe range [{low:g}, {high:g}]")
        speed, time = fastest.get(name, (0.0, 0.0))
        if speed > joint.max_speed_dps + 1e-6:
            found.append(f"{what}, at {time:.2f} s: too fast: {speed:.0f} deg/s, above its "
                         f"limit of {joint.max_speed_dps:g} deg/s")
    return found
