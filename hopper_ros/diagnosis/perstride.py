"""A model coefficient given a value per stride from a few basis columns over strides (issue 28): what `drift`
(time) and `dependence` (position along the track) share.

The next apexes' change with the coefficient comes from one moved re-simulation per stride (`sensitivity`); the
basis' coefficients are fitted to the next-apex residuals (normalised as E_p, E_v, E_t) on the training folds
(`held_out`, the best of several candidate bases chosen on them) and judged by re-simulating every held-out stride
with the value its training folds gave it (`judge`), against a simpler basis (`stands`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .acceptance import paired_t
from .data import StrideData
from .records import Errors
from .simulate import Variant, simulate_variants

OUTPUTS = ("height", "length", "speed", "time")


@dataclass(frozen=True)
class Parameter:
    """A scalar coefficient of `laws.Coefficients`, its words, and the step of its sensitivity's re-simulation:
    a share of its value (`relative`, the per-stride change is then a share too) or in its own unit. `moves_stance`:
    a change of it moves each stance's start (the ground's height), so it is judged on the strides with their ramps
    read from their own start of stance (`data.own_ramps`)."""

    name: str
    words: str
    step: float
    relative: bool = True
    moves_stance: bool = False

    def values(self, value: float, change):
        return value * (1.0 + change) if self.relative else value + change


def normalised(data: StrideData, pred: dict) -> np.ndarray:
    """(strides, 4) next-apex residuals, recorded - predicted, in the units of E_p, E_v, E_t [%]."""
    s = data.strides
    scale = np.hypot(s.next_apex_height, s.stride_length)
    recorded = {"height": s.next_apex_height, "length": s.stride_length, "speed": s.next_forward_speed,
                "time": s.stride_time}
    units = {"height": scale, "length": scale, "speed": np.abs(s.next_forward_speed), "time": s.stride_time}
    return np.column_stack([100.0 * (recorded[k] - pred[k]) / units[k] for k in OUTPUTS])


def predicted(data: StrideData, variant: Variant) -> dict:
    return {k: v[0] for k, v in simulate_variants(data, [variant])["pred"].items()}


def with_values(variant: Variant, params, changes: np.ndarray) -> Variant:
    """`variant` with each parameter's value per stride moved by its column of `changes` (strides, parameters)."""
    values = {p.name: p.values(float(getattr(variant.coefficients, p.name)), changes[:, k])
              for k, p in enumerate(params)}
    return Variant(variant.coefficients, variant.sensors, {**variant.per_stride, **values})


def sensitivity(data: StrideData, variant: Variant, params, change: np.ndarray | None = None):
    """(residual, slopes, ok): the normalised next-apex residuals under `variant` (the parameters moved by
    `change`, (strides, parameters), when given) and their fall per unit of each parameter's change (one moved
    re-simulation each), (parameters, strides, 4)."""
    if change is None:
        here = variant
        moved = [variant.with_changes({p.name: p.values(float(getattr(variant.coefficients, p.name)), p.step)})
                 for p in params]
    else:
        here = with_values(variant, params, change)
        moved = [with_values(variant, params, change + p.step * (np.arange(len(params)) == k)) for k, p in
                 enumerate(params)]
    residual = normalised(data, predicted(data, here))
    slopes = np.array([(residual - normalised(data, predicted(data, m))) / p.step for m, p in zip(moved, params)])
    ok = np.all(np.isfinite(slopes), axis=(0, 2)) & np.all(np.isfinite(residual), axis=1)
    return residual, slopes, ok


def _solve(slopes, residual, rows, columns):
    """Least squares of the residuals on the slopes times each column (strides, parameters) over `rows`:
    (coefficients, SSE)."""
    design = np.stack([np.einsum("pnk,np->nk", slopes[:, rows], c[rows]).ravel() for c in columns], axis=1)
    target = residual[rows].ravel()
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    return coef, float(np.sum((target - design @ coef) ** 2))


def fit(slopes, residual, rows, candidates: list, refine=None, iterations: int = 0):
    """The candidate basis (a tuple of columns, each (strides, parameters)) that fits `rows` best, its
    coefficients, and the change per stride and parameter; `refine(change)` -> (residual, slopes) re-linearises
    there (`iterations` Gauss-Newton steps, the candidate kept)."""
    best = min(range(len(candidates)), key=lambda j: _solve(slopes, residual, rows, candidates[j])[1])
    columns = candidates[best]
    coef = _solve(slopes, residual, rows, columns)[0]
    for _ in range(iterations):
        r, sl = refine(sum(cf * c for cf, c in zip(coef, columns)))
        rows = rows & np.all(np.isfinite(r), axis=1) & np.all(np.isfinite(sl), axis=(0, 2))
        coef = coef + _solve(sl, r, rows, columns)[0]
    return best, coef, sum(cf * c for cf, c in zip(coef, columns))


def held_out(slopes, residual, ok, fold, folds: int, candidates: list, refine=None, iterations: int = 0):
    """Per stride and parameter, the change its training folds give it (each fold choosing its own candidate)."""
    out = np.zeros(candidates[0][0].shape)
    for k in range(folds):
        train, test = ok & (fold != k), fold == k
        out[test] = fit(slopes, residual, train, candidates, refine, iterations)[2][test]
    return out


def judge(data: StrideData, variant: Variant, params, changes: dict) -> tuple[dict, dict]:
    """Per named change (strides, parameters), the held-out stride SSE of the normalised next apex (inf where a
    stride falls) and the held-out errors, every stride re-simulated with its values."""
    sse, errors = {}, {}
    for form, change in changes.items():
        pred = predicted(data, with_values(variant, params, change))
        r = normalised(data, pred)
        sse[form] = np.where(np.all(np.isfinite(r), axis=1), np.sum(r * r, axis=1), np.inf)
        errors[form] = Errors.of(data, pred)
    return sse, errors


def stands(sse: dict, errors: dict, simple: str, form: str, min_strides: int) -> tuple[float, float]:
    """(t, share): the one-sided t over strides that `form` fits the held-out next apexes better than `simple`,
    and the share of the held-out E_p + E_v + E_t it takes off."""
    both = np.isfinite(sse[simple]) & np.isfinite(sse[form])
    t = paired_t(sse[simple][both], sse[form][both]) if both.sum() >= min_strides else 0.0
    return t, 1.0 - errors[form].total / max(errors[simple].total, 1e-12)
