"""Checks of the independent plant (test/independent_plant) against first principles only."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from independent_plant import effects as fx  # noqa: E402
from independent_plant.plant import (Model, Plant, Servo, StrideCommand,  # noqa: E402
                                     apex_from, flight_closed_form)
from independent_plant.runner import NoiseSpec, measure, read_csv, simulate, write_csv  # noqa: E402
from independent_plant.suite import SPECS, make_recording  # noqa: E402

M = Model()


def _touchdown(plant, za=0.32, va=1.8, theta=0.38):
    servo = Servo(0.0, theta, 0.0, theta, plant.servo_T)
    seg, ttd, xtd, thtd = plant.descend(0.0, np.array([0.0, za, va, 0.0]), servo)
    return seg, ttd, xtd, thtd


def _energy_stance(model, segs, t):
    e = []
    for seg in segs:
        tt = t[(t >= seg.t0) & (t <= seg.t1)]
        x = seg.sol(tt)
        rho = np.hypot(x[0] - x[4], x[1] - x[5])
        e.append(0.5 * model.m_b * (x[2] ** 2 + x[3] ** 2) + model.m_b * model.g * x[1]
                 + 0.5 * model.k * (rho - model.rho_0) ** 2)
    return np.concatenate(e)


def test_stance_energy_is_conserved_without_damping_and_torque():
    model = Model(d=0.0)
    plant = Plant(model)
    _, ttd, xtd, thtd = _touchdown(plant)
    r = plant.stance(ttd, xtd, thtd, StrideCommand(thtd, 0.0, 0.06))
    t = np.linspace(r.t_td, r.t_lo, 400)
    e = _energy_stance(model, r.segments, t)
    assert abs(r.t_lo - r.t_td - 0.07) < 0.02
    assert np.ptp(e) / np.mean(e) < 1e-6
    # lift-off at the rest length (d = 0: the force vanishes there), energy split kept
    x = r.segments[-1].sol(r.t_lo)
    assert abs(math.hypot(x[0] - x[4], x[1] - x[5]) - model.rho_0) < 1e-7


def test_stance_cartesian_forces_match_the_polar_lagrangian_2_9():
    """(2.9): m rho'' = m rho th'^2 - m g cos th + k(rho0 - rho) - d rho';
    d/dt(m rho^2 th') = m g rho sin th + tau, for an arbitrary state and torque sign."""
    plant = Plant(M)
    for (rho, th, rhod, thd, tau) in [(0.18, 0.3, -1.2, -8.0, -4.0), (0.19, -0.2, 0.9, -11.0, 2.5)]:
        yt, zt = 0.7, 0.0
        y, z = yt - rho * math.sin(th), zt + rho * math.cos(th)
        e = np.array([-math.sin(th), math.cos(th)])
        n = np.array([-math.cos(th), -math.sin(th)])
        v = rhod * e + rho * thd * n
        x = np.array([y, z, v[0], v[1], yt, zt, 0.0])
        law = lambda s, tau=tau: tau
        dx = plant._stance_rhs(0.01, x, 0.0, 0, law)
        a = np.array(dx[2:4])
        # polar components of the acceleration
        rho_dd = a @ e + rho * thd ** 2
        p_dot = M.m_b * rho * (a @ n)          # d/dt (m rho^2 th') = m rho (rho th'' + 2 rho' th')
        assert rho_dd * M.m_b == pytest.approx(
            M.m_b * rho * thd ** 2 - M.m_b * M.g * math.cos(th) + M.k * (M.rho_0 - rho) - M.d * rhod,
            rel=1e-12, abs=1e-9)
        assert p_dot == pytest.approx(M.m_b * M.g * rho * math.sin(th) + tau, rel=1e-12, abs=1e-9)
    # the commanded ramp with tau_0 > 0 pushes the body forward with the leg vertical
    x = np.array([0.0, 0.19, 1.0, 0.0, 0.0, 0.0, 0.0])
    dx = plant._stance_rhs(0.0, x, 0.0, 0, StrideCommand(0.0, 4.0, 0.06).torque)
    assert dx[2] > 0


def test_flight_matches_the_closed_form_2_13_to_2_16():
    plant = Plant(M)
    x0 = np.array([0.3, 0.19, 1.7, 1.9])
    servo = Servo(0.0, -0.3, -9.0, 0.35, plant.servo_T)
    seg, ta, xa = plant.ascend(0.0, x0, servo)
    t = np.linspace(0.0, ta, 50)
    y, z, vy, vz = flight_closed_form(t, *x0, M)
    sol = seg.sol(t)
    assert np.max(np.abs(sol[0] - y)) < 1e-9 and np.max(np.abs(sol[1] - z)) < 1e-9
    assert np.max(np.abs(sol[2] - vy)) < 1e-9 and np.max(np.abs(sol[3] - vz)) < 1e-9
    ta_cf, ya, za, vya = apex_from(*x0, M)
    assert ta == pytest.approx(ta_cf, abs=1e-9) and xa[1] == pytest.approx(za, abs=1e-10)
    # descent from the apex and the toe on the ground at touchdown
    seg2, ttd, xtd, thtd = plant.descend(ta, xa, servo)
    t2 = np.linspace(ta, ttd, 30)
    y2, z2, _, _ = flight_closed_form(t2 - ta, *xa, M)
    assert np.max(np.abs(seg2.sol(t2)[1] - z2)) < 1e-9
    assert xtd[1] - M.rho_0 * math.cos(thtd) == pytest.approx(0.0, abs=1e-10)
    assert abs(thtd - 0.35) < 1e-3                      # the servo has settled by touchdown


@pytest.mark.parametrize("m_t", [M.m_t, 0.09])
def test_liftoff_collision_factor_2_12(m_t):
    plant = Plant(M, [fx.ToeMassError(m_t)])
    _, ttd, xtd, thtd = _touchdown(plant)
    r = plant.stance(ttd, xtd, thtd, StrideCommand(thtd, 5.0, 0.06))
    pre = r.segments[-1].sol(r.t_lo)[2:4]
    assert np.allclose(r.x_lo[2:4], M.m_b / (M.m_b + m_t) * pre, rtol=1e-13, atol=0)
    # lift-off where the leg force (2.28) vanishes
    x = r.segments[-1].sol(r.t_lo)
    rho = math.hypot(x[0] - x[4], x[1] - x[5])
    e = np.array([x[0] - x[4], x[1] - x[5]]) / rho
    force = M.k * (M.rho_0 - rho) - M.d * (e @ x[2:4])
    assert abs(force) < 1e-6 or abs(rho - M.rho_0) < 1e-9


@pytest.fixture(scope="module")
def short_recording(tmp_path_factory):
    rng = np.random.default_rng(7)
    plant = Plant(M)
    traj = simulate(plant, 8, rng, run_strides=(4, 4))
    cols = measure(traj, [], NoiseSpec(), np.random.default_rng(8))
    path = tmp_path_factory.mktemp("ip") / "rec.csv"
    write_csv(path, *cols)
    return traj, read_csv(path), path


def test_csv_time_base_runs_and_header(short_recording):
    traj, data, path = short_recording
    assert path.read_text().splitlines()[0] == "t,y,z,theta,tau"
    dt = np.diff(data["t"])
    assert np.all(dt > 0)
    within = dt[dt < 0.0035]
    assert np.allclose(within, 1e-3, atol=1e-9)
    assert np.all(np.isclose(np.round(data["t"] * 1000), data["t"] * 1000, atol=1e-6))
    gaps = dt[dt >= 0.0035]
    assert len(gaps) == len(traj.runs) - 1 == 1 and np.all(gaps > 0.003)
    assert len(traj.stances) == 8


def test_tau_column_is_the_commanded_ramp_and_zero_in_flight(short_recording):
    traj, data, _ = short_recording
    t, tau = data["t"], data["tau"]
    in_stance = np.zeros(t.size, bool)
    for st in traj.stances:
        sel = (t >= st.t_td) & (t < st.t_lo)
        in_stance |= sel
        ramp = sel & (t < st.t_td + st.cmd.t_f)
        expect = -st.cmd.tau_0 * (1 - (t[ramp] - st.t_td) / st.cmd.t_f)
        assert np.allclose(tau[ramp], expect, atol=2e-6)
        assert np.all(tau[sel & ~ramp] == 0)
    assert np.all(tau[~in_stance] == 0)
    assert np.count_nonzero(tau) > 8 * 40


def test_measurement_quantisation_and_theta_at_touchdown(short_recording):
    traj, data, _ = short_recording
    q = 2 * math.pi / 52000
    assert np.allclose(data["theta"] / q, np.round(data["theta"] / q), atol=1e-3)
    qy = 1.74 * 2 * math.pi / 49152
    assert np.allclose(data["y"] / qy, np.round(data["y"] / qy), atol=1e-2)
    for st in traj.stances:
        assert abs(st.theta_td - st.cmd.theta_td) < 1e-3
    # noise level: measured minus truth
    y, z, th = traj.eval(data["t"])
    assert 0.5e-4 < np.std(data["z"] - z) < 2.5e-4
    assert 2e-4 < np.std(data["theta"] - th) < 1e-3


def _phase_outputs(effects):
    """Outputs of each phase from FIXED inputs, so that phases can be compared separately."""
    plant = Plant(M, effects)
    out = {}
    x_lo = np.array([0.3, 0.19, 1.7, 1.9])
    servo = Servo(0.0, -0.3, -9.0, 0.38, plant.servo_T)
    seg, ta, xa = plant.ascend(0.0, x_lo, servo)
    out["ascent"] = np.array([ta, *xa])
    seg, ttd, xtd, thtd = plant.descend(0.0, np.array([0.0, 0.32, 1.8, 0.0]), Servo(0, 0.38, 0, 0.38))
    out["descent"] = np.array([ttd, *xtd])
    x_td = np.array([0.0, M.rho_0 * math.cos(0.38), 1.8, -1.6])
    r = plant.stance(0.0, x_td, 0.38, StrideCommand(0.38, 6.0, 0.058))
    pre = r.segments[-1].sol(r.t_lo)[2:4]
    out["stance"] = np.array([r.t_lo, *r.segments[-1].sol(r.t_lo)[:4]])
    out["liftoff_factor"] = r.x_lo[2:4] / pre
    return out


NOMINAL = None


@pytest.mark.parametrize("name", [n for n in SPECS if not n.startswith("clean")])
def test_each_effect_changes_only_its_phase(name):
    global NOMINAL
    if NOMINAL is None:
        NOMINAL = _phase_outputs([])
    effects = SPECS[name].make()
    acts = set().union(*(e.acts_in for e in effects))
    got = _phase_outputs(effects)
    changed = {k for k in got if not np.allclose(got[k], NOMINAL[k], rtol=0, atol=1e-10)}
    allowed = set()
    if "flight" in acts:
        allowed |= {"ascent", "descent"}
    if "touchdown" in acts:
        allowed |= {"descent", "stance"}
    if "stance" in acts:
        allowed |= {"stance"}
    if "liftoff" in acts:
        allowed |= {"liftoff_factor"}
    assert changed <= allowed, (name, changed, allowed)
    if acts - {"sensor"}:
        assert changed, f"{name}: no phase output changed"
    else:
        assert not changed


def test_touchdown_losses_act_along_and_across_the_leg():
    th, vy, vz = 0.35, 1.8, -1.7
    e = np.array([-math.sin(th), math.cos(th)])
    n = np.array([-math.cos(th), -math.sin(th)])
    v = np.array([vy, vz])
    a = np.array(fx.TouchdownLossAlong(0.1).touchdown(vy, vz, th, M))
    assert a @ e == pytest.approx(0.9 * (v @ e)) and a @ n == pytest.approx(v @ n)
    c = np.array(fx.TouchdownLossAcross(0.1).touchdown(vy, vz, th, M))
    assert c @ n == pytest.approx(0.9 * (v @ n)) and c @ e == pytest.approx(v @ e)


def test_actuator_effects_need_a_torque_and_sensors_leave_the_physics():
    zero = StrideCommand(0.38, 0.0, 0.058)
    x_td = np.array([0.0, M.rho_0 * math.cos(0.38), 1.8, -1.6])
    base = Plant(M).stance(0.0, x_td, 0.38, zero)
    for eff in (fx.ActuatorGain(0.8), fx.ActuatorDelay(0.01), fx.ActuatorLag(0.01),
                fx.ActuatorSaturation(3.0)):
        r = Plant(M, [eff]).stance(0.0, x_td, 0.38, zero)
        assert r.t_lo == pytest.approx(base.t_lo, abs=1e-9)
        assert np.allclose(r.x_lo, base.x_lo, atol=1e-9)
    # a sensor offset shifts the channel by exactly its value
    rng = np.random.default_rng(3)
    traj = simulate(Plant(M), 2, rng, run_strides=(2, 2))
    quiet = NoiseSpec(y_std=0, z_std=0, theta_std=0, quantise=False)
    t, y, z, th, tau = measure(traj, [], quiet, rng)
    t2, y2, z2, th2, tau2 = measure(traj, [fx.SensorOffset(0.02, "theta")], quiet, rng)
    assert np.allclose(th2 - th, 0.02) and np.array_equal(y, y2) and np.array_equal(z, z2)
    t3, y3, z3, th3, _ = measure(traj, [fx.SensorDelay(0.004, "z")], quiet, rng)
    assert np.allclose(z3[10:200], z[6:196])


def test_recordings_are_reproducible_from_their_seed():
    spec = SPECS["clean_1"]
    a, truth_a, _ = make_recording(spec, strides=3)
    b, truth_b, _ = make_recording(spec, strides=3)
    for u, v in zip(a, b):
        assert np.array_equal(u, v)
    assert truth_a["seed"] == spec.seed and truth_a["strides"] == 3


def test_suite_covers_the_families_and_has_pairs():
    fams, others, pairs = set(), 0, 0
    for name, spec in SPECS.items():
        effs = spec.make()
        fams |= {e.family for e in effs}
        others += sum(e.family == "other" for e in effs) if len(effs) == 1 else 0
        if len(effs) == 2:
            pairs += 1
            assert len({e.site for e in effs}) == 2
        for e in effs:
            d = e.describe()
            assert d["site"] in ("flight", "touchdown", "stance_along_leg", "stance_hip", "liftoff",
                                 "actuator", "sensor_y", "sensor_z", "sensor_theta")
            assert d["direction"] in ("horizontal", "vertical", "along", "across", "both", None)
    assert len(SPECS) >= 22 and others >= 6 and pairs >= 5
    assert fams >= {"flight_resistance", "boom", "touchdown", "stance_leg", "actuator", "liftoff",
                    "sensor", "other"}
