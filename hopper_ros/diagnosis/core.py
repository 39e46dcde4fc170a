"""The mismatch tool: locate (residual forces per phase and event), name (library effects and
discovered terms, fitted and ranked on held-out strides, with guards), model (refit, before/after).

Plain Python (numpy/scipy). Candidates are the entries of `physics.effects` and the term sets that
`discover` finds where `locate` sees a residual above noise; both are searched the same way: one
magnitude on a grid, every (grid point, stride) a lane of one integration, fitted per fold on the
training strides, scored on the held-out ones (trajectory SSE and the next apex, E_p, E_v, E_t).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from hopper_ros.config import load_yaml
from hopper_ros.recording.recordings import Recording
from hopper_ros.physics import effects as library
from hopper_ros.physics import laws
from hopper_ros.physics.metrics import position_error_pct, time_error_pct, velocity_error_pct
from hopper_ros.physics.params import ModelParams

from .data import LEAD_RESOLVED, PHASES, StrideData, prepare
from .discover import Discovery, discover_site, hinge_of
from .locate import SITES as LOCATE_SITES
from .locate import Location, fit_locations, locate, trajectory_location
from .ringing import CHANNEL_SITE, Ringing, discover_ringing
from .simulate import CHANNELS, Variant, simulate_variants


@dataclass
class Settings:
    folds: int = 5
    grid: int = 7
    min_strides: int = 6
    max_effects: int = 3
    min_reduction: float = 0.10      # held-out trajectory SSE must fall by at least this share ...
    min_total_reduction: float = 0.02  # ... and by this share of the model's own SSE (later rounds: not noise)
    min_t: float = 3.0               # ... with a one-sided t of the per-stride log ratio
    apex_tolerance: float = 0.01     # a held-out E_p/E_v/E_t may not grow by more than this share
    apex_improvement: float = 0.03   # ... and their sum must fall by at least this share
    sensor_alone: float = 0.5        # a sensor fault that leaves the next apex as it was must explain this share
    sensor_margin: float = 0.15      # a sensor effect must beat the best physics effect's reduction by this share
    discovery_margin: float = 0.15   # a discovered term set must beat the best library effect by this share
    margin_residual: float = 0.5     # ... or (a sensor) leave at most this share of what it leaves (paired t >= min_t)
    near_full: float = 0.95          # ... when it removes at least this share of the held-out residual
    tie_t: float = 2.5               # an effect fitting held-out strides not worse by this t is a look-alike ...
    tie_share: float = 0.02          # ... and so is one whose reduction is within this share of the best's
    locate_threshold: float = 2.5    # residual over noise for a site to stand out
    screen: int = 8                  # candidates the screening passes on to the full search
    screen_strides: int = 24         # strides the screening uses
    liftoff_window: float = 0.003
    exchange: int = 3                # runners-up tried as the partner of an exchanged effect
    polish: int = 3                  # passes of the joint refit of an accepted effect with the earlier ones
    restarts: int = 3                # first-round runners-up that start the rounds again ...
    restart_threshold: float = 5.0   # ... when the accepted set leaves a residual this far over the noise level
    trajectory_threshold: float = 10.0   # nothing located by force: a re-simulated phase this many noise levels off
    secondary_grid: int = 5          # values of an accepted entry's secondary parameter tried (geometric)


def load_settings(path="diagnosis.yaml") -> Settings:
    data = load_yaml(path)
    values = data.get("diagnosis", data) if isinstance(data, dict) else None
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected a mapping under `diagnosis:`")
    known = {f for f in Settings.__dataclass_fields__}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"{path}: diagnosis: unknown key(s) {unknown}; known: {sorted(known)}")
    try:
        return Settings(**{k: type(getattr(Settings, k))(v) for k, v in values.items()})
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: diagnosis: {exc}") from None


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

    def describe(self, value: float) -> str:
        if self.discovery is not None:
            return self.discovery.words(value)
        return self.words + "".join(f"; {k} = {v:.4g} {u}" for k, (v, u) in self.held.items())

    def holding(self, p, value: float) -> "Candidate":
        """This candidate with its secondary parameter `p` held at `value` (physical units)."""
        def build(variant: Variant, x: float, inner=self.build) -> Variant:
            return inner(variant, x).with_changes(coefficients={p.coefficient: float(value)})

        return dataclasses.replace(self, build=build, held={**self.held, p.name: (float(value), p.unit)})


LOCATED_SITES = {  # library site -> located sites where it shows first
    "flight": ("flight_horizontal", "flight_vertical"),
    "touchdown": ("touchdown_along", "touchdown_across", "touchdown_timing"),
    "stance_leg": ("stance_along",), "stance_hip": ("stance_hip",), "actuator": ("stance_hip",),
    "liftoff": ("liftoff_along", "liftoff_across"), "sensor": (),
}


DIRECTED_SITES = {  # (library site, direction) -> the located sites where that change acts
    ("flight", "horizontal"): ("flight_horizontal",), ("flight", "vertical"): ("flight_vertical",),
    ("flight", "both"): ("flight_horizontal", "flight_vertical"),
    ("touchdown", "along"): ("touchdown_along",), ("touchdown", "across"): ("touchdown_across",),
    ("touchdown", "vertical"): ("touchdown_timing",),
    ("stance_leg", "along"): ("stance_along",), ("stance_leg", "horizontal"): ("stance_along", "stance_hip"),
    ("liftoff", "both"): ("liftoff_along", "liftoff_across"),
}


def candidate_sites(c: Candidate) -> tuple:
    """The located sites where a candidate's change acts: a discovered term set at its own site, a library
    effect by its site and direction."""
    if c.kind == "discovered":
        return (c.site,)
    effect = library.get(c.name)
    return DIRECTED_SITES.get((effect.site, effect.direction), LOCATED_SITES[effect.site])


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


def _ringing_candidates(data: StrideData, located: set, taken: set, log: dict) -> list[Candidate]:
    """A ringing channel after lift-off, where its flight site is located (found once per recording)."""
    out = []
    for channel, site in CHANNEL_SITE.items():
        if site not in located or f"discovered_{channel}_ringing" in taken:
            continue
        if channel not in data.ringing:
            data.ringing[channel] = discover_ringing(data, channel)
            if data.ringing[channel] is not None:
                log["discoveries"].append(data.ringing[channel])
        if data.ringing[channel] is not None:
            out.append(ringing_candidate(data.ringing[channel]))
    return out


# ---------------------------------------------------------------------------- ranking


def search_grid(c: Candidate, n: int) -> np.ndarray:
    """n magnitudes between the bounds, denser near the candidate's "off" value (small effects are common)."""
    origin = float(np.clip(c.origin, c.low, c.high))
    span = c.high - c.low
    below = int(round((n - 1) * (origin - c.low) / span)) if span > 0 else 0
    above = n - 1 - below
    u_below = np.linspace(1.0, 0.0, below + 1)[:-1] ** 2 if below else np.empty(0)
    u_above = np.linspace(0.0, 1.0, above + 1)[1:] ** 2 if above else np.empty(0)
    return np.concatenate([origin - (origin - c.low) * u_below, [origin], origin + (c.high - origin) * u_above])


