"""The simulated robot's physics, sensors and force plate, without ROS (hopper_ros.sim)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hopper_ros.config import load_yaml
from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.encoders import BoomKinematics, CounterUnwrapper
from hopper_ros.physics.evaluation import sample_thesis_strides
from hopper_ros.physics.exact import simulate_stride
from hopper_ros.sim.config import EFFECTS, MODEL_EFFECTS, load_sim_config
from hopper_ros.sim.experiment import StrideExperiment, drive_hold
from hopper_ros.sim.robot import SimRobot

HARDWARE = load_yaml("hardware.yaml")
BASE = load_sim_config()
EXTRA_EFFECTS = [name for name in EFFECTS if name not in MODEL_EFFECTS]


def run_stride(config, apex_height, forward_speed, touchdown_angle, tau_0, ramp_duration, hardware=HARDWARE):
    robot = SimRobot(config, hardware)
    robot.throw(apex_height, forward_speed, touchdown_angle)
    experiment = StrideExperiment(tau_0, touchdown_angle, ramp_duration, drive_hold(hardware),
                                  config.pre_touchdown_height)
    robot.run_experiment(experiment)
    samples = robot.run_until(lambda sample: experiment.done, 3.0)
    return experiment, samples


def thesis_strides(params, count, seed):
    strides = sample_thesis_strides(params, count, seed=seed)
    return list(zip(*strides.columns()))


def exact_at_realised_touchdown(params, experiment, apex_height, forward_speed, tau_0, ramp):
    """The exact model's stride at the leg angle the drive actually held at touchdown.

    The drive's position regulator holds the leg to within a few encoder counts (quantisation
    limit cycle), 1e-4 rad: enough to move the next apex by ~0.1 % on slow strides. The return map
    is compared at the inputs the robot realised.
    """
    touchdown_angle = experiment.event("touchdown").leg_angle
    return simulate_stride(params, apex_height, forward_speed, touchdown_angle, tau_0, ramp)


@pytest.mark.parametrize("which", ["all_off", "model_effects"])
def test_lockstep_matches_the_exact_return_map(which):
    config = BASE.all_effects_off() if which == "all_off" else BASE.only_model_effects()
    params = config.model_params()
    counts = HARDWARE["encoders"]["motor"]
    count = 2.0 * math.pi / (counts["lines"] * counts["quadrature"] * counts["transmission"])
    compared = 0
    for apex_height, forward_speed, touchdown_angle, tau_0, ramp in thesis_strides(params, 12, seed=4):
        experiment, _ = run_stride(config, apex_height, forward_speed, touchdown_angle, tau_0, ramp)
        exact = exact_at_realised_touchdown(params, experiment, apex_height, forward_speed, tau_0, ramp)
        assert experiment.fell == (not exact.ok)
        if not exact.ok:
            continue
        assert abs(experiment.event("touchdown").leg_angle - touchdown_angle) < 5 * count
        apex = experiment.next_apex
        assert apex.z == pytest.approx(exact.next_apex.z, rel=1e-6)          # issue: < 0.1 %
        assert apex.ydot == pytest.approx(exact.next_apex.ydot, rel=1e-6)
        assert apex.t == pytest.approx(exact.next_apex.t, rel=1e-6)
        assert experiment.event("touchdown").t == pytest.approx(exact.touchdown.t, abs=1e-8)
        assert experiment.event("liftoff").t == pytest.approx(exact.liftoff.t, abs=1e-8)
        compared += 1
    assert compared >= 8


def test_model_effects_change_the_stride_as_the_model_says():
    """Switching one of the model's effects off in the sim matches the model without it."""
    stride = (0.38, 1.8, 0.30, 5.0, 0.11)
    for effect in MODEL_EFFECTS:
        config = BASE.only_model_effects().with_effects(**{effect: False})
        experiment, _ = run_stride(config, *stride)
        exact = exact_at_realised_touchdown(config.model_params(), experiment, 0.38, 1.8, 5.0, 0.11)
        assert experiment.next_apex.z == pytest.approx(exact.next_apex.z, rel=1e-6), effect


