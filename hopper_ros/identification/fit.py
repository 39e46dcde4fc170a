"""Parameter identification by Nelder-Mead (section 4.2): minimise C (4.4) over the fitted
parameters with one of the model library's predictors.

The search runs on x = ln(p / p_initial) (scale-free, every parameter stays positive) inside
the configured bounds (a point outside costs more than any inside), starts from
`settings.initial` with a simplex of +-`initial_step`, and restarts from its best point with a
fresh simplex `restarts` times (Nelder-Mead can stall on a degenerate simplex).

Predictors:
- "lanes": the laws with library effects (`settings.effects`), least squares by `lanesfit`.
- "aas", "corrected": one vectorised call predicts all strides (~0.5 ms / ~1 ms for 120).
- "exact": the exact model costs ~3 ms a stride, 0.3 s per cost evaluation, far too much for
  thousands of evaluations. It is reached by defect correction: fit the corrected AAS, then
  `defect_iterations` times fit the corrected AAS plus the fixed per-stride difference
  exact - corrected taken at the current estimate (the difference is ~0.1 % and varies slowly
  with the parameters, so the fixed point is the exact model's optimum up to that variation),
  then optionally polish with Nelder-Mead on the exact model itself (`polish_evaluations`).
  Every reported error of an "exact" fit is the exact model's.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import minimize

from hopper_ros.physics.params import ModelParams

from .cost import OUTCOMES, StrideErrors, errors_of, predicted_outcomes
from .settings import IdentificationSettings
from .strides import Strides

OUT_OF_BOUNDS_COST = 1.0e4    # [%] above any attainable cost (a failed stride scores failed_error)


@dataclass
class FitResult:
    params: ModelParams
    cost: float                          # C (4.4) with `method` on the fitted strides
    errors: StrideErrors
    method: str
    evaluations: int                     # cost evaluations (of the surrogate for "exact")
    exact_strides: int = 0               # strides integrated by the exact model
    wall_time: float = 0.0
    stages: list = field(default_factory=list)   # (stage, cost, evaluations)
    effects: dict = field(default_factory=dict)  # "lanes": fitted effect magnitudes {name: physical value}


def lanes_fit_result(fit, settings: IdentificationSettings) -> FitResult:
    """A `lanesfit.LanesFit` as a FitResult (evaluations: lanes calls, each with its Jacobian)."""
    errors = fit.errors(settings.failed_stride_error_pct)
    return FitResult(fit.params, errors.cost(), errors, "lanes", fit.calls, 0, fit.wall_time, fit.stages, fit.effects)


class ParameterVector:
    """The fitted parameters as x = ln(p / reference), the others held at `base`."""

    def __init__(self, names, base: ModelParams, bounds: dict[str, tuple[float, float]], reference: ModelParams | None = None):
        self.names = tuple(names)
        self.base = base
        reference = reference or base
        self.reference = np.array([getattr(reference, n) for n in self.names], dtype=float)
        self.low = np.log(np.array([bounds[n][0] for n in self.names]) / self.reference)
        self.high = np.log(np.array([bounds[n][1] for n in self.names]) / self.reference)

    def x_of(self, params: ModelParams) -> np.ndarray:
        return np.log(np.array([getattr(params, n) for n in self.names]) / self.reference)

    def params_of(self, x: np.ndarray) -> ModelParams:
        return self.base.replace(**dict(zip(self.names, (float(v) for v in self.reference * np.exp(x)))))

    def outside(self, x: np.ndarray) -> float:
        """How far x lies outside the bounds (0 inside)."""
        return float(np.sum(np.maximum(self.low - x, 0.0) + np.maximum(x - self.high, 0.0)))


def _objective(vector: ParameterVector, cost_of: Callable[[ModelParams], float], counter: list, progress=None):
    def objective(x):
        counter[0] += 1
        beyond = vector.outside(x)
        if beyond > 0.0:
            return OUT_OF_BOUNDS_COST * (1.0 + beyond)
        try:
            params = vector.params_of(x)
        except ValueError:          # e.g. a damping ratio of 1 or more: the AAS needs it below 1
            return OUT_OF_BOUNDS_COST
        value = cost_of(params)
        if progress is not None and counter[0] % 50 == 0:
            progress(counter[0], value)
        return value if math.isfinite(value) else OUT_OF_BOUNDS_COST

    return objective


def nelder_mead(objective, x0: np.ndarray, step: float, xatol: float, fatol: float, max_evaluations: int,
                restarts: int) -> tuple[np.ndarray, float, int]:
    """scipy's Nelder-Mead from x0 with a +-step simplex, restarted from its best point."""
    x, best, used = np.asarray(x0, dtype=float), math.inf, 0
    for attempt in range(restarts + 1):
        simplex = np.vstack([x] + [x + step * np.eye(len(x))[i] for i in range(len(x))])
        result = minimize(objective, x, method="Nelder-Mead",
                          options={"initial_simplex": simplex, "xatol": xatol, "fatol": fatol,
                                   "maxfev": max_evaluations, "adaptive": len(x) > 4})
        used += int(result.nfev)
        improved = best - float(result.fun)
        x, best = np.asarray(result.x, dtype=float), min(best, float(result.fun))
        if attempt > 0 and improved <= fatol:
            break
    return x, best, used


