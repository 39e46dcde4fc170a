"""The residual's dependence on variables the model does not use (issue 28, point 1): the leg angle, periodic
(a motor's cogging, a gear's eccentricity), and the direction of the leg's motion since its last reversal (an
encoder's backlash).

After the accepted effects (and a drift), where they leave the recording not explained:
- **a ripple periodic in the leg angle** (`find_ripple`). Where the torque about the hip is located, its
  bias-corrected residual samples are regressed on sin/cos(2 pi theta/P) for each period P of a frequency scan
  (`angle_scan` periods, geometric, from the motor's turn through the gear over `motor_harmonics` to the angle's
  whole range over `ripple_cycles`): the period whose fit predicts held-out strides' residuals best is kept when
  it predicts them better than a constant and a slope in the angle (a torque offset, a torsion spring: not
  periodic) do (one-sided t over strides of at least `min_t`). Its sin/cos amplitudes become the
  law `laws.hip_losses` (`hip_ripple_sin`, `hip_ripple_cos`, `hip_ripple_period`), one scale refitted;
- **an encoder's backlash** (`simulate.backlash_reading`): the leg angle read through a play of width b, the
  reading standing still after each reversal until the leg has turned b, then lagging it by b/2; the held angle
  at touchdown lags the swing into the hold by b/2 as well. Its width is the magnitude.
Both are candidates searched, refitted beside the accepted effects and guarded like any effect (`Search`,
`acceptance`), in a round with the library's effects (screened as in a round): a law of what the model does not
use is said only where it wins that round (a sensor fault by the sensor margin), so that a library law that does
the job keeps its name (plant B's torque dead band: a backlash takes 64 % of its residual off, the hip's dry
friction more). The winner joins the accepted effects, which are then revisited beside it (one that stood in
for it is dropped: plant B's backlash was named an actuator lag).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from hopper_ros.physics import effects as library

from . import acceptance
from .candidates import Candidate, library_candidate
from .discover import FOLDS, site_residuals
from .periodic import scan_period
from .records import Reference, Scored
from .search import Search
from .simulate import BACKLASH, Variant

SITE = "stance_hip"
NEAR = (-1.0, -0.5, 0.0, 0.5, 1.0)    # the periods tried by trajectory about the scan's best, in steps of the scan


def gear_ratio(settings) -> float:
    """Motor turns per leg turn: `gear_ratio`, or hardware.yaml's motor.gear_ratio."""
    if settings.gear_ratio > 0:
        return float(settings.gear_ratio)
    from hopper_ros.hardware.config import load_hardware
    return float(load_hardware().motor.gear_ratio)


@dataclass
class Ripple:
    """A torque about the hip a sin(2 pi theta/P) + b cos(2 pi theta/P) (at scale 1)."""
    period: float          # [rad] of the leg angle
    sin: float             # [N m]
    cos: float
    t: float               # held-out t of the scan's fit over the constant and the angle alone
    gear: float            # motor turns per leg turn

    @property
    def amplitude(self) -> float:
        return math.hypot(self.sin, self.cos)

    def turns(self) -> str:
        """The period in turns of the motor, and which harmonic of its turn it is where it is one (within 5 %)."""
        turns = self.period * self.gear / (2 * math.pi)
        harmonic = round(1.0 / turns) if turns < 1.5 else 0
        if harmonic >= 1 and abs(turns * harmonic - 1.0) <= 0.05:
            return (f"{'once' if harmonic == 1 else f'{harmonic} times'} a turn of the motor (1:{self.gear:g}): "
                    "cogging or a gear's eccentricity")
        return f"every {turns:.2f} turns of the motor (1:{self.gear:g}): a belt's or gear's tooth, not the motor's turn"

    def words(self, scale: float = 1.0) -> str:
        return (f"in stance, about the hip: a torque ripple periodic in the leg angle, +-{scale * self.amplitude:.3g} "
                f"N m every {self.period:.3g} rad of the leg angle ({self.turns()})")

    def terms(self) -> list:
        symbol = f"2 pi theta/{self.period:.4g}"
        return [(f"sin({symbol})", self.sin, "a torque periodic in the leg angle", "N m"),
                (f"cos({symbol})", self.cos, "a torque periodic in the leg angle", "N m")]


class Backlash:
    """The leg angle's encoder read through a play (the magnitude: its width [rad])."""
    measurement = True

    def words(self, width: float) -> str:
        return (f"the leg angle's encoder lags the motion by a backlash of {1e3 * width:.2g} mrad after each "
                f"reversal (the reading stands still until the leg has turned that far, then follows "
                f"{0.5e3 * width:.2g} mrad behind)")

    def terms(self) -> list:
        return [("play", 1.0, "the width of the play between the leg and its encoder", "rad")]


def periods(theta: np.ndarray, gear: float, settings) -> np.ndarray:
    """The frequency scan's periods [rad]: geometric from the motor's turn over `motor_harmonics` to the angle's
    range over `ripple_cycles` (none where the range is shorter)."""
    shortest = 2 * math.pi / gear / settings.motor_harmonics
    longest = (np.nanmax(theta) - np.nanmin(theta)) / settings.ripple_cycles
    if not longest > shortest:
        return np.zeros(0)
    return np.geomspace(shortest, longest, settings.angle_scan)


