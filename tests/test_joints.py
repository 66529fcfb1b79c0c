"""Joints: clamps, speed limits, torque-on without a jump, latched faults, safe actions."""

from __future__ import annotations

import asyncio
import itertools

import pytest
import structlog
from emulators.dynamixel import Dynamixel1Emulator
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from servo_fixtures import FakeClock, eventually, make_driver, servo_settings

from hal.errors import HalError, ServoFaultError, UnknownJoint, UnsafeCommand
from hal.servos.api import FaultKind, ServoApi
from hal.servos.joints import Joints
from hal.servos.sim import SimServos


async def started(safe_action="hold", **overrides) -> SimServos:
    servos = SimServos(servo_settings(safe_action, **overrides), FakeClock())
    await servos.start(poll=False)
    return servos


def joint_settings(servos, name):
    return next(j for j in servos.settings.joints if j.name == name)


def assert_commands_safe(servos: SimServos) -> None:
    """Every goal ever written is inside its joint's range and within its speed per step."""
    for bus, driver in servos.drivers.items():
        by_id = {j.id: j for j in servos.settings.joints if j.bus == bus}
        last: dict[int, tuple[float, float]] = {}
        for write in driver.writes:
            for servo_id, raw in write.goals.items():
                joint = by_id[servo_id]
                degrees = joint.servo.to_degrees(raw, joint.direction, joint.offset_deg)
                unit = joint.servo.degrees_per_unit
                low, high = joint.range_deg
                assert low - unit <= degrees <= high + unit, (joint.name, degrees)
                if servo_id in last:
                    _, previous = last[servo_id]
                    # One step of the control loop at the joint's limit, plus one unit of rounding.
                    step_limit = joint.max_speed_dps * servos.step + unit
                    assert abs(degrees - previous) <= step_limit + 1e-9, (joint.name, write.time)
                last[servo_id] = (write.time, degrees)


async def test_the_simulation_implements_the_game_interface():
    servos = await started()
    assert isinstance(servos, ServoApi)
    assert servos.groups["left_arm"] == ("left_shoulder", "left_elbow")


async def test_start_reads_where_the_joints_are_and_moves_nothing():
    servos = await started()
    positions = await servos.read_positions()
    assert positions["left_shoulder"] == pytest.approx(-10.0, abs=0.3)
    assert all(not d.writes for d in servos.drivers.values())


async def test_a_target_outside_the_range_is_clamped_and_the_clamp_logged():
    servos = await started()
    await servos.set_compliant("left_arm", False)
    with structlog.testing.capture_logs() as logs:
        await servos.move({"left_shoulder": 170.0}, duration=1.0)
    assert servos.true_position("left_shoulder") == pytest.approx(60.0, abs=0.3)
    clamps = [e for e in logs if e["event"].startswith("joint target clamped")]
    assert clamps and clamps[0]["joint"] == "left_shoulder" and clamps[0]["asked_deg"] == 170.0
    assert_commands_safe(servos)


async def test_a_short_duration_cannot_beat_the_speed_limit():
    servos = await started()
    await servos.set_compliant("body", False)
    clock = servos.clock
    begin = clock.now()
    await servos.move({"torso": 30.0}, duration=0.1)  # 30 deg at 20 deg/s needs >= 1.5 s
    assert clock.now() - begin >= 30.0 / 20.0
    assert_commands_safe(servos)


async def test_duration_is_honoured_when_it_is_slow_enough():
    servos = await started()
    await servos.set_compliant("head", False)
    begin = servos.clock.now()
    await servos.move({"head_yaw": 20.0, "head_pitch": 10.0}, duration=3.0)
    assert servos.clock.now() - begin == pytest.approx(3.0, abs=servos.step)
    assert servos.true_position("head_yaw") == pytest.approx(20.0, abs=0.5)


async def test_one_goal_packet_per_bus_per_control_step():
    servos = await started()
    await servos.set_compliant("left_arm", False)
    servos.drivers["body"].writes.clear()
    await servos.move({"left_shoulder": 0.0, "left_elbow": 30.0}, duration=1.0)
    writes = servos.drivers["body"].writes
    assert len(writes) == round(1.0 / servos.step)
    assert all(set(w.goals) == {1, 2} for w in writes)


