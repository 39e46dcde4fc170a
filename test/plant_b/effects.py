"""Concealed effects for plant B.  Each effect is a small object overriding
one or more hooks of plant.Effect.  Magnitudes are given in the effect's own
parameterisation (see README.md)."""
from __future__ import annotations

import math

import numpy as np

from .plant import Effect


def _sgn(x):
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


# ----------------------------------------------------------- flight resistance
class QuadraticDrag(Effect):
    family, site, unit = "flight_resistance", "flight", "1/m"

    def __init__(self, c):
        self.id = "quadratic_air_drag"
        self.magnitude = self.c = c
        self.words = ("aerodynamic drag quadratic in the body speed acting "
                      "along the velocity in flight (per unit mass)")
        self.equation = "a_drag = -c*|v|*v, v=(y',z'), flight only"

    def parameters(self):
        return {"c_per_m": self.c}

    def flight_accel(self, t, x, ctx):
        sp = math.hypot(x[2], x[3])
        return -self.c * sp * x[2], -self.c * sp * x[3]


# ----------------------------------------------------------------------- boom
class BoomDescentDrag(Effect):
    family, site, unit = "boom", "flight", "1/s"

    def __init__(self, b):
        self.id = "boom_descent_drag"
        self.magnitude = self.b = b
        self.words = ("the boom bearing/counterweight resists vertical motion "
                      "only while the body descends: an extra vertical force "
                      "proportional to the downward speed")
        self.equation = "z'' += -b*z' if z'<0 (flight), else 0"

    def parameters(self):
        return {"b_per_s": self.b}

    def flight_accel(self, t, x, ctx):
        return 0.0, (-self.b * x[3] if x[3] < 0 else 0.0)


class GravityError(Effect):
    family, site, unit = "boom", "flight", "fraction of g"

    def __init__(self, eps):
        self.id = "effective_gravity_error"
        self.magnitude = self.eps = eps
        self.words = ("the effective (boom-corrected) gravity differs from the "
                      "nominal value, in flight and in stance")
        self.equation = "g_true = g_nom*(1+eps) in all phases"

    def parameters(self):
        return {"eps": self.eps}

    def gravity(self, g, ctx):
        return g * (1.0 + self.eps)


# ----------------------------------------------------------------- stance leg
class SofteningSpring(Effect):
    family, site, unit = "stance_leg", "stance_along_leg", "N/m^2"

    def __init__(self, k2):
        self.id = "softening_leg_spring"
        self.magnitude = self.k2 = k2
        self.words = ("the leg spring softens with compression: a negative "
                      "quadratic term in the spring force")
        self.equation = "F_spring = k*x - k2*x^2, x = rho0 - rho"

    def parameters(self):
        return {"k2": self.k2}

    def leg_force(self, F, rho, rhod, th, ctx):
        x = ctx["rho0"] - rho
        return F - self.k2 * x * x


class AsymmetricDamping(Effect):
    family, site, unit = "stance_leg", "stance_along_leg", "N s/m"

    def __init__(self, dd):
        self.id = "extension_extra_damping"
        self.magnitude = self.dd = dd
        self.words = ("leg damping is larger while the leg extends than while "
                      "it compresses (valve-like asymmetric damper)")
        self.equation = "F_damp = -d*rho' - dd*rho' if rho'>0"

    def parameters(self):
        return {"d_extra_extension": self.dd}

    def leg_force(self, F, rho, rhod, th, ctx):
        return F - self.dd * rhod if rhod > 0 else F


# ------------------------------------------------------------------ touchdown
class UnsprungToeImpact(Effect):
    family, site, unit = "touchdown", "touchdown", "kg"

    def __init__(self, m_u):
        self.id = "unsprung_toe_impact"
        self.magnitude = self.m_u = m_u
        self.words = ("an unsprung mass between the spring and the toe hits "
                      "the ground plastically: the body velocity component "
                      "along the leg is reduced by momentum sharing at touchdown")
        self.equation = ("rho'+ = rho'- * m_b/(m_b+m_u); tangential velocity "
                         "unchanged")

    def parameters(self):
        return {"m_u": self.m_u}

    def touchdown(self, vel, toe, th, ctx):
        er = (-math.sin(th), math.cos(th))
        vr = vel[0] * er[0] + vel[1] * er[1]
        f = ctx["m_b"] / (ctx["m_b"] + self.m_u)
        dv = (f - 1.0) * vr
        return (vel[0] + dv * er[0], vel[1] + dv * er[1]), toe


