"""The boom's sphere (issue 28, point 1, the position of the body on its track; point 4, in every phase): the body
carried at the boom's tip moves on a sphere of radius R about the boom's pivot, where the model's (2.8)-(2.9) has
it on a plane (`laws.boom_sphere`), in flight and in stance:

    y'' += 2 (z - z_p) z' y'/R^2,   z'' += -(z - z_p) y'^2/R^2 + g b^2/2              (height read along the arc)
                                    z'' += -(z - z_p) (y'^2 + z'^2)/R^2 + g b^2     (height read as R sin beta)

b = (z - z_p)/R, z_p the pivot's height in the model's heights (hardware.yaml: the boom's parallel height less the
running surface's, as `hardware.encoders` converts the elevation, as R sin beta). The forward speed's centripetal
acceleration pulls a body raised above the pivot down, more the faster it runs (0.35 m/s^2 at 2 m/s, 0.235 m above
the pivot of a 1.65 m boom); what the corrected g (4.5)-(4.7) holds is the mean of the terms in the height alone. A
recording does not say how its heights were read from the elevation: both readings are fitted and the trajectories
choose (`angle.best_candidate`; measured at R = 1.65 m: plant C, whose height is the arc's, fits the arc better,
MuJoCo's hinges read as R sin beta the sine). One magnitude, 1/R^2, searched from 0 to the curvature of a sphere of
half the boom's length (`REACH`), said as R beside hardware.yaml's boom length; offered where the accepted effects
leave the recording not explained (`unused`), in a round with the library's effects.
"""

from __future__ import annotations

import math

from .candidates import Candidate

NAME = "boom_curvature"     # the candidate's name and the coefficient of 1/R^2 [1/m^2] (`laws.Coefficients`)
REACH = 2.0                 # the shortest radius searched is the boom's length over REACH
SAID_AT = (2.0, 0.35)       # (forward speed [m/s], height [m]) at which the words give the pull's size
SITE = "flight_vertical"    # where it acts alone (in stance beside the leg's far larger forces): its pull


def pivot_and_length() -> tuple[float, float]:
    """(z_p, L) [m]: the boom pivot's height above the running surface and the boom's length (hardware.yaml)."""
    from hopper_ros.hardware.config import load_hardware
    boom = load_hardware().boom
    return float(boom.parallel_height - boom.ground_height), float(boom.length)


def radius(curvature: float) -> float:
    """R [m] of a curvature 1/R^2 (inf where it is 0)."""
    return math.inf if curvature <= 0.0 else 1.0 / math.sqrt(curvature)


READINGS = {1.0: "the height read as R sin(elevation)", 0.0: "the height read along the arc"}


class Sphere:
    """The words of the law at a curvature 1/R^2, its height read as R sin beta (`sine` 1) or along the arc (0)."""

    def __init__(self, pivot_height: float, boom_length: float, sine: float):
        self.pivot_height, self.boom_length, self.sine = pivot_height, boom_length, sine

    def words(self, curvature: float) -> str:
        speed, height = SAID_AT
        pull = curvature * speed ** 2 * (height - self.pivot_height)
        return (f"in every phase, the body moves on the boom's sphere, radius R = {radius(curvature):.3g} m about the "
                f"pivot {1e3 * self.pivot_height:.0f} mm above the ground (hardware.yaml's boom: "
                f"{self.boom_length:.3g} m), not on the model's plane: the forward speed pulls the raised body down "
                f"by (z - z_p) y'^2/R^2 ({pull:.2g} m/s^2 at {speed:g} m/s and z = {height:g} m), with a Coriolis push "
                f"2 (z - z_p) z' y'/R^2 along the track ({READINGS[self.sine]})")

    def terms(self) -> list:
        return [("1/R^2", 1.0, "the curvature of the sphere the boom's tip moves on", "1/m^2")]


def sphere_candidates() -> list[Candidate]:
    """The law with the height read as R sin beta and along the arc."""
    pivot_height, boom_length = pivot_and_length()
    return [sphere_candidate(sine, pivot_height, boom_length) for sine in READINGS]


def sphere_candidate(sine: float, pivot_height: float, boom_length: float) -> Candidate:
    found = Sphere(pivot_height, boom_length, sine)

    def build(variant, value: float):
        return variant.with_changes(coefficients={NAME: float(value), "boom_pivot_height": pivot_height,
                                                  "boom_sine_reading": sine})

    return Candidate(NAME, "physics", "boom", SITE, "m", found.words(1.0 / boom_length ** 2), 0.0,
                     (REACH / boom_length) ** 2, build, radius,
                     "runs at several forward speeds at the same apex height (the pull grows with the speed's square "
                     "and the height above the pivot; a flight drag or a changed g does not)", discovery=found,
                     equation="y'' += 2 (z - z_p) z' y'/R^2; z'' += -(z - z_p) (y'^2 + s z'^2)/R^2 + (1 + s) g "
                              "(z - z_p)^2/(2 R^2), s = 1 for a height read as R sin beta, 0 along the arc; in flight "
                              "and stance")
