"""Physics that no library entry names: sparse regression of the located residuals on term libraries.

Per site (flight horizontal/vertical, stance along the leg and about the hip, the velocity jumps at
touchdown and lift-off) the bias-corrected residual forces of `locate` are regressed on the site's
term library (`physics.laws`: powers and signs of velocities, powers of the spring's compression,
the torque, the time since touchdown, a hinge max(0, z - z_k) ...) by best-subset selection: every
subset of at most three terms, and a hinge's knot among quantiles of its variable, judged by
cross-validation over strides (the smallest subset within one standard error of the best; SINDy's
thresholded least squares splits a coefficient between collinear terms and never tries a term that
stands in for two correlated ones); the model is kept only if it predicts held-out strides better than
no term at all. The term set becomes a candidate effect whose coefficients are refitted (one scale)
and ranked on held-out strides exactly like a library effect.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from hopper_ros.physics import laws

from .sites import REGISTRY, hinge_of

KNOT_QUANTILES = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95)   # where a hinge term's knot may sit, over the samples
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
        library = REGISTRY[self.site].terms
        hinge = hinge_of(self.field)
        out = []
        for (key, words, unit), c in zip(library.terms, self.coefficients):
            if c:
                if hinge and key == hinge[0]:
                    symbol = key.split(">")[1]
                    words = words.replace(symbol, f"{symbol} = {self.knot:.3g} m", 1)
                out.append((key, float(c), words, unit))
        return out

    def words(self, scale: float = 1.0) -> str:
        phase, direction = REGISTRY[self.site].phase, REGISTRY[self.site].direction
        terms = {key: (c, w, u) for key, c, w, u in self.terms()}
        parts = []
        for (odd, even), say in DIRECTIONAL.items():
            if odd in terms and even in terms:       # a v + b |v|: one law each way of the motion
                a, b = scale * terms.pop(odd)[0], scale * terms.pop(even)[0]
                parts.append(say(a + b, a - b))
        parts += [f"{w} ({key}), {scale * c:+.3g} {u}" for key, (c, w, u) in terms.items()]
        where = {"flight": "in flight", "stance": "in stance", "touchdown": "at touchdown",
                 "lift-off": "at lift-off"}[phase]
        return f"{where}, {direction}: " + "; ".join(parts)


# a velocity's term and its size's, (a v + b |v|): (a + b) v when v > 0, (a - b) v when v < 0, said as one law
DIRECTIONAL = {
    ("zdot", "|zdot|"): lambda up, down: (f"a vertical force proportional to the vertical speed, {up:+.3g} N s/m while "
                                          f"rising and {down:+.3g} N s/m while descending (a drag that acts one way "
                                          "more than the other) (zdot, |zdot|)"),
    ("rho'", "|rho'|"): lambda extension, compression: (
        f"extra leg damping that differs with the direction: {extension:+.3g} N s/m in extension, "
        f"{compression:+.3g} N s/m in compression (rho', |rho'|)"),
}


def _context(kind: str, ctx: dict, knot: float = 0.0):
    if kind == "flight":
        return laws.FlightContext(ctx["y"], ctx["z"], ctx["ydot"], ctx["zdot"], knot)
    if kind == "stance":
        return laws.stance_context(ctx["rho"], ctx["rho_dot"], ctx["rest_length"], ctx["theta"], ctx["theta_dot"],
                                   ctx["theta_td"], ctx["since_touchdown"], ctx["torque"], ctx["command"], knot)
    return laws.JumpContext(ctx["along"], ctx["across"])


def _knots(site: str, sets) -> tuple:
    """Candidate knots of the site's hinge term: quantiles of its variable over the recorded samples."""
    if hinge_of(REGISTRY[site].field) is None:
        return (0.0,)
    kind = REGISTRY[site].context
    values = [ctx["z"] if kind == "flight" else ctx["rest_length"] - ctx["rho"]
              for r in sets[0] if r is not None and site in r.samples for ctx in [r.samples[site][1]]]
    if not values:
        return (0.0,)
    return tuple(float(q) for q in np.quantile(np.concatenate(values), KNOT_QUANTILES))


def site_residuals(site: str, sets) -> list[tuple[np.ndarray, dict]]:
    """Per stride (bias-corrected residual samples, their context) of one site (strides without it left out)."""
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
        out.append((values - bias, ctx))
    return out


