"""Physics that no library entry names: sparse regression of the located residuals on term libraries.

Per site (flight horizontal/vertical, stance along the leg and about the hip, the velocity jumps at
touchdown and lift-off) the bias-corrected residual forces of `locate` are regressed on the site's
term library (`physics.laws`: powers and signs of velocities, powers of the spring's compression,
the torque, the time since touchdown, a hinge max(0, z - z_k) ...) by sequentially thresholded least
squares (SINDy's STLSQ); the threshold, and a hinge's knot among quantiles of its variable, are chosen
by cross-validation over strides (the sparsest model within one standard error of the best), and the
model is kept only if it predicts held-out strides better than no term at all. The term set becomes a candidate effect whose coefficients are refitted (one scale)
and ranked on held-out strides exactly like a library effect.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hopper_ros.physics import laws

from .locate import SITE_WORDS

SITE_LIBRARY = {   # site -> (term library, Coefficients field, context kind)
    "flight_horizontal": (laws.FLIGHT_Y_TERMS, "flight_y_terms", "flight"),
    "flight_vertical": (laws.FLIGHT_Z_TERMS, "flight_z_terms", "flight"),
    "stance_along": (laws.LEG_TERMS, "leg_terms", "stance"),
    "stance_hip": (laws.HIP_TERMS, "hip_terms", "stance"),
    "touchdown_along": (laws.JUMP_TERMS, "touchdown_along_terms", "jump"),
    "touchdown_across": (laws.JUMP_TERMS, "touchdown_across_terms", "jump"),
    "liftoff_along": (laws.JUMP_TERMS, "liftoff_along_terms", "jump"),
    "liftoff_across": (laws.JUMP_TERMS, "liftoff_across_terms", "jump"),
}
THRESHOLDS = (0.0, 0.02, 0.05, 0.1, 0.2, 0.35, 0.5)
KNOT_QUANTILES = (0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95)   # where a hinge term's knot may sit, over the samples
FOLDS = 5
MIN_T = 1.5          # held-out improvement over strides, one-sided t: a pre-screen (an effect only some strides
#                      reach, a tether above a height, is weak over strides); the candidate then faces the guards


@dataclass
class Discovery:
    site: str
    field: str
    coefficients: tuple       # one per term of the site's library (0 = not used)
    keys: tuple
    explained: float          # share of the residual's variance explained on held-out strides
    t: float
    knot: float = 0.0         # [m] where the site's hinge term (if any) engages

    def terms(self) -> list[tuple[str, float, str, str]]:
        library = SITE_LIBRARY[self.site][0]
        hinge = hinge_of(self.field)
        out = []
        for (key, words, unit, _), c in zip(library, self.coefficients):
            if c:
                if hinge and key == hinge[0]:
                    symbol = key.split(">")[1]
                    words = words.replace(symbol, f"{symbol} = {self.knot:.3g} m", 1)
                out.append((key, float(c), words, unit))
        return out

    def words(self, scale: float = 1.0) -> str:
        phase, direction = SITE_WORDS[self.site]
        parts = [f"{w} ({key}), {scale * c:+.3g} {u}" for key, c, w, u in self.terms()]
        where = {"flight": "in flight", "stance": "in stance", "touchdown": "at touchdown",
                 "lift-off": "at lift-off"}[phase]
        return f"{where}, {direction}: " + "; ".join(parts)


def hinge_of(field: str):
    """(term key, knot field) of the hinge term in the library of Coefficients field `field`, or None."""
    return laws.HINGES.get(field[:-len("_terms")])


def _context(kind: str, ctx: dict, knot: float = 0.0):
    if kind == "flight":
        return laws.FlightContext(ctx["y"], ctx["z"], ctx["ydot"], ctx["zdot"], knot)
    if kind == "stance":
        return laws.StanceContext(ctx["rho"], ctx["rho_dot"], ctx["rest_length"], ctx["theta"], ctx["theta_dot"],
                                  ctx["theta_td"], ctx["since_touchdown"], ctx["torque"], ctx["command"], knot)
    return laws.JumpContext(ctx["along"], ctx["across"])


def _knots(site: str, sets) -> tuple:
    """Candidate knots of the site's hinge term: quantiles of its variable over the recorded samples."""
    if hinge_of(SITE_LIBRARY[site][1]) is None:
        return (0.0,)
    kind = SITE_LIBRARY[site][2]
    values = [ctx["z"] if kind == "flight" else ctx["rest_length"] - ctx["rho"]
              for r in sets[0] if r is not None and site in r.samples for ctx in [r.samples[site][1]]]
    if not values:
        return (0.0,)
    return tuple(float(q) for q in np.quantile(np.concatenate(values), KNOT_QUANTILES))


