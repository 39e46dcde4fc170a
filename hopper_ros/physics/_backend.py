"""One formula, two speeds: the model's closed forms are written once against a tiny
namespace `xp` that is either `math` on Python floats (a single stride in tens of
microseconds) or numpy on arrays (many strides at once). `select` picks it from the inputs.

Both branches of `xp.where` are always evaluated, so formulas guard their own domains
(safe denominators, clipped arccos arguments) instead of relying on the condition.
"""

from __future__ import annotations

import math
from numbers import Real
from types import SimpleNamespace

import numpy as np

SCALAR = SimpleNamespace(
    exp=math.exp, expm1=math.expm1, log1p=math.log1p, sin=math.sin, cos=math.cos, sqrt=math.sqrt,
    hypot=math.hypot, arctan2=math.atan2, arccos=math.acos, abs=abs, minimum=min, maximum=max,
    pi=math.pi, nan=math.nan, isfinite=math.isfinite, asarray=float, to_int=int,
    where=lambda condition, if_true, if_false: if_true if condition else if_false,
    clip=lambda value, low, high: low if value < low else high if value > high else value,
    mod=lambda value, divisor: value % divisor,
)

ARRAY = SimpleNamespace(
    exp=np.exp, expm1=np.expm1, log1p=np.log1p, sin=np.sin, cos=np.cos, sqrt=np.sqrt,
    hypot=np.hypot, arctan2=np.arctan2, arccos=np.arccos, abs=np.abs, minimum=np.minimum, maximum=np.maximum,
    pi=np.pi, nan=np.nan, isfinite=np.isfinite, where=np.where, clip=np.clip, mod=np.mod,
    asarray=lambda value: np.asarray(value, dtype=float),
    to_int=lambda value: np.asarray(value).astype(int),
)


def select(*values):
    """`SCALAR` when every value is a real scalar (float, int, numpy scalar), else `ARRAY`.

    None is ignored (optional arguments).
    """
    for value in values:
        if value is None or type(value) is float or type(value) is int:
            continue
        if isinstance(value, np.ndarray) or not isinstance(value, Real) or isinstance(value, bool):
            return ARRAY
    return SCALAR
