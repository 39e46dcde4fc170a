"""One formula, two speeds: the model's closed forms are written once against a tiny
namespace `xp` that is either `math` on Python floats (a single stride in tens of
microseconds) or numpy on arrays (many strides at once). `select` picks it from the inputs.

Both branches of `xp.where` are always evaluated, so formulas guard their own domains
(safe denominators, clipped arccos arguments) instead of relying on the condition.
"""

from __future__ import annotations

import math
from numbers import Real

import numpy as np


class Scalar:
    exp, expm1, log1p = staticmethod(math.exp), staticmethod(math.expm1), staticmethod(math.log1p)
    sin, cos, sqrt, hypot = staticmethod(math.sin), staticmethod(math.cos), staticmethod(math.sqrt), staticmethod(math.hypot)
    arctan2, arccos = staticmethod(math.atan2), staticmethod(math.acos)
    abs, minimum, maximum = staticmethod(abs), staticmethod(min), staticmethod(max)
    pi = math.pi
    nan = math.nan

    @staticmethod
    def where(condition, if_true, if_false):
        return if_true if condition else if_false

    @staticmethod
    def clip(value, low, high):
        return low if value < low else high if value > high else value

    @staticmethod
    def mod(value, divisor):
        return value % divisor

    @staticmethod
    def isfinite(value):
        return math.isfinite(value)

    @staticmethod
    def asarray(value):
        return float(value)

    @staticmethod
    def logical_and(a, b):
        return a and b

    @staticmethod
    def logical_not(a):
        return not a

    @staticmethod
    def to_int(value):
        return int(value)


class Array:
    exp, expm1, log1p = staticmethod(np.exp), staticmethod(np.expm1), staticmethod(np.log1p)
    sin, cos, sqrt, hypot = staticmethod(np.sin), staticmethod(np.cos), staticmethod(np.sqrt), staticmethod(np.hypot)
    arctan2, arccos = staticmethod(np.arctan2), staticmethod(np.arccos)
    abs, minimum, maximum = staticmethod(np.abs), staticmethod(np.minimum), staticmethod(np.maximum)
    where, clip, mod, isfinite = staticmethod(np.where), staticmethod(np.clip), staticmethod(np.mod), staticmethod(np.isfinite)
    logical_and, logical_not = staticmethod(np.logical_and), staticmethod(np.logical_not)
    pi = np.pi
    nan = np.nan

    @staticmethod
    def asarray(value):
        return np.asarray(value, dtype=float)

    @staticmethod
    def to_int(value):
        return np.asarray(value).astype(int)


SCALAR = Scalar()
ARRAY = Array()


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
