"""The effect library (issue 14): one law per mechanism, used by every integrator; entries well formed."""

import math

import numpy as np
import pytest

from hopper_ros.physics import effects, lanes, laws
from hopper_ros.physics.exact import simulate_stride
from hopper_ros.physics.params import load_params

PARAMS = load_params()
STRIDES = ((0.35, 2.0, 0.35, 5.0, 0.07), (0.40, 1.5, 0.30, 2.0, 0.08), (0.32, 2.2, 0.38, -1.0, 0.07))


def _lanes(c, strides=STRIDES):
    z, v, th, tau, tf = (np.array(x) for x in zip(*strides))
    return lanes.simulate_lanes(lanes.broadcast(c, len(z)), z, v, th, tau, tf, duration=0.8)


def test_lanes_reproduce_the_exact_model():
    r = _lanes(laws.Coefficients.from_model(PARAMS))
    for i, (z, v, th, tau, tf) in enumerate(STRIDES):
        exact = simulate_stride(PARAMS, z, v, th, tau, tf)
        assert r.next_apex_height[i] == pytest.approx(exact.next_apex.z, rel=1e-3)
        assert r.next_forward_speed[i] == pytest.approx(exact.next_apex.ydot, rel=1e-3)
        assert r.stride_time[i] == pytest.approx(exact.next_apex.t, rel=1e-3)


def test_laws_broadcast_floats_and_arrays_alike():
    c = laws.Coefficients.from_model(PARAMS, leg_friction=2.0, quadratic_drag=0.1, hip_viscous=0.05)
    arrays = lanes.broadcast(c, 3)
    y, z, vy, vz = np.array([0.0, 0.01, -0.02]), np.array([0.19, 0.18, 0.2]), np.array([2.0, 1.5, 1.0]), np.array([-1, 0.5, 0.1])
    f = laws.stance_forces(arrays, y, z, vy, vz, 0.0, 0.05, np.array([1.0, 0.0, -2.0]))
    for i in range(3):
        g = laws.stance_forces(c, y[i], z[i], vy[i], vz[i], 0.0, 0.05, [1.0, 0.0, -2.0][i])
        assert float(g.ydd) == pytest.approx(f.ydd[i]) and float(g.zdd) == pytest.approx(f.zdd[i])
    ay, az = laws.flight_acceleration(arrays, y, z, vy, vz)
    assert float(laws.flight_acceleration(c, y[1], z[1], vy[1], vz[1])[1]) == pytest.approx(az[1])


def test_ramp_is_2_32_with_the_robots_sign():
    assert laws.ramp_torque(0.0, 5.0, 0.1) == pytest.approx(-5.0)
    assert laws.ramp_torque(0.05, 5.0, 0.1) == pytest.approx(-2.5)
    assert laws.ramp_torque(0.1, 5.0, 0.1) == 0.0 and laws.ramp_torque(-0.01, 5.0, 0.1) == 0.0


def test_every_entry_is_documented_and_acts():
    """Each library entry, at a value inside its bounds, changes the next apex (all in one lanes call)."""
    base = laws.Coefficients.from_model(PARAMS)
    variants = [base]
    for effect in effects.LIBRARY:
        assert effect.site in effects.SITES and effect.words and effect.equation, effect.name
        low, high = effect.search_bounds(base)
        assert low < high, effect.name
        value = low + 0.6 * (high - low) if effect.name != "ground_height" else 0.006
        variants.append(effects.apply(base, {effect.name: effect.physical(value)})[0])
    z, v, th, tau, tf = (np.tile(np.array(x), len(variants)) for x in zip(*STRIDES))
    r = lanes.simulate_lanes(lanes.stack(variants, len(STRIDES)), z, v, th, tau, tf, duration=0.8)
    height = r.next_apex_height.reshape(len(variants), -1)
    speed = r.next_forward_speed.reshape(len(variants), -1)
    for k, effect in enumerate(effects.LIBRARY, start=1):
        moved = np.nanmax(np.abs(height[k] - height[0]) + np.abs(speed[k] - speed[0]))
        assert moved > 1e-4, f"{effect.name} on does not change the next apex"


def test_sensor_entries_and_plausibility():
    for e in effects.SENSORS:
        assert e.kind == "sensor" and e.primary.plausible[0] < e.primary.plausible[1]
    assert set(effects.SENSOR_OFF) == set(effects.SENSOR_KEYS)
    _, sensors = effects.apply(laws.Coefficients(), {"z_delay": 0.004})
    assert sensors["z_delay"] == 0.004 and sensors["y_scale"] == 1.0


def test_unknown_effect_names_itself():
    with pytest.raises(ValueError, match="unknown effect 'warp_drive'"):
        effects.get("warp_drive")


def test_inverse_parameters_round_trip():
    e = effects.get("torque_saturation")
    assert e.physical(e.search_value(4.0)) == pytest.approx(4.0)
    assert math.isinf(e.physical(0.0))


def test_toe_slip_agrees_with_the_independent_plant():
    """The toe slip (a massless toe on Coulomb friction, the leg damper setting its speed) was derived here and in
    test/independent_plant/ apart; with one mu for sticking and sliding the next apexes agree, and the slip moves
    them (early in stance the hip torque tilts the ground force out of the friction cone)."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from independent_plant import effects as fx
    from independent_plant.plant import Plant
    from independent_plant.suite import REFERENCE_STRIDES, nominal_model, one_stride

    strides = np.array(REFERENCE_STRIDES)
    for mu in (0.45, 0.3):
        ours = _lanes(laws.Coefficients.from_model(PARAMS, ground_friction=mu), strides)
        plain = _lanes(laws.Coefficients.from_model(PARAMS), strides)
        theirs = np.array([one_stride(Plant(nominal_model(), [fx.ToeSlip(mu, mu_s=mu)]), *s)[:2] for s in strides])
        for ours_k, plain_k, theirs_k in ((ours.next_apex_height, plain.next_apex_height, theirs[:, 0]),
                                          (ours.next_forward_speed, plain.next_forward_speed, theirs[:, 1])):
            effect = np.abs(ours_k - plain_k)
            assert np.max(effect) > 0.003
            assert np.all(np.abs(ours_k - theirs_k) < 0.1 * np.max(effect)), (ours_k, theirs_k, plain_k)


def test_toe_slip_in_the_simulated_robots_plant():
    """The simulated robot's plant integrates the same law: its toe slides in stance, and its next apex is the
    lanes' one."""
    from hopper_ros.sim.config import load_sim_config
    from hopper_ros.sim.plant import Plant

    config = load_sim_config().with_effects(toe_slip={"mu": 0.3})
    plant = Plant(config, leg_inertia=1e-3, leg_friction=0.0)
    z, v, th, tau, tf = STRIDES[0]
    plant.throw(z, v, th)
    toe = []
    while not any(e.kind == "apex" for e in plant.events[1:]) and plant.t < 1.0:
        plant.advance(1e-3, lambda t: laws.ramp_torque(t - plant.touchdown_time, tau, tf) if plant.in_contact else 0.0)
        toe.append(plant.toe_position - plant.toe_y)     # the slide from where it touched down
    slide = np.array(toe)[np.isfinite(toe)]
    assert slide.size and np.max(np.abs(slide)) > 5e-4
    apex = next(e for e in plant.events[1:] if e.kind == "apex")
    lane = _lanes(plant.coefficients, STRIDES[:1])
    assert apex.z == pytest.approx(lane.next_apex_height[0], abs=2e-4)
    assert apex.ydot == pytest.approx(lane.next_forward_speed[0], abs=2e-3)