async def test_torque_on_sets_the_goal_to_the_present_position_first():
    servos = await started()
    await servos.set_compliant("left_arm", True)
    servos.push("left_shoulder", 25.0)  # a child moves the arm while it is limp
    servos.drivers["body"].writes.clear()
    await servos.set_compliant("left_arm", False)
    first = servos.drivers["body"].writes[0].goals
    shoulder = joint_settings(servos, "left_shoulder")
    assert first[1] == shoulder.servo.to_raw(25.0, 1, 0.0)
    assert servos.servo("left_shoulder").torque
    await servos.clock.sleep(1.0)
    assert servos.true_position("left_shoulder") == pytest.approx(25.0, abs=0.3)  # no jump


async def test_teaching_reads_a_limp_arm_while_the_others_hold():
    servos = await started()
    await servos.set_compliant("head", False)
    await servos.set_compliant("left_arm", True)
    servos.push("left_elbow", 70.0)
    positions = await servos.read_positions("left_arm")
    assert positions["left_elbow"] == pytest.approx(70.0, abs=0.3)
    assert servos.servo("head_yaw").torque and not servos.servo("left_elbow").torque
    with pytest.raises(UnsafeCommand, match="left_elbow"):
        await servos.move({"left_elbow": 20.0})


async def test_torque_is_not_turned_on_for_a_joint_pushed_outside_its_range():
    servos = await started()
    await servos.set_compliant("left_arm", True)
    servos.push("left_shoulder", 100.0)  # range ends at 60
    with pytest.raises(UnsafeCommand, match="left_shoulder"):
        await servos.set_compliant("left_arm", False)
    assert not servos.servo("left_shoulder").torque


@pytest.mark.parametrize("kind", [FaultKind.OVERHEATING, FaultKind.OVERLOAD, FaultKind.VOLTAGE,
                                  FaultKind.HARDWARE, FaultKind.SILENT])
async def test_a_servo_fault_latches_naming_the_joint_and_holds_the_rest(kind):
    servos = await started("hold")
    await servos.set_compliant("left_arm", False)
    await servos.set_compliant("head", False)
    heard = []
    servos.on_fault(heard.append)
    servos.inject_fault("left_elbow", kind)
    await servos.poll_health()
    assert [(f.joint, f.kind) for f in servos.faults] == [("left_elbow", kind)]
    assert heard == list(servos.faults)
    assert servos.servo("head_yaw").torque and servos.servo("left_shoulder").torque  # held
    if kind is not FaultKind.SILENT:
        assert not servos.servo("left_elbow").torque  # the faulty servo is freed
    with pytest.raises(ServoFaultError, match="left_elbow"):
        await servos.move({"head_yaw": 10.0})


async def test_torque_off_safe_action_frees_every_joint():
    servos = await started("torque_off")
    await servos.set_compliant("head", False)
    servos.inject_fault("head_pitch", FaultKind.OVERLOAD)
    await servos.poll_health()
    assert not any(servos.servo(name).torque for name in servos.joints)


async def test_a_soft_temperature_limit_latches_before_the_servo_shuts_down():
    servos = await started(max_temperature_c=60.0)
    servos.servo("torso").temperature_c = 61.0
    await servos.poll_health()
    assert servos.faults[0].joint == "torso" and servos.faults[0].kind is FaultKind.OVERHEATING


async def test_a_fault_during_a_move_stops_it_at_the_next_step():
    servos = await started()
    await servos.set_compliant("body", False)

    async def fault_soon():
        await asyncio.sleep(0)
        servos.inject_fault("torso", FaultKind.OVERLOAD)
        await servos.poll_health()

    task = asyncio.create_task(fault_soon())
    with pytest.raises(ServoFaultError):
        await servos.move({"torso": 30.0})
    await task
    assert servos.true_position("torso") < 29.0


async def test_clearing_faults_allows_motion_again():
    servos = await started()
    servos.inject_fault("torso", FaultKind.OVERHEATING)
    await servos.poll_health()
    servos.inject_fault("torso", None)
    await servos.clear_faults()
    await servos.set_compliant("body", False)
    await servos.move({"torso": 5.0})
    assert servos.true_position("torso") == pytest.approx(5.0, abs=0.3)


async def test_a_repeating_error_is_logged_once_with_its_count():
    servos = await started()
    servos.inject_fault("head_yaw", FaultKind.SILENT)
    with structlog.testing.capture_logs() as logs:
        for _ in range(5):
            await servos.poll_health()
        servos.inject_fault("head_yaw", None)
        await servos.poll_health()
    errors = [e for e in logs if e["event"] == "servo error"]
    latched = [e for e in logs if e["event"] == "servo fault latched"]
    ended = [e for e in logs if e["event"] == "servo error no longer seen"]
    assert len(errors) == 1 and len(latched) == 1
    assert ended and ended[0]["times"] == 5 and ended[0]["joint"] == "head_yaw"