def _folds(n: int, k: int) -> np.ndarray:
    return np.arange(n) % max(2, min(k, n))


def _errors(data: StrideData, pred: dict) -> dict:
    """Mean E_p, E_v, E_t (4.1)-(4.3) of the next apex over the strides the model completes; `fallen` counts
    the strides it does not (their errors cannot be computed: a model that drops strides is not better)."""
    s = data.strides
    ep = position_error_pct(s.next_apex_height, s.stride_length, pred["height"], pred["length"])
    ev = velocity_error_pct(s.next_forward_speed, pred["speed"])
    et = time_error_pct(s.stride_time, pred["time"])
    done = np.isfinite(ep) & np.isfinite(ev) & np.isfinite(et)
    if not done.any():
        return {"E_p": math.inf, "E_v": math.inf, "E_t": math.inf, "fallen": int(done.size)}
    return {"E_p": float(np.mean(ep[done])), "E_v": float(np.mean(ev[done])), "E_t": float(np.mean(et[done])),
            "fallen": int(done.size - done.sum())}


def _interp_pred(grid, pred_grid: dict, values: np.ndarray) -> dict:
    """Next-apex predictions per stride at per-stride magnitudes, interpolated on the grid."""
    out = {}
    for key, arr in pred_grid.items():       # arr: (grid, strides)
        col = np.empty(arr.shape[1])
        for i in range(arr.shape[1]):
            ok = np.isfinite(arr[:, i])
            col[i] = np.interp(values[i], grid[ok], arr[ok, i]) if ok.sum() >= 2 else np.nan
        out[key] = col
    return out


@dataclass
class Stack:
    """The model a round searches on top of: the base variant and the effects accepted so far, whose
    magnitudes are refitted with every new candidate (backfitting: a first effect fitted alone absorbs
    part of a second one's signature)."""
    base: Variant
    effects: list

    def variant(self, values=None) -> Variant:
        v = self.base
        for k, r in enumerate(self.effects):
            v = r["candidate"].build(v, float(r["value"] if values is None else values[k]))
        return v


def _partner_points(r: dict) -> tuple[np.ndarray, int, float, float]:
    """Three magnitudes of an accepted effect to refit it at (its value and one either side, inside its
    bounds), the index of its value among them, and the range its refit may move over."""
    c, v = r["candidate"], float(r["value"])
    span = c.high - c.low
    step = max(0.5 * abs(v - c.origin), 0.02 * span)
    below, above = min(step, v - c.low), min(step, c.high - v)
    if below <= 1e-9 * span:
        xs, centre = np.array([v, v + above, v + 2 * above]), 0
    elif above <= 1e-9 * span:
        xs, centre = np.array([v - 2 * below, v - below, v]), 2
    else:
        xs, centre = np.array([v - below, v, v + above]), 1
    width = xs[2] - xs[0]
    return xs, centre, max(c.low, xs[0] - 0.5 * width), min(c.high, xs[2] + 0.5 * width)


def _newton(xs: np.ndarray, ys: list, x):
    """The quadratic through (xs[j], ys[j]) at x (arrays broadcast)."""
    d1 = (ys[1] - ys[0]) / (xs[1] - xs[0])
    d2 = ((ys[2] - ys[1]) / (xs[2] - xs[1]) - d1) / (xs[2] - xs[0])
    return ys[0] + d1 * (x - xs[0]) + d2 * (x - xs[0]) * (x - xs[1])


