"""k-fold cross-validation of the identification (section 4.2) and its Table 4.1 / Table 4.2.

The strides are shuffled (seed) and split into k folds of nearly equal size; for each fold the
parameters are fitted on the other k-1 folds (training) and the fitted model predicts the
held-out fold (test). Table 4.1 lists every parameter's mean and standard deviation over the
k fits; Table 4.2 the mean E_p, E_v, E_t (4.1)-(4.3) on test and training strides, each as the
mean and standard deviation over the folds of the fold's mean error.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hopper_ros.physics.params import ModelParams

from .cost import StrideErrors, errors_of, predicted_outcomes
from .fit import FitResult, fit_parameters, lanes_fit_result
from .progress import ProgressBar
from .settings import PARAMETERS, IdentificationSettings
from .strides import Strides

UNITS = {"body_mass": "kg", "toe_mass": "kg", "gravity": "m/s^2", "stiffness": "N/m", "damping": "N s/m",
         "flight_damping_horizontal": "1/s", "flight_damping_vertical": "1/s", "rest_length": "m"}
SYMBOLS = {"body_mass": "m_b", "toe_mass": "m_t", "gravity": "g", "stiffness": "k", "damping": "d",
           "flight_damping_horizontal": "d_h^f", "flight_damping_vertical": "d_v^f", "rest_length": "rho_0"}
DESCRIPTIONS = {"body_mass": "Body mass", "toe_mass": "Toe mass", "gravity": "Corrected gravity",
                "stiffness": "Spring constant", "damping": "Damping constant",
                "flight_damping_horizontal": "Horizontal flight damping", "flight_damping_vertical": "Vertical flight damping",
                "rest_length": "Leg rest length"}


@dataclass
class Fold:
    train: np.ndarray           # stride indices
    test: np.ndarray
    fit: FitResult
    train_errors: StrideErrors
    test_errors: StrideErrors


@dataclass
class CrossValidation:
    method: str
    strides: Strides
    folds: list[Fold]
    fitted: tuple[str, ...]
    wall_time: float

    def parameter_table(self) -> dict[str, tuple[float, float]]:
        """Table 4.1: parameter -> (mean, std over folds); held parameters have std 0."""
        out = {}
        for name in PARAMETERS:
            values = np.array([getattr(f.fit.params, name) for f in self.folds])
            out[name] = (float(values.mean()), float(values.std(ddof=1)) if len(values) > 1 else 0.0)
        return out

    def mean_params(self) -> ModelParams:
        return ModelParams(**{name: mean for name, (mean, _) in self.parameter_table().items()})

    @property
    def effects(self) -> tuple[str, ...]:
        """The library effects fitted with the model ("lanes" only)."""
        return tuple(self.folds[0].fit.effects) if self.folds else ()

    def effect_table(self) -> dict[str, tuple[float, float]]:
        """Effect -> (mean, std over folds) of its physical magnitude (averaged in search units: 1/value for a limit)."""
        from .lanesfit import mean_magnitudes

        return mean_magnitudes([f.fit.effects for f in self.folds])

    def mean_effects(self) -> dict[str, float]:
        """{effect: mean physical magnitude}: what the identified model file carries under `effects:`."""
        return {name: mean for name, (mean, _) in self.effect_table().items()}

    def error_table(self) -> dict[str, dict[str, tuple[float, float]]]:
        """Table 4.2: {"test"|"train": {"E_p"|"E_v"|"E_t": (mean, std over folds)}}."""
        out = {}
        for part in ("test", "train"):
            per_fold = np.array([getattr(f, f"{part}_errors").means() for f in self.folds])
            out[part] = {name: (float(per_fold[:, i].mean()), float(per_fold[:, i].std(ddof=1)) if len(per_fold) > 1 else 0.0)
                         for i, name in enumerate(("E_p", "E_v", "E_t"))}
        return out

    def test_errors(self) -> StrideErrors:
        """Every stride's error when it was held out (one value per stride)."""
        n = len(self.strides)
        out = StrideErrors(np.empty(n), np.empty(n), np.empty(n), np.zeros(n, dtype=bool))
        for fold in self.folds:
            for name in ("position", "velocity", "time", "failed"):
                getattr(out, name)[fold.test] = getattr(fold.test_errors, name)
        return out


def fold_indices(count: int, folds: int, seed: int) -> list[np.ndarray]:
    if count < folds:
        raise ValueError(f"{count} strides cannot be split into {folds} folds")
    order = np.random.default_rng(seed).permutation(count)
    return [np.sort(part) for part in np.array_split(order, folds)]