async def test_rest_brings_every_powered_joint_to_its_rest_position():
    servos = await started()
    for group in servos.groups:
        await servos.set_compliant(group, False)
    await servos.move({"left_shoulder": 40.0, "head_yaw": -30.0})
    await servos.rest()
    for joint in servos.settings.joints:
        assert servos.true_position(joint.name) == pytest.approx(joint.rest_deg, abs=0.4)
    assert_commands_safe(servos)


async def test_unknown_joints_and_nonsense_values_are_refused():
    servos = await started()
    with pytest.raises(UnknownJoint) as caught:
        await servos.move({"tail": 1.0, "torso": 0.0, "fin": 2.0})
    assert str(caught.value) == "unknown joints: tail, fin"  # not KeyError's quoted repr
    # A HalError for the game and the daemon, still a KeyError for older callers.
    assert isinstance(caught.value, HalError) and isinstance(caught.value, KeyError)
    with pytest.raises(UnknownJoint, match="unknown group or joint 'tail'"):
        await servos.set_compliant("tail", False)
    with pytest.raises(UnknownJoint, match="unknown group or joint 'arms'"):
        await servos.read_positions("arms")
    with pytest.raises(UnsafeCommand):
        await servos.move({"torso": float("nan")})
    with pytest.raises(UnsafeCommand):
        await servos.move({"torso": 1.0}, duration=float("inf"))


moves = st.lists(
    st.tuples(
        st.dictionaries(
            st.sampled_from(["left_shoulder", "left_elbow", "torso", "head_yaw", "head_pitch"]),
            st.floats(-400, 400, allow_nan=False),
            min_size=1,
        ),
        st.one_of(st.none(), st.floats(0, 3)),
        st.one_of(st.none(), st.floats(1, 500)),
        st.sampled_from(["move", "rest", "limp_arm", "stiff_arm"]),
    ),
    max_size=6,
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(moves)
def test_no_command_sequence_leaves_the_range_or_exceeds_the_speed_limit(sequence):
    async def run():
        servos = await started()
        for group in servos.groups:
            await servos.set_compliant(group, False)
        for pose, duration, speed, action in sequence:
            try:
                if action == "move":
                    await servos.move(pose, duration, speed)
                elif action == "rest":
                    await servos.rest(duration)
                elif action == "limp_arm":
                    await servos.set_compliant("left_arm", True)
                else:
                    await servos.set_compliant("left_arm", False)
            except UnsafeCommand:
                pass  # refusing is always safe
            for joint in servos.settings.joints:
                low, high = joint.range_deg
                unit = joint.servo.degrees_per_unit
                assert low - unit <= servos.true_position(joint.name) <= high + unit
        assert_commands_safe(servos)

    asyncio.run(run())


# --- the joints layer over a real bus, against the emulator ---------------------------------


async def test_joints_move_an_emulated_ax12_arm_over_the_pty(tmp_path):
    settings = servo_settings(buses=servo_settings().buses[:1], joints=servo_settings().joints[:3])
    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2, 3], rate=100000) as emulator:
        driver = make_driver("dynamixel1", emulator.path)
        joints = Joints(settings, {"body": driver}, FakeClock())
        await joints.start(poll=False)
        try:
            assert (await joints.ping_all()) == {"left_shoulder": 12, "left_elbow": 12, "torso": 12}
            await joints.set_compliant("left_arm", False)
            await joints.move({"left_shoulder": 20.0, "left_elbow": 60.0}, duration=0.2)
            async def arrived():
                positions = await joints.read_positions("left_arm")
                return positions["left_shoulder"] == pytest.approx(20.0, abs=0.3) and positions[
                    "left_elbow"
                ] == pytest.approx(60.0, abs=0.3)

            await eventually(arrived)

            emulator.faults.silent.add(3)
            await joints.poll_health()
            assert [(f.joint, f.kind) for f in joints.faults] == [("torso", FaultKind.SILENT)]
            statuses = {s.joint: s for s in await joints.survey()}
            assert statuses["torso"].position_deg is None
            assert statuses["left_elbow"].temperature_c == 32.0
        finally:
            await joints.close()


async def test_an_unplugged_bus_latches_bus_lost_for_its_joints(tmp_path):
    settings = servo_settings(buses=servo_settings().buses[:1], joints=servo_settings().joints[:3])
    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2, 3]) as emulator:
        joints = Joints(settings, {"body": make_driver("dynamixel1", emulator.path)}, FakeClock())
        await joints.start(poll=False)
        try:
            emulator.unplug()
            await joints.poll_health()
            assert {f.kind for f in joints.faults} == {FaultKind.BUS_LOST}
            assert {f.joint for f in joints.faults} == {"left_shoulder", "left_elbow", "torso"}
        finally:
            await joints.close()