@pytest.mark.parametrize("effect", EXTRA_EFFECTS)
def test_each_extra_effect_changes_the_stride(effect):
    stride = (0.40, 2.0, 0.30, 6.0, 0.10)
    reference, _ = run_stride(BASE.only_model_effects(), *stride)
    changed, samples = run_stride(BASE.only_model_effects().with_effects(**{effect: True}), *stride)
    assert not changed.fell
    apex, before = changed.next_apex, reference.next_apex
    change = max(abs(apex.z - before.z) / before.z, abs(apex.ydot - before.ydot) / before.ydot)
    assert change > 2e-3, f"{effect} changed the next apex by only {change:.2e}"

    stance = [s.truth for s in samples if s.truth.in_contact]
    touchdown = changed.event("touchdown").t
    settings = BASE.effects[effect]
    if effect == "torque_saturation":
        assert max(abs(s.hip_torque) for s in stance) == pytest.approx(settings["max_torque"], rel=1e-9)
    if effect == "actuation_delay":
        early = [s for s in stance if s.t < touchdown + settings["delay"] - 1e-4]
        late = [s for s in stance if s.t > touchdown + settings["delay"] + 1e-4]
        assert early and all(s.hip_torque == 0.0 for s in early)
        assert abs(late[0].hip_torque) > 0.8 * stride[3]
    if effect == "touchdown_impact":
        before_td = reference.event("touchdown")
        assert before_td.ydot != pytest.approx(changed.event("touchdown").ydot, rel=1e-3)


def test_ground_compliance_lets_the_toe_sink_by_force_over_stiffness():
    config = BASE.only_model_effects().with_effects(ground_compliance={"stiffness": 30000.0, "damping": 200.0})
    robot = SimRobot(config, HARDWARE)
    robot.throw(0.40, 1.5, 0.2)
    experiment = StrideExperiment(0.0, 0.2, 0.1, drive_hold(HARDWARE), config.pre_touchdown_height)
    robot.run_experiment(experiment)
    depths, forces = [], []
    while not experiment.done:
        sample = robot.step()
        if sample.truth.in_contact:
            depths.append(robot.plant.state[6])
            forces.append(sample.force.vertical)
    peak = int(np.argmax(forces))
    # at peak force the damper is nearly idle: depth ~ F / k_g
    assert depths[peak] == pytest.approx(forces[peak] / 30000.0, rel=0.1)
    assert max(depths) > 1e-3


def test_leg_friction_dissipates_energy():
    stride = (0.40, 1.6, 0.25, 0.0, 0.1)
    config = BASE.all_effects_off()
    plain, _ = run_stride(config, *stride)
    rubbing, _ = run_stride(config.with_effects(leg_friction={"force": 4.0}), *stride)
    m, g = config.physics["body_mass"], config.gravity

    def energy(event):
        return 0.5 * m * (event.ydot ** 2 + event.zdot ** 2) + m * g * event.z

    lost_plain = energy(plain.events[0]) - energy(plain.next_apex)
    lost_rubbing = energy(rubbing.events[0]) - energy(rubbing.next_apex)
    assert lost_rubbing > lost_plain + 0.05   # [J]


def test_force_plate_impulse_equals_momentum_change():
    config = BASE.only_model_effects()
    experiment, samples = run_stride(config, 0.38, 1.8, 0.3, 5.0, 0.11)
    touchdown, liftoff = experiment.event("touchdown"), experiment.event("liftoff")
    period = config.period
    stance = [s for s in samples if touchdown.t < s.truth.t <= liftoff.t + period]
    m, g = config.physics["body_mass"], config.gravity
    impulse_z = sum(s.force.vertical for s in stance) * period
    impulse_y = sum(s.force.forward for s in stance) * period
    duration = liftoff.t - touchdown.t
    # Riemann sum of a 1 kHz sampled force: a few per cent of the impulse is the sampling
    assert impulse_z - m * g * duration == pytest.approx(m * (liftoff.zdot - touchdown.zdot), rel=0.05)
    assert impulse_y == pytest.approx(m * (liftoff.ydot - touchdown.ydot), abs=0.05 * m * abs(touchdown.zdot))
    assert all(not s.force.contact for s in samples if not s.truth.in_contact)
    toe = [s.force.center_of_pressure for s in stance if s.truth.in_contact]
    rest_length = config.physics["rest_length"]
    assert max(toe) - min(toe) < 1e-12
    assert toe[0] == pytest.approx(touchdown.y + rest_length * math.sin(touchdown.leg_angle), abs=1e-12)


