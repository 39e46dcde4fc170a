"""One formula, two speeds: the model's closed forms are written once against a tiny
namespace `xp` that is either `math` on Python floats (a single stride in microseconds) or
numpy on arrays (many strides at once). `select` picks it from the inputs.

Both branches of `xp.where` are always evaluated, so formulas guard their own domains
(safe denominators, clipped arccos arguments) instead of relying on the condition.

The namespaces are module objects: a formula looks a name up in `xp` a hundred times per
stride, and the interpreter's module attribute lookup is the fastest one (a SimpleNamespace's
costs ~10 ns more each). On floats, `minimum`/`maximum` are two-argument expressions with the
builtins' results (`max(a, b)` is b if b > a else a, NaN and signed zeros alike): the builtins
take ~70 ns a call, their generality.
"""

from __future__ import annotations

import math
import operator
from numbers import Real
from types import ModuleType

import numpy as np


def _namespace(name: str, **members) -> ModuleType:
    namespace = ModuleType(f"{__name__}.{name}")
    namespace.__dict__.update(members)
    return namespace


SCALAR = _namespace(
    "SCALAR",
    exp=math.exp, expm1=math.expm1, log1p=math.log1p, sin=math.sin, cos=math.cos, sqrt=math.sqrt,
    hypot=math.hypot, arctan2=math.atan2, arccos=math.acos, abs=abs, pi=math.pi, nan=math.nan,
    isfinite=math.isfinite, asarray=float, to_int=int, mod=operator.mod,
    minimum=lambda a, b: b if b < a else a,
    maximum=lambda a, b: b if b > a else a,
    where=lambda condition, if_true, if_false: if_true if condition else if_false,
    clip=lambda value, low, high: low if value < low else high if value > high else value,
)

ARRAY = _namespace(
    "ARRAY",
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
        if type(value) is float or value is None or type(value) is int:
            continue
        if isinstance(value, np.ndarray) or not isinstance(value, Real) or isinstance(value, bool):
            return ARRAY
    return SCALAR
