"""Ground reaction forces over the stance (section 4.4, Figs 4.8 and 4.9).

Two measurements of the same force:
- from the kinematics: F = m_b (a + g e_z), the body's acceleration a from the 1 kHz
  positions by the constant-acceleration Kalman model of appendix A, run forward and then
  backward (Rauch-Tung-Striebel smoother: offline, so no lag);
- from the force plate: the plate's samples, smoothed by a moving average as the thesis did.

"Virtual footfalls" (after [63] in the thesis): every instantaneous GRF vector drawn through
the body's centre of mass and extended to the ground, at y_vf = y - z F_y / F_z. A force
along the leg (no hip torque) passes through the toe, so all its footfalls fall on the toe;
a hip torque adds (tau / rho) across the leg and moves them off the toe. `footfall_offsets`
measures where they fall relative to the toe early, in the middle and late in the stance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hopper_ros.recording.recordings import Recording
from .strides import Strides

SIGMA_JERK = 60.0         # [m/s^3] white-jerk intensity of the constant-acceleration model (appendix A's
                          # sigma_w; its real-time filter uses 500, offline smoothing can afford less: on the
                          # simulated robot 60 gives 3-5 N rms against the plate, 500 about 25 N)
MOVING_AVERAGE = 5        # [samples] force plate smoothing
POSITION_NOISE = 1.3e-4   # [m] position measurement noise: one 0.22 mm count as a uniform error, doubled


def kalman_smooth(t: np.ndarray, x: np.ndarray, sigma_measurement: float, sigma_jerk: float = SIGMA_JERK):
    """Position, velocity and acceleration of x(t) by the constant-acceleration model of
    appendix A (white jerk of intensity sigma_jerk^2), filtered forward and RTS-smoothed back."""
    n = len(t)
    dt = float(np.median(np.diff(t)))
    f = np.array([[1.0, dt, dt * dt / 2.0], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    q = sigma_jerk ** 2 * np.array([[dt ** 5 / 20, dt ** 4 / 8, dt ** 3 / 6],
                                    [dt ** 4 / 8, dt ** 3 / 3, dt ** 2 / 2],
                                    [dt ** 3 / 6, dt ** 2 / 2, dt]])
    r = sigma_measurement ** 2
    xs_prior = np.empty((n, 3))
    ps_prior = np.empty((n, 3, 3))
    xs = np.empty((n, 3))
    ps = np.empty((n, 3, 3))
    state = np.array([x[0], (x[1] - x[0]) / dt if n > 1 else 0.0, 0.0])
    cov = np.diag([r, 1.0, 1e4])
    for k in range(n):
        if k > 0:
            state = f @ state
            cov = f @ cov @ f.T + q
        xs_prior[k], ps_prior[k] = state, cov
        gain = cov[:, 0] / (cov[0, 0] + r)
        state = state + gain * (x[k] - state[0])
        cov = cov - np.outer(gain, cov[0, :])
        xs[k], ps[k] = state, cov
    for k in range(n - 2, -1, -1):
        c = ps[k] @ f.T @ np.linalg.inv(ps_prior[k + 1])
        xs[k] = xs[k] + c @ (xs[k + 1] - xs_prior[k + 1])
        ps[k] = ps[k] + c @ (ps[k + 1] - ps_prior[k + 1]) @ c.T
    return xs[:, 0], xs[:, 1], xs[:, 2]


def moving_average(values: np.ndarray, width: int = MOVING_AVERAGE) -> np.ndarray:
    if width <= 1:
        return values.copy()
    kernel = np.ones(width) / width
    padded = np.pad(values, (width // 2, width - 1 - width // 2), mode="edge")
    return np.convolve(padded, kernel, mode="valid")


@dataclass
class StanceForces:
    """GRF over one stance: samples from touchdown to lift-off (ground frame, N)."""

    label: str
    t: np.ndarray                    # [s] from touchdown
    y: np.ndarray                    # body position (smoothed) [m]
    z: np.ndarray
    toe_y: float                     # toe position [m] (from the touchdown: y + rho_0 sin theta_td)
    kinematic: np.ndarray            # (n, 2) m_b (a + g e_z)
    plate: np.ndarray | None         # (n, 2) force plate, smoothed; None without a plate
    tau_0: float
    touchdown_angle: float

    def footfalls(self, source: str = "plate") -> np.ndarray:
        """Virtual footfalls y - z F_y / F_z of each sample (NaN where F_z is small)."""
        force = self.plate if source == "plate" else self.kinematic
        with np.errstate(divide="ignore", invalid="ignore"):
            out = self.y - self.z * force[:, 0] / force[:, 1]
        return np.where(force[:, 1] > 0.1 * np.max(force[:, 1]), out, np.nan)

    def footfall_offsets(self, source: str = "plate") -> tuple[float, float, float]:
        """Mean footfall minus toe [m] over the first, middle and last fifth of the stance
        (negative: behind the toe)."""
        offsets = self.footfalls(source) - self.toe_y
        n = len(offsets)
        parts = (slice(0, max(1, n // 5)), slice(2 * n // 5, max(2 * n // 5 + 1, 3 * n // 5)), slice(n - max(1, n // 5), n))
        return tuple(float(np.nanmean(offsets[p])) for p in parts)

    def direction_difference_deg(self) -> float:
        """Median angle between the kinematic and the plate force vectors [deg]."""
        if self.plate is None:
            return math.nan
        a = np.arctan2(self.kinematic[:, 0], self.kinematic[:, 1])
        b = np.arctan2(self.plate[:, 0], self.plate[:, 1])
        strong = self.plate[:, 1] > 0.1 * np.max(self.plate[:, 1])
        return float(np.degrees(np.median(np.abs(a - b)[strong])))


def stance_forces(recording: Recording, strides: Strides, index: int, body_mass: float, gravity: float,
                  rest_length: float, label: str = "", position_noise: float = POSITION_NOISE,
                  sigma_jerk: float = SIGMA_JERK, average: int = MOVING_AVERAGE) -> StanceForces:
    """The GRF of stride `index`'s stance from the kinematics and (if recorded) the force plate.

    `position_noise` [m] and `sigma_jerk` [m/s^3] tune the smoother, `average` [samples] the
    force plate's moving average.
    """
    start, stop = int(strides.start[index]), int(strides.stop[index])
    t, y, z = recording.t[start:stop], recording.y[start:stop], recording.z[start:stop]
    ys, _, ay = kalman_smooth(t, y, position_noise, sigma_jerk)
    zs, _, az = kalman_smooth(t, z, position_noise, sigma_jerk)
    td, lo = strides.touchdown_time[index], strides.liftoff_time[index]
    inside = (t >= td) & (t <= lo)
    kinematic = body_mass * np.column_stack([ay[inside], az[inside] + gravity])
    plate = None
    if recording.force is not None:
        ft = recording.force["t"]
        forward = moving_average(recording.force["forward"], average)
        vertical = moving_average(recording.force["vertical"], average)
        plate = np.column_stack([np.interp(t[inside], ft, forward), np.interp(t[inside], ft, vertical)])
    theta_td = float(strides.touchdown_angle[index])
    touchdown_y = float(np.interp(td, t, ys))
    toe_y = touchdown_y + rest_length * math.sin(theta_td)
    return StanceForces(label, t[inside] - td, ys[inside], zs[inside], toe_y, kinematic, plate,
                        float(strides.tau_0[index]), theta_td)


PROFILES = ("none", "ramp", "constant")
PROFILE_TITLES = {"none": "no torque (lossy SLIP, Fig 4.8a)", "ramp": "ramp torque (2.32) (TD-SLIP, Fig 4.8b)",
                  "constant": "constant torque (Fig 4.9)"}