def _quadratic_min(xs: np.ndarray, ys: list, low: float, high: float) -> np.ndarray:
    """Per column, where the quadratic through the three points is lowest within [low, high]."""
    d1 = (ys[1] - ys[0]) / (xs[1] - xs[0])
    d2 = ((ys[2] - ys[1]) / (xs[2] - xs[1]) - d1) / (xs[2] - xs[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(d2 > 0, (xs[0] + xs[1]) / 2 - d1 / np.where(d2 > 0, 2 * d2, 1.0), low)
    tries = np.stack([np.clip(vertex, low, high), np.full_like(vertex, low), np.full_like(vertex, high),
                      np.full_like(vertex, xs[0]), np.full_like(vertex, xs[1]), np.full_like(vertex, xs[2])])
    values = _newton(xs, ys, tries)
    return np.take_along_axis(tries, np.argmin(values, axis=0)[None], 0)[0]


class _Backfit:
    """A candidate's (partner point, grid value, stride) block: the partners refitted per grid value."""

    def __init__(self, sse: np.ndarray, pred: dict, points: list):
        self.sse, self.pred, self.points = sse, pred, points

    def _ys(self, block: np.ndarray, i: int, columns) -> list:
        xs, centre, _, _ = self.points[i]
        others = iter((1 + 2 * i, 2 + 2 * i))
        return [block[0][:, columns] if j == centre else block[next(others)][:, columns] for j in range(3)]

    def partner_values(self, columns) -> list:
        """Per partner, its magnitude at every grid value (on these strides' summed SSE): the one partner
        whose refit gains most is refitted, the others stay (partners that look alike would otherwise
        each take the whole correction); `_polish` repeats the fit from the new magnitudes."""
        total = self.sse[:, :, columns].sum(axis=2)[:, :, None]
        moves, gains = [], []
        for i, p in enumerate(self.points):
            ys = self._ys(total, i, [0])
            x = _quadratic_min(p[0], ys, p[2], p[3])[:, 0]
            moves.append(x)
            gains.append(_newton(p[0], ys, x[:, None])[:, 0] - total[0, :, 0])
        if len(moves) > 1:
            best = np.argmin(np.array(gains), axis=0)
            moves = [np.where(best == i, x, p[0][p[1]]) for i, (x, p) in enumerate(zip(moves, self.points))]
        return moves

    def at(self, block: np.ndarray, partner: list, columns) -> np.ndarray:
        """(grid, strides) of `block` with the partners at `partner` (per grid value), additive in partners."""
        out = block[0][:, columns].copy()
        for i, x in enumerate(partner):
            out += _newton(self.points[i][0], self._ys(block, i, columns), x[:, None]) - block[0][:, columns]
        return out


def rank_candidates(data: StrideData, stack: Stack, candidates: list[Candidate], settings: Settings,
                    base_sse: np.ndarray, base_errors: dict, grids: dict | None = None) -> list[dict]:
    """Grid each candidate's magnitude on top of `stack` (its accepted effects refitted at each grid value),
    fit it per fold on the training strides, score it on the held-out ones. Returns result dicts, best first."""
    if not candidates:
        return []
    grids = grids or {c.name: search_grid(c, settings.grid) for c in candidates}
    points = [_partner_points(r) for r in stack.effects]
    partner_rows = [None]
    for i, (xs, centre, _, _) in enumerate(points):
        for j in range(3):
            if j != centre:
                values = [float(r["value"]) for r in stack.effects]
                values[i] = float(xs[j])
                partner_rows.append(values)
    bases = [stack.variant(values) for values in partner_rows]
    variants = [c.build(b, float(v)) for c in candidates for b in bases for v in grids[c.name]]
    sim = simulate_variants(data, variants)
    n = sim["sse"].shape[1]
    fold = _folds(n, settings.folds)
    results, row = [], 0
    for c in candidates:
        grid = grids[c.name]
        size = len(bases) * len(grid)
        fit = _Backfit(sim["sse"][row:row + size].reshape(len(bases), len(grid), n),
                       {k: v[row:row + size].reshape(len(bases), len(grid), n) for k, v in sim["pred"].items()},
                       points)
        row += size
        everything = np.arange(n)
        partner_all = fit.partner_values(everything)
        profile_all = fit.at(fit.sse, partner_all, everything).sum(axis=1)
        floor = 0.5 * fit.sse[0].min(axis=0)
        held, held_values = np.empty(n), np.empty(n)
        pred_held = {k: np.empty((len(grid), n)) for k in fit.pred}
        fold_values, partner_folds = [], [[] for _ in points]
        for f in np.unique(fold):
            train, test = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
            partner = fit.partner_values(train)
            m = _vertex(grid, fit.at(fit.sse, partner, train).sum(axis=1))
            fold_values.append(m)
            for i, x in enumerate(partner):
                partner_folds[i].append(float(np.interp(m, grid, x)))
            held[test] = np.maximum(_quadratic_at(grid, fit.at(fit.sse, partner, test), m), floor[test])
            held_values[test] = m
            for k, block in fit.pred.items():
                pred_held[k][:, test] = fit.at(block, partner, test)
        value = _vertex(grid, profile_all)
        fit_total = float(_quadratic_at(grid, profile_all[:, None], value)[0])
        errors = _errors(data, _interp_pred(grid, pred_held, held_values))
        results.append(_score({"name": c.name, "candidate": c, "value": value, "fold_values": fold_values,
                               "partner_values": [float(np.interp(value, grid, x)) for x in partner_all],
                               "partner_fold_values": partner_folds, "magnitude": c.physical(value),
                               "fit_reduction": float(1.0 - max(fit_total, 0.0) / base_sse.sum()),
                               "grid_reduction": float(1.0 - profile_all.min() / base_sse.sum()),
                               "held_sse": held, "errors": errors, "grid": grid},
                              data, base_sse, base_errors, settings))
    results.sort(key=lambda r: -r["reduction"])
    return results


def _vertex(grid: np.ndarray, values: np.ndarray) -> float:
    """Where a sampled SSE is lowest: the vertex of the parabola through the best grid point and its neighbours
    (an SSE is quadratic in a magnitude near its minimum; its logarithm is not)."""
    k = int(np.argmin(values))
    j = min(max(k, 1), len(grid) - 2)
    x, y = grid[j - 1:j + 2], values[j - 1:j + 2]
    a = np.polyfit(x, y, 2)
    if a[0] <= 0:
        return float(grid[k])
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    return float(np.clip(-a[1] / (2 * a[0]), lo, hi))


def _quadratic_at(grid: np.ndarray, values: np.ndarray, x: float) -> np.ndarray:
    """Columns of `values` (grid x columns) interpolated at x through the three nearest grid points."""
    k = int(np.clip(np.searchsorted(grid, x), 1, len(grid) - 2))
    xs = grid[k - 1:k + 2]
    out = 0.0
    for j in range(3):
        others = [xs[i] for i in range(3) if i != j]
        out = out + values[k - 1 + j] * ((x - others[0]) * (x - others[1]) / ((xs[j] - others[0]) * (xs[j] - others[1])))
    return out


APEX_ERRORS = ("E_p", "E_v", "E_t")


def _apex_sum(errors: dict) -> float:
    return sum(errors[k] for k in APEX_ERRORS)


def _guards(r: dict, base_errors: dict, settings: Settings) -> None:
    """Trajectory and next-apex criteria on held-out strides; a sensor's magnitude must be a real sensor's."""
    why = []
    if r["reduction"] < settings.min_reduction:
        why.append(f"held-out trajectory residual falls only {100 * r['reduction']:.1f} %")
    elif r.get("total_reduction", 1.0) < settings.min_total_reduction:
        why.append(f"it explains only {100 * r['total_reduction']:.1f} % of the model's residual")
    if r["t"] < settings.min_t:
        why.append(f"not consistent over strides (t {r['t']:.1f})")
    if r["delta_bic"] >= 0:
        why.append("information criterion against it")
    e, b = r["errors"], base_errors
    worse = [k for k in APEX_ERRORS if not e[k] <= b[k] * (1 + settings.apex_tolerance) + 1e-6]
    if worse:
        why.append("held-out " + ", ".join(worse) + " worse")
    # a sensor fault changes what is measured, not the motion: the next apex it predicts is the same (a delay)
    # or moves with the measurement, so it must not be worse; physics must predict it better
    # (then the fault must account for most of the model's residual: a small one fits what the physics left;
    # a discovered ringing need not: its discovery already showed an oscillation the smooth residual cannot make)
    c = r["candidate"]
    measured = c.kind == "sensor" or getattr(c.discovery, "measurement", False)
    better = _apex_sum(e) <= _apex_sum(b) * (1 - settings.apex_improvement)
    if not measured and not better:
        why.append("the next apex is not predicted better")
    elif c.kind == "sensor" and not better and r.get("total_reduction", 1.0) < settings.sensor_alone:
        why.append(f"the next apex is not predicted better and it explains only {100 * r['total_reduction']:.0f} % "
                   "of the model's residual")
    if e["fallen"] > b["fallen"]:
        why.append(f"{e['fallen'] - b['fallen']} more strides fall")
    if c.kind == "sensor" and not _plausible(r):
        why.append(f"{r['magnitude']:.4g} {c.unit} is not a fault a real sensor has and this data resolves")
    r["rejected"] = why
    r["significant"] = not why


def _plausible(r: dict) -> bool:
    c = r["candidate"]
    return c.plausible[0] <= abs(r["magnitude"] - c.off) <= c.plausible[1]


def correlation_length(resid: np.ndarray) -> float:
    r = resid - resid.mean()
    if r.size < 10 or np.dot(r, r) == 0:
        return 1.0
    ac = np.correlate(r, r, "full")[r.size - 1:] / np.dot(r, r)
    neg = np.flatnonzero(ac <= 0)
    cut = int(neg[0]) if neg.size else min(len(ac), 200)
    return float(max(1.0, 1.0 + 2.0 * ac[1:cut].sum()))


def _choose(ranking: list[dict], settings: Settings) -> tuple[dict | None, list[dict]]:
    """The accepted effect of a round and those it cannot be told apart from on this data.

    A sensor fault must beat the best physics effect, a discovered term set the best library effect,
    by a margin. Any other effect that passed its guards (with or without a margin) whose held-out
    fit is not worse than the accepted one's by a one-sided t of `tie_t` over strides is reported beside it
    as not separable."""
    passed = [r for r in ranking if r["significant"]]
    best_physics = max((r for r in passed if r["candidate"].kind == "physics"), key=lambda r: r["reduction"], default=None)
    best_library = max((r for r in passed if r["candidate"].kind != "discovered"), key=lambda r: r["reduction"],
                       default=None)
    for r in passed:
        c = r["candidate"]
        if c.kind == "sensor" and not _beats(r, best_physics, settings.sensor_margin, settings):
            r["significant"], r["margin_only"] = False, True
            r["rejected"].append("a physics effect explains the same residual about as well")
        if c.kind == "discovered" and best_library is not None and \
                r["reduction"] < best_library["reduction"] + settings.discovery_margin * r["reduction"]:
            r["significant"], r["margin_only"] = False, True
            r["rejected"].append("a library effect explains it about as well")
    ok = [r for r in ranking if r["significant"]]
    if not ok:
        return None, []
    top = max(ok, key=lambda r: r["reduction"])
    ties = [r for r in passed if r is not top and (_paired_t(r["held_sse"], top["held_sse"]) < settings.tie_t
                                                    or r["reduction"] >= top["reduction"] * (1 - settings.tie_share))]
    return top, ties


def _beats(r: dict, rival: dict | None, margin: float, settings: Settings) -> bool:
    """A sensor fault `r` beats the best physics effect `rival` by a margin: its reduction by `margin` of its own,
    or (near a full reduction, `near_full`, where reductions differ little) it leaves at most `margin_residual` of
    what the rival leaves on held-out strides, consistently over strides (paired t >= min_t). A discovered term set
    against a library entry has only the first: the same law written as terms (a constant force where the
    speed never changes sign) can fit closer than the entry's grid, and the entry's name is the answer."""
    if rival is None or r["reduction"] >= rival["reduction"] + margin * r["reduction"]:
        return True
    return bool(r["reduction"] >= settings.near_full
                and r["held_sse"].sum() <= settings.margin_residual * rival["held_sse"].sum()
                and _paired_t(rival["held_sse"], r["held_sse"]) >= settings.min_t)


def _paired_t(worse: np.ndarray, better: np.ndarray) -> float:
    """One-sided t over strides that `worse` fits held-out strides worse than `better`."""
    d = np.log(worse / better)
    sd = d.std(ddof=1)
    return float(d.mean() / (sd / math.sqrt(len(d)))) if sd > 0 else (math.inf if d.mean() > 0 else 0.0)


def _screen(data: StrideData, stack: Stack, candidates: list[Candidate], settings: Settings,
            located: set) -> list[Candidate]:
    """The candidates worth a full search: the best by trajectory reduction on a subset of strides
    (coarse grid), plus every candidate acting where locate sees a residual."""
    n = len(data.strides)
    if len(candidates) <= settings.screen:
        return candidates
    index = np.linspace(0, n - 1, min(n, settings.screen_strides)).round().astype(int)
    sub = dataclasses.replace(data, strides=data.strides.subset(index))
    sse, errors = _baseline(sub, stack)
    ranked = rank_candidates(sub, stack, candidates, dataclasses.replace(settings, grid=5), sse, errors)
    # the best grid point counts too: an SSE that is not parabolic in the magnitude (a torque limit) has a
    # vertex far from its minimum on a coarse grid
    ranked.sort(key=lambda r: -max(r["fit_reduction"], r["grid_reduction"]))
    keep = {r["name"] for r in ranked[:settings.screen]}
    keep |= {c.name for c in candidates if c.kind != "sensor" and set(LOCATED_SITES[c.site]) & located
             and any(r["name"] == c.name and r["reduction"] > 0 for r in ranked)}
    return [c for c in candidates if c.name in keep]


def _refine(data, stack, ranking, settings, base_sse, base_errors, exact: int = 12) -> list[dict]:
    """Every candidate again on a fine grid between the neighbours of its best grid value (an SSE is not
    parabolic where an effect switches on, e.g. a torque limit), then the best scored from strides simulated
    at their fold magnitudes (no interpolation)."""
    grids = {}
    for r in ranking:
        grid, c = r["grid"], r["candidate"]
        k = int(np.argmin(np.abs(grid - r["value"])))
        grids[c.name] = np.linspace(grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)], settings.grid)
    refined = {r["name"]: r for r in rank_candidates(data, stack, [r["candidate"] for r in ranking], settings,
                                                       base_sse, base_errors, grids=grids)}
    ranking = [refined[r["name"]] if refined[r["name"]]["fit_reduction"] > r["fit_reduction"] else r
               for r in ranking]
    ranking.sort(key=lambda r: -r["fit_reduction"])
    best = ranking[:exact] + [r for r in ranking[exact:] if r["candidate"].kind == "discovered"]
    _evaluate_exactly(data, stack, best, settings, base_sse, base_errors)
    ranking.sort(key=lambda r: -r["reduction"])
    return ranking


