"""Entry point: load a recording and a model, diagnose, write the report."""

from __future__ import annotations

import time
from pathlib import Path

from hopper_ros.config import load_yaml
from hopper_ros.identification.recordings import Recording, load_recording
from hopper_ros.physics.params import ModelParams

from .core import diagnose, load_settings


def load_model(path="model.yaml") -> ModelParams:
    data = load_yaml(path)
    return ModelParams(**(data["model"] if "model" in data else data))


def diagnose_file(recording, model="model.yaml", output=None, settings="diagnosis.yaml") -> dict:
    started = time.perf_counter()
    rec = recording if isinstance(recording, Recording) else load_recording(recording)
    params = model if isinstance(model, ModelParams) else load_model(model)
    cfg = settings if not isinstance(settings, (str, Path)) else load_settings(settings)
    result = diagnose(rec, params, cfg)
    result["wall_time"] = time.perf_counter() - started
    if output is not None:
        from .report import write_report
        result["report"] = write_report(result, Path(output))
    return result
