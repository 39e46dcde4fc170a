"""A leg force that relaxes (issue 28, point 1: the leg's compression history, not its state alone): air trapped in a
telescoping leg that leaks out, or a spring in series with a damper beside the leg's own spring.

The law (`laws.relaxation_rate`) adds F_r to the leg force, F_r = 0 at touchdown, with x = rho_0 - rho:

    F_r' = (k_r + gamma F_r / L) x' / (1 - x / L) - F_r / tau_r

an air spring of small-signal stiffness k_r = gamma p_a A^2 / V_0 in a chamber of length L = V_0 / A at rest, compressed
adiabatically (gamma = 1.4) and leaking through an orifice in tau_r; with 1/L = 0 a linear spring k_r in series with a
damper (a Maxwell element: an elastomer's or a polymer spring's creep). A compression fast against tau_r meets the
stiffness k + k_r, a slow one k, and a loop of energy is lost between; late in stance F_r turns negative and pulls
the leg in. A stiffer spring (`leg_stiffness`, `spring_cubic`) stores and returns; a damping (`leg_damping`) grows with
the speed and stores nothing; a hysteresis (`leg_hysteresis`) does not depend on the speed at all.

After the accepted effects, where they leave the recording not explained (the stage of `unused.find_unused_law`, in
its round with the library's effects): k_r searched at each relaxation time tau_r of a geometric grid
(`relaxation_times` from `relaxation_time_min` to `relaxation_time_max`) and each chamber (a linear spring and
`relaxation_lengths` lengths from `relaxation_length_min` to `relaxation_length_max`), then a pattern search over
tau_r and 1/L from the grid's best (`relaxation_refinements` steps, halved where none is better); what the held-out
trajectories fit best is kept, then guarded and refitted like any effect.
"""

from __future__ import annotations

import numpy as np

from .angle import best_candidate
from .candidates import Candidate
from .simulate import Variant

NAME = "leg_relaxation"
SITE = "stance_along"
STIFFNESS_MAX = 4000.0   # [N/m] the stiffest relaxing spring searched (about the leg's own stiffness)


def times(settings) -> np.ndarray:
    """The relaxation times tried first [s] (geometric)."""
    return np.geomspace(settings.relaxation_time_min, settings.relaxation_time_max, settings.relaxation_times)


def best_relaxation(search, stack, current, settings) -> Candidate:
    """The candidate the held-out trajectories fit best: over `times` x (a linear spring and the chamber lengths),
    then a pattern search from there (k_r, tau_r and L trade against each other over a stance, so the grid's best
    point can sit beside a stand-in where the plant's own lies between its points): each of
    `relaxation_refinements` steps tries the eight neighbours of tau_r and 1/L a step longer, shorter, larger,
    smaller (the valley of a trade runs across both), moves to the best, and halves the steps where none was better.
    Both stay within the grid's range: a force that relaxes in many stances is a stiffer spring, the library's."""
    coarse = times(settings)
    lengths = np.geomspace(settings.relaxation_length_min, settings.relaxation_length_max, settings.relaxation_lengths)
    curvatures = np.concatenate([[0.0], 1.0 / lengths[::-1]])
    best = best_candidate(search, stack, [relaxation_candidate(t, b) for t in coarse for b in curvatures], current)
    time_step = float(np.sqrt(coarse[1] / coarse[0]))      # relaxation_times >= 2 (settings.LIMITS)
    curvature_step, curvature_max = 0.5 / settings.relaxation_length_max, 1.0 / settings.relaxation_length_min
    for _ in range(settings.relaxation_refinements):
        t, b = best.discovery.time, best.discovery.curvature
        trials = {(min(max(t * f, coarse[0]), coarse[-1]), min(max(b + d * curvature_step, 0.0), curvature_max))
                  for f in (1.0 / time_step, 1.0, time_step) for d in (-1.0, 0.0, 1.0)} - {(t, b)}
        moved = best_candidate(search, stack, [best] + [relaxation_candidate(*trial) for trial in sorted(trials)],
                               current)
        if (moved.discovery.time, moved.discovery.curvature) == (t, b):
            time_step, curvature_step = float(np.sqrt(time_step)), 0.5 * curvature_step
        best = moved
    return best


class Relaxation:
    """The leg's relaxing force at one relaxation time and chamber curvature 1/L (the magnitude: k_r [N/m])."""

    def __init__(self, time: float, curvature: float = 0.0):
        self.time, self.curvature = float(time), float(curvature)

    def words(self, stiffness: float) -> str:
        relax = f"relax in {1e3 * self.time:.3g} ms"
        if self.curvature > 0.0:
            return (f"in stance, along the leg: an air spring that leaks, {stiffness:.3g} N/m at touchdown in a "
                    f"chamber of {1e3 / self.curvature:.3g} mm at rest, compressed adiabatically and letting its "
                    f"force {relax}, beside the leg's spring (air trapped in the telescope: the leg is stiffer in a "
                    f"fast compression than in a slow one, stiffer the deeper, and loses energy between)")
        return (f"in stance, along the leg: a force that relaxes, a spring of {stiffness:.3g} N/m in series with a "
                f"damper that lets its force {relax}, beside the leg's spring (a Maxwell element, reset at "
                f"touchdown: the leg is stiffer in a fast compression than in a slow one and loses energy between; "
                f"an elastomer's creep, air that leaks from the leg)")

    def terms(self) -> list:
        chamber = f", L = {1e3 / self.curvature:.3g} mm" if self.curvature > 0.0 else ""
        return [(f"F_r (tau_r = {1e3 * self.time:.3g} ms{chamber})", 1.0,
                 "a relaxing leg force: a leaking air spring, or a spring k_r in series with a damper", "N/m")]


def relaxation_candidate(time: float, curvature: float = 0.0) -> Candidate:
    found = Relaxation(time, curvature)

    def build(variant: Variant, stiffness: float, tau_r=found.time, bend=found.curvature) -> Variant:
        return variant.with_changes(coefficients={"leg_relaxing_stiffness": float(stiffness),
                                                  "leg_relaxation_time": tau_r, "leg_relaxation_curvature": bend})

    equation = (f"F += F_r; F_r' = (k_r + 1.4 F_r / L) x' / (1 - x / L) - F_r / tau_r, L = {1e3 / curvature:.3g} mm"
                if curvature > 0.0 else "F += F_r; F_r' = k_r x' - F_r / tau_r")
    return Candidate(NAME, "physics", "stance", SITE, "N/m", found.words(0.0), 0.0, STIFFNESS_MAX, build, float,
                     "the leg compressed at several speeds (drops from several heights, or held compressed): its "
                     "stiffness grows with the speed and a held compression's force falls in tau_r (a damping's "
                     "force grows with the speed but stores nothing; a stiffer spring holds its force)",
                     discovery=found, equation=f"{equation}, tau_r = {1e3 * time:.3g} ms, F_r = 0 at touchdown")