async def test_a_herkulex_overload_is_latched_freed_and_reset_on_clear(tmp_path):
    from emulators.herkulex import HerkulexEmulator

    from hal.servos import herkulex as hx

    settings = servo_settings(buses=servo_settings().buses[1:], joints=servo_settings().joints[3:])
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2]) as emulator:
        joints = Joints(settings, {"head": make_driver("herkulex", emulator.path, baud=115200)},
                        FakeClock())
        await joints.start(poll=False)
        try:
            await joints.set_compliant("head", False)
            await eventually(lambda: emulator.ram[2][hx.Ram.TORQUE_CONTROL] == hx.TorqueControl.ON)
            emulator.faults.error_bits[2] = int(hx.StatusError.OVERLOAD)
            await joints.poll_health()
            assert [(f.joint, f.kind) for f in joints.faults] == [("head_pitch", FaultKind.OVERLOAD)]
            # The faulty servo is freed; with "hold" its neighbour keeps its torque.
            await eventually(lambda: emulator.ram[2][hx.Ram.TORQUE_CONTROL] == hx.TorqueControl.FREE)
            assert emulator.ram[1][hx.Ram.TORQUE_CONTROL] == hx.TorqueControl.ON
            await joints.clear_faults()
            await eventually(lambda: 2 not in emulator.faults.error_bits)
            await joints.poll_health()
            assert joints.faults == ()
        finally:
            await joints.close()


async def test_motion_needs_torque_turned_on_the_safe_way_first():
    servos = await started()  # torque as found: unknown
    with pytest.raises(UnsafeCommand, match="torso"):
        await servos.move({"torso": 10.0})
    assert all(not d.writes for d in servos.drivers.values())


async def test_rest_after_start_powers_joints_safely_but_not_one_outside_its_range():
    servos = SimServos(servo_settings(), FakeClock())
    servos.servo("left_shoulder").present = joint_settings(servos, "left_shoulder").servo.to_raw(
        100.0, 1, 0.0
    )  # found hanging outside its range (-90..60) at power-on
    await servos.start(poll=False)
    with structlog.testing.capture_logs() as logs:
        await servos.rest()
    assert not servos.servo("left_shoulder").torque
    assert any(e["event"].startswith("joints outside") and "left_shoulder" in e["joints"]
               for e in logs)
    assert servos.servo("torso").torque and servos.servo("head_yaw").torque
    assert servos.true_position("left_elbow") == pytest.approx(10.0, abs=0.4)
    assert_commands_safe(servos)


async def test_rest_leaves_a_joint_made_compliant_on_purpose_limp():
    servos = await started()
    await servos.set_compliant("left_arm", True)
    await servos.rest()
    assert not servos.servo("left_elbow").torque and servos.servo("torso").torque


# --- the stricter servos: temperature, latched bits, impossible readings, start-up ----------


def herkulex_head(emulator_path):
    return servo_settings(
        backend="real",
        buses=(servo_settings().buses[1].__class__(
            name="head", port=str(emulator_path), protocol="herkulex", baud=115200),),
        joints=servo_settings().joints[3:],
        max_temperature_c=65.0,
    )


async def test_a_hot_herkulex_is_warned_about_then_latched_before_its_own_cutoff(tmp_path):
    from emulators.herkulex import HerkulexEmulator

    from hal.servos import herkulex as hx

    clock = FakeClock()
    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2], clock=clock.now,
                          heat_c_per_s=1.0) as emulator:
        settings = herkulex_head(emulator.path)
        joints = Joints(settings, {"head": make_driver("herkulex", emulator.path, baud=115200)},
                        clock)
        await joints.start(poll=False)
        try:
            await joints.set_compliant("head", False)
            emulator.set_load(2, 1.0)  # head_pitch holds the head up against a hand
            with structlog.testing.capture_logs() as logs:
                seen = []
                while not joints.faults:
                    clock.t += 1.0
                    await joints.poll_health()
                    statuses = {s.joint: s for s in await joints.survey()}
                    seen.append(statuses["head_pitch"].temperature_c)
            warnings = [e for e in logs if e["event"] == "servo temperature near its limit"]
            assert [w["joint"] for w in warnings] == ["head_pitch"]  # once, not every poll
            assert 60.0 <= warnings[0]["temperature_c"] < 65.0
            (fault,) = joints.faults
            assert (fault.joint, fault.kind) == ("head_pitch", FaultKind.OVERHEATING)
            assert seen == sorted(seen) and seen[-1] >= 65.0  # it rose under load
            # The controller acted first: the servo's own 85 C cut-off has not been reached.
            assert not emulator.servos[2].latched & hx.StatusError.EXCEED_TEMPERATURE
            await eventually(lambda: not emulator.torque_on(2))  # freed (a write, not answered)
            assert emulator.torque_on(1)  # the other holds
        finally:
            await joints.close()


