"""Energy terms of the deadbeat controller, (5.1)-(5.5), corrected, and the exact model's
energy bookkeeping they are checked against.

Apex energy (body mass, the only mass in flight and stance): E = m_b (y'^2 / 2 + g z).
Over one stride, E_next - E = W_tau - E_d - E_k - E_c - E_f, with

- W_tau  work of the hip torque, int tau theta' dt                          (5.5)
- E_d    leg damping loss, int d rho'^2 dt over stance                       (5.2), (5.3)
- E_k    spring energy left at lift-off, k (rho_lo - rho_0)^2 / 2            (5.4)
- E_c    lift-off collision loss, m_b |v_lo|^2 (1 - r^2) / 2, r of (2.12)
- E_f    flight damping loss, int m_b (d_h y'^2 + d_v z'^2) dt over both flights.

The thesis keeps E_loss = E_d + E_k; the extended model also loses E_c and E_f, which the
controller must supply too (they are of the same order as E_k).

Corrections to the seed:
- (5.1) swaps y and z: E_tau = m (y'*^2 - y'^2) / 2 + m g (z* - z) + E_loss, apex speeds
  and heights.
- (5.2) integrates d rho' instead of d rho'^2, and from t_lo to 0 (hence the minus sign of
  (5.3)): E_d = int_0^t_lo d rho'^2 dt.
- (5.3) divides by M^2 where it multiplies, and its phase is -phi_2 (= arccos zeta), not phi_3:
  E_d = d M^2 w0 / (4 zeta) [zeta cos(2 psi - phi_2) + 1
        - e^{-2 zeta w0 t_lo} (zeta cos(2 w_d t_lo + 2 psi - phi_2) + 1)],  psi = phi_1 + phi_2.
- (5.4) lacks k.
- (5.5)'s ramp is 1 - t/t_lo (the seed prints 1 - 1/t_lo); with the applied sign of the
  package (tau = -tau_0 (1 - t/t_f)) the work is W_tau = -tau_0 int_0^{min(t_lo, t_f)}
  (1 - t/t_f) theta' dt, positive when running forward.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import quad

from .aas import StanceSolution
from .corrected import chebyshev_nodes
from .exact import StrideResult, ramp_torque
from .flight import flight_state
from .params import ModelParams

_GAUSS_NODES, _GAUSS_WEIGHTS = np.polynomial.legendre.leggauss(24)


def apex_energy(params: ModelParams, apex_height, forward_speed):
    """Mechanical energy of the body at an apex, m_b (y'^2/2 + g z) [J]."""
    return params.body_mass * (0.5 * np.square(forward_speed) + params.gravity * np.asarray(apex_height))


def required_torque_work(params: ModelParams, apex_height, forward_speed, target_height, target_speed, losses):
    """(5.1), corrected: the torque work that brings the next apex to the target [J]."""
    m, g = params.body_mass, params.gravity
    return 0.5 * m * (np.square(target_speed) - np.square(forward_speed)) + m * g * (
        np.asarray(target_height) - apex_height) + losses


def damping_loss(params: ModelParams, stance: StanceSolution, stance_time):
    """E_d (5.2)-(5.3), corrected, on the AAS leg rate (2.18) [J]."""
    xp = stance.xp
    w0, zeta, a = stance.natural_frequency, stance.damping_ratio, stance.decay_rate
    amplitude, phase_2 = stance.amplitude, stance.phase_2
    psi = stance.phase_1 + phase_2
    # d / (4 zeta) = m w0 / 2 keeps the undamped limit finite
    prefactor = params.body_mass * amplitude * amplitude * w0 * w0 / 2.0
    bracket = (zeta * xp.cos(2.0 * psi - phase_2) + 1.0
               - xp.exp(-2.0 * a * stance_time) * (zeta * xp.cos(2.0 * stance.damped_frequency * stance_time + 2.0 * psi - phase_2) + 1.0))
    return prefactor * bracket


def spring_energy_left(params: ModelParams, liftoff_leg_length):
    """E_k (5.4), corrected: k (rho_lo - rho_0)^2 / 2 [J]."""
    return 0.5 * params.stiffness * np.square(np.asarray(liftoff_leg_length) - params.rest_length)


def collision_loss(params: ModelParams, liftoff_ydot, liftoff_zdot):
    """Energy the body loses in the lift-off collision (2.12) [J]."""
    r = params.collision_factor
    return 0.5 * params.body_mass * (np.square(liftoff_ydot) + np.square(liftoff_zdot)) * (1.0 - r * r)


def torque_work(stance: StanceSolution, tau_0, stance_time, ramp_duration):
    """W_tau (5.5), corrected, on the AAS leg angle rate (2.20) [J].

    theta'(t) = X - (2 omega M / rho_0) e^{-a t} cos(w_d t + phi_1); with s = -a + i w_d,
    int_0^T (1 - t/t_f) e^{s t} dt = (e^{sT} - 1)/s - (e^{sT}(sT - 1) + 1)/(s^2 t_f).
    """
    t_f = np.asarray(ramp_duration, dtype=float)
    span = np.minimum(stance_time, t_f)
    s = -np.asarray(stance.decay_rate) + 1j * np.asarray(stance.damped_frequency)
    growth = np.exp(s * span)
    ramp_exp = (growth - 1.0) / s - (growth * (s * span - 1.0) + 1.0) / (s * s * t_f)
    oscillating = np.real(np.exp(1j * np.asarray(stance.phase_1)) * ramp_exp)
    mean_part = stance.mean_angle_rate * (span - span * span / (2.0 * t_f))
    angle_integral = mean_part - 2.0 * stance.angular_rate * stance.amplitude / stance.rest_length * oscillating
    return -np.asarray(tau_0) * angle_integral


def flight_damping_loss(params: ModelParams, duration, ydot0, zdot0):
    """int_0^T m_b (d_h y'^2 + d_v z'^2) dt along the closed-form flight [J] (Gauss-Legendre)."""
    duration = np.asarray(duration, dtype=float)
    t = 0.5 * duration[..., None] * (_GAUSS_NODES + 1.0)
    _, _, ydot, zdot = flight_state(t, 0.0, 0.0, np.asarray(ydot0)[..., None], np.asarray(zdot0)[..., None],
                                    params.gravity, params.flight_damping_horizontal, params.flight_damping_vertical)
    power = params.flight_damping_horizontal * ydot ** 2 + params.flight_damping_vertical * zdot ** 2
    return params.body_mass * 0.5 * duration * (power @ _GAUSS_WEIGHTS)


@dataclass(frozen=True)
class EnergyBudget:
    """One stride's energy flows [J]; `residual` = change of apex energy - (work - losses)."""

    apex_energy: float
    next_apex_energy: float
    torque_work: float
    damping_loss: float
    spring_energy_left: float
    collision_loss: float
    flight_damping_loss: float

    @property
    def losses(self) -> float:
        return self.damping_loss + self.spring_energy_left + self.collision_loss + self.flight_damping_loss

    @property
    def residual(self) -> float:
        return self.next_apex_energy - self.apex_energy - (self.torque_work - self.losses)


def exact_energy_budget(params: ModelParams, stride: StrideResult, tau_0: float, ramp_duration: float) -> EnergyBudget:
    """The exact model's bookkeeping of a stride, by quadrature on its dense stance solution.

    `stride` must come from `exact.simulate_stride(..., sample_period=...)` (dense output).
    """
    if not stride.ok or not stride.stance_solutions or stride.stance_solutions[0].sol is None:
        raise ValueError("need a successful stride simulated with sample_period set (dense output)")
    d = params.damping
    t_end = stride.liftoff.t - stride.touchdown.t

    def integrate(integrand):
        total = 0.0
        for sol in stride.stance_solutions:
            lo, hi = sol.t[0], min(sol.t[-1], t_end)
            if hi > lo:
                total += quad(lambda t: integrand(t, sol.sol(t)), lo, hi, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
        return total

    work = integrate(lambda t, s: float(ramp_torque(t, tau_0, ramp_duration)) * s[3])
    loss_d = integrate(lambda t, s: d * s[2] * s[2])
    apex, td, lo, after, nxt = stride.apex, stride.touchdown, stride.liftoff, stride.liftoff_after_collision, stride.next_apex
    flight = float(flight_damping_loss(params, td.t - apex.t, apex.ydot, 0.0)
                   + flight_damping_loss(params, nxt.t - after.t, after.ydot, after.zdot))
    return EnergyBudget(
        apex_energy=float(apex_energy(params, apex.z, apex.ydot)),
        next_apex_energy=float(apex_energy(params, nxt.z, nxt.ydot)),
        torque_work=work,
        damping_loss=loss_d,
        spring_energy_left=float(spring_energy_left(params, lo.rho)),
        collision_loss=float(collision_loss(params, lo.ydot, lo.zdot)),
        flight_damping_loss=flight,
    )


def corrected_stance_energy(params: ModelParams, prediction, tau_0):
    """(W_tau, E_d) of a corrected-AAS prediction [J]: Clenshaw-Curtis quadrature on its
    stance nodes over [0, T], plus the trapezoid from T to the corrected lift-off t_lo.

    Uses the corrected theta' = p / (m rho^2) and rho' instead of the AAS's (2.18), (2.20);
    the thesis's (5.5) on the AAS's theta' misses the torque's own effect on theta'.
    """
    c = prediction.correction
    m, d = params.body_mass, params.damping
    ramp = np.asarray(prediction.ramp_duration, dtype=float)
    tau_0 = np.asarray(tau_0, dtype=float)
    _, cumulative = chebyshev_nodes(c.t.shape[-1])
    span = c.t[..., -1]
    weights = cumulative[-1] * span[..., None]                  # int_0^T f ~= sum_j w_j f(t_j)
    power = ramp_torque(c.t, tau_0[..., None], ramp[..., None]) * c.momentum / (m * c.leg_length ** 2)
    dissipation = d * c.leg_rate ** 2
    t_lo = np.asarray(prediction.stance_time, dtype=float)
    tail = 0.5 * (t_lo - span)
    power_lo = ramp_torque(t_lo, tau_0, ramp) * np.asarray(prediction.liftoff_theta_dot)
    work = np.sum(weights * power, axis=-1) + tail * (power[..., -1] + power_lo)
    loss = np.sum(weights * dissipation, axis=-1) + tail * (dissipation[..., -1] + d * np.asarray(prediction.liftoff_rho_dot) ** 2)
    return work, loss


def predicted_energy_budget(params: ModelParams, prediction, tau_0, apex_height, forward_speed) -> EnergyBudget:
    """The same flows from a predictor (one stride): the closed forms (5.3), (5.5) on the AAS
    stance, or quadrature on the corrected stance when the prediction carries one."""
    stance = prediction.stance
    t_lo = prediction.stance_time
    r = params.collision_factor
    if prediction.correction is not None:
        work, loss = (float(np.ravel(v)[0]) for v in corrected_stance_energy(params, prediction, tau_0))
    else:
        work = float(torque_work(stance, tau_0, t_lo, prediction.ramp_duration))
        loss = float(damping_loss(params, stance, t_lo))
    flight = (flight_damping_loss(params, prediction.descent_time, forward_speed, 0.0)
              + flight_damping_loss(params, prediction.ascent_time, r * prediction.liftoff_ydot, r * prediction.liftoff_zdot))
    return EnergyBudget(
        apex_energy=float(apex_energy(params, apex_height, forward_speed)),
        next_apex_energy=float(apex_energy(params, prediction.next_apex_height, prediction.next_forward_speed)),
        torque_work=work,
        damping_loss=loss,
        spring_energy_left=float(spring_energy_left(params, prediction.liftoff_rho)),
        collision_loss=float(collision_loss(params, prediction.liftoff_ydot, prediction.liftoff_zdot)),
        flight_damping_loss=float(flight),
    )
