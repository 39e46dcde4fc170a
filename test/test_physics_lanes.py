"""The lanes integrator's two paths (issue 27): numba's compilation of `physics.laws` and numpy's, one result.

Every library entry at three magnitudes, every discovered term of every site both ways, and a mix (compliant
ground, actuator lag, hip friction, toe slip) run as lanes of one call on each path; the compiled path may
differ from numpy's only by rounding. Without numba the numpy path runs and says so once.
"""

import numpy as np
import pytest

from conftest import run_without_numba
from hopper_ros.physics import effects, lanes, laws
from hopper_ros.physics.params import load_params

PARAMS = load_params()
STRIDES = ((0.35, 2.0, 0.35, 5.0, 0.07), (0.40, 1.5, 0.30, 2.0, 0.08), (0.32, 2.2, 0.38, -1.0, 0.07),
           (0.30, 1.0, 0.20, 8.0, 0.10))
TERM_SCALE = {"flight_y_terms": 0.5, "flight_z_terms": 0.5, "leg_terms": 40.0, "hip_terms": 0.3,
              "touchdown_along_terms": 0.05, "touchdown_across_terms": 0.05, "liftoff_along_terms": 0.05,
              "liftoff_across_terms": 0.05}


def _variants() -> list[laws.Coefficients]:
    base = laws.Coefficients.from_model(PARAMS)
    out = [base]
    for effect in effects.LIBRARY:
        low, high = effect.search_bounds(base)
        for share in (0.3, 0.6, 0.9):
            value = low + share * (high - low) if effect.name != "ground_height" else 0.006 * share
            out.append(effects.apply(base, {effect.name: effect.physical(value)})[0])
    for name in laws.Coefficients.term_names():
        count = len(getattr(base, name))
        for i in range(count):
            for sign in (1.0, -1.0):
                terms = [0.0] * count
                terms[i] = sign * TERM_SCALE[name]
                knots = {"flight_z_terms": {"flight_z_knot": 0.33}, "leg_terms": {"leg_knot": 0.01}}.get(name, {})
                out.append(base.replace(**{name: tuple(terms)}, **knots))
    out.append(effects.apply(base, {"ground_compliance": 4e4, "actuator_lag": 0.004, "hip_dry_friction": 0.05,
                                    "toe_slip": 0.5})[0])
    out += [base.replace(track_gravity=a) for a in (0.13, -0.13)]     # a tilted boom axis (diagnosis.dependence)
    # a Bouc-Wen hysteresis in the leg force (diagnosis.unused), a state of the lanes
    out += [base.replace(leg_hysteresis=f, leg_hysteresis_yield=x) for f, x in ((3.0, 0.002), (10.0, 0.0005))]
    # a relaxing leg force (a Maxwell element: air leaking from the leg, diagnosis.relaxation), a state of the lanes,
    # alone and beside the hysteresis
    out += [base.replace(leg_relaxing_stiffness=k, leg_relaxation_time=r) for k, r in ((600.0, 0.03), (1500.0, 0.005))]
    out.append(base.replace(leg_relaxing_stiffness=800.0, leg_relaxation_time=0.02, leg_hysteresis=3.0))
    # a round toe rolling in stance (diagnosis.foot): its centre the toe's state, alone and beside a hip friction
    out += [base.replace(foot_radius=r) for r in (0.01, 0.03)]
    out.append(effects.apply(base.replace(foot_radius=0.02), {"hip_dry_friction": 0.05})[0])
    # the boom's sphere in every phase (diagnosis.sphere), the height read as R sin(elevation) and along the arc
    out += [base.replace(boom_curvature=0.6, boom_pivot_height=0.115, boom_sine_reading=s) for s in (1.0, 0.0)]
    return out


def _run(compiled: bool):
    variants = _variants()
    columns = (np.tile(np.array(x), len(variants)) for x in zip(*STRIDES))
    return lanes.simulate_lanes(lanes.stack(variants, len(STRIDES)), *columns, duration=0.8, compiled=compiled)


def test_compiled_and_numpy_lanes_agree_on_every_law():
    fast, slow = _run(True), _run(False)
    assert slow.fell.sum() < 0.2 * slow.fell.size      # the lanes mostly complete their strides
    for name in ("y", "z", "theta", "ydot", "zdot", "next_apex_height", "next_forward_speed", "stride_time",
                 "stride_length", "touchdown_time", "liftoff_time"):
        a, b = getattr(fast, name), getattr(slow, name)
        assert np.array_equal(np.isnan(a), np.isnan(b)), name
        assert np.nanmax(np.abs(a.astype(float) - b.astype(float))) <= 1e-12, name
    assert np.array_equal(fast.fell, slow.fell)


def test_stack_gives_each_lane_its_variants_coefficients():
    variants = _variants()
    stacked = lanes.stack(variants, 3)
    for name in laws.Coefficients.scalar_names():
        assert np.array_equal(getattr(stacked, name), np.repeat([getattr(v, name) for v in variants], 3)), name
    for name in laws.Coefficients.term_names():
        for i, lane_values in enumerate(getattr(stacked, name)):
            assert np.array_equal(lane_values, np.repeat([getattr(v, name)[i] for v in variants], 3)), (name, i)


def test_compiled_path_is_required_when_asked(monkeypatch):
    monkeypatch.setattr(lanes, "_COMPILED", False)
    with pytest.raises(RuntimeError, match="not available"):
        lanes.simulate_lanes(laws.Coefficients.from_model(PARAMS), np.array([0.35]), 2.0, 0.35, 5.0, 0.07,
                             duration=0.1, compiled=True)


def test_without_numba_the_numpy_path_runs_and_says_so_once():
    script = ("import numpy as np\n"
              "from hopper_ros.physics import lanes, laws\n"
              "from hopper_ros.physics.params import load_params\n"
              "c = laws.Coefficients.from_model(load_params())\n"
              "for _ in range(3):\n"
              "    r = lanes.simulate_lanes(c, np.array([0.35, 0.4]), 2.0, 0.35, 5.0, 0.07, duration=0.5)\n"
              "print(repr(float(r.next_apex_height[0])))\n")
    done = run_without_numba(script)
    assert done.returncode == 0, done.stderr
    said = [line for line in done.stderr.splitlines() if "compiled lanes are not available" in line]
    assert len(said) == 1, done.stderr
    reference = lanes.simulate_lanes(laws.Coefficients.from_model(PARAMS), np.array([0.35, 0.4]), 2.0, 0.35, 5.0,
                                     0.07, duration=0.5, compiled=False)
    assert float(done.stdout.strip()) == float(reference.next_apex_height[0])
