"""Hysteresis in the leg force (issue 28, point 1: the direction of motion since the last reversal): a force along
the leg that depends on the compression since the compression last reversed, not on its speed.

The law (`laws.hysteresis_rate`, a Bouc-Wen element: Bouc 1967, Wen 1976, n = 1, beta = gamma = 1/2) adds F_h q
to the leg force, q in [-1, 1] with x_y q' = x' - (|x'| q + x' |q|)/2 in the compression x = rho_0 - rho, q = 0 at
touchdown: after each reversal q turns over about x_y of compression, elastic first and saturating at +-1, so a loop
of about 2 F_h x_max is lost each stance whatever the speed, with a smooth turn at the bottom. A dry friction along
the leg (`leg_friction`, the library's) turns with the sign of the speed, at once; a damping grows with it.

After the accepted effects, where they leave the recording not explained (the stage of `angle.find_angle_law`, in
its round with the library's effects, `leg_friction` and `leg_damping` among them): F_h searched at each yield x_y of
a geometric grid (`hysteresis_yields` from `hysteresis_yield_min` to `hysteresis_yield_max`), the yield the
held-out trajectories fit best kept, then guarded and refitted like any effect.
"""

from __future__ import annotations

import numpy as np

from .candidates import Candidate
from .simulate import Variant

SITE = "stance_along"
NAME = "leg_hysteresis"
FORCE_MAX = 20.0       # [N] the largest F_h searched (a tenth of the leg's force at a typical compression)


class Hysteresis:
    """The leg force's hysteresis at one yield deflection (the magnitude: F_h [N])."""

    def __init__(self, yield_deflection: float):
        self.yield_deflection = float(yield_deflection)

    def words(self, force: float) -> str:
        return (f"in stance, along the leg: hysteresis in the leg force, +-{force:.3g} N that turns over "
                f"{1e3 * self.yield_deflection:.2g} mm of compression after each reversal (a Bouc-Wen element reset "
                f"at touchdown: the force depends on the compression since its last reversal, not on its speed; "
                f"a spring seat or elastomer; {2 * force:.3g} N between loading and unloading)")

    def terms(self) -> list:
        return [(f"q (Bouc-Wen, x_y = {self.yield_deflection:.4g} m)", 1.0,
                 "hysteresis in the leg force: F_h times the state q in [-1, 1]", "N")]


def yields(settings) -> np.ndarray:
    """The yield deflections tried [m] (geometric)."""
    return np.geomspace(settings.hysteresis_yield_min, settings.hysteresis_yield_max, settings.hysteresis_yields)


def hysteresis_candidate(yield_deflection: float) -> Candidate:
    found = Hysteresis(yield_deflection)

    def build(variant: Variant, value: float, x_y=found.yield_deflection) -> Variant:
        return variant.with_changes(coefficients={"leg_hysteresis": float(value), "leg_hysteresis_yield": x_y})

    return Candidate(NAME, "physics", "stance", SITE, "N", found.words(0.0), 0.0, FORCE_MAX, build, float,
                     "the leg compressed and released slowly on a scale (a loop that does not shrink with the speed) "
                     "against a fast drop (a friction's loop is the same; a damping's grows)", discovery=found,
                     equation=f"F += F_h q; {1e3 * yield_deflection:.3g} mm q' = x' - (|x'| q + x' |q|)/2, q = 0 at "
                              "touchdown")
