"""The few helpers a law of `physics.laws` needs to run on Python floats, numpy arrays of lanes and
compiled lanes alike (`physics.compiled` overloads `where`, `clip`, `ones_like`, `nan_to_num` and
`nonzero` with their scalar forms for numba), and the smoothed sign of dry friction.
"""

from __future__ import annotations

import numpy as np

SMOOTH_SPEED = 0.005   # [m/s] or [rad/s]: speed below which a dry friction law is smoothed, tanh(v / v_s)


# ---------------------------------------------------------------------------- helpers (overloaded when compiled)


def where(condition, if_true, if_false):
    """np.where; a plain bool picks a branch (a float stays a float)."""
    if type(condition) is bool or type(condition) is np.bool_:
        return if_true if condition else if_false
    out = np.where(condition, if_true, if_false)
    return out[()] if out.ndim == 0 else out


def clip(value, low, high):
    """np.clip; floats stay floats."""
    if isinstance(value, float) and isinstance(low, float) and isinstance(high, float):
        return min(max(value, low), high)
    return np.clip(value, low, high)


def ones_like(value):
    return np.ones_like(value)


def nan_to_num(value):
    return np.nan_to_num(value)


def nonzero(coefficient) -> bool:
    """Whether a coefficient (a float, or an array of lanes) may change a law: arrays always count."""
    return bool(np.ndim(coefficient)) or coefficient != 0.0


def smooth_sign(v, speed=SMOOTH_SPEED):
    """sign(v), smoothed over |v| < `speed` so that dry friction integrates."""
    return np.tanh(v / speed)