def _evaluate_exactly(data, stack, results, settings, base_sse, base_errors) -> None:
    """Held-out scores of fitted candidates from strides simulated at their fold magnitudes (no interpolation)."""
    fold = _folds(len(data.strides), settings.folds)
    folds = list(np.unique(fold))
    variants = [r["candidate"].build(stack.variant([p[fi] for p in r["partner_fold_values"]]), float(v))
                for r in results for fi, v in enumerate(r["fold_values"])]
    sim = simulate_variants(data, variants)
    idx = np.array([folds.index(f) for f in fold])
    cols = np.arange(len(fold))
    for k, r in enumerate(results):
        rows = k * len(folds) + idx
        held = sim["sse"][rows, cols]
        pred = {key: v[rows, cols] for key, v in sim["pred"].items()}
        r["held_sse"], r["errors"] = held, _errors(data, pred)
        _score(r, data, base_sse, base_errors, settings)


def _score(r: dict, data, base_sse: np.ndarray, base_errors: dict, settings: Settings) -> dict:
    """A result's statistics from its held-out SSE per stride against `base_sse`, then its guards."""
    held = r["held_sse"]
    d = np.log(base_sse / held)
    sd = d.std(ddof=1)
    n_eff = data.sample_count / data.corr_length
    r["total_reduction"] = float((base_sse.sum() - held.sum()) / data.model_sse)
    r["t"] = float(d.mean() / (sd / math.sqrt(len(d)))) if sd > 0 else 0.0
    r["reduction"] = float(1.0 - held.sum() / base_sse.sum())
    r["delta_bic"] = float(-2 * 0.5 * n_eff * math.log(base_sse.sum() / held.sum()) + math.log(n_eff))
    _guards(r, base_errors, settings)
    return r


