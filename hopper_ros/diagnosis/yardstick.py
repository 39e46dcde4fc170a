"""The trajectory test's noise level: the sensors' and that of the re-simulations' start.

Every stride is re-simulated from its apex as the recording gives it (`identification.strides`: the vertex of a
quadratic fitted to z, the slope of one fitted to y, the held touchdown angle). Those estimates have errors of
their own, and a re-simulated path carries them on: 0.1 mm of apex height moves the leg angle in stance by
0.5 mrad, fifteen times the noise level of an angle quantised in steps of 2 pi / 52,000 rad. A recording of a
plant the model describes exactly then leaves the recording "by trajectory" although nothing is missing.

The expected square of a sample's residual is the channel's sensor variance plus, for each start value, the
square of the path's change when that value moves by its standard error (the fits' own, `Strides.apex_errors`;
the held angle's from its quantum and noise). The changes are re-simulations from the moved values (one lane per
value and stride), so the sensitivities are the model's own, touchdown timing included.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from hopper_ros.identification.strides import APEX_ERRORS, ExtractionSettings

from .data import PHASES, StrideData
from .locate import Location, trajectory_location
from .simulate import CHANNELS, Variant, simulate_variants


def start_errors(data: StrideData) -> dict[str, np.ndarray]:
    """Per stride, the standard error of each start value of a re-simulation (`Strides` field -> array)."""
    s = data.strides
    errors = {}
    if s.apex_errors is not None and len(s.apex_errors) == len(s):
        errors = {name: s.apex_errors[:, k] for k, name in enumerate(APEX_ERRORS)}
    # the held touchdown angle: the median of a still leg's samples, within one quantum of the truth
    q, sigma = data.quantum["theta"], data.sigma["theta"]
    extra = max(sigma * sigma - q * q / 12.0, 0.0)
    held = math.sqrt(q * q / 12.0 + extra / ExtractionSettings().touchdown_samples)
    errors["touchdown_angle"] = np.full(len(s), held)
    return errors


def trajectory_sd(data: StrideData, base: Variant, base_series: list[dict]) -> list[dict]:
    """Per stride and channel, the noise level of every sample of the re-simulation's residual against the
    recording (`base_series`: `simulate_variants(..., keep_series=True)["series"]` of `base`)."""
    variance = [{ch: np.full(r[ch].shape[-1], data.sigma[ch] ** 2) for ch in CHANNELS} for r in base_series]
    for name, error in start_errors(data).items():
        moved = dataclasses.replace(data.strides)
        setattr(moved, name, getattr(data.strides, name) + error)
        series = simulate_variants(dataclasses.replace(data, strides=moved), [base], keep_series=True)["series"]
        for i, (r0, r1) in enumerate(zip(base_series, series)):
            for ch in CHANNELS:
                change = np.nan_to_num(r1[ch][0] - r0[ch][0], nan=0.0, posinf=0.0, neginf=0.0)
                variance[i][ch] += change * change
    return [{ch: np.sqrt(v[ch]) for ch in CHANNELS} for v in variance]


def trajectory_by_phase(data: StrideData, base_series: list[dict], sd: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """(strides, phases, channels) sums of the squared residuals over their noise levels `sd`, and their sample
    counts (the leg angle in stance only, as the search scores it)."""
    s = data.strides
    by_phase = np.zeros((len(s), len(PHASES), len(CHANNELS)))
    counts = np.zeros_like(by_phase)
    for i in range(len(s)):
        ph = data.phase[int(s.start[i]):int(s.stop[i])]
        stance = (ph == 1) | (ph == 2)
        for ci, ch in enumerate(CHANNELS):
            r = base_series[i][ch][0] / sd[i][ch]
            use = np.isfinite(r) & (stance if ch == "theta" else True)
            for pi in range(len(PHASES)):
                mask = use & (ph == pi)
                by_phase[i, pi, ci] = float(np.sum(r[mask] ** 2))
                counts[i, pi, ci] = mask.sum()
    return by_phase, counts


def locate_by_trajectory(data: StrideData, base: Variant, base_series: list[dict], settings) -> Location | None:
    """Where the model's re-simulated strides first leave the recording by more than `settings`'
    trajectory_threshold noise levels (`locate.trajectory_location`), the noise levels these (`trajectory_sd`)."""
    by_phase, counts = trajectory_by_phase(data, base_series, trajectory_sd(data, base, base_series))
    return trajectory_location(by_phase, counts, settings.locate_threshold, settings.trajectory_threshold, PHASES,
                               CHANNELS)
