"""Identification with the laws and library effects (`hopper identify --effects`): the "lanes" predictor.

Every stride is re-simulated from its recorded apex and inputs by `physics.lanes` (the laws of
`physics.laws`, written once, with the named effects of `physics.effects` switched on), all the
strides of a fit in one vectorised call. The fitted vector is the usual model parameters, as
x = ln(p / p_initial), plus each effect's primary parameter in its search units (1/value for a
limit), scaled to u = (s - low) / (high - low) over its `search_bounds`, so every component moves
on a scale of one.

The fit (`fit_lanes`):

1. least squares (scipy.optimize.least_squares, trust-region reflective inside the bounds) on the
   strides' signed relative errors behind E_p, E_v, E_t (next apex height and stride length over
   |[z, y]|, next speed, stride time; their squares sum to E_p^2 + E_v^2 + E_t^2 per stride). The
   Jacobian is by forward differences (`fd_step` 1 %: lanes' fixed-step event handling makes the
   outcomes rough at the 1e-5 level, so 0.1 % steps give derivatives 5-12 % off), the base point and
   every perturbed variant stacked as extra lanes of ONE lanes call, made whenever the residuals
   are: a cost evaluation with its Jacobian costs one call (~20 calls a fit).
2. optionally (`polish_iterations` > 0, off by default) L-BFGS-B on C (4.4) itself from there, its
   gradient by the chain rule from the same one-call Jacobian; the point of lower C is kept
   (measured: C 0.07-0.7 % lower, for as many calls again).

Every reported error is E_p, E_v, E_t (4.1)-(4.3) and C (4.4), as for the other predictors. The
folds of a cross-validation run side by side and share their lanes calls (`fit_lanes_many`).
A stride the laws find no next apex for (it fell, or the apex comes after the simulated duration)
scores `failed_stride_error_pct` on E_p, E_v and E_t.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, minimize

from hopper_ros.physics import effects as effect_library
from hopper_ros.physics import lanes, laws
from hopper_ros.physics.params import ModelParams

from .cost import OUTCOMES, StrideErrors, errors_of
from .strides import Strides

def model_coefficients(values: dict) -> laws.Coefficients:
    """laws.Coefficients of the model's parameters (a mapping of every ModelParams field), without
    ModelParams' validation (the search may pass a damping ratio above 1: the laws integrate it)."""
    m_b, m_t = values["body_mass"], values["toe_mass"]
    return laws.Coefficients(mass=m_b, stiffness=values["stiffness"], damping=values["damping"],
                             rest_length=values["rest_length"], gravity=values["gravity"],
                             flight_damping_y=values["flight_damping_horizontal"],
                             flight_damping_z=values["flight_damping_vertical"], collision_factor=m_b / (m_b + m_t))


def with_effects(params: ModelParams, magnitudes: dict[str, float]) -> laws.Coefficients:
    """The laws' coefficients of a model with library effects on ({name: physical magnitude})."""
    coefficients, _ = effect_library.apply(model_coefficients(params.as_dict()), magnitudes)
    return coefficients


