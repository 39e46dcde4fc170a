"""The simulated robot's physics, sensors and force plate, without ROS (hopper_ros.sim)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import run_without_numba
from hopper_ros.config import load_yaml
from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.config import load_hardware
from hopper_ros.hardware.encoders import BoomKinematics, CounterUnwrapper
from hopper_ros.physics import effects as library
from hopper_ros.physics import lanes, laws
from hopper_ros.physics.evaluation import sample_thesis_strides
from hopper_ros.physics.exact import simulate_stride
from hopper_ros.sim.config import EFFECTS, SimConfig, load_sim_config
from hopper_ros.sim.experiment import ExperimentSeries, StrideExperiment, drive_hold
from hopper_ros.sim.plant import Plant
from hopper_ros.sim.robot import SimRobot

HARDWARE = load_hardware()
BASE = load_sim_config()
# the extended TD-SLIP model's own terms, each taken out of the physics
WITHOUT_MODEL_TERMS = {"flight_damping": {"flight_damping_horizontal": 0.0, "flight_damping_vertical": 0.0},
                       "toe_mass": {"toe_mass": 0.0}, "boom_gravity": {"gravity": 9.81}}


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


@pytest.mark.parametrize("which", ["slip", "model"])
def test_lockstep_matches_the_exact_return_map(which):
    """No effect on: the simulated robot is the model (with its terms, or the plain SLIP without them)."""
    config = BASE.all_effects_off()
    if which == "slip":
        config = config.with_physics(**{k: v for terms in WITHOUT_MODEL_TERMS.values() for k, v in terms.items()})
    params = config.model_params()
    counts = HARDWARE.encoders.motor
    count = 2.0 * math.pi / (counts.lines * counts.quadrature * counts.transmission)
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


def test_model_terms_change_the_stride_as_the_model_says():
    """Taking one of the model's terms out of the sim's physics matches the model without it."""
    stride = (0.38, 1.8, 0.30, 5.0, 0.11)
    for term, changes in WITHOUT_MODEL_TERMS.items():
        config = BASE.all_effects_off().with_physics(**changes)
        experiment, _ = run_stride(config, *stride)
        exact = exact_at_realised_touchdown(config.model_params(), experiment, 0.38, 1.8, 5.0, 0.11)
        assert experiment.next_apex.z == pytest.approx(exact.next_apex.z, rel=1e-6), term


def test_the_sim_config_lists_every_physics_entry_of_the_library():
    assert list(EFFECTS) == [effect.name for effect in library.LIBRARY]
    assert set(BASE.effects) == set(EFFECTS)
    assert not BASE.enabled_effects()                      # all off: the robot is the model
    assert BASE.coefficients() == library.apply(
        laws.Coefficients.from_model(BASE.model_params()), {})[0]


LIBRARY_STRIDE = (0.40, 2.0, 0.30, 6.0, 0.10)


@pytest.fixture(scope="module")
def library_strides():
    """One stride with no effect, then one per physics entry of the library enabled through the config."""
    runs = {"none": (BASE, *run_stride(BASE, *LIBRARY_STRIDE))}
    for name in EFFECTS:
        config = BASE.with_effects(**{name: True})
        runs[name] = (config, *run_stride(config, *LIBRARY_STRIDE))
    return runs


@pytest.mark.parametrize("effect", list(EFFECTS))
def test_each_library_effect_changes_the_stride(library_strides, effect):
    _, reference, _ = library_strides["none"]
    config, changed, samples = library_strides[effect]
    assert config.enabled_effects() == {effect: BASE.effects[effect][EFFECTS[effect]]}
    assert not changed.fell
    apex, before = changed.next_apex, reference.next_apex
    change = max(abs(apex.z - before.z) / before.z, abs(apex.ydot - before.ydot) / before.ydot)
    assert change > 2e-3, f"{effect} changed the next apex by only {change:.2e}"

    stance = [s.truth for s in samples if s.truth.in_contact]
    touchdown = changed.event("touchdown").t
    magnitude = config.value(effect)
    if effect == "torque_saturation":
        assert max(abs(s.hip_torque) for s in stance) == pytest.approx(magnitude, rel=1e-9)
    if effect == "actuation_delay":
        early = [s for s in stance if s.t < touchdown + magnitude - 1e-4]
        late = [s for s in stance if s.t > touchdown + magnitude + 1e-4]
        assert early and all(s.hip_torque == 0.0 for s in early)
        assert abs(late[0].hip_torque) > 0.8 * LIBRARY_STRIDE[3]
    if effect == "actuator_lag":     # the applied torque follows the ramp's step at touchdown with T_l
        first = stance[0]
        assert abs(first.hip_torque) < 0.5 * LIBRARY_STRIDE[3]
        assert max(abs(s.hip_torque) for s in stance) < LIBRARY_STRIDE[3]
    if effect == "touchdown_loss_across":
        before_td = reference.event("touchdown")
        assert before_td.ydot != pytest.approx(changed.event("touchdown").ydot, rel=1e-3)


def test_the_plant_and_the_lanes_integrator_are_one_model(library_strides):
    """The same stride, effect by effect, by the sim's plant and by `physics.lanes` with the config's
    coefficients (at the touchdown angle the drive realised): the same next apex, to the lanes'
    coarser event location."""
    names = list(library_strides)
    coefficients = lanes.stack([library_strides[n][0].coefficients() for n in names], 1)
    realised = np.array([library_strides[n][1].event("touchdown").leg_angle for n in names])
    count = len(names)
    apex_height, speed, _, tau_0, ramp = LIBRARY_STRIDE
    result = lanes.simulate_lanes(coefficients, np.full(count, apex_height), np.full(count, speed), realised,
                                  np.full(count, tau_0), np.full(count, ramp), duration=0.7)
    assert not result.fell.any()
    for i, name in enumerate(names):
        apex = library_strides[name][1].next_apex
        assert apex.z == pytest.approx(result.next_apex_height[i], rel=1e-3), name
        assert apex.ydot == pytest.approx(result.next_forward_speed[i], rel=3e-3), name
        assert apex.t == pytest.approx(result.stride_time[i], abs=2e-3), name


def _series_samples(config, compiled, periods):
    """Section 4.1's experiments one after another for `periods` periods, the plant's kernel compiled or not."""
    robot = SimRobot(config, HARDWARE)
    robot.plant = Plant(config, robot.motor.leg_inertia_total, robot.motor.leg_friction, compiled=compiled)
    assert robot.plant.kernel.compiled == compiled
    series = ExperimentSeries(robot, seed=3)
    samples = []
    for _ in range(periods):
        if robot.experiment is None or robot.experiment.done:
            series.start_next()
        samples.append(robot.step())
    return samples


def test_the_compiled_plant_and_the_python_plant_give_the_same_strides():
    """The plant's kernel compiled by numba (the default) and in Python (where numba is missing): with every effect
    on, the same events (touchdown, bottom, lift-off, apex, falls and a scuffed landing) and the same truth, force
    plate and packets every period, to rounding."""
    pytest.importorskip("numba")
    config = BASE.with_effects(**{name: True for name in EFFECTS})
    compiled, python = (_series_samples(config, flag, 1000) for flag in (True, False))
    events = [(e.kind, e.t, e.y, e.z, e.ydot, e.zdot, e.leg_angle) for s in compiled for e in s.events]
    reference = [(e.kind, e.t, e.y, e.z, e.ydot, e.zdot, e.leg_angle) for s in python for e in s.events]
    assert {e[0] for e in events} == {"apex", "touchdown", "bottom", "liftoff", "fall"}
    assert [e[0] for e in events] == [e[0] for e in reference]
    np.testing.assert_allclose([e[1:] for e in events], [e[1:] for e in reference], rtol=0, atol=1e-12)

    def series(samples):
        return np.array([(s.truth.y, s.truth.z, s.truth.ydot, s.truth.zdot, s.truth.leg_angle, s.truth.leg_rate,
                          s.truth.hip_torque, s.force.forward, s.force.vertical) for s in samples])

    np.testing.assert_allclose(series(compiled), series(python), rtol=1e-12, atol=1e-12)
    assert [s.packet for s in compiled] == [s.packet for s in python]


def test_without_numba_the_plant_runs_in_python():
    script = ("from hopper_ros.hardware.config import load_hardware\n"
              "from hopper_ros.sim.config import load_sim_config\n"
              "from hopper_ros.sim.robot import SimRobot\n"
              "robot = SimRobot(load_sim_config(), load_hardware())\n"
              "robot.throw(0.4, 2.0, 0.3)\n"
              "samples = robot.run_until(lambda s: any(e.kind == 'touchdown' for e in s.events), 1.0)\n"
              "print(robot.plant.kernel.compiled, samples[-1].events[0].kind)\n")
    done = run_without_numba(script)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "touchdown"]


def test_ground_compliance_lets_the_toe_sink_by_force_over_stiffness():
    config = BASE.with_effects(ground_compliance={"k_g": 30000.0})
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
    deepest = int(np.argmax(depths))
    # k_g depth + d_g depth' = F: at the deepest point the damper is idle, depth = F / k_g
    assert depths[deepest] == pytest.approx(forces[deepest] / 30000.0, rel=0.02)
    assert max(depths) > 1e-3


def test_leg_friction_dissipates_energy():
    stride = (0.40, 1.6, 0.25, 0.0, 0.1)
    config = BASE.all_effects_off()
    plain, _ = run_stride(config, *stride)
    rubbing, _ = run_stride(config.with_effects(leg_friction={"F_c": 4.0}), *stride)
    m, g = config.physics["body_mass"], config.gravity

    def energy(event):
        return 0.5 * m * (event.ydot ** 2 + event.zdot ** 2) + m * g * event.z

    lost_plain = energy(plain.events[0]) - energy(plain.next_apex)
    lost_rubbing = energy(rubbing.events[0]) - energy(rubbing.next_apex)
    assert lost_rubbing > lost_plain + 0.05   # [J]


def test_force_plate_impulse_equals_momentum_change():
    config = BASE.all_effects_off()
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
    hardware = HARDWARE.with_offsets(azimuth=2 ** 31 - 3000)   # the register wraps within the stride
    config = BASE.all_effects_off()
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
    with pytest.raises(ValueError, match="leg_friction.F_c must be a non-negative number"):
        BASE.with_effects(leg_friction={"F_c": -1.0})
    data = load_yaml("sim.yaml")
    old_style = {**data["sim"], "effects": {"leg_friction": {"enabled": False, "force": 2.0}}}
    with pytest.raises(ValueError, match=r"my\.yaml: sim\.effects\.leg_friction: unknown key\(s\) \['force'\]"):
        SimConfig.from_dict({"sim": old_style}, source="my.yaml")
    with pytest.raises(ValueError, match=r"my\.yaml: sim\.effects: unknown effect 'boom_gravity'"):
        SimConfig.from_dict({"sim": {**data["sim"], "effects": {"boom_gravity": {"enabled": True}}}}, source="my.yaml")
    with pytest.raises(ValueError, match="sensor fault"):
        BASE.with_effects(z_delay={"z_delay": 0.002})
    with pytest.raises(ValueError, match=r"my\.yaml: sim\.physics: unknown parameter"):
        SimConfig.from_dict({"sim": {**data["sim"], "physics": {**data["sim"]["physics"], "mass": 2.0}}},
                            source="my.yaml")
    # a library entry the file does not list can be given with its magnitude
    config = SimConfig.from_dict({"sim": {**data["sim"], "effects": {}}}, source="my.yaml")
    assert not config.enabled("quadratic_drag")
    with pytest.raises(ValueError, match="'quadratic_drag' has no magnitude"):
        config.with_effects(quadratic_drag=True)
    assert config.with_effects(quadratic_drag={"c": 0.2}).coefficients().quadratic_drag == 0.2
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