# ---------------------------------------------------------------------- ground
class FloorUndulation(Effect):
    family, site, unit = "ground", "touchdown", "m"

    def __init__(self, a, wavelength, phase):
        self.id = "undulating_floor"
        self.magnitude = self.a = a
        self.L, self.ph = wavelength, phase
        self.words = ("the running surface is not level: its height varies "
                      "sinusoidally along the boom circle (z is logged above "
                      "the nominal level)")
        self.equation = "h(y) = a*sin(2*pi*y/L + phi); toe contact at h"

    def parameters(self):
        return {"a": self.a, "L": self.L, "phi": self.ph}

    def ground_height(self, y):
        return self.a * math.sin(2 * math.pi * y / self.L + self.ph)


# ------------------------------------------------------------------- actuator
class BackEMF(Effect):
    family, site, unit = "actuator", "actuator", "rad/s"

    def __init__(self, w_nl):
        self.id = "backemf_torque_speed"
        self.magnitude = self.w = w_nl
        self.words = ("voltage-limited hip motor: delivered torque falls "
                      "linearly with the leg angular rate (torque-speed line "
                      "with no-load speed w0 at the leg)")
        self.equation = "tau = tau_cmd * max(0, 1 - |theta'|/w0)"

    def parameters(self):
        return {"w0": self.w}

    def hip_torque(self, tau, s, x, ctx):
        return tau * max(0.0, 1.0 - abs(x[3]) / self.w)


class TorqueDeadband(Effect):
    family, site, unit = "actuator", "actuator", "N m"

    def __init__(self, tdb):
        self.id = "torque_deadband"
        self.magnitude = self.tdb = tdb
        self.words = ("hip torque dead band (static friction in the gearbox): "
                      "commands smaller than tau_db produce nothing and larger "
                      "ones are reduced by tau_db")
        self.equation = "tau = sign(tau_cmd)*max(0, |tau_cmd| - tau_db)"

    def parameters(self):
        return {"tau_db": self.tdb}

    def hip_torque(self, tau, s, x, ctx):
        return _sgn(tau) * max(0.0, abs(tau) - self.tdb)


# -------------------------------------------------------------------- liftoff
class EarlyLiftoff(Effect):
    family, site, unit = "liftoff", "liftoff", "N"

    def __init__(self, F_lo):
        self.id = "early_liftoff_threshold"
        self.magnitude = self.F = F_lo
        self.words = ("the toe leaves the ground while the leg still pushes: "
                      "lift-off when the leg force falls to F_lo instead of 0")
        self.equation = "lift-off at k(rho0-rho) - d rho' = F_lo"

    def parameters(self):
        return {"F_lo": self.F}

    def liftoff_threshold(self, ctx):
        return self.F


# --------------------------------------------------------------------- sensors
class ZScale(Effect):
    family, site, unit = "sensor", "sensor_z", "fraction"

    def __init__(self, s):
        self.id = "z_sensor_scale"
        self.magnitude = self.s = s
        self.words = "the height encoder has a scale-factor error"
        self.equation = "z_meas = (1+s)*z"

    def parameters(self):
        return {"s": self.s}

    def sensor(self, t, y, z, th):
        return y, z * (1.0 + self.s), th


class ThetaDelay(Effect):
    family, site, unit = "sensor", "sensor_theta", "s"

    def __init__(self, delay):
        self.id = "theta_sensor_delay"
        self.magnitude = self.delay = delay
        self.words = "the leg-angle channel is logged late by a constant delay"
        self.equation = "theta_meas(t) = theta(t - delay)"

    def parameters(self):
        return {"delay": self.delay}

    def theta_delay(self):
        return self.delay


class ThetaBacklash(Effect):
    family, site, unit = "sensor", "sensor_theta", "rad"

    def __init__(self, width):
        self.id = "theta_encoder_backlash"
        self.magnitude = self.b = width
        self.words = ("gear backlash between leg and angle encoder: the "
                      "reading lags by half the play after each reversal")
        self.equation = ("theta_meas = clamp(theta_meas_prev, theta - b/2, "
                         "theta + b/2)")

    def parameters(self):
        return {"b": self.b}

    def sensor(self, t, y, z, th):
        out = np.empty_like(th)
        h = 0.5 * self.b
        m = th[0]
        for i, v in enumerate(th):
            m = min(max(m, v - h), v + h)
            out[i] = m
        return y, z, out


