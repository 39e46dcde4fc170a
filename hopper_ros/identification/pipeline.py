"""One identification run: recording -> strides -> k-fold cross-validation per predictor ->
identifiability, and the AAS's bias against the exact model (what `hopper identify` and
`hopper report` print and write)."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field

import yaml

from hopper_ros.physics.params import ModelParams

from .crossval import CrossValidation, cross_validate
from .identifiability import Identifiability, analyse
from hopper_ros.recording.recordings import Recording, RecordingError, load_recording
from .settings import FITTABLE, IdentificationSettings
from .strides import Strides, extract_strides

ACCURACY_ORDER = ("lanes", "exact", "corrected", "aas")   # most accurate predictor first (lanes: with effects)


@dataclass
class Identification:
    recording: Recording
    strides: Strides
    settings: IdentificationSettings
    cross_validations: dict[str, CrossValidation] = field(default_factory=dict)
    truth: ModelParams | None = None
    identifiability: Identifiability | None = None

    @property
    def best_method(self) -> str:
        return next(m for m in ACCURACY_ORDER if m in self.cross_validations)

    def aas_bias_pct(self) -> dict[str, float] | None:
        """Per fitted parameter: 100 (AAS estimate / exact estimate - 1), both mean over folds, on
        the same strides: the bias the AAS's own approximation puts into the identification."""
        if "aas" not in self.cross_validations or "exact" not in self.cross_validations:
            return None
        aas = self.cross_validations["aas"].parameter_table()
        exact = self.cross_validations["exact"].parameter_table()
        return {name: 100.0 * (aas[name][0] / exact[name][0] - 1.0) for name in self.settings.fitted}


def true_params(recording: Recording) -> ModelParams | None:
    """The true parameters a simulated recording carries in its metadata (None for real data)."""
    text = recording.custom_data.get("hopper_ros.true_model")
    if not text:
        return None
    try:
        return ModelParams.from_dict(yaml.safe_load(text), source="bag metadata hopper_ros.true_model")
    except ValueError:
        return None


def identify(source: str | os.PathLike | Recording, settings: IdentificationSettings, methods: tuple[str, ...],
             *, show_progress: bool = True, stream=None, max_strides: int | None = None) -> Identification:
    """Extract the strides of a recording and cross-validate the identification per predictor.

    `settings.effects` (library effects) are fitted by the "lanes" predictor only; they imply it."""
    if settings.effects and "lanes" not in methods:
        methods = tuple(methods) + ("lanes",)
    recording = source if isinstance(source, Recording) else load_recording(source)
    strides = extract_strides(recording, settings.initial.rest_length, settings.extraction)
    if max_strides is not None:
        strides = strides.subset(slice(0, max_strides))
    if len(strides) < settings.folds:
        reasons = "; ".join(sorted({r for _, r in strides.rejected})) or "none found"
        raise RecordingError(f"{recording.source}: {len(strides)} usable stride(s), {settings.folds}-fold "
                             f"cross-validation needs at least {settings.folds} (rejected: {reasons})")
    result = Identification(recording, strides, settings, truth=true_params(recording))
    for method in methods:
        result.cross_validations[method] = cross_validate(strides, settings, method, show_progress,
                                                          stream if stream is not None else sys.stderr)
    estimate = result.cross_validations[result.best_method].mean_params()
    result.identifiability = analyse(estimate, strides, FITTABLE, "corrected")
    return result
