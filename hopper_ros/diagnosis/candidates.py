"""The candidates of the mismatch tool: a library effect, a discovered term set or a ringing channel, each
one magnitude between bounds that `build` turns into a model variant (`simulate.Variant`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from hopper_ros.physics import effects as library
from hopper_ros.physics import laws

from .data import StrideData
from .discover import Discovery
from .ringing import Ringing, discover_ringing
from .simulate import Variant
from .sites import CHANNEL_SITE, effect_sites, hinge_of


@dataclass
class Candidate:
    name: str
    kind: str                     # physics | sensor | discovered
    family: str
    site: str
    unit: str
    words: str
    low: float                    # search bounds of its one magnitude (search units)
    high: float
    build: Callable               # (variant, value) -> variant
    physical: Callable            # value -> magnitude in `unit`
    separate: str = ""
    plausible: tuple = (0.0, math.inf)
    off: float = 0.0              # the magnitude (physical) at which a sensor fault is off
    origin: float = 0.0           # the search value at which the candidate changes nothing
    discovery: Discovery | None = None
    equation: str = ""
    secondary: tuple = ()         # library.Parameter: fitted once the candidate is accepted (`_fit_secondary`)
    held: dict = dataclasses.field(default_factory=dict)   # secondary name -> (value, unit) other than the model's
    refinements: int = 1          # fine-grid passes of a search (`Search.refine`): more where the SSE turns sharply

    def describe(self, value: float) -> str:
        if self.discovery is not None:
            return self.discovery.words(value)
        return self.words + "".join(f"; {k} = {v:.4g} {u}" for k, (v, u) in self.held.items())

    def holding(self, p, value: float) -> "Candidate":
        """This candidate with its secondary parameter `p` held at `value` (physical units)."""
        def build(variant: Variant, x: float, inner=self.build) -> Variant:
            return inner(variant, x).with_changes(coefficients={p.coefficient: float(value)})

        return dataclasses.replace(self, build=build, held={**self.held, p.name: (float(value), p.unit)})


def candidate_sites(c: Candidate) -> tuple:
    """The located sites where a candidate's change acts: a discovered term set at its own site, a library
    effect by its site and direction."""
    if c.kind == "discovered" or c.name not in library.EFFECTS:     # discovered, or a law of `angle`
        return (c.site,)
    effect = library.get(c.name)
    return effect_sites(effect.site, effect.direction)


def library_candidate(effect: library.Effect, base: laws.Coefficients, excited: dict | None = None) -> Candidate:
    low, high = effect.data_bounds(base, excited or {})
    p = effect.primary
    if p.coefficient == "toe_mass":
        origin = float(base.mass) * (1.0 / float(base.collision_factor) - 1.0)
    elif p.coefficient in laws.Coefficients.scalar_names():
        origin = effect.search_value(float(getattr(base, p.coefficient)))
    else:
        origin = library.SENSOR_OFF.get(p.coefficient, 0.0)

    def build(variant: Variant, value: float, effect=effect) -> Variant:
        changes = effect.coefficients(value, variant.coefficients)
        if effect.kind == "sensor":
            return variant.with_changes(sensors=changes)
        return variant.with_changes(coefficients=changes)

    return Candidate(effect.name, effect.kind, effect.family, effect.site, effect.primary.unit, effect.words,
                     low, high, build, effect.physical, effect.separate, effect.primary.plausible,
                     off=library.SENSOR_OFF.get(p.coefficient, 0.0), origin=origin, equation=effect.equation,
                     secondary=effect.secondary)


def discovered_candidate(found: Discovery) -> Candidate:
    def build(variant: Variant, value: float, found=found) -> Variant:
        old = getattr(variant.coefficients, found.field)
        new = {found.field: tuple(float(o) + value * c for o, c in zip(old, found.coefficients))}
        hinge = hinge_of(found.field)
        if hinge is not None:
            new[hinge[1]] = found.knot
        return variant.with_changes(coefficients=new)

    return Candidate(f"discovered_{found.site}", "discovered", "discovered", found.site, "x fitted terms",
                     found.words(), 0.0, 2.0, build, float,
                     "a force plate, or strides that lengthen the phase where the terms act", discovery=found,
                     equation=" + ".join(f"{c:+.4g} {k}" for k, c, _, _ in found.terms()))


def ringing_candidate(found: Ringing) -> Candidate:
    def build(variant: Variant, value: float, found=found) -> Variant:
        return variant.with_changes(sensors=found.sensors(value))

    (a, b), w = found.amplitudes, f"2 pi {found.frequency:.4g} s"
    return Candidate(f"discovered_{found.channel}_ringing", "discovered", "discovered", found.site, "x fitted terms",
                     found.words(), 0.0, 2.0, build, float,
                     "an accelerometer on the body, or the boom's modes measured by tapping it", discovery=found,
                     equation=f"{found.channel}_meas += exp(-{found.decay:.4g} s) ({a:+.4g} sin({w}) {b:+.4g} cos({w})) m,"
                              " s = time since lift-off")


def ringing_candidates(data: StrideData, located: set, taken: set, discoveries: list) -> list[Candidate]:
    """A ringing channel after lift-off, where its flight site is located (found once per recording; a new one is
    added to `discoveries`)."""
    out = []
    for channel, site in CHANNEL_SITE.items():
        if site not in located or f"discovered_{channel}_ringing" in taken:
            continue
        if channel not in data.ringing:
            data.ringing[channel] = discover_ringing(data, channel)
            if data.ringing[channel] is not None:
                discoveries.append(data.ringing[channel])
        if data.ringing[channel] is not None:
            out.append(ringing_candidate(data.ringing[channel]))
    return out


def search_grid(c: Candidate, n: int) -> np.ndarray:
    """n magnitudes between the bounds, denser near the candidate's "off" value (small effects are common)."""
    origin = float(np.clip(c.origin, c.low, c.high))
    span = c.high - c.low
    below = int(round((n - 1) * (origin - c.low) / span)) if span > 0 else 0
    above = n - 1 - below
    u_below = np.linspace(1.0, 0.0, below + 1)[:-1] ** 2 if below else np.empty(0)
    u_above = np.linspace(0.0, 1.0, above + 1)[1:] ** 2 if above else np.empty(0)
    return np.concatenate([origin - (origin - c.low) * u_below, [origin], origin + (c.high - origin) * u_above])