def find_ripple(sets, settings, gear: float) -> list[Ripple]:
    """The period of the hip's residual in the leg angle that predicts held-out strides best (the vertex of the
    scan's held-out SSE about its least), where it beats a constant and a slope in the angle there (t >= `min_t`):
    the ripple at it and at periods `NEAR` steps of the scan about it, which the trajectories tell apart (the
    residual's own fit is biased by what else it holds); none otherwise."""
    strides = []
    for residual, ctx in site_residuals(SITE, sets):
        ok = np.isfinite(residual) & np.isfinite(ctx["theta"])
        if ok.sum() >= 4:
            strides.append((np.asarray(ctx["theta"], float)[ok], residual[ok]))
    if len(strides) < 2 * FOLDS:
        return []
    scan = periods(np.concatenate([th for th, _ in strides]), gear, settings)
    if len(scan) < 3:
        return []
    fold = np.arange(len(strides)) % FOLDS
    residuals = [r for _, r in strides]

    def design(th, period=None):
        if period is None:
            return np.column_stack([np.ones_like(th), th])
        return np.column_stack([np.sin(2 * np.pi * th / period), np.cos(2 * np.pi * th / period)])

    found, t = scan_period(lambda period: [design(th, period) for th, _ in strides], residuals, fold, scan, NEAR,
                           settings.min_t)
    return [Ripple(period, sine, cosine, t, gear) for period, sine, cosine in found]


def ripple_candidate(found: Ripple) -> Candidate:
    def build(variant: Variant, value: float, found=found) -> Variant:
        return variant.with_changes(coefficients={"hip_ripple_sin": value * found.sin,
                                                  "hip_ripple_cos": value * found.cos,
                                                  "hip_ripple_period": found.period})

    return Candidate("hip_ripple", "physics", "actuator", SITE, "N m", found.words(), 0.0, 2.0, build,
                     lambda value, found=found: value * found.amplitude,
                     "a torque sensor, or the leg turned slowly through a revolution of the motor", discovery=found,
                     equation=f"tau += a sin(2 pi theta/P) + b cos(2 pi theta/P), P = {found.period:.4g} rad")


def backlash_candidate(settings, quantum: float) -> Candidate:
    def build(variant: Variant, value: float) -> Variant:
        return variant.with_changes(sensors={BACKLASH: value})

    return Candidate(BACKLASH, "sensor", "sensor", "touchdown_timing", "rad", Backlash().words(0.0), 0.0,
                     settings.backlash_max, build, float,
                     "the leg turned back and forth slowly against a second encoder on the leg",
                     plausible=(max(2.0 * quantum, 1e-4), settings.backlash_max), discovery=Backlash(),
                     equation="theta_meas = clamp(theta_meas_prev, theta - b/2, theta + b/2)")


def best_candidate(search: Search, stack, candidates: list[Candidate], current: Reference) -> Candidate:
    """Of one law's variants (periods, yields), the one whose search reduces the held-out residual most."""
    trial = search.search(stack, [dataclasses.replace(c, name=f"{c.name}_{k}") for k, c in enumerate(candidates)],
                          current)
    return candidates[int(max(trial, key=lambda r: r.reduction).name.split("_")[-1])]


def find_angle_law(search: Search, chosen: list[Scored], current: Reference, sets, located: set) -> Scored | None:
    """The backlash, or the ripple where the hip is located, where it wins a round beside the accepted effects
    (refitted beside it) against the library's effects (screened as in a round; a sensor fault by the sensor
    margin): a law of what the model does not use is said only where no law of what it uses does the job.
    None otherwise."""
    settings = search.settings
    laws = [backlash_candidate(settings, search.data.quantum.get("theta", 0.0))]
    stack = search.stack(chosen)
    ripples = find_ripple(sets, settings, gear_ratio(settings)) if SITE in located else []
    if ripples:      # the period the trajectories fit best
        laws.append(best_candidate(search, stack, [ripple_candidate(r) for r in ripples], current))
    return win_round(search, chosen, current, laws, located, "the leg angle and its reversals")


def at_bound(r: Scored, share: float = 1e-3) -> bool:
    """The fit sits at the end of its search that is not the candidate's origin: the data ask for more than the law
    can give, so it stands in for something else (the MuJoCo plant's dry hip friction came back a servo released
    23 ms late at 60 N m/rad, the stiffest searched, on a robot whose servo lets go before touchdown)."""
    c = r.candidate
    end = c.high if abs(c.high - c.origin) >= abs(c.low - c.origin) else c.low
    return abs(r.value - end) <= share * (c.high - c.low)


def win_round(search: Search, chosen: list[Scored], current: Reference, laws: list[Candidate],
              located: set, what: str) -> Scored | None:
    """The best of `laws` where it wins a round beside the accepted effects `chosen` against the library's effects
    (screened as in a round), polished beside them; None where a library effect wins, nothing passes or the law's fit
    sits at the far end of its search (`at_bound`)."""
    settings = search.settings
    stack = search.stack(chosen)
    taken = {r.name for r in chosen}
    excited = {"command": float(np.max(np.abs(search.data.strides.tau_0), initial=0.0))}
    rivals = search.screen(stack, [library_candidate(e, stack.variant().coefficients, excited)
                                   for e in library.LIBRARY + library.SENSORS if e.name not in taken], located)
    search.progress.say(f"{what}: {len(laws)} laws against {len(rivals)} library effects")
    ranking = search.search(stack, laws + rivals, current)
    top, ties = acceptance.choose(ranking, settings)
    if top is None or top.name not in {c.name for c in laws} or at_bound(top):
        return None
    top.ties, top.alternatives = ties, [r.candidate for r in ranking[:settings.screen] if r is not top]
    return search.polish(chosen, top, current)


def on_plain_model(rec, params, settings) -> Scored | None:
    """The stage forced on the plain model, whatever the rounds would accept and whether or not it is explained:
    the check that it finds its law only where a recording has it."""
    from .core import start
    from .locate import locate
    search, _, model = start(rec, params, settings)
    locations, sets = locate(search.data, search.base)
    located = {loc.site for loc in locations if loc.ratio >= settings.locate_threshold}
    return find_angle_law(search, [], model, sets, located)
