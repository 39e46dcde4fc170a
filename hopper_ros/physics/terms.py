"""The term libraries of the mismatch tool's discovered terms: per site (flight, stance along the
leg and about the hip, the touchdown and lift-off velocity resets) its terms and `value(i, context)`;
a `*_terms` coefficient of `laws.Coefficients` weighs them (`sum_terms`). docs/diagnosis.md derives each.
Written for floats, arrays and compiled lanes as the laws are (`physics.broadcast`).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from .broadcast import nonzero, ones_like, smooth_sign


# ---------------------------------------------------------------------------- term libraries
# Each library: its terms (key, words for a researcher, unit of its coefficient) and one function
# `value(i, context)` giving term i at a site's context. A site's extra acceleration/force/torque/velocity
# change is sum_i c_i term_i (`sum_terms`).

TermLibrary = namedtuple("TermLibrary", "terms value")


def flight_y_term(i, c):
    if i == 0:
        return ones_like(c.ydot)
    if i == 1:
        return c.ydot
    if i == 2:
        return np.abs(c.ydot) * c.ydot
    if i == 3:
        return smooth_sign(c.ydot)
    return c.zdot


def flight_z_term(i, c):
    if i == 0:
        return ones_like(c.zdot)
    if i == 1:
        return c.zdot
    if i == 2:
        return np.abs(c.zdot) * c.zdot
    if i == 3:
        return smooth_sign(c.zdot)
    if i == 4:
        return np.abs(c.zdot)
    if i == 5:
        return c.z
    if i == 6:
        return c.ydot
    return np.maximum(c.z - c.knot, 0.0)


def leg_term(i, c):
    """Along the leg, positive pushing the body away from the toe."""
    if i == 0:
        return ones_like(c.rho)
    if i == 1:
        return c.compression
    if i == 2:
        return c.compression ** 2
    if i == 3:
        return c.compression ** 3
    if i == 4:
        return -c.rho_dot
    if i == 5:
        return -np.abs(c.rho_dot) * c.rho_dot
    if i == 6:
        return -np.abs(c.rho_dot)
    if i == 7:
        return -smooth_sign(c.rho_dot)
    if i == 8:
        return c.since_touchdown
    if i == 9:
        return c.torque / c.rho
    return np.maximum(c.compression - c.knot, 0.0)


def hip_term(i, c):
    """About the hip, positive increasing theta."""
    if i == 0:
        return ones_like(c.rho)
    if i == 1:
        return c.command
    if i == 2:
        return c.theta - c.theta_td
    if i == 3:
        return c.theta
    if i == 4:
        return -c.theta_dot
    if i == 5:
        return -smooth_sign(c.theta_dot)
    if i == 6:
        return c.since_touchdown
    return c.compression


def jump_term(i, c):
    """A velocity change at an event, along or across the leg, from the velocity just before it."""
    if i == 0:
        return ones_like(c.along)
    if i == 1:
        return c.along
    return c.across


FLIGHT_Y_TERMS = TermLibrary((
    ("1", "a constant horizontal force", "N"),
    ("ydot", "a horizontal force proportional to the forward speed (viscous drag)", "N s/m"),
    ("|ydot|ydot", "a horizontal force quadratic in the forward speed (air drag)", "N s^2/m^2"),
    ("sign(ydot)", "a constant horizontal force against the motion (dry friction of the boom's vertical axis)", "N"),
    ("zdot", "a horizontal force proportional to the vertical speed", "N s/m"),
), flight_y_term)
FLIGHT_Z_TERMS = TermLibrary((
    ("1", "a constant vertical force (upward when positive)", "N"),
    ("zdot", "a vertical force proportional to the vertical speed (viscous drag)", "N s/m"),
    ("|zdot|zdot", "a vertical force quadratic in the vertical speed (air drag)", "N s^2/m^2"),
    ("sign(zdot)", "a constant vertical force against the motion (dry friction of the boom's horizontal axis)", "N"),
    ("|zdot|", "a vertical force proportional to the vertical speed's size (with zdot: a drag on the way up or down "
     "only)", "N s/m"),
    ("z", "a vertical force proportional to the height (a spring pulling the boom)", "N/m"),
    ("ydot", "a vertical force proportional to the forward speed", "N s/m"),
    ("z>z_k", "a force proportional to the height above z_k (something that engages above a height: "
     "a tether or cable going taut, a stop)", "N/m"),
), flight_z_term)
LEG_TERMS = TermLibrary((
    ("1", "a constant force along the leg", "N"),
    ("x", "a force proportional to the leg's compression (a stiffer spring)", "N/m"),
    ("x^2", "a force quadratic in the leg's compression (a progressive spring; a softening one where negative)",
     "N/m^2"),
    ("x^3", "a force cubic in the leg's compression (a hardening spring)", "N/m^3"),
    ("rho'", "a force proportional to the leg's extension rate (extra leg damping)", "N s/m"),
    ("|rho'|rho'", "a force quadratic in the leg's extension rate", "N s^2/m^2"),
    ("|rho'|", "a force proportional to the leg's speed in either direction (with rho': damping that differs in "
     "compression and extension)", "N s/m"),
    ("sign(rho')", "a constant force against the leg's sliding (dry friction in the leg)", "N"),
    ("t", "a force growing with the time since touchdown", "N/s"),
    ("tau/rho", "a force along the leg proportional to the hip torque over the leg length", "1"),
    ("x>x_k", "a force proportional to the compression beyond x_k (a stop or a second spring that engages)", "N/m"),
), leg_term)
# the term whose break point (knot) is chosen from the data, per library: (term key, Coefficients field of its knot)
HINGES = {"flight_z": ("z>z_k", "flight_z_knot"), "leg": ("x>x_k", "leg_knot")}
HIP_TERMS = TermLibrary((
    ("1", "a constant torque at the hip", "N m"),
    ("tau", "a torque proportional to the commanded hip torque (actuator gain)", "1"),
    ("theta-theta_td", "a torque proportional to the leg's swing since touchdown (a torsional spring at the hip)",
     "N m/rad"),
    ("theta", "a torque proportional to the leg angle (a spring centring the leg)", "N m/rad"),
    ("theta'", "a torque proportional to the leg's angular rate (viscous friction at the hip)", "N m s/rad"),
    ("sign(theta')", "a constant torque against the leg's rotation (dry friction at the hip)", "N m"),
    ("t", "a torque growing with the time since touchdown", "N m/s"),
    ("x", "a torque proportional to the leg's compression", "N"),
), hip_term)
JUMP_TERMS = TermLibrary((
    ("1", "a constant velocity change", "m/s"),
    ("v_along", "a share of the velocity along the leg", "1"),
    ("v_across", "a share of the velocity across the leg", "1"),
), jump_term)
TERM_LIBRARIES = {"flight_y": FLIGHT_Y_TERMS, "flight_z": FLIGHT_Z_TERMS, "leg": LEG_TERMS, "hip": HIP_TERMS,
                  "touchdown_along": JUMP_TERMS, "touchdown_across": JUMP_TERMS,
                  "liftoff_along": JUMP_TERMS, "liftoff_across": JUMP_TERMS}


def sum_terms(term, coefficients, context):
    """sum_i coefficients[i] term(i, context), the terms whose coefficient is zero skipped."""
    total = 0.0
    for i in range(len(coefficients)):
        if nonzero(coefficients[i]):
            total = total + coefficients[i] * term(i, context)
    return total


def zero_terms(name: str) -> tuple:
    return tuple(0.0 for _ in TERM_LIBRARIES[name].terms)
