"""Prediction error metrics (4.1)-(4.3) and the identification cost (4.4).

Positions and times of the next apex are measured from the stride's opening apex. The
thesis defines the apex time by y' = 0 below (4.3); z' = 0 is meant.
"""

from __future__ import annotations

import numpy as np


def position_error_pct(height, forward, predicted_height, predicted_forward):
    """E_p (4.1): 100 |[z, y] - [z_hat, y_hat]| / |[z, y]| at the next apex."""
    return 100.0 * np.hypot(np.subtract(height, predicted_height), np.subtract(forward, predicted_forward)) / np.hypot(height, forward)


def velocity_error_pct(speed, predicted_speed):
    """E_v (4.2): 100 |y' - y'_hat| / |y'| at the next apex."""
    return 100.0 * np.abs(np.subtract(speed, predicted_speed)) / np.abs(speed)


def time_error_pct(stride_time, predicted_stride_time):
    """E_t (4.3): 100 |t_a - t_a_hat| / |t_a|, apex-to-apex time."""
    return 100.0 * np.abs(np.subtract(stride_time, predicted_stride_time)) / np.abs(stride_time)


def identification_cost(position_errors, velocity_errors, time_errors) -> float:
    """C (4.4): the root of the summed squares of the three mean errors over N strides."""
    return float(np.sqrt(np.mean(position_errors) ** 2 + np.mean(velocity_errors) ** 2 + np.mean(time_errors) ** 2))
