"""Entry point: load a recording and a model (with any library effects it carries), diagnose, write reports."""

from __future__ import annotations

import time
from pathlib import Path

from hopper_ros.recording.recordings import Recording, load_recording
from hopper_ros.physics.params import ModelParams, load_model

from .core import diagnose
from .progress import QUIET, Progress
from .records import Diagnosis
from .settings import load_settings


def diagnose_file(recording, model="model.yaml", output=None, settings="diagnosis.yaml", json_path=None,
                  progress: Progress = QUIET) -> Diagnosis:
    """Diagnose a recording (a path or a `Recording`) against a model (a config name or path, a `ModelParams`,
    or (params, effects)); with `output` write diagnosis.md and .png there, with `json_path` the JSON."""
    started = time.perf_counter()
    rec = recording if isinstance(recording, Recording) else load_recording(recording)
    if isinstance(model, ModelParams):
        params, model_effects = model, {}
    elif isinstance(model, tuple):
        params, model_effects = model
    else:
        params, model_effects = load_model(model)
    cfg = settings if not isinstance(settings, (str, Path)) else load_settings(settings)
    result = diagnose(rec, params, cfg, model_effects, progress)
    result.wall_time = time.perf_counter() - started
    if output is not None:
        from .report import write_report
        result.report = write_report(result, Path(output))
    if json_path is not None:
        from .report import write_json
        result.json = write_json(result, Path(json_path))
    return result
