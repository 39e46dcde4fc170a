"""A residual periodic in a variable the model does not use, found by a frequency scan on held-out strides (issue
28 point 1): the leg angle's ripple (angle.py) and the boom angle's eccentricity (azimuth.py)."""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from . import acceptance
from .fitting import vertex


def held_out_sse(designs: list, residuals: list, fold: np.ndarray) -> np.ndarray:
    """Per stride, the residual's SSE predicted by the least squares fitted on the other folds."""
    out = np.zeros(len(designs))
    gram = np.array([X.T @ X for X in designs])
    rhs = np.array([X.T @ y for X, y in zip(designs, residuals)])
    for k in np.unique(fold):
        train = fold != k
        coef = np.linalg.lstsq(gram[train].sum(axis=0), rhs[train].sum(axis=0), rcond=None)[0]
        for i in np.flatnonzero(~train):
            e = residuals[i] - designs[i] @ coef
            out[i] = e @ e
    return out


def scan_period(designs_of: Callable, residuals: list, fold: np.ndarray, scan: np.ndarray, near, min_t: float):
    """The period of `scan` whose designs (`designs_of(period)`: a (samples, 2) sine and cosine matrix per stride;
    `designs_of(None)`: the plain shape it must beat) predict held-out strides best, the vertex of the scan's
    held-out SSE about its least, where it beats the plain shape (paired t >= `min_t`): ([(period, sine, cosine)]
    at it and at `near` steps of the scan about it, t); ([], t) otherwise."""
    plain = held_out_sse(designs_of(None), residuals, fold)
    trials = [held_out_sse(designs_of(period), residuals, fold) for period in scan]
    best = int(np.argmin([trial.sum() for trial in trials]))
    t = acceptance.paired_t(plain, trials[best])
    if not t >= min_t:
        return [], t
    step = math.log(scan[1] / scan[0])
    centre = math.exp(vertex(np.log(scan), np.array([trial.sum() for trial in trials])))
    found = []
    for period in centre * np.exp(step * np.array(near)):
        coef = np.linalg.lstsq(np.vstack(designs_of(period)), np.concatenate(residuals), rcond=None)[0]
        found.append((float(period), float(coef[0]), float(coef[1])))
    return found, float(t)
