"""What apex-to-apex strides can and cannot tell about the parameters.

Structure. In the model every force on the body is divided by m_b: stance (2.9) has k/m_b,
d/m_b and tau/m_b, flight (2.8) has g, d_h^f, d_v^f (per unit mass already), and the lift-off
collision (2.12) the ratio m_b/(m_b + m_t). Scaling (m_b, m_t, k, d) by a common factor
therefore changes nothing but the torque's effect: without hip torque the strides cannot
determine m_b at all, with torque only through tau/m_b. g and the leg's k/m_b, d/m_b are
fixed by the flight and stance times and the energy the stance loses. (`scale_invariance`
checks this on the predictors.)

Numbers. Around an estimate, the sensitivities J of the strides' signed relative errors
(next apex height and stride length over |[z, y]|, next speed, stride time: the terms of
E_p, E_v, E_t (4.1)-(4.3)) to ln(parameter) give, with the residual variance s^2, the
linearised covariance s^2 (J^T J)^-1 of ln(parameter): its diagonal is each parameter's
relative standard error, its off-diagonal the correlations; the smallest singular value of J
and its vector name the combination the data determine worst.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hopper_ros.physics.params import ModelParams

from .cost import predicted_outcomes
from .strides import Strides

WELL_DETERMINED_PCT = 5.0      # relative standard error below this: identifiable
POORLY_DETERMINED_PCT = 50.0   # above this: not identifiable from these strides


def signed_residuals(strides: Strides, predicted: dict[str, np.ndarray]) -> np.ndarray:
    """(N, 4) signed relative errors [%] behind E_p, E_v, E_t."""
    scale = np.hypot(strides.next_apex_height, strides.stride_length)
    return 100.0 * np.column_stack([
        (predicted["next_apex_height"] - strides.next_apex_height) / scale,
        (predicted["stride_length"] - strides.stride_length) / scale,
        (predicted["next_forward_speed"] - strides.next_forward_speed) / strides.next_forward_speed,
        (predicted["stride_time"] - strides.stride_time) / strides.stride_time])


@dataclass
class Identifiability:
    names: tuple[str, ...]
    relative_std_pct: np.ndarray       # per parameter
    correlation: np.ndarray            # (P, P)
    weakest_direction: np.ndarray      # unit vector in ln(parameter) space
    singular_values: np.ndarray
    residual_std_pct: float
    strides: int
    method: str

    def verdict(self, name: str) -> str:
        value = self.relative_std_pct[self.names.index(name)]
        if not np.isfinite(value) or value > POORLY_DETERMINED_PCT:
            return "not identifiable"
        if value > WELL_DETERMINED_PCT:
            return "weakly identifiable"
        return "identifiable"

    def strongest_correlation(self, name: str) -> tuple[str, float]:
        i = self.names.index(name)
        row = np.abs(self.correlation[i]).copy()
        row[i] = -1.0
        j = int(np.argmax(row))
        return self.names[j], float(self.correlation[i, j])

    def weakest_combination(self, threshold: float = 0.2) -> str:
        """The worst-determined direction in words, e.g. '+0.50 ln m_b +0.50 ln k ...'."""
        from .crossval import SYMBOLS

        terms = [(w, n) for w, n in zip(self.weakest_direction, self.names) if abs(w) >= threshold]
        return " ".join(f"{w:+.2f} ln {SYMBOLS[n]}" for w, n in terms)


def analyse(params: ModelParams, strides: Strides, names, method: str = "corrected",
            relative_step: float = 1e-4) -> Identifiability:
    """Linearised identifiability of `names` around `params` on `strides`."""
    names = tuple(names)
    base = signed_residuals(strides, predicted_outcomes(params, strides, method))
    usable = np.all(np.isfinite(base), axis=1)
    columns = []
    for name in names:
        value = getattr(params, name)
        plus = predicted_outcomes(params.replace(**{name: value * np.exp(relative_step)}), strides, method)
        minus = predicted_outcomes(params.replace(**{name: value * np.exp(-relative_step)}), strides, method)
        derivative = (signed_residuals(strides, plus) - signed_residuals(strides, minus)) / (2.0 * relative_step)
        usable &= np.all(np.isfinite(derivative), axis=1)
        columns.append(derivative)
    jacobian = np.stack([c[usable].ravel() for c in columns], axis=1)
    residuals = base[usable].ravel()
    dof = max(1, residuals.size - len(names))
    variance = float(residuals @ residuals) / dof
    _, singular, vt = np.linalg.svd(jacobian, full_matrices=False)
    # covariance from the eigen-decomposition: a direction the data do not constrain (eigenvalue
    # ~0) gets an enormous variance instead of being dropped as a pseudo-inverse would
    eigenvalues, vectors = np.linalg.eigh(jacobian.T @ jacobian)
    floor = max(float(eigenvalues.max()), 1e-300) * 1e-16
    covariance = variance * (vectors / np.maximum(eigenvalues, floor)) @ vectors.T
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = covariance / np.outer(std, std)
    direction = vt[-1] * np.sign(vt[-1][np.argmax(np.abs(vt[-1]))])
    return Identifiability(names, 100.0 * std, correlation, direction, singular, float(np.sqrt(variance)),
                           int(usable.sum()), method)


def scale_invariance(params: ModelParams, strides: Strides, factor: float = 1.5, method: str = "corrected"
                     ) -> tuple[float, float]:
    """Largest relative change of the predicted outcomes when (m_b, m_t, k, d) are all scaled by
    `factor`: (on the strides without torque, on the strides with torque)."""
    scaled = params.replace(body_mass=params.body_mass * factor, toe_mass=params.toe_mass * factor,
                            stiffness=params.stiffness * factor, damping=params.damping * factor)
    a, b = predicted_outcomes(params, strides, method), predicted_outcomes(scaled, strides, method)
    change = np.max(np.stack([np.abs(b[n] / a[n] - 1.0) for n in a]), axis=0)
    torque_free = np.abs(strides.tau_0) == 0.0
    without = float(np.nanmax(change[torque_free])) if torque_free.any() else float("nan")
    with_torque = float(np.nanmax(change[~torque_free])) if (~torque_free).any() else float("nan")
    return without, with_torque