class LanesVector:
    """The fitted vector: model parameters as ln(p / reference), effects as u in [0, 1] of their search bounds."""

    def __init__(self, names, effect_names, start: ModelParams, bounds: dict, reference: ModelParams):
        self.names = tuple(names)
        self.effects = tuple(effect_names)
        self.start = start
        self.reference = np.array([getattr(reference, n) for n in self.names], dtype=float)
        base = model_coefficients(reference.as_dict())
        self.library = [effect_library.get(n) for n in self.effects]
        self.search_low = np.array([e.search_bounds(base)[0] for e in self.library], dtype=float)
        self.search_high = np.array([e.search_bounds(base)[1] for e in self.library], dtype=float)
        self.low = np.concatenate([np.log(np.array([bounds[n][0] for n in self.names]) / self.reference),
                                   np.zeros(len(self.effects))])
        self.high = np.concatenate([np.log(np.array([bounds[n][1] for n in self.names]) / self.reference),
                                    np.ones(len(self.effects))])

    def __len__(self) -> int:
        return len(self.names) + len(self.effects)

    def x0(self, start_effects: dict | None = None) -> np.ndarray:
        """The start: the model's start values; each effect at its given magnitude, else off (the laws as the
        model has them: 0, a gain of 1, no limit, or the model's own value), at least 1 % inside its bounds."""
        model = np.log(np.array([getattr(self.start, n) for n in self.names]) / self.reference)
        base = model_coefficients(self.start.as_dict())
        u = []
        for effect, low, high in zip(self.library, self.search_low, self.search_high):
            physical = (start_effects or {}).get(effect.name)
            if physical is None:
                p = effect.primary
                physical = self.start.toe_mass if p.coefficient == "toe_mass" else float(getattr(base, p.coefficient))
            u.append(min(max((effect.search_value(physical) - low) / (high - low), 0.01), 0.99))
        return np.clip(np.concatenate([model, np.array(u, dtype=float)]), self.low, self.high)

    def values(self, x: np.ndarray) -> tuple[dict, np.ndarray]:
        """(ModelParams fields as a dict, the effects' search values) of x."""
        x = np.asarray(x, dtype=float)
        values = self.start.as_dict()
        for name, value in zip(self.names, self.reference * np.exp(x[:len(self.names)])):
            values[name] = float(value)
        search = self.search_low + x[len(self.names):] * (self.search_high - self.search_low)
        return values, search

    def coefficients(self, x: np.ndarray) -> laws.Coefficients:
        values, search = self.values(x)
        c = model_coefficients(values)
        for effect, value in zip(self.library, search):
            c = c.replace(**effect.coefficients(float(value), c))
        return c

    def params_of(self, x: np.ndarray) -> ModelParams:
        return ModelParams(**self.values(x)[0])

    def effects_of(self, x: np.ndarray) -> dict[str, float]:
        """{effect: physical magnitude} of x."""
        _, search = self.values(x)
        return {e.name: float(e.physical(float(v))) for e, v in zip(self.library, search)}


def duration_for(strides: Strides, factor: float) -> float:
    """Simulated time per lane: `factor` times the longest recorded stride (an apex after it is a failed stride)."""
    return float(factor * np.max(strides.stride_time)) + 0.02


def _concatenate(parts: list[laws.Coefficients]) -> laws.Coefficients:
    values = {}
    for name in laws.Coefficients.scalar_names():
        values[name] = np.concatenate([getattr(p, name) for p in parts])
    for name in laws.Coefficients.term_names():
        values[name] = tuple(np.concatenate(column) for column in zip(*(getattr(p, name) for p in parts)))
    return laws.Coefficients(**values)


def simulate_batch(requests: list[tuple[list[laws.Coefficients], Strides]], step: float, duration: float
                   ) -> list[list[dict[str, np.ndarray]]]:
    """Several (coefficient variants, strides) requests in ONE lanes call: every stride of a request under every
    one of its variants. Per request, per variant, the four outcomes (NaN: no next apex within `duration`)."""
    parts, inputs, sizes = [], [], []
    for variants, strides in requests:
        n = len(strides)
        parts.append(lanes.stack(variants, n))
        inputs.append([np.tile(np.asarray(v, dtype=float), len(variants)) for v in strides.inputs()])
        sizes.append((len(variants), n))
    stacked = _concatenate(parts)
    columns = [np.concatenate(column) for column in zip(*inputs)]
    result = lanes.simulate_lanes(stacked, *columns, duration=duration, h=step, sample=max(step, 1e-3))
    out, offset = [], 0
    for count, n in sizes:
        per_request = []
        for _ in range(count):
            part = slice(offset, offset + n)
            per_request.append({"next_apex_height": np.asarray(result.next_apex_height[part], dtype=float),
                                "stride_length": np.asarray(result.stride_length[part], dtype=float),
                                "next_forward_speed": np.asarray(result.next_forward_speed[part], dtype=float),
                                "stride_time": np.asarray(result.stride_time[part], dtype=float)})
            offset += n
        out.append(per_request)
    return out


def simulate_outcomes(variants: list[laws.Coefficients], strides: Strides, step: float, duration: float
                      ) -> list[dict[str, np.ndarray]]:
    """Every stride under every coefficient variant in ONE lanes call: per variant the four outcomes (NaN: failed)."""
    return simulate_batch([(variants, strides)], step, duration)[0]


