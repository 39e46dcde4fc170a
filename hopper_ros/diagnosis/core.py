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
from hopper_ros.identification.recordings import Recording
from hopper_ros.physics import effects as library
from hopper_ros.physics import laws
from hopper_ros.physics.metrics import position_error_pct, time_error_pct, velocity_error_pct
from hopper_ros.physics.params import ModelParams

from .data import PHASES, StrideData, prepare
from .discover import Discovery, discover_site
from .locate import Location, locate
from .simulate import Variant, simulate_variants


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
    sensor_margin: float = 0.15      # a sensor effect must beat the best physics effect's reduction by this share
    discovery_margin: float = 0.15   # a discovered term set must beat the best library effect by this share
    tie_t: float = 2.5               # an effect fitting held-out strides not worse by this t is a look-alike ...
    tie_share: float = 0.02          # ... and so is one whose reduction is within this share of the best's
    locate_threshold: float = 2.5    # residual over noise for a site to stand out
    screen: int = 8                  # candidates the screening passes on to the full search
    screen_strides: int = 24         # strides the screening uses
    liftoff_window: float = 0.003


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

    def describe(self, value: float) -> str:
        if self.discovery is not None:
            return self.discovery.words(value)
        return self.words


LOCATED_SITES = {  # library site -> located sites where it shows first
    "flight": ("flight_horizontal", "flight_vertical"), "touchdown": ("touchdown_along", "touchdown_across"),
    "stance_leg": ("stance_along",), "stance_hip": ("stance_hip",), "actuator": ("stance_hip",),
    "liftoff": ("liftoff_along", "liftoff_across"), "sensor": (),
}


def library_candidate(effect: library.Effect, base: laws.Coefficients) -> Candidate:
    low, high = effect.search_bounds(base)
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
                     off=library.SENSOR_OFF.get(p.coefficient, 0.0), origin=origin, equation=effect.equation)


def discovered_candidate(found: Discovery) -> Candidate:
    def build(variant: Variant, value: float, found=found) -> Variant:
        old = getattr(variant.coefficients, found.field)
        new = tuple(float(o) + value * c for o, c in zip(old, found.coefficients))
        return variant.with_changes(coefficients={found.field: new})

    return Candidate(f"discovered_{found.site}", "discovered", "discovered", found.site, "x fitted terms",
                     found.words(), 0.0, 2.0, build, float,
                     "a force plate, or strides that lengthen the phase where the terms act", discovery=found,
                     equation=" + ".join(f"{c:+.4g} {k}" for k, c, _, _ in found.terms()))


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


def rank_candidates(data: StrideData, current: Variant, candidates: list[Candidate], settings: Settings,
                    base_sse: np.ndarray, base_errors: dict, grids: dict | None = None) -> list[dict]:
    """Grid each candidate's magnitude on top of `current`, fit it per fold on the training strides, score it
    on the held-out ones. Returns result dicts, best first."""
    if not candidates:
        return []
    grids = grids or {c.name: search_grid(c, settings.grid) for c in candidates}
    variants = [c.build(current, float(v)) for c in candidates for v in grids[c.name]]
    sim = simulate_variants(data, variants)
    n = sim["sse"].shape[1]
    fold = _folds(n, settings.folds)
    results, row = [], 0
    for c in candidates:
        grid = grids[c.name]
        sse = sim["sse"][row:row + len(grid)]
        pred_grid = {k: v[row:row + len(grid)] for k, v in sim["pred"].items()}
        row += len(grid)
        floor = 0.5 * sse.min(axis=0)
        held = np.empty(n)
        held_values = np.empty(n)
        fold_values = []

        def fit(columns):
            return _vertex(grid, sse[:, columns].sum(axis=1))

        for f in np.unique(fold):
            train = fold != f
            m = fit(train)
            fold_values.append(m)
            held[~train] = np.maximum(_quadratic_at(grid, sse[:, ~train], m), floor[~train])
            held_values[~train] = m
        value = fit(np.ones(n, bool))
        fit_total = float(_quadratic_at(grid, sse.sum(axis=1)[:, None], value)[0])
        d = np.log(base_sse / held)
        sd = d.std(ddof=1)
        t_stat = float(d.mean() / (sd / math.sqrt(n))) if sd > 0 else 0.0
        reduction = 1.0 - held.sum() / base_sse.sum()
        n_eff = data.sample_count / data.corr_length
        llr = 0.5 * n_eff * math.log(base_sse.sum() / held.sum())
        errors = _errors(data, _interp_pred(grid, pred_grid, held_values))
        results.append({"name": c.name, "candidate": c, "value": value, "fold_values": fold_values,
                        "magnitude": c.physical(value), "reduction": float(reduction), "t": t_stat,
                        "fit_reduction": float(1.0 - max(fit_total, 0.0) / base_sse.sum()),
                        "delta_bic": float(-2 * llr + math.log(n_eff)), "held_sse": held, "errors": errors,
                        "grid": grid})
    for r in results:
        r["total_reduction"] = float((base_sse.sum() - r["held_sse"].sum()) / data.model_sse)
        _guards(r, base_errors, settings)
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
    keys = ("E_p", "E_v", "E_t")
    worse = [k for k in keys if not e[k] <= b[k] * (1 + settings.apex_tolerance) + 1e-6]
    if worse:
        why.append("held-out " + ", ".join(worse) + " worse")
    if not sum(e[k] for k in keys) <= sum(b[k] for k in keys) * (1 - settings.apex_improvement):
        why.append("the next apex is not predicted better")
    if e["fallen"] > b["fallen"]:
        why.append(f"{e['fallen'] - b['fallen']} more strides fall")
    c = r["candidate"]
    if c.kind == "sensor" and not (c.plausible[0] <= abs(r["magnitude"] - c.off) <= c.plausible[1]):
        why.append(f"{r['magnitude']:.4g} {c.unit} is not a fault a real sensor has and this data resolves")
    r["rejected"] = why
    r["significant"] = not why


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
    best_physics = max((r["reduction"] for r in passed if r["candidate"].kind == "physics"), default=0.0)
    best_library = max((r["reduction"] for r in passed if r["candidate"].kind != "discovered"), default=0.0)
    for r in passed:
        c = r["candidate"]
        if c.kind == "sensor" and r["reduction"] < best_physics + settings.sensor_margin * r["reduction"]:
            r["significant"] = False
            r["rejected"].append("a physics effect explains the same residual about as well")
        if c.kind == "discovered" and r["reduction"] < best_library + settings.discovery_margin * r["reduction"]:
            r["significant"] = False
            r["rejected"].append("a library effect explains it about as well")
    ok = [r for r in ranking if r["significant"]]
    if not ok:
        return None, []
    top = max(ok, key=lambda r: r["reduction"])
    ties = [r for r in passed if r is not top and (_paired_t(r["held_sse"], top["held_sse"]) < settings.tie_t
                                                    or r["reduction"] >= top["reduction"] * (1 - settings.tie_share))]
    return top, ties


