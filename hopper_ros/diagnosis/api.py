"""Entry point: load a recording and a model (with any library effects it carries), diagnose, write reports."""

from __future__ import annotations

import time
from pathlib import Path

from hopper_ros.config import load_yaml
from hopper_ros.identification.recordings import Recording, load_recording
from hopper_ros.physics import effects as library
from hopper_ros.physics.params import ModelParams

from .core import diagnose, load_settings


def load_model(path="model.yaml") -> tuple[ModelParams, dict]:
    """A model file: `model:` (ModelParams) and optional `effects: {library name: magnitude}`."""
    data = load_yaml(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping with `model:`")
    params = ModelParams.from_dict(data["model"] if "model" in data else data, source=str(path))
    found = data.get("effects") or {}
    if not isinstance(found, dict):
        raise ValueError(f"{path}: effects: expected a mapping of effect names to magnitudes")
    model_effects = {}
    for name, value in found.items():
        try:
            library.get(name)
        except ValueError as exc:
            raise ValueError(f"{path}: effects.{name}: {exc}") from None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{path}: effects.{name}: expected a number, got {value!r}")
        model_effects[name] = float(value)
    return params, model_effects


def diagnose_file(recording, model="model.yaml", output=None, settings="diagnosis.yaml", json_path=None) -> dict:
    started = time.perf_counter()
    rec = recording if isinstance(recording, Recording) else load_recording(recording)
    if isinstance(model, ModelParams):
        params, model_effects = model, {}
    elif isinstance(model, tuple):
        params, model_effects = model
    else:
        params, model_effects = load_model(model)
    cfg = settings if not isinstance(settings, (str, Path)) else load_settings(settings)
    result = diagnose(rec, params, cfg, model_effects)
    result["wall_time"] = time.perf_counter() - started
    if output is not None:
        from .report import write_report
        result["report"] = write_report(result, Path(output))
    if json_path is not None:
        from .report import write_json
        result["json"] = write_json(result, Path(json_path))
    return result