def test_packets_decode_to_the_true_positions_across_counter_wrap():
    hardware = dict(HARDWARE)
    encoders = {name: dict(section) for name, section in HARDWARE["encoders"].items()}
    encoders["azimuth"]["offset_counts"] = 2 ** 31 - 3000   # the register wraps within the stride
    hardware["encoders"] = encoders
    config = BASE.only_model_effects()
    experiment, samples = run_stride(config, 0.38, 2.0, 0.3, 5.0, 0.11, hardware=hardware)
    kinematics = BoomKinematics.from_config(hardware)
    unwrappers = [CounterUnwrapper() for _ in range(3)]
    resolution_y, resolution_z = kinematics.position_resolution()
    for sample in samples:
        decoded = packet_format.decode(packet_format.encode(sample.packet))
        assert decoded == sample.packet
        counts = [u.update(c) for u, c in zip(unwrappers, (decoded.azimuth_counts, decoded.elevation_counts,
                                                            decoded.motor_counts))]
        position = kinematics.position(*counts)
        truth = sample.truth
        assert 0.0 <= truth.y - position.y < resolution_y * 1.01
        assert abs(truth.z - position.z) < resolution_z * 1.5
        assert 0.0 <= truth.leg_angle - position.leg_angle < kinematics.motor.resolution * 1.01
    assert unwrappers[0].wraps == 1
    sequences = [s.packet.sequence for s in samples]
    assert sequences == list(range(sequences[0], sequences[0] + len(samples)))
    clock = [s.packet.mcu_time_us for s in samples]
    assert set(np.diff(clock)) == {1000}


@pytest.mark.parametrize("damage, reason", [
    (lambda b: b[:-1], "malformed_size"),
    (lambda b: b"XX" + b[2:], "malformed_magic"),
    (lambda b: b[:2] + bytes([9]) + b[3:], "malformed_version"),
    (lambda b: b[:20] + bytes([b[20] ^ 1]) + b[21:], "malformed_checksum"),
])
def test_damaged_packets_are_rejected_with_a_reason(damage, reason):
    good = packet_format.encode(packet_format.EncoderPacket(7, 123456, 1, -2, 3, 4))
    with pytest.raises(packet_format.PacketError) as error:
        packet_format.decode(damage(good))
    assert error.value.reason == reason


def test_sensor_noise_is_seeded_and_switchable():
    noisy = BASE.with_sensors(encoder_noise=True, force_plate_noise=True)
    first = [s.packet for s in run_stride(noisy, 0.38, 1.8, 0.3, 5.0, 0.11)[1][:50]]
    second = [s.packet for s in run_stride(noisy, 0.38, 1.8, 0.3, 5.0, 0.11)[1][:50]]
    clean = [s.packet for s in run_stride(BASE, 0.38, 1.8, 0.3, 5.0, 0.11)[1][:50]]
    assert first == second
    assert first != clean


def test_bad_sim_config_names_the_problem():
    with pytest.raises(ValueError, match="unknown effect 'magic'"):
        BASE.with_effects(magic=True)
    with pytest.raises(ValueError, match="leg_friction.force must be a non-negative number"):
        BASE.with_effects(leg_friction={"force": -1.0})
    with pytest.raises(ValueError, match="toe"):
        SimRobot(BASE, HARDWARE).throw(0.1, 1.0, 0.3)
    assert math.isfinite(BASE.gravity)


def test_a_throw_with_lead_time_rises_into_the_requested_apex_and_hold_waits():
    robot = SimRobot(BASE, HARDWARE)
    robot.throw(0.38, 1.7, 0.3, lead_time=0.05, hold=True)
    start = robot.plant.state[:4]
    assert start[3] > 0.0                                     # rising
    for _ in range(100):
        robot.step()
    assert robot.plant.state[:4] == start                     # held: the body does not move
    robot.plant.release()
    events = []
    while not events:
        events = [e for e in robot.step().events if e.kind == "apex"]
    assert events[0].t == pytest.approx(0.1 + 0.05, abs=1e-9)
    assert events[0].z == pytest.approx(0.38, abs=1e-9) and events[0].ydot == pytest.approx(1.7, abs=1e-9)