class Batcher:
    """Lets several fits, each in its own thread, share lanes calls: once every fit still running has asked for
    one, all their requests go into ONE `simulate_batch` call (a call costs ~2 s of fixed overhead at a few
    hundred lanes and little more per lane up to a few thousand)."""

    def __init__(self, fits: int, step: float, max_lanes: int = 8000):
        self.active = fits
        self.step = step
        self.max_lanes = max_lanes      # a bigger round is split into several calls (lanes keeps every sample)
        self.condition = threading.Condition()
        self.pending: dict[int, tuple] = {}
        self.results: dict[int, object] = {}
        self.calls = 0
        self._tokens = 0

    def simulate(self, variants, strides, duration) -> list[dict[str, np.ndarray]]:
        with self.condition:
            self._tokens += 1
            token = self._tokens
            self.pending[token] = (variants, strides, duration)
            self._run_if_complete()
            while token not in self.results:
                self.condition.wait()
            result = self.results.pop(token)
        if isinstance(result, BaseException):
            raise result
        return result

    def leave(self) -> None:
        """A fit is done (or failed): the others no longer wait for it."""
        with self.condition:
            self.active -= 1
            self._run_if_complete()

    def _run_if_complete(self) -> None:
        if not self.pending or len(self.pending) < self.active:
            return
        groups, size = [[]], 0
        for token, (variants, strides, _) in self.pending.items():
            lanes_wanted = len(variants) * len(strides)
            if groups[-1] and size + lanes_wanted > self.max_lanes:
                groups.append([])
                size = 0
            groups[-1].append(token)
            size += lanes_wanted
        for tokens in groups:
            requests = [self.pending.pop(t) for t in tokens]
            try:
                outcomes = simulate_batch([(v, s) for v, s, _ in requests], self.step, max(d for _, _, d in requests))
            except Exception as exc:        # every waiting fit raises it
                outcomes = [exc] * len(tokens)
            self.calls += 1
            self.results.update(zip(tokens, outcomes))
        self.condition.notify_all()


def lanes_outcomes(params: ModelParams, magnitudes: dict[str, float], strides: Strides, step: float = 5e-4,
                   duration_factor: float = 1.5) -> dict[str, np.ndarray]:
    """The four outcomes of every stride by the laws with the effects on (NaN where no next apex)."""
    if len(strides) == 0:
        return {name: np.empty(0) for name in OUTCOMES}
    return simulate_outcomes([with_effects(params, magnitudes)], strides, step, duration_for(strides, duration_factor))[0]


def signed_residuals(strides: Strides, predicted: dict[str, np.ndarray], failed_error: float) -> np.ndarray:
    """(N, 4) signed relative errors [%] behind E_p, E_v, E_t; a failed stride scores `failed_error` on E_p, E_v, E_t."""
    scale = np.hypot(strides.next_apex_height, strides.stride_length)
    r = 100.0 * np.column_stack([
        (predicted["next_apex_height"] - strides.next_apex_height) / scale,
        (predicted["stride_length"] - strides.stride_length) / scale,
        (predicted["next_forward_speed"] - strides.next_forward_speed) / np.abs(strides.next_forward_speed),
        (predicted["stride_time"] - strides.stride_time) / np.abs(strides.stride_time)])
    failed = ~np.all(np.isfinite(r), axis=1)
    r[failed] = failed_error * np.array([math.sqrt(0.5), math.sqrt(0.5), 1.0, 1.0])   # E_p = E_v = E_t = failed_error
    return r


def cost_of_residuals(r: np.ndarray) -> float:
    """C (4.4) from the (N, 4) signed residuals."""
    e_p = np.hypot(r[:, 0], r[:, 1])
    return float(np.sqrt(np.mean(e_p) ** 2 + np.mean(np.abs(r[:, 2])) ** 2 + np.mean(np.abs(r[:, 3])) ** 2))


def cost_gradient(r: np.ndarray, jacobian: np.ndarray) -> tuple[float, np.ndarray]:
    """C (4.4) and its gradient from the residuals (N, 4) and their Jacobian (N, 4, P)."""
    e_p = np.hypot(r[:, 0], r[:, 1])
    means = np.array([np.mean(e_p), np.mean(np.abs(r[:, 2])), np.mean(np.abs(r[:, 3]))])
    cost = float(np.sqrt(np.sum(means ** 2)))
    safe = np.where(e_p > 0, e_p, 1.0)
    d_p = (r[:, 0, None] * jacobian[:, 0] + r[:, 1, None] * jacobian[:, 1]) / safe[:, None]
    d_v = np.sign(r[:, 2])[:, None] * jacobian[:, 2]
    d_t = np.sign(r[:, 3])[:, None] * jacobian[:, 3]
    d_means = np.stack([d_p.mean(axis=0), d_v.mean(axis=0), d_t.mean(axis=0)])
    gradient = (means @ d_means) / cost if cost > 0 else np.zeros(jacobian.shape[2])
    return cost, gradient