def _held_out(data: StrideData, base: Variant, chosen: list[dict], fold: np.ndarray) -> tuple[np.ndarray, dict]:
    """Per stride, the trajectory SSE and the next apex with the chosen effects at the magnitudes fitted without
    the stride's fold."""
    folds = list(np.unique(fold))
    variants = []
    for fi in range(len(folds)):
        v = base
        for r in chosen:
            v = r["candidate"].build(v, float(r["fold_values"][fi]))
        variants.append(v)
    sim = simulate_variants(data, variants)
    rows, cols = np.array([folds.index(f) for f in fold]), np.arange(len(fold))
    return sim["sse"][rows, cols], {k: sim["pred"][k][rows, cols] for k in sim["pred"]}


def _held_out_variants(data: StrideData, base: Variant, chosen: list[dict], fold: np.ndarray) -> dict:
    """Per-stride next apex with the chosen effects at the magnitudes fitted without the stride's fold."""
    return _held_out(data, base, chosen, fold)[1]


def _search(data, stack, candidates, settings, base_sse, base_errors) -> list[dict]:
    return _refine(data, stack, rank_candidates(data, stack, candidates, settings, base_sse, base_errors),
                   settings, base_sse, base_errors)


def _polish(data, base, partners, result, settings, base_sse, base_errors) -> dict:
    """The joint fit of `result` with its partners, repeated from the refitted magnitudes: each pass refits
    the partners by a quadratic about their values, exact once the magnitudes stop moving."""
    for _ in range(settings.polish if partners else 0):
        _adopt(partners, result)
        step = np.diff(result["grid"]).max()
        grid = {result["name"]: np.linspace(result["value"] - step, result["value"] + step, settings.grid)}
        again = rank_candidates(data, Stack(base, partners), [result["candidate"]], settings, base_sse,
                                base_errors, grids=grid)
        _evaluate_exactly(data, Stack(base, partners), again, settings, base_sse, base_errors)
        moved = [abs(a - b) for a, b in zip(again[0]["partner_values"], [r["value"] for r in partners])]
        if again[0]["reduction"] < result["reduction"]:
            break
        result.update(again[0])
        if all(m <= 1e-3 * (r["candidate"].high - r["candidate"].low) for m, r in zip(moved, partners)):
            break
    _adopt(partners, result)
    return result


def _adopt(chosen: list[dict], result: dict) -> None:
    """The accepted effects take the magnitudes they were refitted to beside `result`."""
    for r, value, folds in zip(chosen, result["partner_values"], result["partner_fold_values"]):
        r["value"], r["fold_values"], r["magnitude"] = value, list(folds), r["candidate"].physical(value)


def _baseline(data, stack) -> tuple[np.ndarray, dict]:
    """Per-stride trajectory SSE and the next-apex errors of the model `stack` (the reference its additions are
    judged against)."""
    sim = simulate_variants(data, [stack.variant()])
    return sim["sse"][0], _errors(data, {k: v[0] for k, v in sim["pred"].items()})


def _revisit(data, base, chosen, settings, current_sse, current_errors):
    """Each earlier effect tried again beside the later ones, against its round's runners-up: one that
    stood in for a pair (a lower gain for a gain and drag) is replaced, one no longer needed is dropped."""
    i = 0
    while i < len(chosen) - 1 and len(chosen) > 1:
        old = chosen[i]
        others = chosen[:i] + chosen[i + 1:]
        stack = Stack(base, others)
        sse, errors = _baseline(data, stack)
        taken = {r["name"] for r in others}
        pool = [old["candidate"]] + [c for c in old.get("alternatives", []) if c.name not in taken]
        ranking = _search(data, stack, pool, settings, sse, errors)
        best, ties = _choose(ranking, settings)
        if best is None:
            chosen.pop(i)
            current_sse, current_errors = sse, errors
            continue
        again = next(r for r in ranking if r["name"] == old["name"])
        if best is not again and again["significant"] and _paired_t(again["held_sse"], best["held_sse"]) < settings.tie_t:
            ties = [best] + [r for r in ties if r is not again]
            best = again                  # not clearly better: keep the first
        best["ties"] = ties               # the look-alikes beside the later effects, where they are told apart best
        best["location"] = old.get("location", [])
        best["alternatives"] = [c for c in pool if c.name != best["name"]]
        _polish(data, base, others, best, settings, sse, errors)
        chosen[i] = best
        current_sse, current_errors = best["held_sse"], best["errors"]
        i += 1
    return current_sse, current_errors


