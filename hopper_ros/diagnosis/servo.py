"""The flight's position servo released late (issue 28, point 3: a law gated in time): the servo that holds the leg at
its touchdown angle in flight still acts for t_h after touchdown (the drive switched from position to current mode
late), pulling the sweeping leg back toward that angle: `laws.servo_hold`, in stance

    tau += -K_p (theta - theta_td)   for 0 <= t - t_td < t_h.

A viscous hip friction (`hip_viscous_friction`) or the rotor's inertia (`rotor_inertia`) takes torque through the
whole stance; this only at its start. Where the accepted effects leave the recording not explained (the stage of
`unused.find_unused_law`, in its round with the library's effects, those among them): K_p searched at each release
time t_h of a geometric grid (`servo_releases` from `servo_release_min` to `servo_release_max`, then twice as many
between the best one's neighbours), the t_h the held-out trajectories fit best kept, then guarded and refitted like
any effect.
"""

from __future__ import annotations

import numpy as np

from .angle import best_candidate
from .candidates import Candidate
from .simulate import Variant

NAME = "servo_release"
SITE = "stance_hip"
STIFFNESS_MAX = 60.0   # [N m/rad] the stiffest servo searched (a tenth of a rad off gives 6 N m, the size of a command)


def releases(settings) -> np.ndarray:
    """The release times tried first [s] (geometric)."""
    return np.geomspace(settings.servo_release_min, settings.servo_release_max, settings.servo_releases)


def best_release(search, stack, current, settings) -> Candidate:
    """The candidate of the release time the held-out trajectories fit best: on `releases`, then again on twice as
    many between the best one's neighbours (the pull's impulse grows with t_h as with K_p; only the right t_h leaves
    the rest of the stance alone)."""
    coarse = releases(settings)
    best = best_candidate(search, stack, [servo_candidate(t) for t in coarse], current)
    k = int(np.argmin(np.abs(coarse - best.discovery.release)))
    fine = np.geomspace(coarse[max(k - 1, 0)], coarse[min(k + 1, len(coarse) - 1)], 2 * settings.servo_releases + 1)
    return best_candidate(search, stack, [servo_candidate(t) for t in fine], current)


class ServoRelease:
    """The servo released `release` s after touchdown (the magnitude: K_p [N m/rad])."""

    def __init__(self, release: float):
        self.release = float(release)

    def words(self, stiffness: float) -> str:
        return (f"in stance, about the hip: the flight's position servo is released {1e3 * self.release:.3g} ms after "
                f"touchdown instead of at it, pulling the leg back toward its touchdown angle with {stiffness:.3g} "
                f"N m/rad until then (the drive switched from position to current mode late)")

    def terms(self) -> list:
        return [(f"-(theta - theta_td) for t < {1e3 * self.release:.3g} ms", 1.0,
                 "the position servo's pull toward the touchdown angle early in stance", "N m/rad")]


def servo_candidate(release: float) -> Candidate:
    found = ServoRelease(release)

    def build(variant: Variant, stiffness: float, t_h=found.release) -> Variant:
        return variant.with_changes(coefficients={"servo_stiffness": float(stiffness), "servo_release": t_h})

    return Candidate(NAME, "physics", "actuator", SITE, "N m/rad", found.words(0.0), 0.0, STIFFNESS_MAX, build, float,
                     "the drive's mode switch timed against the touchdown (its status word), or strides with the ramp "
                     "begun at once against strides with it begun later", discovery=found,
                     equation=f"tau += -K_p (theta - theta_td) for t - t_td < {1e3 * release:.3g} ms")