class LanesProblem:
    """Residuals of a training set under the laws, with the forward-difference Jacobian from the same call."""

    def __init__(self, strides: Strides, vector: LanesVector, settings, batcher: Batcher | None = None):
        self.strides = strides
        self.vector = vector
        self.lanes = settings.lanes
        self.failed = settings.failed_stride_error_pct
        self.duration = duration_for(strides, self.lanes.duration_factor)
        self.batcher = batcher
        self.calls = 0
        self.lanes_simulated = 0
        self._cache: tuple[bytes, np.ndarray, np.ndarray] | None = None

    def residuals_and_jacobian(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((N, 4) residuals, (N, 4, P) Jacobian) at x, one lanes call (cached for the last x)."""
        x = np.asarray(x, dtype=float)
        key = x.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1], self._cache[2]
        step = self.lanes.fd_step
        points, steps = [x], []
        for i in range(len(x)):
            h = step if x[i] + step <= self.vector.high[i] else -step    # stay inside the bounds
            point = x.copy()
            point[i] += h
            points.append(point)
            steps.append(h)
        variants = [self.vector.coefficients(p) for p in points]
        if self.batcher is not None:
            outcomes = self.batcher.simulate(variants, self.strides, self.duration)
        else:
            outcomes = simulate_outcomes(variants, self.strides, self.lanes.step, self.duration)
        self.calls += 1
        self.lanes_simulated += len(variants) * len(self.strides)
        base = signed_residuals(self.strides, outcomes[0], self.failed)
        columns = [(signed_residuals(self.strides, o, self.failed) - base) / h for o, h in zip(outcomes[1:], steps)]
        jacobian = np.stack(columns, axis=2) if columns else np.zeros(base.shape + (0,))
        self._cache = (key, base, jacobian)
        return base, jacobian


@dataclass
class LanesFit:
    params: ModelParams
    effects: dict[str, float]
    x: np.ndarray
    residuals: np.ndarray       # (N, 4) at the result
    cost: float                 # C (4.4) on the fitted strides
    calls: int                  # lanes calls (each: the residuals and the Jacobian)
    lanes: int                  # strides integrated
    stages: list                # (stage, C, calls)
    wall_time: float = 0.0

    def errors(self, failed_error: float) -> StrideErrors:
        """E_p, E_v, E_t per fitted stride (as `cost.errors_of`)."""
        r = self.residuals
        failed = np.all(r == failed_error * np.array([math.sqrt(0.5), math.sqrt(0.5), 1.0, 1.0]), axis=1)
        return StrideErrors(np.hypot(r[:, 0], r[:, 1]), np.abs(r[:, 2]), np.abs(r[:, 3]), failed)


def fit_lanes(strides: Strides, settings, start_effects: dict | None = None, progress=None,
              batcher: Batcher | None = None) -> LanesFit:
    """Least squares, then optionally C (4.4), on `strides` with the laws and `settings.effects` (module docstring)."""
    started = time.perf_counter()
    vector = LanesVector(settings.fitted, settings.effects, settings.initial, settings.bounds, settings.initial)
    problem = LanesProblem(strides, vector, settings, batcher)
    ls = settings.lanes
    x0 = vector.x0(start_effects)
    # scipy's trust-region reflective starts with a radius of |x0| (~0.01 here: the start is the reference);
    # searching y = x + shift puts the first radius at `initial_radius` instead of wasting calls growing it
    shift = np.full(len(x0), ls.initial_radius / math.sqrt(len(x0)))
    stages = []

    def fun(y):
        r, _ = problem.residuals_and_jacobian(y - shift)
        if progress is not None:
            progress(problem.calls, cost_of_residuals(r))
        return r.ravel()

    def jac(y):
        _, j = problem.residuals_and_jacobian(y - shift)
        return j.reshape(-1, len(y))

    lower, upper = vector.low + shift, vector.high + shift
    width = upper - lower
    y0 = np.clip(x0 + shift, lower + 1e-6 * width, upper - 1e-6 * width)
    solution = least_squares(fun, y0, jac=jac, bounds=(lower, upper), method="trf", xtol=ls.xtol, ftol=ls.ftol,
                             gtol=ls.ftol, max_nfev=ls.max_iterations)
    best_x = np.asarray(solution.x, dtype=float) - shift
    r_best, _ = problem.residuals_and_jacobian(best_x)
    best_cost = cost_of_residuals(r_best)
    stages.append(("least squares", best_cost, problem.calls))
    if ls.polish_iterations > 0:
        calls_before = problem.calls

        def cost_and_gradient(x):
            r, j = problem.residuals_and_jacobian(x)
            value, gradient = cost_gradient(r, j)
            if progress is not None:
                progress(problem.calls, value)
            return value, gradient

        polished = minimize(cost_and_gradient, best_x, jac=True, method="L-BFGS-B",
                            bounds=list(zip(vector.low, vector.high)),
                            options={"maxiter": ls.polish_iterations, "maxfun": 2 * ls.polish_iterations})
        x_c = np.asarray(polished.x, dtype=float)
        r_c, _ = problem.residuals_and_jacobian(x_c)
        if cost_of_residuals(r_c) < best_cost:
            best_x, r_best, best_cost = x_c, r_c, cost_of_residuals(r_c)
        stages.append(("C (4.4)", best_cost, problem.calls - calls_before))
    try:
        params = vector.params_of(best_x)
    except ValueError as exc:
        raise ValueError(f"the lanes fit ended at non-physical model parameters: {exc}") from None
    return LanesFit(params, vector.effects_of(best_x), best_x, r_best, best_cost, problem.calls,
                    problem.lanes_simulated, stages, time.perf_counter() - started)


def fit_lanes_many(training_sets: list[Strides], settings, progress=None) -> list[LanesFit]:
    """One `fit_lanes` per training set, run side by side (threads) sharing their lanes calls (`Batcher`):
    the folds of a cross-validation cost about as many calls as one fit. `progress(k, calls, cost)` per fit."""
    batcher = Batcher(len(training_sets), settings.lanes.step, settings.lanes.batch_lanes)
    results: list = [None] * len(training_sets)

    def run(k):
        try:
            report = None if progress is None else (lambda calls, cost, k=k: progress(k, calls, cost))
            results[k] = fit_lanes(training_sets[k], settings, progress=report, batcher=batcher)
        except BaseException as exc:       # noqa: BLE001 - re-raised in the caller's thread
            results[k] = exc
        finally:
            batcher.leave()

    threads = [threading.Thread(target=run, args=(k,), name=f"lanes-fit-{k}", daemon=True)
               for k in range(len(training_sets))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for result in results:
        if isinstance(result, BaseException):
            raise result
    return results


def errors_many(fits: list[tuple[ModelParams, dict, Strides]], settings) -> list[StrideErrors]:
    """E_p, E_v, E_t of several (model, effects, strides) in ONE lanes call (the held-out folds of a CV)."""
    requests = [([with_effects(p, e)], s) for p, e, s in fits]
    duration = max(duration_for(s, settings.lanes.duration_factor) for _, _, s in fits)
    outcomes = simulate_batch(requests, settings.lanes.step, duration)
    return [errors_of(s, o[0], settings.failed_stride_error_pct) for (_, _, s), o in zip(fits, outcomes)]


def lanes_errors(params: ModelParams, magnitudes: dict, strides: Strides, settings) -> StrideErrors:
    """E_p, E_v, E_t of every stride under the laws with the effects (as `cost.errors_of`)."""
    predicted = lanes_outcomes(params, magnitudes, strides, settings.lanes.step, settings.lanes.duration_factor)
    return errors_of(strides, predicted, settings.failed_stride_error_pct)


def mean_magnitudes(per_fold: list[dict[str, float]]) -> dict[str, tuple[float, float]]:
    """{effect: (mean, std)} over folds of physical magnitudes, averaged in search units (1/value for a limit)."""
    out = {}
    if not per_fold:
        return out
    for name in per_fold[0]:
        effect = effect_library.get(name)
        search = np.array([effect.search_value(f[name]) for f in per_fold], dtype=float)
        mean = float(effect.physical(float(search.mean())))
        physical = np.array([f[name] for f in per_fold], dtype=float)
        std = float(physical.std(ddof=1)) if len(physical) > 1 and np.all(np.isfinite(physical)) else (
            0.0 if len(physical) == 1 else math.nan)
        out[name] = (mean, std)
    return out