async def test_a_latched_error_bit_is_logged_once_with_its_count_and_cleared(tmp_path):
    from emulators.herkulex import HerkulexEmulator

    from hal.servos import herkulex as hx

    with HerkulexEmulator(tmp_path / "ttyHX", ids=[1, 2]) as emulator:
        settings = herkulex_head(emulator.path)
        joints = Joints(settings, {"head": make_driver("herkulex", emulator.path, baud=115200)},
                        FakeClock())
        await joints.start(poll=False)
        try:
            with structlog.testing.capture_logs() as logs:
                for _ in range(3):
                    emulator.latch(1, int(hx.StatusError.INVALID_PACKET))  # noise on the line
                    await joints.poll_health()
                    assert emulator.servos[1].latched == 0  # cleared: the LED stops blinking
                await joints.poll_health()
            bits = [e for e in logs if e["event"] == "servo error bit"]
            assert [(b["joint"], b["bit"], b["cleared"]) for b in bits] == [
                ("head_yaw", "INVALID_PACKET", True)
            ]
            (ended,) = [e for e in logs if e["event"] == "servo error bit no longer seen"]
            assert (ended["joint"], ended["times"]) == ("head_yaw", 3)
            assert joints.faults == ()  # a packet error is not a fault of the servo
        finally:
            await joints.close()


async def test_an_impossible_reading_is_a_named_fault_never_a_position(tmp_path):
    settings = servo_settings(buses=servo_settings().buses[:1], joints=servo_settings().joints[:3])
    with Dynamixel1Emulator(tmp_path / "ttyAX", ids=[1, 2, 3]) as emulator:
        emulator.set_present(3, 7990)  # an AX-12A reports 0..1023
        joints = Joints(settings, {"body": make_driver("dynamixel1", emulator.path)}, FakeClock())
        await joints.start(poll=False)
        try:
            (fault,) = joints.faults
            assert (fault.joint, fault.kind) == ("torso", FaultKind.IMPOSSIBLE)
            assert "7990" in fault.detail and "0 to 1023" in fault.detail
            statuses = {s.joint: s for s in await joints.survey()}
            assert statuses["torso"].position_deg is None and not statuses["torso"].healthy
            assert statuses["left_shoulder"].healthy
            with pytest.raises(ServoFaultError, match="torso"):
                await joints.set_compliant("body", False)
        finally:
            await joints.close()


async def test_a_joint_just_outside_its_range_is_brought_in_at_its_speed_limit():
    servos = await started()
    await servos.set_compliant("body", True)
    servos.push("torso", 31.8)  # range -30..30, within the 2 degree tolerance
    servos.drivers["body"].writes.clear()
    await servos.set_compliant("body", False)
    torso = joint_settings(servos, "torso")
    goals = [torso.servo.to_degrees(w.goals[3], 1, 0.0) for w in servos.drivers["body"].writes]
    assert goals[0] == pytest.approx(31.8, abs=0.3)  # first: hold where it is
    assert goals[-1] == pytest.approx(30.0, abs=0.3)
    limit = torso.max_speed_dps * servos.step + torso.servo.degrees_per_unit
    assert all(abs(b - a) <= limit for a, b in itertools.pairwise(goals))
    assert len(goals) > 3  # not snapped in one control step (1.8 deg at 20 deg/s)
    assert servos.true_position("torso") == pytest.approx(30.0, abs=0.3)


async def test_every_joint_outside_its_range_is_named_at_start_whatever_its_group():
    servos = SimServos(servo_settings(), FakeClock())
    for name, degrees in (("left_shoulder", 100.0), ("head_pitch", -40.0)):
        settings = joint_settings(servos, name)
        servos.servo(name).present = settings.servo.to_raw(degrees, settings.direction,
                                                           settings.offset_deg)
    with structlog.testing.capture_logs() as logs:
        await servos.start(poll=False)
    (warning,) = [e for e in logs if e["event"] == "joints found outside their safe range"]
    assert "left_shoulder" in warning["joints"] and "head_pitch" in warning["joints"]
    assert warning["groups"] == ["head", "left_arm"] and warning["count"] == 2