def _exchange(data, base, chosen, ranking, settings, current_sse, current_errors):
    """When no effect passes on top of the accepted ones, an accepted one may be standing in for a pair
    (it fitted both alone): each strong runner-up is added, the earlier effects revisited beside it (and
    swapped for their rounds' runners-up), and the set kept if every effect in it then passes its guards
    against the model without it. Returns (effects, held-out SSE, errors) or None."""
    strong = [r for r in ranking if r["reduction"] >= settings.min_reduction and r["t"] >= settings.min_t]
    for r in strong[:settings.exchange]:
        trial = [dict(e) for e in chosen]
        added = dict(r)
        _polish(data, base, trial, added, settings, current_sse, current_errors)
        trial.append(added)
        _revisit(data, base, trial, settings, added["held_sse"], added["errors"])
        if [e["name"] for e in trial[:-1]] == [e["name"] for e in chosen] or len(trial) <= len(chosen):
            continue                      # nothing was exchanged: the runner-up failed on its own already
        others = trial[:-1]
        sse, without = _baseline(data, Stack(base, others))
        last = _search(data, Stack(base, others), [trial[-1]["candidate"]], settings, sse, without)[0]
        if not last["significant"]:
            continue
        _polish(data, base, others, last, settings, sse, without)
        against = _score({"held_sse": last["held_sse"], "errors": last["errors"], "candidate": last["candidate"],
                          "magnitude": last["magnitude"]}, data, current_sse, current_errors, settings)
        if not against["significant"]:
            continue                      # the exchanged set must beat the accepted one as an added effect would
        last.update({k: trial[-1][k] for k in ("location", "alternatives") if k in trial[-1]})
        last["ties"] = []
        return others + [last], last["held_sse"], last["errors"]
    return None


def _with_secondary(data, stack, r, p, settings, sse, errors, guarded: bool = True) -> dict | None:
    """`r`'s candidate with its secondary parameter `p` on a grid, geometric between its bounds, with the
    model's own value in place of a grid value within half a step of it, the magnitude refitted at each (on
    top of `stack`); the best value other than the model's when held-out strides prefer it (paired t of at
    least `min_t`) and (`guarded`) it passes its guards, else None."""
    own = float(getattr(stack.variant().coefficients, p.coefficient))
    grid = np.geomspace(p.low, p.high, settings.secondary_grid)
    step = (p.high / p.low) ** (0.5 / max(settings.secondary_grid - 1, 1))   # half a grid step
    values = [own] + [float(v) for v in grid if not own / step < v < own * step]
    tried = {v: _search(data, stack, [r["candidate"].holding(p, v)], settings, sse, errors)[0] for v in values}
    value = min(tried, key=lambda v: tried[v]["held_sse"].sum())
    best = tried[value]
    if value == own or (guarded and not best["significant"]) or \
            _paired_t(tried[own]["held_sse"], best["held_sse"]) < settings.min_t:
        return None
    return best


def _secondary_look_alikes(data, stack, ranking, settings, sse, errors) -> list[dict]:
    """A round's look-alikes of its best (as `_choose` ties them) that have a secondary parameter compete with
    it fitted: a compliant ground with its own damping against a softer leg. Returns the ranking, re-sorted."""
    passed = [r for r in ranking if r["significant"]]
    if not passed:
        return ranking
    top = max(passed, key=lambda r: r["reduction"])
    out = []
    for r in ranking:
        alike = r is top or _paired_t(r["held_sse"], top["held_sse"]) < settings.tie_t or \
            r["reduction"] >= top["reduction"] * (1 - settings.tie_share)
        for p in r["candidate"].secondary if r["significant"] and alike else ():
            r = _with_secondary(data, stack, r, p, settings, sse, errors) or r
        out.append(r)
    return sorted(out, key=lambda r: -r["reduction"])


def _fit_secondary(data, base, chosen, settings, only=None, guarded: bool = True) -> None:
    """Each accepted entry's secondary parameters (`_with_secondary`), beside the other accepted effects (`only`:
    those of these indices)."""
    for i in range(len(chosen)) if only is None else only:
        for p in chosen[i]["candidate"].secondary:
            r, others = chosen[i], chosen[:i] + chosen[i + 1:]
            stack = Stack(base, others)
            sse, errors = _baseline(data, stack)
            best = _with_secondary(data, stack, r, p, settings, sse, errors, guarded)
            if best is None:
                continue
            _polish(data, base, others, best, settings, sse, errors)
            best.update({k: r[k] for k in ("location", "ties", "alternatives") if k in r})
            chosen[i] = best


def _discovered_look_alikes(data, base, chosen, settings, log) -> None:
    """Each accepted library effect beside the term sets discovered where it acts, with the other accepted effects
    in place, or one of them replaced by a look-alike of its own (a softer leg by the compliant ground it could not
    be told from): a set that passes its guards there and fits held-out strides not clearly worse (paired t below
    `tie_t`) is reported as its look-alike. The rounds that found the set decided the name; this says what else the
    data allow (a flight-only lift beside the lower gravity it looks like in flight, once a compliant ground has
    been explained in stance by the ground itself rather than by a softer leg)."""
    for i, r in enumerate(chosen):
        c = r["candidate"]
        if c.kind == "discovered":
            continue
        ties = r.setdefault("ties", [])
        others = chosen[:i] + chosen[i + 1:]
        contexts = [others] + [others[:j] + [dict(t)] + others[j + 1:] for j, o in enumerate(others)
                               for t in o.get("ties", []) if t["candidate"].kind != "discovered"]
        for context in contexts:
            known = {t["name"] for t in ties}
            sites = [site for site in candidate_sites(c) if site in LOCATE_SITES and f"discovered_{site}" not in known]
            if not sites:
                break
            stack = Stack(base, context)
            _, sets = locate(data, stack.variant())
            found = [f for f in (discover_site(site, sets) for site in sites) if f is not None]
            if not found:
                continue
            log["discoveries"].extend(found)
            sse, errors = _baseline(data, stack)
            ranking = _search(data, stack, [c] + [discovered_candidate(f) for f in found], settings, sse, errors)
            own = next(x for x in ranking if x["name"] == c.name)
            ties += [x for x in ranking if x is not own and x["significant"]
                     and _paired_t(x["held_sse"], own["held_sse"]) < settings.tie_t]


def _cumulative_errors(data, base, chosen, fold) -> None:
    """Held-out E_p/E_v/E_t after each accepted effect and those before it, at their final magnitudes."""
    for k in range(1, len(chosen) + 1):
        chosen[k - 1]["errors"] = _errors(data, _held_out_variants(data, base, chosen[:k], fold))