def site_samples(site: str, sets, knot: float = 0.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per stride (design matrix, bias-corrected residual) of one site."""
    library, kind = REGISTRY[site].terms, REGISTRY[site].context
    out = []
    for residual, ctx in site_residuals(site, sets):
        context = _context(kind, ctx, knot)
        X = np.column_stack([np.broadcast_to(library.value(i, context), residual.shape)
                             for i in range(len(library.terms))])
        ok = np.all(np.isfinite(X), axis=1) & np.isfinite(residual)
        if ok.any():
            out.append((X[ok], residual[ok]))
    return out


def _grams(per_stride):
    """Per stride X'X, X'y and y'y: every subset's fit and held-out SSE follow from these."""
    return (np.array([X.T @ X for X, _ in per_stride]), np.array([X.T @ y for X, y in per_stride]),
            np.array([y @ y for _, y in per_stride]))


def _solve(gram, rhs):
    """Least squares from the normal equations, None where the columns are (nearly) collinear."""
    scale = np.sqrt(np.diag(gram))
    if np.any(scale <= 0):
        return None
    normed = gram / np.outer(scale, scale)
    if np.linalg.cond(normed) > 1e8:
        return None
    return np.linalg.solve(normed, rhs / scale) / scale


def _solve_folds(grams, rhss):
    """`_solve` for every fold's training set at once ((folds, k, k), (folds, k)): the same normalisation,
    condition check and solve per fold, in one call each; None where any fold's columns are collinear."""
    scale = np.sqrt(np.diagonal(grams, axis1=1, axis2=2))
    if np.any(scale <= 0):
        return None
    normed = grams / (scale[:, :, None] * scale[:, None, :])
    if np.any(np.linalg.cond(normed) > 1e8):
        return None
    return np.linalg.solve(normed, (rhss / scale)[:, :, None])[:, :, 0] / scale


def _cross_validate(per_stride, max_terms: int):
    """Best-subset selection by cross-validation over strides: every subset of at most `max_terms` terms
    (collinear ones skipped: a sign of a velocity that never changes sign in the phase is a constant) fitted
    on the training folds, its SSE on each held-out stride; the subset picked is the smallest within one
    standard error of the best (then the best of that size). Returns (held-out SSE per stride, the zero
    model's, the subset) or None."""
    n = len(per_stride)
    fold = np.arange(n) % FOLDS
    gram, rhs, yy = _grams(per_stride)
    total_gram, total_rhs = gram.sum(axis=0), rhs.sum(axis=0)
    training_gram = np.array([total_gram - gram[fold == f].sum(axis=0) for f in range(FOLDS)])
    training_rhs = np.array([total_rhs - rhs[fold == f].sum(axis=0) for f in range(FOLDS)])
    rows = [np.flatnonzero(fold == f) for f in range(FOLDS)]
    held_out = [(yy[r], rhs[r], gram[r]) for r in rows]
    tried = []
    for size in range(1, max_terms + 1):
        for subset in itertools.combinations(range(gram.shape[1]), size):
            columns = list(subset)
            coefs = _solve_folds(training_gram[:, columns][:, :, columns], training_rhs[:, columns])
            if coefs is None:
                continue
            held = np.empty(n)
            for f, (y2, xy, xx) in enumerate(held_out):
                coef = coefs[f]
                held[rows[f]] = (y2 - 2 * xy[:, subset] @ coef
                                 + np.einsum("i,nij,j->n", coef, xx[:, subset][:, :, subset], coef))
            tried.append((held.sum(), size, subset, held))
    if not tried:
        return None
    best = min(tried, key=lambda trial: trial[0])
    se = np.std(best[3] - yy) * np.sqrt(n)
    near = [trial for trial in tried if trial[0] <= best[0] + se]
    pick = min(near, key=lambda trial: (trial[1], trial[0]))
    return pick[3], yy, pick[2]


def discover_site(site: str, sets, max_terms: int = 3) -> Discovery | None:
    """The term set (and hinge knot) of `site` that held-out strides prefer, or None."""
    library, field = REGISTRY[site].terms, REGISTRY[site].field
    hinge = hinge_of(field)
    hinge_column = [k for k, *_ in library.terms].index(hinge[0]) if hinge else -1
    trials = []

    def trial(knot):
        per_stride = site_samples(site, sets, knot)
        found = _cross_validate(per_stride, max_terms) if len(per_stride) >= 2 * FOLDS else None
        if found is not None:
            trials.append((found[0].sum(), knot, per_stride, *found))

    knots = _knots(site, sets)
    for knot in knots:
        trial(knot)
    if not trials:
        return None
    best = min(trials, key=lambda t: t[0])
    if hinge_column in best[5]:        # the knot refined between the quantiles about the best
        k = knots.index(best[1])
        for knot in np.linspace(knots[max(k - 1, 0)], knots[min(k + 1, len(knots) - 1)], 9)[1:-1]:
            trial(float(knot))
    _, knot, per_stride, held, zero, subset = min(trials, key=lambda t: t[0])
    n = len(per_stride)
    d = zero - held
    t = float(d.mean() / (d.std(ddof=1) / np.sqrt(n))) if d.std(ddof=1) > 0 else 0.0
    explained = float(1.0 - held.sum() / zero.sum()) if zero.sum() > 0 else 0.0
    if t < MIN_T or explained <= 0:
        return None
    gram, rhs, _ = _grams(per_stride)
    ix = np.ix_(subset, subset)
    coef = np.zeros(gram.shape[1])
    coef[list(subset)] = _solve(gram.sum(axis=0)[ix], rhs.sum(axis=0)[list(subset)])
    used = hinge_column in subset
    return Discovery(site, field, tuple(float(c) for c in coef), tuple(k for k, *_ in library.terms), explained, t,
                     knot if used else 0.0)