def cross_validate(strides: Strides, settings: IdentificationSettings, method: str | None = None,
                   show_progress: bool = True, stream=None) -> CrossValidation:
    """Fit on k-1 folds, test on the held-out one, for each fold."""
    method = method or settings.predictor
    started = time.perf_counter()
    parts = fold_indices(len(strides), settings.folds, settings.seed)
    bar = ProgressBar(len(parts), f"{method} {settings.folds}-fold CV", stream=stream) if show_progress else None
    if method == "lanes":
        return _cross_validate_lanes(strides, settings, parts, bar, started)
    folds = []
    for k, test in enumerate(parts):
        train = np.setdiff1d(np.arange(len(strides)), test)
        training = strides.subset(train)
        progress = None
        if bar is not None:
            def progress(evaluations, cost, k=k):
                bar.note(f"fold {k + 1}: {evaluations} evaluations, C = {cost:.4f} %")
        fit = fit_parameters(training, settings, method, progress=progress)
        test_strides = strides.subset(test)
        test_errors = errors_of(test_strides, predicted_outcomes(fit.params, test_strides, fit.method),
                                settings.failed_stride_error_pct)
        folds.append(Fold(train, test, fit, fit.errors, test_errors))
        if bar is not None:
            bar.step(f"fold {k + 1}: train C = {fit.cost:.4f} %, test C = {test_errors.cost():.4f} %")
    if bar is not None:
        bar.close()
    return CrossValidation(fit.method, strides, folds, settings.fitted, time.perf_counter() - started)


def _cross_validate_lanes(strides: Strides, settings: IdentificationSettings, parts, bar, started) -> CrossValidation:
    """The folds' fits side by side, sharing their lanes calls; the held-out folds in one more call."""
    from .lanesfit import errors_many, fit_lanes_many

    trains = [np.setdiff1d(np.arange(len(strides)), test) for test in parts]
    progress = None
    if bar is not None:
        def progress(k, calls, cost):
            bar.note(f"fold {k + 1}: {calls} lanes calls, C = {cost:.4f} %")
    fits = fit_lanes_many([strides.subset(train) for train in trains], settings, progress)
    tests = errors_many([(f.params, f.effects, strides.subset(test)) for f, test in zip(fits, parts)], settings)
    folds = []
    for k, (train, test, fit, test_errors) in enumerate(zip(trains, parts, fits, tests)):
        result = lanes_fit_result(fit, settings)
        folds.append(Fold(train, test, result, result.errors, test_errors))
        if bar is not None:
            bar.step(f"fold {k + 1}: train C = {result.cost:.4f} %, test C = {test_errors.cost():.4f} %")
    if bar is not None:
        bar.close()
    return CrossValidation("lanes", strides, folds, settings.fitted, time.perf_counter() - started)


def format_parameter_table(cv: CrossValidation, truth: ModelParams | None = None) -> str:
    """Table 4.1 as markdown (with the true values and errors when known)."""
    table = cv.parameter_table()
    header = ["Parameter", "Description", "Mean", "Std.", "Units", "fitted"]
    if truth is not None:
        header += ["true", "error [%]"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for name in PARAMETERS:
        mean, std = table[name]
        row = [SYMBOLS[name], DESCRIPTIONS[name], _number(mean), f"±{_number(std)}", UNITS[name],
               "yes" if name in cv.fitted else "held"]
        if truth is not None:
            true = getattr(truth, name)
            row += [_number(true), f"{100.0 * (mean / true - 1.0):+.2f}" if true else "-"]
        lines.append("| " + " | ".join(row) + " |")
    if cv.effects:
        from hopper_ros.physics.effects import get

        for name, (mean, std) in cv.effect_table().items():
            effect = get(name)
            row = [effect.primary.name, f"effect {name}: {effect.words}", _number(mean), f"±{_number(std)}",
                   effect.primary.unit or "1", "yes"]
            if truth is not None:
                row += ["-", "-"]
            lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def format_error_table(cv: CrossValidation) -> str:
    """Table 4.2 as markdown."""
    table = cv.error_table()
    lines = ["| Error metrics | Test data | Training data |", "|---|---|---|"]
    for name in ("E_p", "E_v", "E_t"):
        (tm, ts), (rm, rs) = table["test"][name], table["train"][name]
        lines.append(f"| {name} [%] | {tm:.3f} ±{ts:.3f} | {rm:.3f} ±{rs:.3f} |")
    return "\n".join(lines)


def _number(value: float) -> str:
    if value == 0.0:
        return "0"
    if abs(value) >= 100:
        return f"{value:.1f}"
    if abs(value) >= 1:
        return f"{value:.3f}"
    return f"{value:.4g}"