def fit_parameters(strides: Strides, settings: IdentificationSettings, method: str | None = None,
                   start: ModelParams | None = None, progress: Callable[[int, float], None] | None = None) -> FitResult:
    """Identify `settings.fitted` on `strides` with the predictor `method` (default: settings')."""
    method = method or settings.predictor
    if len(strides) == 0:
        raise ValueError("no strides to identify the parameters on")
    if method == "lanes":
        from .lanesfit import fit_lanes

        return lanes_fit_result(fit_lanes(strides, settings.with_changes(initial=start) if start else settings,
                                          progress=progress), settings)
    started = time.perf_counter()
    start = start or settings.initial
    vector = ParameterVector(settings.fitted, start, settings.bounds, reference=settings.initial)
    nm = settings.nelder_mead
    failed = settings.failed_stride_error_pct
    counter = [0]
    stages = []
    if method in ("aas", "corrected"):
        x, value, _ = nelder_mead(_objective(vector, lambda p: errors_of(strides, predicted_outcomes(p, strides, method),
                                                                          failed).cost(), counter, progress),
                                  vector.x_of(start), nm.initial_step, nm.xatol, nm.fatol, nm.max_evaluations, nm.restarts)
        params = vector.params_of(x)
        errors = errors_of(strides, predicted_outcomes(params, strides, method), failed)
        stages.append((method, errors.cost(), counter[0]))
        return FitResult(params, errors.cost(), errors, method, counter[0], 0, time.perf_counter() - started, stages)
    if method != "exact":
        raise ValueError(f"unknown predictor {method!r}; choose aas, corrected, exact or lanes")

    surrogate = fit_parameters(strides, settings, "corrected", start, progress)
    params, evaluations = surrogate.params, surrogate.evaluations
    stages.append(("corrected", surrogate.cost, surrogate.evaluations))
    exact_strides = 0
    ex = settings.exact
    exact = predicted_outcomes(params, strides, "exact")
    exact_strides += len(strides)
    for iteration in range(ex.defect_iterations):
        corrected = predicted_outcomes(params, strides, "corrected")
        defect = {name: exact[name] - corrected[name] for name in OUTCOMES}

        def surrogate_cost(p, defect=defect):
            prediction = predicted_outcomes(p, strides, "corrected")
            return errors_of(strides, {n: prediction[n] + defect[n] for n in OUTCOMES}, failed).cost()

        counter = [0]
        x, _, _ = nelder_mead(_objective(vector, surrogate_cost, counter, progress), vector.x_of(params), ex.defect_step,
                              nm.xatol, nm.fatol, nm.max_evaluations, 0)
        evaluations += counter[0]
        candidate = vector.params_of(x)
        candidate_exact = predicted_outcomes(candidate, strides, "exact")
        exact_strides += len(strides)
        before = errors_of(strides, exact, failed).cost()
        after = errors_of(strides, candidate_exact, failed).cost()
        stages.append((f"defect correction {iteration + 1}", after, counter[0]))
        moved = float(np.max(np.abs(x - vector.x_of(params))))
        if after <= before:
            params, exact = candidate, candidate_exact
        if moved < ex.defect_tolerance or abs(before - after) < nm.fatol:
            break
    if ex.polish_evaluations > 0:
        counter = [0]

        def exact_cost(p):
            return errors_of(strides, predicted_outcomes(p, strides, "exact"), failed).cost()

        x, _, _ = nelder_mead(_objective(vector, exact_cost, counter, progress), vector.x_of(params), ex.polish_step,
                              nm.xatol, nm.fatol, ex.polish_evaluations, 0)
        exact_strides += counter[0] * len(strides)
        candidate = vector.params_of(x)
        candidate_exact = predicted_outcomes(candidate, strides, "exact")
        exact_strides += len(strides)
        if errors_of(strides, candidate_exact, failed).cost() <= errors_of(strides, exact, failed).cost():
            params, exact = candidate, candidate_exact
        stages.append(("exact polish", errors_of(strides, exact, failed).cost(), counter[0]))
    errors = errors_of(strides, exact, failed)
    return FitResult(params, errors.cost(), errors, "exact", evaluations, exact_strides, time.perf_counter() - started, stages)
