"""Plant B controller: a one-step model-predictive apex controller.

At each apex the controller picks (theta_td, tau_0) so that the NOMINAL
extended TD-SLIP model (plant.Plant without effects, looser tolerances)
lands on a next-apex target that moves part of the way from the current
apex (z, y') toward a randomly wandering set-point.  A few bounded Gauss-Newton steps with a
finite-difference Jacobian (scipy least_squares, bounded, with a weak
pull of tau_0 toward 5 N m).  The ramp duration t_f is a random fraction
(0.85-1.0) of the predicted stance time.  Random excitation is added to the
result, so strides cover theta_td ~0.2-0.55 rad and tau_0 ~2-8 N m.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from .plant import Control, Fall, Plant, Params

TH_LIM = (0.18, 0.57)
TAU_LIM = (1.8, 8.3)
Z_RANGE = (0.28, 0.40)
V_RANGE = (1.0, 2.3)


class ApexController:
    def __init__(self, rng: np.random.Generator, params: Params | None = None):
        self.rng = rng
        self.model = Plant(params, effects=(), rtol=1e-8, atol=1e-10)
        self.u = np.array([0.33, 4.5])
        self.ts = 0.066
        self.new_targets()

    def new_targets(self):
        self.z_t = self.rng.uniform(*Z_RANGE)
        self.v_t = self.rng.uniform(*V_RANGE)

    def _predict(self, apex, th_prev, u, frac, update=False):
        c = Control(float(u[0]), float(u[1]), frac * self.ts)
        r = self.model.stride(0.0, apex, th_prev, c)
        if update:
            self.ts = r["stance_time"]
        return np.array([r["apex"][1], r["apex"][2]])

    def command(self, apex, th_prev):
        rng = self.rng
        if rng.random() < 0.25:
            self.new_targets()
        alpha = 0.5
        goal = np.array([apex[1] + alpha * (self.z_t - apex[1]),
                         apex[2] + alpha * (self.v_t - apex[2])])
        frac = rng.uniform(0.85, 1.0)
        lo = np.array([TH_LIM[0], TAU_LIM[0]])
        hi = np.array([TH_LIM[1], TAU_LIM[1]])
        u0 = np.clip(self.u, lo + 1e-6, hi - 1e-6)
        scale = np.array([0.012, 0.03])

        # excitation: on some strides tau_0 is drawn at random and only
        # theta_td is optimised (speed first, height weakly)
        free_tau = rng.random() < 0.35
        if free_tau:
            u0[1] = rng.uniform(2.0, 8.0)
            scale = np.array([0.05, 0.03])

        def resid(x):
            u = np.array([x[0], u0[1]]) if free_tau else x
            try:
                f = self._predict(apex, th_prev, u, frac)
            except Fall:
                return np.array([50.0, 50.0, 0.0])
            return np.concatenate([(f - goal) / scale, [(u[1] - 5.0) * 0.05]])
        try:
            self._predict(apex, th_prev, u0, frac, update=True)
            if free_tau:
                sol = least_squares(resid, u0[:1], bounds=(lo[:1], hi[:1]),
                                    x_scale=[0.05], diff_step=[3e-3],
                                    max_nfev=10, xtol=1e-4, ftol=1e-4)
                u = np.array([sol.x[0], u0[1]])
            else:
                sol = least_squares(resid, u0, bounds=(lo, hi),
                                    x_scale=[0.05, 1.0], diff_step=[3e-3, 3e-3],
                                    max_nfev=12, xtol=1e-4, ftol=1e-4)
                u = sol.x
            self._predict(apex, th_prev, u, frac, update=True)  # for t_f
        except (Fall, np.linalg.LinAlgError, ValueError):
            u = u0
        self.u = u
        th = float(np.clip(u[0] + rng.normal(0, 0.02), *TH_LIM))
        tau = float(np.clip(u[1] + rng.normal(0, 0.45), *TAU_LIM))
        return Control(th, tau, frac * self.ts)
