"""Behaviours against the configured robot: every joint exists, nothing clamped, nothing too fast.

Offsets are relative, so a behaviour is checked from each joint's rest position at
full strength (the largest it is ever played): a keyframe that would leave the
joint's safe range would be clamped by the joints layer, and a move between
keyframes whose minimum-jerk peak speed exceeds the joint's limit would be slowed,
so that the behaviour would not look as written. Each is an error naming the
file, the behaviour, the keyframe and the joint.
"""

from __future__ import annotations

from collections.abc import Mapping

from hal.servos.settings import ServoSettings
from kasparctl.body.behaviours import MINIMUM_JERK_PEAK, Behaviour


def absent_joints(library: Mapping[str, Behaviour], servos: ServoSettings) -> list[str]:
    """The joints the behaviours move that this robot does not have (sorted)."""
    present = {joint.name for joint in servos.joints}
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
    for behaviour in library.values():
        where = f"{behaviour.source}: behaviour {behaviour.name!r}"
        missing: set[str] = set()
        for number, (time, pose) in enumerate(behaviour.keyframes, 1):
            for name, offset in pose.items():
                joint = joints.get(name)
                at = f"{where}, keyframe {number} (at {time:g} s), joint {name}"
                if joint is None:
                    # Once per behaviour, at its first keyframe.
                    if absent_is_problem and name not in missing:
                        missing.add(name)
                        found.append(f"{at}: not a joint of this robot (skipped when played)")
                    continue
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
    return found
