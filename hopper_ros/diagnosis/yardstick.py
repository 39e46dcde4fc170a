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
from dataclasses import dataclass

import numpy as np

from hopper_ros.identification.strides import APEX_FIT_FIELDS, ExtractionSettings

from .data import PHASES, StrideData
from .locate import Location, trajectory_location
from .records import Errors
from .simulate import CHANNELS, Variant, simulate_variants


def start_errors(data: StrideData) -> dict[str, tuple[np.ndarray, dict]]:
    """Per start value of a re-simulation: its standard error per stride and the `Strides` fields it moves by it
    (name -> (error, field -> moved values))."""
    s = data.strides
    out = {}
    if s.apex_errors is not None and len(s.apex_errors) == len(s):
        for k, name in enumerate(APEX_FIT_FIELDS):
            out[name] = (s.apex_errors[:, k], {name: getattr(s, name) + s.apex_errors[:, k]})
    # the held touchdown angle: the median of a still leg's samples, within one quantum of the truth
    q, sigma = data.quantum["theta"], data.sigma["theta"]
    extra = max(sigma * sigma - q * q / 12.0, 0.0)
    held = np.full(len(s), math.sqrt(q * q / 12.0 + extra / ExtractionSettings().touchdown_samples))
    out["touchdown_angle"] = (held, {"touchdown_angle": s.touchdown_angle + held})
    if not data.rec.commands:
        # a ramp (2.32) read from the logged torque is timed from the detected touchdown, the toe's height
        # crossing zero: late by delta, it is the same line with tau_0 (1 - delta/t_f) and t_f - delta
        rest, gravity = data.params.rest_length, data.params.gravity
        drop = np.maximum(s.apex_height - rest * np.cos(s.touchdown_angle), 1e-3)
        toe_noise = np.hypot(data.sigma["z"], rest * np.sin(s.touchdown_angle) * data.sigma["theta"])
        late = toe_noise / np.sqrt(2.0 * gravity * drop)
        timed = (s.tau_0 != 0) & (s.ramp_duration < ExtractionSettings().max_ramp_duration)
        late = np.where(timed, np.minimum(late, 0.5 * s.ramp_duration), 0.0)
        out["ramp_start"] = (late, {"tau_0": s.tau_0 * (1.0 - late / s.ramp_duration),
                                    "ramp_duration": s.ramp_duration - late})
    return out


@dataclass
class StartMove:
    """The re-simulations with one start value moved by its standard error: per stride the change of the
    residual series (channel -> samples) and of the predicted next apex (height, length, speed, time)."""

    name: str
    error: np.ndarray
    series: list
    pred: dict


def start_moves(data: StrideData, base: Variant, base_sim: dict) -> list[StartMove]:
    """Every start value of `start_errors` moved (`base_sim`: `simulate_variants(data, [base], keep_series=True)`)."""
    moves = []
    for name, (error, changes) in start_errors(data).items():
        moved = dataclasses.replace(data.strides, **changes)
        sim = simulate_variants(dataclasses.replace(data, strides=moved), [base], keep_series=True)
        series = [{ch: _finite(r1[ch][0] - r0[ch][0]) for ch in CHANNELS}
                  for r0, r1 in zip(base_sim["series"], sim["series"])]
        pred = {k: _finite(sim["pred"][k][0] - base_sim["pred"][k][0]) for k in base_sim["pred"]}
        moves.append(StartMove(name, error, series, pred))
    return moves


def _finite(x: np.ndarray) -> np.ndarray:
    return np.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0)


def trajectory_sd(data: StrideData, base_series: list[dict], moves: list[StartMove]) -> list[dict]:
    """Per stride and channel, the noise level of every sample of the re-simulation's residual against the
    recording: the sensor's and each moved start value's change, added in quadrature."""
    variance = [{ch: np.full(r[ch].shape[-1], data.sigma[ch] ** 2) for ch in CHANNELS} for r in base_series]
    for move in moves:
        for i, change in enumerate(move.series):
            for ch in CHANNELS:
                variance[i][ch] = variance[i][ch] + change[ch] ** 2
    return [{ch: np.sqrt(v[ch]) for ch in CHANNELS} for v in variance]


def noise_floor(data: StrideData, moves: list[StartMove], draws: int = 64, seed: int = 0) -> Errors:
    """The held-out next-apex errors E_p, E_v, E_t of a model without any mismatch on this recording: each
    prediction off by the moved start values' changes and each recorded next apex by its own fit's error (the
    stride's opening apex's taken for its closing one), drawn as normal errors and averaged over `draws`."""
    s = data.strides
    variance = {"height": 0.0, "length": 0.0, "speed": 0.0, "time": 0.0}
    for move in moves:
        for key in variance:
            variance[key] = variance[key] + move.pred[key] ** 2
    errors = {name: (s.apex_errors[:, k] if s.apex_errors is not None else np.zeros(len(s)))
              for k, name in enumerate(APEX_FIT_FIELDS)}
    variance["height"] = variance["height"] + errors["apex_height"] ** 2
    variance["length"] = variance["length"] + 2 * errors["apex_y"] ** 2
    variance["speed"] = variance["speed"] + errors["forward_speed"] ** 2
    variance["time"] = variance["time"] + 2 * errors["apex_time"] ** 2
    recorded = {"height": s.next_apex_height, "length": s.stride_length, "speed": s.next_forward_speed,
                "time": s.stride_time}
    rng = np.random.default_rng(seed)
    drawn = [Errors.of(data, {k: recorded[k] + rng.normal(0.0, 1.0, len(s)) * np.sqrt(variance[k])
                              for k in recorded}) for _ in range(draws)]
    return Errors(*(float(np.mean([getattr(e, k) for e in drawn])) for k in ("E_p", "E_v", "E_t")), 0)


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


def locate_by_trajectory(data: StrideData, base_series: list[dict], moves: list[StartMove], settings) -> Location | None:
    """Where the model's re-simulated strides first leave the recording by more than `settings`'
    trajectory_threshold noise levels (`locate.trajectory_location`), the noise levels these (`trajectory_sd`)."""
    by_phase, counts = trajectory_by_phase(data, base_series, trajectory_sd(data, base_series, moves))
    return trajectory_location(by_phase, counts, settings.locate_threshold, settings.trajectory_threshold, PHASES,
                               CHANNELS)