def _paired_t(worse: np.ndarray, better: np.ndarray) -> float:
    """One-sided t over strides that `worse` fits held-out strides worse than `better`."""
    d = np.log(worse / better)
    sd = d.std(ddof=1)
    return float(d.mean() / (sd / math.sqrt(len(d)))) if sd > 0 else (math.inf if d.mean() > 0 else 0.0)


def _screen(data: StrideData, current: Variant, candidates: list[Candidate], settings: Settings,
            located: set) -> list[Candidate]:
    """The candidates worth a full search: the best by trajectory reduction on a subset of strides
    (coarse grid), plus every candidate acting where locate sees a residual."""
    n = len(data.strides)
    if len(candidates) <= settings.screen:
        return candidates
    index = np.linspace(0, n - 1, min(n, settings.screen_strides)).round().astype(int)
    sub = dataclasses.replace(data, strides=data.strides.subset(index))
    first = simulate_variants(sub, [current])
    errors = _errors(sub, {k: v[0] for k, v in first["pred"].items()})
    ranked = rank_candidates(sub, current, candidates, dataclasses.replace(settings, grid=5), first["sse"][0], errors)
    ranked.sort(key=lambda r: -r["fit_reduction"])
    keep = {r["name"] for r in ranked[:settings.screen]}
    keep |= {c.name for c in candidates if c.kind != "sensor" and set(LOCATED_SITES[c.site]) & located
             and any(r["name"] == c.name and r["reduction"] > 0 for r in ranked)}
    return [c for c in candidates if c.name in keep]


def _refine(data, current, ranking, settings, base_sse, base_errors, exact: int = 12) -> list[dict]:
    """Every candidate again on a fine grid between the neighbours of its best grid value (an SSE is not
    parabolic where an effect switches on, e.g. a torque limit), then the best scored from strides simulated
    at their fold magnitudes (no interpolation)."""
    grids = {}
    for r in ranking:
        grid, c = r["grid"], r["candidate"]
        k = int(np.argmin(np.abs(grid - r["value"])))
        grids[c.name] = np.linspace(grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)], settings.grid)
    refined = {r["name"]: r for r in rank_candidates(data, current, [r["candidate"] for r in ranking], settings,
                                                       base_sse, base_errors, grids=grids)}
    ranking = [refined[r["name"]] if refined[r["name"]]["fit_reduction"] > r["fit_reduction"] else r
               for r in ranking]
    ranking.sort(key=lambda r: -r["fit_reduction"])
    best = ranking[:exact] + [r for r in ranking[exact:] if r["candidate"].kind == "discovered"]
    _evaluate_exactly(data, current, best, settings, base_sse, base_errors)
    ranking.sort(key=lambda r: -r["reduction"])
    return ranking