def site_samples(site: str, sets, knot: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per stride (design matrix, bias-corrected residual) of one site."""
    library, _, kind = SITE_LIBRARY[site]
    rec, clean, _ = sets
    out = []
    for r, c0 in zip(rec, clean):
        if r is None or c0 is None or site not in r.samples or site not in c0.samples:
            continue
        values, ctx, u = r.samples[site]
        bias_values, _, bias_u = c0.samples[site]
        if len(bias_u) > 1:
            order = np.argsort(bias_u)
            bias = np.interp(u, bias_u[order], bias_values[order])
        else:
            bias = np.full_like(values, bias_values[0])
        context = _context(kind, ctx, knot)
        X = np.column_stack([np.broadcast_to(term(context), values.shape) for _, _, _, term in library])
        ok = np.all(np.isfinite(X), axis=1) & np.isfinite(values - bias)
        if ok.any():
            out.append((X[ok], (values - bias)[ok]))
    return out


def stlsq(X, y, threshold, iterations=8):
    """Sequentially thresholded least squares on standardised columns; threshold relative to the largest."""
    scale = X.std(axis=0)
    scale = np.where(scale > 1e-12, scale, np.maximum(np.abs(X).mean(axis=0), 1e-12))
    Xs = X / scale
    coef = np.linalg.lstsq(Xs, y, rcond=None)[0]
    for _ in range(iterations):
        big = np.abs(coef) >= threshold * np.max(np.abs(coef)) if np.any(coef) else np.zeros_like(coef, bool)
        if not big.any():
            return np.zeros_like(coef)
        new = np.zeros_like(coef)
        new[big] = np.linalg.lstsq(Xs[:, big], y, rcond=None)[0]
        if np.array_equal(new != 0, coef != 0):
            coef = new
            break
        coef = new
    return coef / scale


def _cross_validate(per_stride, max_terms: int):
    """Held-out SSE per stride for each threshold (inf where a fold's model has too many terms), the
    zero model's SSE, and the threshold picked: the sparsest within one standard error of the best."""
    n = len(per_stride)
    fold = np.arange(n) % FOLDS
    cv = []
    for thr in THRESHOLDS:
        sse = np.zeros(n)
        for f in range(FOLDS):
            train = [per_stride[i] for i in range(n) if fold[i] != f]
            X = np.vstack([p[0] for p in train])
            y = np.concatenate([p[1] for p in train])
            coef = stlsq(X, y, thr)
            if np.count_nonzero(coef) > max_terms:
                sse[:] = np.inf
                break
            for i in np.flatnonzero(fold == f):
                Xi, yi = per_stride[i]
                sse[i] = np.sum((yi - Xi @ coef) ** 2)
        cv.append(sse)
    cv = np.array(cv)
    zero = np.array([np.sum(p[1] ** 2) for p in per_stride])
    totals = cv.sum(axis=1)
    if not np.isfinite(totals).any():
        return None
    best = int(np.nanargmin(np.where(np.isfinite(totals), totals, np.nan)))
    se = np.std(cv[best] - zero) * np.sqrt(n)
    pick = max(k for k in range(len(THRESHOLDS)) if np.isfinite(totals[k]) and totals[k] <= totals[best] + se)
    return cv[pick], zero, pick


def discover_site(site: str, sets, max_terms: int = 3) -> Discovery | None:
    trials = []
    for knot in _knots(site, sets):
        per_stride = site_samples(site, sets, knot)
        if len(per_stride) < 2 * FOLDS:
            return None
        found = _cross_validate(per_stride, max_terms)
        if found is not None:
            trials.append((found[0].sum(), knot, per_stride, *found))
    if not trials:
        return None
    _, knot, per_stride, held, zero, pick = min(trials, key=lambda trial: trial[0])
    n = len(per_stride)
    d = zero - held
    t = float(d.mean() / (d.std(ddof=1) / np.sqrt(n))) if d.std(ddof=1) > 0 else 0.0
    explained = float(1.0 - held.sum() / zero.sum()) if zero.sum() > 0 else 0.0
    if t < MIN_T or explained <= 0:
        return None
    X = np.vstack([p[0] for p in per_stride])
    y = np.concatenate([p[1] for p in per_stride])
    coef = stlsq(X, y, THRESHOLDS[pick])
    if not np.any(coef):
        return None
    library, field, _ = SITE_LIBRARY[site]
    hinge = hinge_of(field)
    used = hinge is not None and coef[[k for k, *_ in library].index(hinge[0])] != 0
    return Discovery(site, field, tuple(float(c) for c in coef), tuple(k for k, *_ in library), explained, t,
                     knot if used else 0.0)