def base_variant(params: ModelParams, model_effects: dict | None = None) -> Variant:
    coefficients, sensors = library.apply(laws.Coefficients.from_model(params), model_effects or {})
    return Variant(coefficients, sensors)


def diagnose(rec: Recording, params: ModelParams, settings: Settings, model_effects: dict | None = None) -> dict:
    data = prepare(rec, params, settings.min_strides, settings.liftoff_window)
    base = base_variant(params, model_effects)
    base_sim = simulate_variants(data, [base], keep_series=True)
    data.corr_length = max(1.0, float(np.median([correlation_length(r["z"][0]) for r in base_sim["series"]])))
    data.model_sse = float(base_sim["sse"][0].sum())
    fold = _folds(len(data.strides), settings.folds)
    current_sse = base_sim["sse"][0]
    base_errors = current_errors = _errors(data, {k: v[0] for k, v in base_sim["pred"].items()})
    excited = {"command": float(np.max(np.abs(data.strides.tau_0), initial=0.0))}
    log = {"rounds": [], "discoveries": []}
    chosen, _, _ = _rounds(data, base, settings, excited, [], current_sse, current_errors, log)
    rounds, discoveries = log["rounds"], log["discoveries"]
    # a refit beside later effects may move a sensor fault to where no real sensor has one: then it is not one
    chosen = [r for r in chosen if r["candidate"].kind != "sensor" or _plausible(r)]
    left = locate(data, Stack(base, chosen).variant())[0] if chosen else []
    if (any(loc.ratio >= settings.restart_threshold for loc in left) or len(chosen) >= settings.max_effects
            or (len(chosen) > 1 and _lost_on_a_margin(log["first_ranking"]))):
        chosen = _restarts(data, base, settings, excited, chosen, log, fold, base_errors)
    _fit_secondary(data, base, chosen, settings)
    _discovered_look_alikes(data, base, chosen, settings, log)
    current = Stack(base, chosen).variant()
    _cumulative_errors(data, base, chosen, fold)
    final_sim = simulate_variants(data, [base, current], keep_series=True)
    before = base_errors
    after = _errors(data, _held_out_variants(data, base, chosen, fold)) if chosen else before
    first_location = _with_chosen_sites(log["first_location"], chosen, settings)
    if not chosen and all(loc.ratio < settings.locate_threshold for loc in first_location):
        found = trajectory_location(base_sim["by_phase"][0], base_sim["counts"], settings.locate_threshold,
                                    settings.trajectory_threshold, PHASES, CHANNELS)
        first_location = [found] + first_location if found else first_location
    residual_location = locate(data, current)[0] if chosen else first_location
    return {"data": data, "rounds": rounds, "chosen": chosen, "before_phase": _rms_table(final_sim, 0, data),
            "after_phase": _rms_table(final_sim, 1, data), "before": before, "after": after,
            "base_series": base_sim["series"], "after_series": final_sim["series"], "location": first_location,
            "residual_location": residual_location, "discoveries": discoveries,
            "verdict": verdict(chosen, residual_location if chosen else first_location, settings.locate_threshold),
            "settings": settings, "model_effects": dict(model_effects or {})}


def _rounds(data, base, settings, excited, chosen, current_sse, current_errors, log):
    """Greedy rounds from the effects in `chosen` (their held-out SSE and errors given) up to `max_effects`:
    locate, screen the library, discover at the located sites, search, accept the best that passes every guard
    (or exchange an accepted one), refit jointly and revisit. `log` collects the rankings, the discoveries and
    the first round's locations and ranking. Returns (chosen, held-out SSE, errors)."""
    for _ in range(len(chosen), settings.max_effects):
        stack = Stack(base, list(chosen))
        current = stack.variant()
        locations, sets = locate(data, current)
        located = {loc.site for loc in locations if loc.ratio >= settings.locate_threshold}
        taken = {r["name"] for r in chosen}
        cands = [library_candidate(e, current.coefficients, excited) for e in library.LIBRARY + library.SENSORS
                 if e.name not in taken]
        cands = _screen(data, stack, cands, settings, located)
        for site in sorted(located & set(LOCATE_SITES)):     # (touchdown timing has no residual samples)
            found = discover_site(site, sets)
            if found is not None and f"discovered_{site}" not in taken:
                log["discoveries"].append(found)
                cands.append(discovered_candidate(found))
        cands += _ringing_candidates(data, located, taken, log)
        ranking = _search(data, stack, cands, settings, current_sse, current_errors)
        ranking = _secondary_look_alikes(data, stack, ranking, settings, current_sse, current_errors)
        log.setdefault("first_location", locations)
        log.setdefault("first_ranking", ranking)
        top, ties = _choose(ranking, settings)
        log["rounds"].append(ranking)
        if top is None and chosen:
            trial = _exchange(data, base, chosen, ranking, settings, current_sse, current_errors)
            if trial is not None:
                chosen, current_sse, current_errors = trial
                continue
        if top is None:
            break
        top["ties"] = ties
        top["location"] = [loc for loc in locations if loc.ratio >= settings.locate_threshold]
        top["alternatives"] = [r["candidate"] for r in ranking[:settings.screen] if r is not top]
        _polish(data, base, chosen, top, settings, current_sse, current_errors)
        chosen.append(top)
        # its secondary parameters now, so that the next rounds search on top of it as the data have it (a
        # compliant ground at the model's damping makes a flight-only lift look like a lower gravity)
        _fit_secondary(data, base, chosen, settings, only=[len(chosen) - 1])
        top = chosen[-1]
        current_sse, current_errors = top["held_sse"], top["errors"]
        if len(chosen) > 1:
            current_sse, current_errors = _revisit(data, base, chosen, settings, current_sse, current_errors)
    return chosen, current_sse, current_errors


