"""A round foot rolling on the ground (issue 28, point 1: physics beyond the library): the leg's end a ball of
radius r_f, rigid with the leg, that rolls without slipping in stance (`laws.stance_forces`, `foot_radius`).

The thesis's stance (2.9) turns the leg about a point toe. With a ball of radius r_f at the leg's end (its rest
length rho_0 reaching the ball's bottom along the leg) the contact point is r_f below the ball's centre and the
centre rolls r_f per radian of leg angle, c = (c_td - r_f (theta - theta_td), h + r_f); the hip is at
c + (rho - r_f) e_rho. So:
- touchdown (the guard of (2.3), `laws.touchdown_height`) comes where z - h = (rho_0 - r_f) cos theta + r_f,
  r_f (1 - cos theta) higher than a point toe's, a height even in theta;
- in stance the hip turns about the contact point: theta' = v . e_theta / (rho - r_f + r_f cos theta), and the
  ground's force, passed by the massless leg, has F along the leg (2.9's spring and damper in rho) and across it
  (tau - r_f F sin theta) / (rho - r_f + r_f cos theta) (tau/rho in (2.9)): the leg force acts from the contact
  point, not along the leg's axis.
An offset o of the leg angle's reading, the sensor law a round foot is otherwise taken for, moves the touchdown to
rho_0 cos(theta - o), odd in theta about o, and shifts the stance's sweep the same way at touchdown and lift-off;
the rolling ball shortens the leg toward the ground by r_f (1 - cos theta) at both ends alike and moves the contact
point forward as the leg sweeps back.

The ramps (2.32) read from the logged torque are timed from the detected touchdown, where a point toe's leg would
meet the ground (`identification.strides`); the ball meets it earlier, by the time the hip takes to fall
r_f (1 - cos theta_td) (`ramp_lead`: 0.8 ms median on plant C's 25 mm toe, under the 1 ms from which `data.prepare`
re-times every ramp from the start of stance). A lane of the law starts its ramp at its own touchdown, so it is
given the same line started that much earlier (`data.earlier_ramps`), as the drive logged it; where `prepare`
re-timed the ramps from the start of stance they start there already and are left as they are.

One magnitude, r_f [m], searched like any effect, from 0 to `REACH`; offered where the accepted effects leave the
recording not explained (`unused`), in a round with the library's effects.
"""

from __future__ import annotations

import numpy as np

from hopper_ros.physics import laws

from .candidates import Candidate
from .data import earlier_ramps, ramps_retimed

NAME = "foot_radius"        # the candidate's name and the coefficient of r_f [m] (`laws.Coefficients`)
REACH = 0.05                # [m] the largest r_f searched (a ball of a quarter of the leg's rest length)
SITE = "stance_hip"         # where its force acts first: the ground's force off the leg's axis, about the hip


class Foot:
    """The words of the law at a radius r_f."""

    def words(self, value: float) -> str:
        return (f"in stance, the toe is a ball of radius r_f = {1e3 * value:.3g} mm rolling on the ground: the "
                f"contact point moves forward r_f per radian the leg turns back, touchdown comes "
                f"r_f (1 - cos theta) higher (at (rho_0 - r_f) cos theta + r_f, the same for the leg ahead or "
                f"behind) and the leg force acts from the contact point, off the leg's axis")

    def terms(self) -> list:
        return [("r_f", 1.0, "the radius of the round toe that rolls on the ground", "m")]


def foot_candidate() -> Candidate:
    def build(variant, value: float):
        return variant.with_changes(coefficients={NAME: float(value)})

    return Candidate(NAME, "physics", "stance", SITE, "m", Foot().words(0.0), 0.0, REACH, build, float,
                     "the toe's shape measured, or strides with the leg held ahead and behind the vertical at "
                     "touchdown (a rolling toe lands at the same height for +-theta, an angle offset does not)",
                     discovery=Foot(),
                     equation="hip = c + (rho - r_f) (-sin theta, cos theta), c = (c_td - r_f (theta - theta_td), "
                              "h + r_f) in (2.9); touchdown at z - h = (rho_0 - r_f) cos theta + r_f")


def ramp_lead(coefficients: laws.Coefficients, apex_height, theta_td):
    """Per lane, how much earlier [s] a round toe meets the ground than the point toe the ramps were timed from: the
    fall from the apex (2.8, without the small flight damping) to the hip's touchdown height with the ball
    (`laws.touchdown_height`) and to the point toe's, r_f (1 - cos theta_td) lower (`laws.foot_rise`); 0 where r_f
    is 0."""
    ball = laws.touchdown_height(coefficients, theta_td)
    point = ball - laws.foot_rise(coefficients, theta_td)

    def fall(height):
        return np.sqrt(2.0 * np.maximum(apex_height - height, 0.0) / coefficients.gravity)

    return fall(point) - fall(ball)


def lane_ramps(data, coefficients: laws.Coefficients, apex_height, theta_td, tau_0, ramp_duration):
    """The ramps (tau_0, t_f) per lane that lanes with a round toe apply from their own touchdown: the recorded ones
    started `ramp_lead` earlier on the same line, where `data.prepare` left them timed from the model's touchdown;
    unchanged otherwise, and where no lane has a round toe."""
    if not np.any(np.asarray(coefficients.foot_radius) != 0.0) or ramps_retimed(data):
        return tau_0, ramp_duration
    return earlier_ramps(tau_0, ramp_duration, ramp_lead(coefficients, apex_height, theta_td))
