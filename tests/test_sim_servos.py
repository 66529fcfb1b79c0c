"""The simulated servos: motion at the commanded speed in clock time, hands, injected faults."""

from __future__ import annotations

import pytest
from servo_fixtures import FakeClock, servo_settings

from hal.errors import HalError, ServoSilent, UnknownJoint
from hal.servos.api import FaultKind
from hal.servos.sim import SimServos


@pytest.fixture
async def sim():
    servos = SimServos(servo_settings(), FakeClock())
    await servos.start(poll=False)
    yield servos
    await servos.close()


async def test_servos_start_limp_at_their_rest_positions(sim):
    for joint in sim.settings.joints:
        assert sim.true_position(joint.name) == pytest.approx(joint.rest_deg, abs=0.3)
        assert not sim.servo(joint.name).torque


async def test_a_servo_moves_toward_its_goal_at_the_written_speed_in_clock_time(sim):
    driver = sim.drivers["body"]
    servo = driver.servos[3]  # torso, an AX-12A
    await driver.write_goals({3: (servo.model.raw_centre + 300, 30.0)}, 0.02)
    start = servo.present
    sim.clock.t += 1.0  # 30 deg/s for 1 s is about 102 units
    positions = await driver.read_positions([3])
    assert positions[3] - start == pytest.approx(30.0 / servo.model.degrees_per_unit, abs=1)
    sim.clock.t += 10.0
    assert (await driver.read_positions([3]))[3] == servo.model.raw_centre + 300


async def test_an_unknown_joint_is_named(sim):
    for call in (sim.servo, sim.true_position, lambda name: sim.push(name, 10.0)):
        with pytest.raises(UnknownJoint, match="unknown joint 'tail'") as caught:
            call("tail")
        assert isinstance(caught.value, HalError)


async def test_a_silent_servo_does_not_answer_or_move(sim):
    sim.inject_fault("head_yaw", FaultKind.SILENT)
    driver = sim.drivers["head"]
    assert await driver.ping(1) is None
    with pytest.raises(ServoSilent) as caught:
        await driver.read_positions([2, 1])
    assert caught.value.servo_id == 1
    await driver.write_goals({1: (900, 100.0)}, 0.02)
    sim.clock.t += 5
    sim.inject_fault("head_yaw", None)
    assert sim.true_position("head_yaw") == pytest.approx(0.0, abs=0.4)


async def test_injected_error_faults_show_in_health(sim):
    sim.inject_fault("torso", FaultKind.OVERHEATING)
    health = await sim.drivers["body"].read_health(3)
    assert health.kind is FaultKind.OVERHEATING and health.flags == ("OVERHEATING",)


async def test_a_hand_moves_only_a_limp_joint(sim):
    sim.push("torso", 20.0)
    assert sim.true_position("torso") == pytest.approx(20.0, abs=0.3)
    await sim.set_compliant("body", False)
    sim.push("torso", -20.0)
    assert sim.true_position("torso") == pytest.approx(20.0, abs=0.3)


async def test_a_whole_gesture_runs_in_simulated_time(sim):
    await sim.set_compliant("head", False)
    real_before = sim.clock.now()
    for _ in range(10):  # nod ten times
        await sim.move({"head_pitch": 20.0}, duration=0.5)
        await sim.move({"head_pitch": -10.0}, duration=0.5)
    assert sim.clock.now() - real_before >= 10.0
    assert sim.true_position("head_pitch") == pytest.approx(-10.0, abs=0.4)