# ----------------------------------------------------------------------- other
class CoggingRipple(Effect):
    family, site, unit = "other", "stance_hip", "N m"

    def __init__(self, A, period, phase):
        self.id = "hip_cogging_ripple"
        self.magnitude = self.A = A
        self.P, self.ph = period, phase
        self.words = ("a torque ripple periodic in the leg angle (cogging / "
                      "belt-tooth) adds to the hip torque during stance")
        self.equation = "tau += A*sin(2*pi*theta/P + phi) in stance"

    def parameters(self):
        return {"A": self.A, "P": self.P, "phi": self.ph}

    def hip_torque(self, tau, s, x, ctx):
        return tau + self.A * math.sin(2 * math.pi * x[1] / self.P + self.ph)


class StiffnessDrift(Effect):
    family, site, unit = "other", "stance_along_leg", "fraction at end"

    def __init__(self, frac):
        self.id = "spring_stiffness_drift"
        self.magnitude = self.f = frac
        self.words = ("the leg spring stiffness drifts linearly over the "
                      "recording (spring heating), from k at the first stride "
                      "to k*(1+f) at the last")
        self.equation = "k_n = k*(1 + f*n/(N-1)), n = stride index"

    def parameters(self):
        return {"f": self.f}

    def stiffness(self, k, ctx):
        N = max(ctx.get("n_strides", 50) - 1, 1)
        return k * (1.0 + self.f * min(ctx.get("stride", 0), N) / N)


class TorqueAxialCoupling(Effect):
    family, site, unit = "other", "stance_along_leg", "1/m"

    def __init__(self, kappa):
        self.id = "hip_torque_axial_coupling"
        self.magnitude = self.kappa = kappa
        self.words = ("the hip transmission loads the leg axially: an along-leg "
                      "force proportional to the commanded hip torque")
        self.equation = "F_leg += kappa*tau_cmd (tau_cmd<0 when pushing forward)"

    def parameters(self):
        return {"kappa": self.kappa}

    def leg_force(self, F, rho, rhod, th, ctx):
        return F + self.kappa * ctx.get("tau_cmd", 0.0)


class BoomRinging(Effect):
    family, site, unit = "other", "flight", "m/s^2"

    def __init__(self, A, freq, T):
        self.id = "boom_ringing_after_liftoff"
        self.magnitude = self.A = A
        self.f, self.T = freq, T
        self.words = ("the flexible boom rings after lift-off: a decaying "
                      "oscillatory vertical acceleration in flight")
        self.equation = ("z'' += A*exp(-(t-t_lo)/T)*sin(2*pi*f*(t-t_lo)), "
                         "flight after each lift-off")

    def parameters(self):
        return {"A": self.A, "f": self.f, "T": self.T}

    def flight_accel(self, t, x, ctx):
        t_lo = ctx.get("t_lo")
        if t_lo is None or t < t_lo:
            return 0.0, 0.0
        u = t - t_lo
        return 0.0, self.A * math.exp(-u / self.T) * math.sin(2 * math.pi * self.f * u)


class TetherPull(Effect):
    family, site, unit = "other", "flight", "N"

    def __init__(self, F):
        self.id = "umbilical_tether_pull"
        self.magnitude = self.F = F
        self.words = ("the power umbilical drags behind the robot: a constant "
                      "backward horizontal force in all phases")
        self.equation = "m_b*y'' += -F in flight; Cartesian force (-F,0) in stance"

    def parameters(self):
        return {"F": self.F}

    def flight_accel(self, t, x, ctx):
        return -self.F / ctx["m_b"], 0.0

    def stance_force(self, s, x, ctx):
        return -self.F, 0.0


class HeavierLiftoffCollision(Effect):
    family, site, unit = "liftoff", "liftoff", "kg"

    def __init__(self, dm):
        self.id = "harder_liftoff_collision"
        self.magnitude = self.dm = dm
        self.words = ("the lift-off collision with the leg stopper takes more "
                      "momentum than the nominal toe mass explains: an extra "
                      "effective mass dm joins the body at lift-off")
        self.equation = ("v+ = v- * m_b/(m_b+m_t+dm) instead of "
                         "m_b/(m_b+m_t)")

    def parameters(self):
        return {"dm": self.dm}

    def liftoff(self, vel, ctx):
        f = (ctx["m_b"] + ctx["m_t"]) / (ctx["m_b"] + ctx["m_t"] + self.dm)
        return (vel[0] * f, vel[1] * f)
