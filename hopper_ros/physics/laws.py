"""The laws of the extended TD-SLIP model and of every effect it can be extended with, written once.

Every integrator of the package builds its dynamics from these functions: the simulated robot's
plant (`hopper_ros.sim.plant`, scalars), the vectorised re-simulation of recorded strides
(`hopper_ros.physics.lanes`, numpy arrays of lanes) used by identification and diagnosis, and the
exact model's stance (`hopper_ros.physics.exact`, the leg force and the ramp). The functions
broadcast: the same code runs on floats and on arrays.

A law is parameterised by `Coefficients`: the model's own (Table 4.1) and one coefficient per
physical mechanism the model leaves out, each with a value that switches it off (0, or 1 for a
gain, inf for a limit). The named, documented effects of `hopper_ros.physics.effects` set these
coefficients; the mismatch tool's discovered terms set the `*_terms` coefficients, sums of
`coefficient x term(state)` over the term libraries of `physics.terms` (docs/diagnosis.md derives each).

Sites: flight accelerations; the touchdown velocity reset; the stance force along the leg; the
torque about the hip in stance; the actuator between the commanded and the applied hip torque;
the lift-off velocity reset (2.12). Sensors are applied where a recording is compared.

One text, three callers: Python floats, numpy arrays of lanes, and the compiled lanes
(`hopper_ros.physics.compiled` has numba compile these same functions for one lane's floats, a
`Coefficients` there being one record of a structured array with the same field names). So a law
uses numpy's ufuncs (`np.sqrt`, `np.tanh`, ..., which numba compiles for floats) and, where numba
takes no float, the helpers of `physics.broadcast` (`where`, `clip`, `ones_like`, `nan_to_num`, `nonzero`)
and `is_on` below, which the compiled module overloads with their scalar forms; no sets, lambdas or dataclasses in a law.
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass, field, fields

import numpy as np

# The helpers and the term libraries are part of laws' namespace (`laws.where`, `laws.LEG_TERMS`, ...):
# physics.compiled overloads and compiles them from here, the diagnosis reads the libraries from here.
from .broadcast import SMOOTH_SPEED, clip, nan_to_num, nonzero, ones_like, smooth_sign, where  # noqa: F401
from .terms import (FLIGHT_Y_TERMS, FLIGHT_Z_TERMS, HINGES, HIP_TERMS, JUMP_TERMS, LEG_TERMS,  # noqa: F401
                    TERM_LIBRARIES, TermLibrary, flight_y_term, flight_z_term, hip_term, jump_term, leg_term,
                    sum_terms, zero_terms)


def ramp_torque(t_stance, tau_0, ramp_duration):
    """Applied hip torque of (2.32) with the robot's sign: -tau_0 (1 - t/t_f) on [0, t_f), 0 otherwise.

    Broadcasts over arrays of times (from touchdown), torques and ramp durations; the one ramp
    of the package.
    """
    inside = (t_stance >= 0.0) & (t_stance < ramp_duration)
    return where(inside, -tau_0 * (1.0 - t_stance / where(inside, ramp_duration, 1.0)), 0.0)


def ramp_impulse(t_stance, tau_0, ramp_duration):
    """The integral of (2.32)'s ramp from the touchdown to `t_stance` [N m s]: the angular impulse it gave
    so far (0 before the touchdown, -tau_0 t_f / 2 once it is over). Floats only."""
    t = min(max(t_stance, 0.0), ramp_duration)
    return -tau_0 * (t - t * t / (2.0 * ramp_duration)) if ramp_duration > 0.0 else 0.0


def mean_ramp_torque(t_from, t_to, tau_0, ramp_duration):
    """(2.32)'s ramp averaged over [t_from, t_to) (times from the touchdown): the constant torque that gives
    the same impulse there, for a drive that holds each setting for a period. Floats only."""
    return (ramp_impulse(t_to, tau_0, ramp_duration) - ramp_impulse(t_from, tau_0, ramp_duration)) / (t_to - t_from)


# ---------------------------------------------------------------------------- coefficients


@dataclass(frozen=True)
class Coefficients:
    """Everything the laws need, SI units. Floats for one robot, arrays (one entry per lane) for many.

    The first eight are the extended TD-SLIP model (Table 4.1); every other field is off at its default.
    """

    mass: object = 2.20                     # m_b [kg]
    stiffness: object = 4696.0              # k [N/m]
    damping: object = 9.87                  # d [N s/m]
    rest_length: object = 0.205             # rho_0 [m]
    gravity: object = 11.42                 # g [m/s^2]
    flight_damping_y: object = 0.01         # d_h^f [1/s] (2.8)
    flight_damping_z: object = 0.23         # d_v^f [1/s] (2.8)
    collision_factor: object = 2.20 / 2.23  # m_b / (m_b + m_t) (2.12)
    # flight
    quadratic_drag: object = 0.0            # c [1/m]: a = -c |v| v
    flight_friction_y: object = 0.0         # [m/s^2] dry friction of the boom about its vertical axis
    flight_friction_z: object = 0.0         # [m/s^2] ... about its horizontal axis
    stance_friction_y: object = 0.0         # [m/s^2] the vertical axis's dry friction in stance too (a bearing turns
    #                                         whenever the body moves forward, not only in flight)
    horizontal_mass_ratio: object = 0.0     # r: horizontal effective mass m_b (1 + r) (the boom's inertia)
    track_gravity: object = 0.0             # [m/s^2] gravity along the track (a tilted boom axis), every phase
    boom_curvature: object = 0.0            # 1/R^2 [1/m^2]: the body carried on the boom's sphere of radius R ...
    boom_pivot_height: object = 0.0         # z_p [m]  ... about a pivot at this height, every phase (`boom_sphere`),
    boom_sine_reading: object = 1.0         #   its height read as R sin(elevation) (1) or along the arc (0)
    # touchdown
    touchdown_loss_along: object = 0.0      # share of the velocity along the leg lost at touchdown
    touchdown_loss_across: object = 0.0     # share of the velocity across the leg lost at touchdown
    ground_height: object = 0.0             # [m] where the toe meets the ground, above the model's z = 0
    # stance, along the leg
    spring_cubic: object = 0.0              # k_3 [N/m^3]: + k_3 (rho_0 - rho)^3
    spring_quadratic: object = 0.0          # k_2 [N/m^2]: + k_2 (rho_0 - rho)^2 (< 0: a spring that softens)
    spring_preload: object = 0.0            # F_p [N]: + F_p (a spring preloaded against the leg's stop)
    quadratic_damping: object = 0.0         # d_2 [N s^2/m^2]: - d_2 |rho'| rho'
    leg_friction: object = 0.0              # F_c [N]: - F_c tanh(rho'/v_s)
    leg_hysteresis: object = 0.0            # F_h [N]: + F_h q, q a Bouc-Wen element's state (`hysteresis_rate`)
    leg_hysteresis_yield: object = 0.002    # x_y [m]: the compression over which q turns after a reversal
    leg_relaxing_stiffness: object = 0.0    # k_r [N/m]: + F_r, a spring in series with a damper (`relaxation_rate`) ...
    leg_relaxation_time: object = 0.03      # tau_r [s]  ... that lets F_r relax in this time, ...
    leg_relaxation_curvature: object = 0.0  # 1/L [1/m]  ... an air spring's stiffening (0: a linear spring)
    ground_stiffness: object = 0.0          # k_g [N/m], 0 = rigid ground
    ground_damping: object = 250.0          # d_g [N s/m]
    ground_friction: object = math.inf      # mu [1]: the toe slides where |G_y| > mu G_z (inf: it never slips)
    foot_radius: object = 0.0               # r_f [m]: the toe a ball of radius r_f rolling on the ground
    # the hip actuator
    torque_gain: object = 1.0               # applied / commanded
    torque_offset: object = 0.0             # [N m] added in stance
    torque_delay: object = 0.0              # [s] command -> torque
    torque_lag: object = 0.0                # [s] first-order time constant
    torque_limit: object = math.inf         # [N m] |tau| <= limit
    torque_speed_slope: object = 0.0        # [s/rad] the torque falls by this share per rad/s of the leg's sweep
    torque_dead_band: object = 0.0          # [N m] the first delta of every command is lost (a gearbox's static
    #                                         friction seen through the command: small commands give no torque)
    hip_viscous: object = 0.0               # [N m s/rad] - b theta'
    hip_friction: object = 0.0              # [N m] - f tanh(theta'/w_s)
    rotor_inertia: object = 0.0             # J [kg m^2] about the hip: the motor's rotor through the gear (J_r N^2)
    hip_ripple_sin: object = 0.0            # [N m] a torque ripple periodic in the leg angle (cogging, a gear's
    hip_ripple_cos: object = 0.0            # [N m]   eccentricity): a sin(2 pi theta/P) + b cos(2 pi theta/P)
    hip_ripple_period: object = 1.0         # P [rad] of the leg angle
    drive_voltage: object = 0.0             # V [V] the drive's voltage over the winding, against the back-EMF (0: the
    winding_resistance: object = 1.0        # R [ohm]  current is not limited by it; `voltage_limited`)
    motor_constant: object = 0.627          # k = G k_t [N m/A] at the hip (hardware.yaml: 26 x 0.02411)
    servo_stiffness: object = 0.0           # K_p [N m/rad] the flight's position servo still holding theta_td ...
    servo_release: object = 0.0             # t_h [s] ... this long after touchdown (`servo_hold`)
    # discovered terms (coefficients of the term libraries of physics.terms)
    flight_y_terms: tuple = field(default_factory=lambda: zero_terms("flight_y"))
    flight_z_terms: tuple = field(default_factory=lambda: zero_terms("flight_z"))
    leg_terms: tuple = field(default_factory=lambda: zero_terms("leg"))
    hip_terms: tuple = field(default_factory=lambda: zero_terms("hip"))
    touchdown_along_terms: tuple = field(default_factory=lambda: zero_terms("touchdown_along"))
    touchdown_across_terms: tuple = field(default_factory=lambda: zero_terms("touchdown_across"))
    liftoff_along_terms: tuple = field(default_factory=lambda: zero_terms("liftoff_along"))
    liftoff_across_terms: tuple = field(default_factory=lambda: zero_terms("liftoff_across"))
    flight_z_knot: object = 0.0             # [m] height z_k above which the flight term z>z_k acts
    leg_knot: object = 0.0                  # [m] compression x_k beyond which the leg term x>x_k acts

    @classmethod
    def from_model(cls, params, **changes) -> "Coefficients":
        """The coefficients of a `ModelParams` (the extended TD-SLIP model), extras off unless given."""
        base = dict(mass=params.body_mass, stiffness=params.stiffness, damping=params.damping,
                    rest_length=params.rest_length, gravity=params.gravity,
                    flight_damping_y=params.flight_damping_horizontal,
                    flight_damping_z=params.flight_damping_vertical, collision_factor=params.collision_factor)
        base.update(changes)
        return cls(**base)

    def replace(self, **changes) -> "Coefficients":
        return Coefficients(**{**self.as_dict(), **changes})

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @staticmethod
    def scalar_names() -> tuple:
        return tuple(f.name for f in fields(Coefficients) if not f.name.endswith("_terms"))

    @staticmethod
    def term_names() -> tuple:
        return tuple(f.name for f in fields(Coefficients) if f.name.endswith("_terms"))


def active(c: Coefficients) -> frozenset:
    """Names of the extra coefficients that are on in any lane (cached on the instance: the laws test it often)."""
    cached = c.__dict__.get("_active")
    if cached is None:
        on = set()
        for name in GATED:
            if np.any(np.asarray(getattr(c, name)) != 0.0):
                on.add(name)
        if np.any(np.isfinite(np.asarray(c.ground_friction))):
            on.add("ground_friction")
        for name in Coefficients.term_names():
            if any(np.any(np.asarray(v) != 0.0) for v in getattr(c, name)):
                on.add(name)
        cached = frozenset(on)
        object.__setattr__(c, "_active", cached)
    return cached


# the coefficients whose law is skipped where they are 0 (`is_on`); ground_friction is on where finite, and a
# `*_terms` field where any of its coefficients is not 0
GATED = ("quadratic_drag", "flight_friction_y", "flight_friction_z", "track_gravity", "boom_curvature", "spring_cubic",
         "spring_quadratic",
         "spring_preload",
         "quadratic_damping", "leg_friction", "leg_hysteresis", "leg_relaxing_stiffness", "hip_viscous", "hip_friction",
         "hip_ripple_sin", "hip_ripple_cos",
         "ground_stiffness", "rotor_inertia", "drive_voltage", "servo_stiffness", "foot_radius", "torque_dead_band",
         "torque_speed_slope", "stance_friction_y")


def is_on(c: Coefficients, name: str) -> bool:
    """Whether the law of coefficient `name` acts in any lane of `c` (compiled: in this lane)."""
    return name in active(c)


# ---------------------------------------------------------------------------- flight

FlightContext = namedtuple("FlightContext", "y z ydot zdot knot")


def flight_acceleration(c: Coefficients, y, z, ydot, zdot):
    """Body acceleration in flight (y'', z''): (2.8) y'' = -d_h y', z'' = -g - d_v z', plus the flight effects."""
    ay = -c.flight_damping_y * ydot
    az = -c.gravity - c.flight_damping_z * zdot
    if is_on(c, "quadratic_drag"):
        speed = np.sqrt(ydot * ydot + zdot * zdot)
        ay = ay - c.quadratic_drag * speed * ydot
        az = az - c.quadratic_drag * speed * zdot
    if is_on(c, "flight_friction_y"):
        ay = ay - c.flight_friction_y * smooth_sign(ydot)
    if is_on(c, "flight_friction_z"):
        az = az - c.flight_friction_z * smooth_sign(zdot)
    if is_on(c, "track_gravity"):
        ay = ay + c.track_gravity
    if is_on(c, "boom_curvature"):
        sphere_y, sphere_z = boom_sphere(c, z, ydot, zdot)
        ay, az = ay + sphere_y, az + sphere_z
    if is_on(c, "flight_y_terms") or is_on(c, "flight_z_terms"):
        context = FlightContext(y, z, ydot, zdot, c.flight_z_knot)
        ay = ay + sum_terms(flight_y_term, c.flight_y_terms, context) / c.mass
        az = az + sum_terms(flight_z_term, c.flight_z_terms, context) / c.mass
    return ay, az


def boom_sphere(c: Coefficients, z, ydot, zdot):
    """(y'', z'') the boom's sphere adds in every phase: the body moves on a sphere of radius R about the boom's
    pivot, at z_p in the model's heights, where the model has a plane. With the elevation beta, the azimuth phi,
    y' ~ R phi' and the sphere's equations R beta'' = -g cos beta - R phi'^2 sin beta cos beta + F_beta/m and
    d/dt(cos^2 beta phi') = 0, to the first order beyond the plane (b = (z - z_p)/R):

        y'' += 2 (z - z_p) z' y'/R^2                 (Coriolis: the angular momentum about the vertical axis)
        z'' += -(z - z_p) y'^2/R^2 + g b^2/2         the height read along the arc, z - z_p = R beta
        z'' += -(z - z_p) (y'^2 + z'^2)/R^2 + g b^2  the height read as R sin beta (hardware.encoders)

    (the forward speed's centripetal acceleration along the elevation; gravity's share along it, g cos beta, and
    for a height read as R sin beta its cos beta once more and the reading's own curve). `boom_curvature` is
    1/R^2, `boom_sine_reading` 1 for the height read as R sin beta, 0 along the arc."""
    height = z - c.boom_pivot_height
    lever = c.boom_curvature * height
    sine = c.boom_sine_reading
    return 2.0 * lever * zdot * ydot, lever * (0.5 * (1.0 + sine) * c.gravity * height - sine * zdot * zdot
                                               - ydot * ydot)


# ---------------------------------------------------------------------------- stance

StanceContext = namedtuple("StanceContext", "rho rho_dot compression theta theta_dot theta_td since_touchdown torque "
                                            "command knot")


def stance_context(rho, rho_dot, rest_length, theta, theta_dot, theta_td, since_touchdown, torque, command, knot):
    """The quantities a stance term may depend on (`leg_term`, `hip_term`); compression = rho_0 - rho."""
    return StanceContext(rho, rho_dot, rest_length - rho, theta, theta_dot, theta_td, since_touchdown, torque,
                         command, knot)


def leg_force(c: Coefficients, rho, rho_dot):
    """Spring-damper force along the leg, k (rho_0 - rho) - d rho' (2.9), zero at lift-off (2.28), plus the
    along-the-leg effects other than the discovered terms (quadratic and cubic spring, preload, quadratic damping, dry
    friction)."""
    x = c.rest_length - rho
    force = c.stiffness * x - c.damping * rho_dot
    if is_on(c, "spring_cubic"):
        force = force + c.spring_cubic * x ** 3
    if is_on(c, "spring_quadratic"):
        force = force + c.spring_quadratic * x ** 2
    if is_on(c, "spring_preload"):
        force = force + c.spring_preload
    if is_on(c, "quadratic_damping"):
        force = force - c.quadratic_damping * np.abs(rho_dot) * rho_dot
    if is_on(c, "leg_friction"):
        force = force - c.leg_friction * smooth_sign(rho_dot)
    return force


def hysteresis_rate(c: Coefficients, q, compression_rate):
    """The rate of the leg's hysteresis state q in [-1, 1] (`leg_hysteresis`: the force F_h q along the leg), a
    Bouc-Wen element (Bouc 1967, Wen 1976; n = 1, beta = gamma = 1/2) in the compression x = rho_0 - rho:

        x_y q' = x' - (|x'| q + x' |q|) / 2

    rate-independent: after each reversal of the compression q turns over x_y (elastic, then saturating at
    +-1 the way it moves), unlike a dry friction, which turns with the speed's sign. Reset to 0 at touchdown."""
    return (compression_rate - 0.5 * (np.abs(compression_rate) * q + compression_rate * np.abs(q))) \
        / c.leg_hysteresis_yield


AIR_ADIABATIC_INDEX = 1.4    # gamma of air: an air spring compressed faster than it exchanges heat


def relaxation_rate(c: Coefficients, relaxing_force, compression, compression_rate):
    """The rate of the leg's relaxing force F_r (`leg_relaxing_stiffness`: + F_r along the leg): air trapped in the
    leg's telescope (piston area A, a chamber of length L = V_0 / A at rest), compressed adiabatically and leaking
    out through an orifice in tau_r (Raibert's hoppers' legs were air springs). With p A = p_a A + F_r, pV^gamma
    constant but for the leak, and k_r = gamma p_a A / L (the small-signal stiffness gamma p_a A^2 / V_0):

        F_r' = (k_r + gamma F_r / L) x' / (1 - x / L) - F_r / tau_r,   x = rho_0 - rho

    With 1/L = 0 (`leg_relaxation_curvature`) it is a linear spring k_r in series with a damper (a Maxwell element
    beside the leg's spring: an elastomer's or a polymer spring's creep). Either way stiff (k + k_r) in a compression
    fast against tau_r, the spring's own k in a slow one, and energy lost between. Reset to 0 at touchdown (relaxed
    in flight)."""
    curvature = c.leg_relaxation_curvature
    return ((c.leg_relaxing_stiffness + AIR_ADIABATIC_INDEX * curvature * relaxing_force) * compression_rate
            / (1.0 - curvature * compression) - relaxing_force / c.leg_relaxation_time)


def hip_losses(c: Coefficients, theta, theta_dot):
    """Friction in the hip joint, -b theta' - f tanh(theta'/w_s), and a ripple periodic in the leg angle
    (a motor's cogging or a gear's eccentricity seen through the gear), a sin(2 pi theta/P) + b cos(2 pi theta/P),
    added to the applied torque."""
    loss = 0.0
    if is_on(c, "hip_viscous"):
        loss = loss - c.hip_viscous * theta_dot
    if is_on(c, "hip_friction"):
        loss = loss - c.hip_friction * smooth_sign(theta_dot)
    if is_on(c, "hip_ripple_sin") or is_on(c, "hip_ripple_cos"):
        phase = 2.0 * np.pi * theta / c.hip_ripple_period
        loss = loss + c.hip_ripple_sin * np.sin(phase) + c.hip_ripple_cos * np.cos(phase)
    return loss


StanceForces = namedtuple("StanceForces", [
    "sin", "cos", "rho", "rho_dot",
    "force",         # along the leg [N]
    "torque",        # about the hip [N m], the applied torque plus hip losses and terms
    "depth_rate",    # toe sinking rate into a compliant ground [m/s]
    "toe_rate",      # the toe's forward sliding speed on a ground of finite friction [m/s]
    "ydd", "zdd",
    "hysteresis_rate",      # the rate of the leg's hysteresis state (`hysteresis_rate`)
    "relaxation_rate"])     # the rate of the leg's relaxing force (`relaxation_rate`)


def stance_forces(c: Coefficients, y, z, ydot, zdot, depth, toe_y, torque, command=0.0, theta_td=0.0,
                  since_touchdown=0.0, compliant=None, hysteresis=0.0, relaxation=0.0) -> StanceForces:
    """Stance dynamics (2.9) in Cartesian form about the toe at (toe_y, ground_height - depth).

        e_rho = (-sin theta, cos theta),   e_theta = (-cos theta, -sin theta)
        m y'' = (F e_rho,y + (tau/rho) e_theta,y) / (1 + r)
        m z'' =  F e_rho,z + (tau/rho) e_theta,z - m g

    F is `leg_force` plus the discovered along-the-leg terms, tau the applied torque plus `hip_losses` and
    the discovered hip terms, r the horizontal mass ratio of the boom; `hysteresis` the leg's hysteresis state q
    (`leg_hysteresis`: + F_h q in F), `relaxation` the leg's relaxing force F_r (`leg_relaxing_stiffness`: + F_r in
    F). A compliant ground holds the
    massless toe with k_g depth + d_g depth' = the force's vertical component; depth' enters rho'. On a
    ground of finite friction the toe slides (`toe_slip_rate`); its speed enters rho' the same way.
    `compliant` (per lane) defaults to ground_stiffness > 0.

    A round toe (`foot_radius` r_f > 0): the leg's end is a ball of radius r_f, rigid with the leg, that rolls on
    the ground without slipping. `toe_y` is then the ball's centre, r_f above the ground (`foot_offset`), the hip
    at (rho - r_f) e_rho from it, and the centre moves -r_f theta' (the contact point rolls r_f per radian the
    leg turns: forward as the leg sweeps back), a state like the sliding toe's. The contact point P is r_f below
    the centre, the hip at (rho - r_f) e_rho + r_f e_z from it, so (2.9)'s kinematics become, with
    a = rho - r_f + r_f cos theta (the hip's distance from P along the leg):

        v = (rho' + r_f sin theta theta') e_rho + a theta' e_theta
        => theta' = v . e_theta / a,   rho' = v . e_rho - r_f sin theta theta'

    The massless leg passes the ground's force at P to the hip: F along the leg (2.9's spring and damper in
    rho), and across it what balances tau about the hip, (P - hip) x G + tau = 0:

        m y'' = (F e_rho,y + X e_theta,y) / (1 + r),   m z'' = F e_rho,z + X e_theta,z - m g,
        X = (tau - r_f F sin theta) / a

    (X = tau/rho at r_f = 0; the body's power F rho' + tau theta', as in (2.9)'s Lagrangian: the same equations
    with p = c + (rho - r_f) e_rho and c = (c_td - r_f (theta - theta_td), r_f) in (2.9)'s L.) The touchdown
    comes r_f (1 - cos theta) higher (`touchdown_height`, the guard of (2.3)) and lift-off is (2.28)'s, in rho.
    Beside a compliant ground, a sliding toe or a rotor's inertia the ball's rolling is added to their laws as
    they are written for a point toe.
    """
    dy, hz = foot_offset(c, y, z, depth, toe_y)
    rho = np.sqrt(dy * dy + hz * hz)
    sin, cos = -dy / rho, hz / rho
    approach = -sin * ydot + cos * zdot                     # rho' with the toe at rest
    theta = 0.0                                             # the leg angle, computed only where a law reads it
    if (is_on(c, "hip_ripple_sin") or is_on(c, "hip_ripple_cos") or is_on(c, "servo_stiffness")
            or is_on(c, "hip_terms") or is_on(c, "leg_terms")):
        theta = np.arctan2(-dy, hz)
    theta_dot = (-ydot * hz + dy * zdot) / (rho * rho)
    arm = rho
    if is_on(c, "foot_radius"):     # the ball rolls: the hip turns about the contact point, r_f below the centre
        arm = rho + c.foot_radius * cos
        theta_dot = (-ydot * cos - zdot * sin) / arm
        approach = approach - c.foot_radius * sin * theta_dot
        rho = rho + c.foot_radius
    if is_on(c, "drive_voltage"):
        torque = voltage_limited(c, torque, theta_dot)
    if is_on(c, "torque_speed_slope"):
        torque = speed_derated(c, torque, theta_dot)
    tau = torque + hip_losses(c, theta, theta_dot)
    if is_on(c, "servo_stiffness"):
        tau = tau + servo_hold(c, theta, theta_td, since_touchdown)
    if is_on(c, "hip_terms"):
        hip_context = stance_context(rho, approach, c.rest_length, theta, theta_dot, theta_td, since_touchdown,
                                     torque, command, 0.0)
        tau = tau + sum_terms(hip_term, c.hip_terms, hip_context)
    spring_only = leg_force(c, rho, approach) + c.damping * approach     # the force's parts without d rho'
    if is_on(c, "leg_hysteresis"):
        spring_only = spring_only + c.leg_hysteresis * hysteresis
    if is_on(c, "leg_relaxing_stiffness"):
        spring_only = spring_only + relaxation
    if is_on(c, "leg_terms"):
        leg_context = stance_context(rho, approach, c.rest_length, theta, theta_dot, theta_td, since_touchdown,
                                     tau, command, c.leg_knot)
        spring_only = spring_only + sum_terms(leg_term, c.leg_terms, leg_context)
    if is_on(c, "rotor_inertia"):
        tau = rotor_torque(c, tau, spring_only - c.damping * approach, sin, cos, rho, approach, theta_dot)
    depth_rate = 0.0
    if is_on(c, "ground_stiffness"):
        push = (spring_only - c.damping * approach) * cos - tau / rho * sin
        rate = (push - c.ground_stiffness * depth) / (c.ground_damping + c.damping * cos * cos)
        depth_rate = where(c.ground_stiffness > 0.0 if compliant is None else compliant, rate, 0.0)
    rho_dot = approach + cos * depth_rate
    across = tau / rho
    toe_rate = 0.0
    if is_on(c, "ground_friction"):
        toe_rate = toe_slip_rate(c, spring_only - c.damping * rho_dot, across, sin, cos)
        rho_dot = rho_dot + sin * toe_rate
    force = spring_only - c.damping * rho_dot
    if is_on(c, "foot_radius"):     # the force acts from the contact point: X balances tau about the hip
        across = (tau - c.foot_radius * force * sin) / arm
        toe_rate = toe_rate - c.foot_radius * theta_dot
    ydd = (-force * sin - across * cos) / (c.mass * (1.0 + c.horizontal_mass_ratio))
    if is_on(c, "track_gravity"):
        ydd = ydd + c.track_gravity
    if is_on(c, "stance_friction_y"):       # the boom's bearing brakes the forward motion in stance as in flight
        ydd = ydd - c.stance_friction_y * smooth_sign(ydot)
    zdd = (force * cos - across * sin) / c.mass - c.gravity
    if is_on(c, "boom_curvature"):
        sphere_y, sphere_z = boom_sphere(c, z, ydot, zdot)
        ydd, zdd = ydd + sphere_y, zdd + sphere_z
    q_rate = 0.0
    if is_on(c, "leg_hysteresis"):
        q_rate = hysteresis_rate(c, hysteresis, -rho_dot)
    r_rate = 0.0
    if is_on(c, "leg_relaxing_stiffness"):
        r_rate = relaxation_rate(c, relaxation, c.rest_length - rho, -rho_dot)
    return StanceForces(sin, cos, rho, rho_dot, force, tau, depth_rate, toe_rate, ydd, zdd, q_rate, r_rate)


def voltage_limited(c: Coefficients, torque, theta_dot):
    """The torque a current-controlled hip motor delivers when its drive's voltage V over the winding's resistance R
    limits the current against the back-EMF of the leg's sweep (motor speed G theta'; k = G k_t, and k_t [N m/A] =
    [V s/rad]): i in [(-V - k theta')/R, (V - k theta')/R], so

        tau in [-k V/R - (k^2/R) theta',  k V/R - (k^2/R) theta']

    a torque limit that falls with the speed in the direction the motor drives (not a fixed saturation). Lanes with
    `drive_voltage` 0 are not limited."""
    k, r = c.motor_constant, c.winding_resistance
    electrical = k * k / r * theta_dot
    stall = k * c.drive_voltage / r
    return where(c.drive_voltage > 0.0, clip(torque, -stall - electrical, stall - electrical), torque)


def speed_derated(c: Coefficients, torque, theta_dot):
    """The torque left of a motor whose torque falls linearly with its speed, tau (1 - s |theta'|), none from the
    no-load sweep 1/s on (a torque-speed line: a drive that derates with the back-EMF, not a fixed clip)."""
    return torque * np.maximum(1.0 - c.torque_speed_slope * np.abs(theta_dot), 0.0)


def servo_hold(c: Coefficients, theta, theta_td, since_touchdown):
    """The flight's position servo released `servo_release` (t_h) after touchdown instead of at it: until then it
    pulls the sweeping leg back toward the angle it held, -K_p (theta - theta_td) for 0 <= t - t_td < t_h."""
    held = (since_touchdown >= 0.0) & (since_touchdown < c.servo_release)
    return where(held, -c.servo_stiffness * (theta - theta_td), 0.0)


def rotor_torque(c: Coefficients, tau, force, sin, cos, rho, rho_dot, theta_dot):
    """The torque about the hip that reaches the leg, and through the toe the body, when the hip turns an inertia J
    (`rotor_inertia`: the motor's rotor through the gear, J_r N^2) as the leg turns: tau - J theta''.

    The body's pitch is held by the boom, so the rotor turns by N theta relative to a body that does not turn.
    With the toe at rest theta'' = (a . e_theta - 2 rho' theta')/rho (the body's acceleration across the leg), and
    a = (F e_rho + (tau_e/rho) e_theta)/M - g e_z with M = diag(m (1 + r), m) (2.9). Solved for tau_e:

        tau_e = (tau - J (A - 2 rho' theta')/rho) / (1 + J B / rho^2),
        A = F e_rho . M^-1 e_theta + g sin(theta) (+ the track's gravity across the leg),  B = e_theta . M^-1 e_theta

    (r = 0: tau_e = (tau + J (2 rho' theta' - g sin theta)/rho) / (1 + J/(m rho^2)); the inertia adds J to the
    body's m rho^2 about the toe). F is the leg's force with the toe at rest (a compliant ground's or a sliding
    toe's motion is left out of theta'' here)."""
    inverse_y = 1.0 / (c.mass * (1.0 + c.horizontal_mass_ratio))
    inverse_z = 1.0 / c.mass
    across_a = force * sin * cos * (inverse_y - inverse_z) + c.gravity * sin
    if is_on(c, "track_gravity"):
        across_a = across_a - c.track_gravity * cos
    across_b = cos * cos * inverse_y + sin * sin * inverse_z
    return (tau - c.rotor_inertia * (across_a - 2.0 * rho_dot * theta_dot) / rho) \
        / (1.0 + c.rotor_inertia * across_b / (rho * rho))


MAX_SLIP_SPEED = 5.0   # [m/s] bound of the massless toe's sliding speed where the leg is nearly vertical


def toe_slip_rate(c: Coefficients, stuck_force, across, sin, cos):
    """Forward sliding speed of the massless toe on a ground of Coulomb friction mu (`ground_friction`).

    The ground's force on the toe is the leg's, G = F e_rho + (tau/rho) e_theta. The toe sticks while
    |G_y| <= mu G_z with F = `stuck_force` (the leg's force with the toe at rest); otherwise it slides in
    the direction s = -sign(G_y) with G_y = -s mu G_z, which fixes the leg force at
    F* = (tau/rho)(cos + s mu sin)/(s mu cos - sin), and the leg damper sets the speed that gives it:
    F = stuck_force - d sin v_toe (rho' = rho'_stuck + sin v_toe). Static and kinetic friction are one mu.
    (A zero denominator gives nan, not a division by zero: the toe then sticks.)
    """
    mu = c.ground_friction
    g_y = -stuck_force * sin - across * cos
    g_z = stuck_force * cos - across * sin
    s = -np.sign(g_y)
    denominator = s * mu * cos - sin
    boundary = across * (cos + s * mu * sin) / where(denominator == 0.0, np.nan, denominator)
    resistance = c.damping * sin
    speed = (stuck_force - boundary) / where(resistance == 0.0, np.nan, resistance)
    sliding = (np.abs(g_y) > mu * np.maximum(g_z, 0.0)) & (g_z > 0.0) & (s * speed > 0.0) & np.isfinite(speed)
    return where(sliding, clip(nan_to_num(speed), -MAX_SLIP_SPEED, MAX_SLIP_SPEED), 0.0)


# ---------------------------------------------------------------------------- the actuator


def actuator_torque(c: Coefficients, command):
    """Torque the hip delivers for a commanded torque (before any lag): dead band, gain, offset, saturation.

    The delay and the first-order lag act in time (the integrators: `torque_delay`, `torque_lag`).
    """
    if is_on(c, "torque_dead_band"):
        command = np.sign(command) * np.maximum(np.abs(command) - c.torque_dead_band, 0.0)
    return clip(c.torque_gain * command + c.torque_offset, -c.torque_limit, c.torque_limit)


# ---------------------------------------------------------------------------- events

JumpContext = namedtuple("JumpContext", "along across")


def _leg_components(theta, ydot, zdot):
    sin, cos = np.sin(theta), np.cos(theta)
    along = -sin * ydot + cos * zdot          # e_rho = (-sin, cos)
    across = -cos * ydot - sin * zdot         # e_theta = (-cos, -sin)
    return sin, cos, along, across


def _from_components(sin, cos, along, across):
    return -sin * along - cos * across, cos * along - sin * across


def touchdown_velocity(c: Coefficients, theta, ydot, zdot, leg_rate=0.0):
    """Body velocity just after touchdown at leg angle theta: the rigid model keeps it; the touchdown
    effects remove shares along and across the leg and add the discovered jump terms; an inertia about the hip is
    spun up (`rotor_spin_up`, the leg turning at `leg_rate` before, 0 where it is held)."""
    sin, cos, along, across = _leg_components(theta, ydot, zdot)
    context = JumpContext(along, across)
    new_along = along * (1.0 - c.touchdown_loss_along)
    new_across = across * (1.0 - c.touchdown_loss_across)
    if is_on(c, "touchdown_along_terms"):
        new_along = new_along + sum_terms(jump_term, c.touchdown_along_terms, context)
    if is_on(c, "touchdown_across_terms"):
        new_across = new_across + sum_terms(jump_term, c.touchdown_across_terms, context)
    ydot, zdot = _from_components(sin, cos, new_along, new_across)
    if is_on(c, "rotor_inertia"):
        ydot, zdot = rotor_spin_up(c, sin, cos, ydot, zdot, leg_rate)
    return ydot, zdot


def rotor_spin_up(c: Coefficients, sin, cos, ydot, zdot, leg_rate=0.0):
    """The body's velocity once the toe is pinned and the leg, held at `leg_rate` (0: held still) in flight, turns
    with the body at theta' = v . e_theta / rho_0, the inertia J (`rotor_inertia`) spun up with it in that instant.

    The impulse P across the leg that the ground gives the body is the one J takes: M dv = P e_theta,
    J (theta'+ - theta'-) = -P rho_0, and the pinned toe asks v+ . e_theta = rho_0 theta'+, so
    P = -(v- . e_theta - rho_0 theta'-) / (B + rho_0^2 / J), B = e_theta . M^-1 e_theta (`rotor_torque`); with
    r = 0 the velocity across the leg is kept in the share m rho_0^2 / (m rho_0^2 + J)."""
    inverse_y = 1.0 / (c.mass * (1.0 + c.horizontal_mass_ratio))
    inverse_z = 1.0 / c.mass
    rho = c.rest_length
    across = -cos * ydot - sin * zdot
    across_b = cos * cos * inverse_y + sin * sin * inverse_z
    impulse = -(across - rho * leg_rate) * c.rotor_inertia \
        / (across_b * c.rotor_inertia + rho * rho)
    return ydot - cos * impulse * inverse_y, zdot - sin * impulse * inverse_z


def liftoff_velocity(c: Coefficients, theta, ydot, zdot):
    """Body velocity after the lift-off collision (2.12), v -> m_b/(m_b + m_t) v, plus the discovered jump terms."""
    ydot, zdot = c.collision_factor * ydot, c.collision_factor * zdot
    if not (is_on(c, "liftoff_along_terms") or is_on(c, "liftoff_across_terms")):
        return ydot, zdot
    sin, cos, along, across = _leg_components(theta, ydot, zdot)
    context = JumpContext(along, across)
    along = along + sum_terms(jump_term, c.liftoff_along_terms, context)
    across = across + sum_terms(jump_term, c.liftoff_across_terms, context)
    return _from_components(sin, cos, along, across)


def touchdown_height(c: Coefficients, theta):
    """Body height at which the toe, at rest length and angle theta, meets the ground (the guard of (2.3)): a round
    toe (`foot_radius` r_f) meets it at (rho_0 - r_f) cos theta + r_f, r_f (1 - cos theta) higher, even in theta
    (an offset o of the angle's reading would give rho_0 cos(theta - o), which is not)."""
    height = c.ground_height + c.rest_length * np.cos(theta)
    if is_on(c, "foot_radius"):
        height = height + foot_rise(c, theta)
    return height


def foot_rise(c: Coefficients, theta):
    """How much higher the hip meets the ground with a round toe (`foot_radius` r_f) than with a point toe at the
    leg's end, the leg at rest length and angle theta: r_f (1 - cos theta) (0 for a point toe)."""
    return c.foot_radius * (1.0 - np.cos(theta))


def foot_at_touchdown(c: Coefficients, y, theta):
    """Forward position of the toe's point the stance turns about (`stance_forces`' toe_y) for the hip at y and the
    leg at rest length and angle theta: the toe, or a round toe's centre, (rho_0 - r_f) sin theta ahead."""
    return y + (c.rest_length - c.foot_radius) * np.sin(theta)


def foot_offset(c: Coefficients, y, z, depth, toe_y):
    """(dy, hz): the hip less the toe's point the stance turns about (`stance_forces`' toe_y, at the ground less
    `depth`; a round toe's centre r_f above it); the leg angle in stance is arctan2(-dy, hz), the leg's length
    sqrt(dy^2 + hz^2) + r_f."""
    return y - toe_y, z - c.ground_height + depth - c.foot_radius


def swing_offset(theta, theta_ref):
    """The centre of mass of body and leg less the body's, per metre of mu r_c (the leg's mass share m_l/(m_b + m_l)
    times its centre's distance below the hip), from the leg at `theta_ref` to `theta`: in flight the centre of mass
    follows (2.8) and the body recoils against the leg's swing, p = c - mu r_c (sin theta, -cos theta) + const."""
    return np.sin(theta) - np.sin(theta_ref), np.cos(theta_ref) - np.cos(theta)