def _restarts(data, base, settings, excited, chosen, log, fold, base_errors) -> list[dict]:
    """When the accepted set leaves a residual clearly above the noise (`restart_threshold`), fills every round
    (`max_effects`), or holds two or more where the first won on a naming margin against a candidate that fitted
    better (`_lost_on_a_margin`), its first effect may stand in for a pair it is not part of (a gain fits a toe
    mass and a delay together better than either alone; a torque offset stands for a theta encoder's offset
    beside a stiffer leg, and two more effects patch what it leaves): the first round's next-best candidates (a
    sensor fault among them if its magnitude is a real sensor's), those that failed only an apex guard alone as
    well (their partner is missing), each start the rounds again, the candidates that lost on a margin first. A
    set found so replaces the accepted one when it holds two effects or more (or, started from a candidate that
    lost on a margin, fewer than the accepted set: the margin gives a library entry its name where it does the
    job alone, not where it needs another effect to patch it), each of which passed its guards beside the
    others, and beats the accepted set as a whole explanation: the held-out trajectory SSE lower by `min_reduction` with a
    paired t of at least `min_t`, the sum of the held-out E_p, E_v, E_t not worse by more than `apex_tolerance`,
    and none of them worse than the model's own (two explanations trade a little E_t for E_p; each compared
    alone, the guard would keep the wrong one)."""
    first = chosen[0]["name"]
    margin = _lost_on_a_margin(log["first_ranking"]) if len(chosen) > 1 else []
    lost = {r["name"] for r in margin}
    # (a sensor fault that lost its round on the sensor margin without fitting better is a runner-up as well: a
    # theta encoder's offset behind the torque offset that stands in for it)
    pool = [(r, True) for r in margin] + [
        (r, False) for r in [r for r in log["first_ranking"] if r["name"] != first and r["name"] not in lost
                             and r["reduction"] >= settings.min_reduction and r["t"] >= settings.min_t
                             and (r["candidate"].kind != "sensor" or _plausible(r))][:settings.restarts]]
    best_sse, best_pred = _held_out(data, base, chosen, fold)
    best, best_errors = chosen, _errors(data, best_pred)
    for r, smaller in pool:
        start = [dict(r, ties=[], location=[], alternatives=[x["candidate"] for x in log["first_ranking"]
                                                              [:settings.screen] if x["name"] != r["name"]])]
        # (its secondary parameters fitted first, unguarded: alone it may fail an apex guard for want of a partner)
        _fit_secondary(data, base, start, settings, guarded=False)
        trial, _, _ = _rounds(data, base, settings, excited, start, start[0]["held_sse"], start[0]["errors"],
                              {"rounds": [], "discoveries": []})
        trial = [e for e in trial if e["candidate"].kind != "sensor" or _plausible(e)]
        fewest, most = (1, len(chosen) - 1) if smaller else (2, settings.max_effects)
        if not fewest <= len(trial) <= most:
            continue
        sse, pred = _held_out(data, base, trial, fold)
        errors = _errors(data, pred)
        if (1.0 - sse.sum() / best_sse.sum() >= settings.min_reduction and _paired_t(best_sse, sse) >= settings.min_t
                and _apex_sum(errors) <= _apex_sum(best_errors) * (1 + settings.apex_tolerance)
                and all(errors[k] <= base_errors[k] * (1 + settings.apex_tolerance) for k in APEX_ERRORS)
                and errors["fallen"] <= best_errors["fallen"]):
            best, best_sse, best_errors = trial, sse, errors
    return best


def _lost_on_a_margin(ranking: list[dict]) -> list[dict]:
    """First-round candidates that passed every guard and fitted better than the round's choice but lost to it on
    a naming margin (a sensor fault against physics, discovered terms against the library): the choice may need
    more effects to fit what one of them fits alone (a torque offset and a theta scale for a torsion spring)."""
    chosen = max((r["reduction"] for r in ranking if r["significant"]), default=math.inf)
    return [r for r in ranking if r.get("margin_only") and r["reduction"] > chosen]


def _with_chosen_sites(locations: list[Location], chosen: list[dict], settings: Settings) -> list[Location]:
    """The force locations with each accepted effect located by its own fit (its held-out gain over the model
    without it, the others kept; the second effect of a pair is judged beside the first) where no force
    location stands stronger at its site."""
    strongest = {}
    for loc in locations:
        strongest[loc.site] = max(strongest.get(loc.site, -math.inf), loc.ratio)
    added = [loc for loc in fit_locations(chosen, candidate_sites, settings.locate_threshold, settings.min_t)
             if loc.ratio > strongest.get(loc.site, -math.inf)]
    return sorted(locations + added, key=lambda loc: -loc.ratio)


def _rms_table(sim: dict, row: int, data: StrideData) -> dict:
    bp = sim["by_phase"][row].sum(axis=0)
    cnt = sim["counts"].sum(axis=0)
    return {ph: {v: (float(math.sqrt(bp[pi, ci] / cnt[pi, ci])) if cnt[pi, ci] else float("nan"))
                 for ci, v in enumerate(("y", "z", "theta"))} for pi, ph in enumerate(PHASES)}


def verdict(chosen: list[dict], left: list[Location] | None = None, threshold: float = math.inf) -> str:
    """The `missing:` line; a located residual that nothing explains is named as such, not hidden."""
    unexplained = [loc for loc in (left or []) if loc.ratio >= threshold]
    tail = ""
    if unexplained:
        tail = ("; unexplained: " + "; ".join(loc.words() for loc in unexplained[:2])
                + " (no library effect or discovered term fits it)")
    if not chosen:
        if not unexplained:
            return "no significant mismatch"
        return ("missing: something no library effect or discovered term models, at "
                + "; ".join(loc.words() for loc in unexplained[:2]))
    parts = []
    for r in chosen:
        c = r["candidate"]
        if c.kind == "discovered":
            text = f"{c.name}: {c.describe(r['value'])}"
        else:
            text = f"{c.name} = {r['magnitude']:.4g} {c.unit}".rstrip()
            text += "".join(f" ({k} {v:.4g} {u})" for k, (v, u) in c.held.items())
        if r.get("ties"):
            text += " (or " + " or ".join(t["name"] for t in r["ties"]) + ": not separable on this data)"
        parts.append(text)
    return "missing: " + ", ".join(parts) + tail


def timing_line(data: StrideData) -> str:
    """Where stance begins against the model's geometry (the held leg starts to turn before the model's leg,
    at its rest length, would reach the ground): empty when they agree."""
    lead = data.touchdown_lead
    if abs(lead) <= LEAD_RESOLVED:
        return ""
    when = "before" if lead > 0 else "after"
    return (f"events: stance begins {abs(lead) * 1e3:.1f} ms {when} the model's leg reaches the ground (median "
            "over strides): the running surface or the leg's length is not where the model has it, or the height "
            "channel lags")


def location_line(locations: list[Location], threshold: float) -> str:
    above = [loc for loc in locations if loc.ratio >= threshold]
    if not above:
        return "location: nothing above the noise level"
    return "location: " + "; ".join(loc.words() for loc in above[:3])
