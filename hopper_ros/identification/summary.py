"""An identification as a JSON document (`hopper identify --json FILE`), for scripts. No ROS import.

    {"recording": ..., "strides": N, "rejected": M, "phases": "labelled"|"detected", "best": method,
     "parameters": {name: {"value", "std", "unit", "fitted"}},          (the best method's CV mean)
     "effects": {name: {"value", "std", "unit"}},
     "methods": {method: {"parameters": {...}, "effects": {...}, "errors": {"test"|"train": {"E_p": [mean, std], ...}},
                          "folds": K, "wall_time_s": s}},
     "identifiability": {name: relative standard error [%]}, "model_file": path or null}
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

from .crossval import UNITS, CrossValidation


def _number(value: float):
    return float(value) if math.isfinite(value) else None


def _method(cv: CrossValidation) -> dict:
    from hopper_ros.physics.effects import get

    return {
        "parameters": {name: {"value": _number(mean), "std": _number(std), "unit": UNITS[name],
                              "fitted": name in cv.fitted} for name, (mean, std) in cv.parameter_table().items()},
        "effects": {name: {"value": _number(mean), "std": _number(std), "unit": get(name).primary.unit or "1"}
                    for name, (mean, std) in (cv.effect_table().items() if cv.effects else [])},
        "errors": {part: {k: [_number(m), _number(s)] for k, (m, s) in table.items()}
                   for part, table in cv.error_table().items()},
        "folds": len(cv.folds),
        "wall_time_s": round(cv.wall_time, 3),
    }


def identification_document(result, model_file: str | os.PathLike | None = None) -> dict:
    methods = {method: _method(cv) for method, cv in result.cross_validations.items()}
    best = methods[result.best_method]
    ident = result.identifiability
    return {
        "recording": str(result.recording.source),
        "strides": len(result.strides),
        "rejected": len(result.strides.rejected),
        "phases": "labelled" if result.strides.labelled else "detected",
        "best": result.best_method,
        "parameters": best["parameters"],
        "effects": best["effects"],
        "methods": methods,
        "aas_bias_pct": result.aas_bias_pct(),
        "identifiability": {n: _number(s) for n, s in zip(ident.names, ident.relative_std_pct)} if ident else {},
        "model_file": str(model_file) if model_file else None,
    }


def write_json(result, path: str | os.PathLike, model_file=None) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(identification_document(result, model_file), indent=1) + "\n", encoding="utf-8")
    return path
