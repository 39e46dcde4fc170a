"""Savitzky-Golay smoothing and differentiation of one phase of a stride, with scipy's edge rule.

`savgol_filter(x, w, 3, deriv, delta, mode="interp")` fits one cubic to the first and to the last `w`
samples for the `w // 2` samples at each end. That fit is linear in the samples, so its values at the
edge positions are fixed weights (`savgol_coeffs(..., pos=p, use="dot")`) times the window: computed once
per (window, derivative, sample period) here, instead of a polynomial fit per call. The interior is
scipy's own convolution. Equal to scipy's result to rounding. The weights are scipy's `savgol_coeffs`, the
same least-squares solve written here (`coefficients`): importing scipy.signal costs a process 0.8 s.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy.linalg import lstsq
from scipy.ndimage import convolve1d

ORDER = 3     # the fitted polynomial's degree


def coefficients(window: int, deriv: int, delta: float, pos: float | None = None, use: str = "conv") -> np.ndarray:
    """scipy.signal's `savgol_coeffs(window, ORDER, deriv, delta, pos, use)` (scipy 1.17's solve: the polynomial's
    Vandermonde matrix at the window's positions, least squares with its `cond`)."""
    pos = window // 2 if pos is None else pos      # `window` odd
    x = np.arange(-pos, window - pos, dtype=np.float64)
    if use == "conv":
        x = x[::-1]
    vandermonde = x ** np.arange(ORDER + 1, dtype=np.float64).reshape(-1, 1)
    y = np.zeros(ORDER + 1)
    y[deriv] = math.factorial(deriv) / delta ** deriv
    return lstsq(vandermonde, y, cond=np.finfo(np.float64).eps * max(vandermonde.shape))[0]


@lru_cache(maxsize=None)
def _weights(window: int, deriv: int, delta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(interior kernel, left-edge weights (half, window), right-edge weights (half, window))."""
    half = window // 2
    kernel = coefficients(window, deriv, delta)
    left = np.array([coefficients(window, deriv, delta, pos=p, use="dot") for p in range(half)])
    right = np.array([coefficients(window, deriv, delta, pos=window - half + p, use="dot") for p in range(half)])
    return kernel, left, right


def savgol(x: np.ndarray, window: int, deriv: int = 0, delta: float = 1.0) -> np.ndarray:
    """scipy's `savgol_filter(x, window, 3, deriv=deriv, delta=delta)` (mode "interp"); `window` odd, <= len(x)."""
    kernel, left, right = _weights(window, deriv, float(delta))
    out = convolve1d(np.asarray(x, dtype=float), kernel, mode="constant")
    half = window // 2
    out[:half] = left @ x[:window]
    out[len(x) - half:] = right @ x[len(x) - window:]
    return out


def smooth(x: np.ndarray, window: int, period: float):
    """(value, first, second derivative) of `x` sampled every `period`, the window shortened to fit (odd, at
    least 7 samples), or None where the phase is too short."""
    w = min(window, len(x) - (1 - len(x) % 2))
    if w < 7:
        return None
    return savgol(x, w, 0), savgol(x, w, 1, period), savgol(x, w, 2, period)