def _evaluate_exactly(data, current, results, settings, base_sse, base_errors) -> None:
    """Held-out scores of fitted candidates from strides simulated at their fold magnitudes (no interpolation)."""
    fold = _folds(len(data.strides), settings.folds)
    folds = list(np.unique(fold))
    variants = [r["candidate"].build(current, float(v)) for r in results for v in r["fold_values"]]
    sim = simulate_variants(data, variants)
    idx = np.array([folds.index(f) for f in fold])
    cols = np.arange(len(fold))
    n = len(fold)
    for k, r in enumerate(results):
        rows = k * len(folds) + idx
        held = sim["sse"][rows, cols]
        pred = {key: v[rows, cols] for key, v in sim["pred"].items()}
        d = np.log(base_sse / held)
        sd = d.std(ddof=1)
        r["held_sse"] = held
        r["total_reduction"] = float((base_sse.sum() - held.sum()) / data.model_sse)
        r["t"] = float(d.mean() / (sd / math.sqrt(n))) if sd > 0 else 0.0
        r["reduction"] = float(1.0 - held.sum() / base_sse.sum())
        n_eff = data.sample_count / data.corr_length
        r["delta_bic"] = float(-2 * 0.5 * n_eff * math.log(base_sse.sum() / held.sum()) + math.log(n_eff))
        r["errors"] = _errors(data, pred)
        _guards(r, base_errors, settings)


def _held_out_variants(data: StrideData, base: Variant, chosen: list[dict], fold: np.ndarray) -> dict:
    """Per-stride next apex with the chosen effects at the magnitudes fitted without the stride's fold."""
    folds = list(np.unique(fold))
    variants = []
    for fi in range(len(folds)):
        v = base
        for r in chosen:
            v = r["candidate"].build(v, float(r["fold_values"][fi]))
        variants.append(v)
    sim = simulate_variants(data, variants)
    idx = np.array([folds.index(f) for f in fold])
    return {k: sim["pred"][k][idx, np.arange(len(fold))] for k in sim["pred"]}


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
    current, current_sse = base, base_sim["sse"][0]
    base_errors = current_errors = _errors(data, {k: v[0] for k, v in base_sim["pred"].items()})
    chosen, rounds, discoveries = [], [], []
    first_location = None
    for round_index in range(settings.max_effects):
        locations, sets = locate(data, current)
        if first_location is None:
            first_location = locations
        located = {loc.site for loc in locations if loc.ratio >= settings.locate_threshold}
        taken = {r["name"] for r in chosen}
        cands = [library_candidate(e, current.coefficients) for e in library.LIBRARY + library.SENSORS
                 if e.name not in taken]
        cands = _screen(data, current, cands, settings, located)
        for site in sorted(located):
            found = discover_site(site, sets)
            if found is not None and f"discovered_{site}" not in taken:
                discoveries.append(found)
                cands.append(discovered_candidate(found))
        ranking = rank_candidates(data, current, cands, settings, current_sse, current_errors)
        ranking = _refine(data, current, ranking, settings, current_sse, current_errors)
        top, ties = _choose(ranking, settings)
        rounds.append(ranking)
        if top is None:
            break
        top["ties"] = ties
        top["location"] = [loc for loc in locations if loc.ratio >= settings.locate_threshold]
        chosen.append(top)
        current = top["candidate"].build(current, top["value"])
        current_sse = top["held_sse"]
        current_errors = top["errors"]
    final_sim = simulate_variants(data, [base, current], keep_series=True)
    before = base_errors
    after = _errors(data, _held_out_variants(data, base, chosen, fold)) if chosen else before
    residual_location = locate(data, current)[0] if chosen else first_location
    return {"data": data, "rounds": rounds, "chosen": chosen, "before_phase": _rms_table(final_sim, 0, data),
            "after_phase": _rms_table(final_sim, 1, data), "before": before, "after": after,
            "base_series": base_sim["series"], "after_series": final_sim["series"], "location": first_location,
            "residual_location": residual_location, "discoveries": discoveries,
            "verdict": verdict(chosen, residual_location if chosen else first_location, settings.locate_threshold),
            "settings": settings, "model_effects": dict(model_effects or {})}


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
        if r.get("ties"):
            text += " (or " + " or ".join(t["name"] for t in r["ties"]) + ": not separable on this data)"
        parts.append(text)
    return "missing: " + ", ".join(parts) + tail


def location_line(locations: list[Location], threshold: float) -> str:
    above = [loc for loc in locations if loc.ratio >= threshold]
    if not above:
        return "location: nothing above the noise level"
    return "location: " + "; ".join(loc.words() for loc in above[:3])
