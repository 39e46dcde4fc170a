"""The trajectory SSE of every (variant, stride) lane against the recording, compiled by numba.

`simulate._residuals` is the reference (numpy, every lane of a stride at once, with the per-phase sums
and the residual series); this computes only what a search reads, the normalised SSE per lane, in one
pass over each lane's recorded samples, with the same sensor model: the lane's clock shifted by the
channel's delay, the lane's samples interpolated linearly, the scale, offset and ringing applied, the
residual over the channel's noise level (1e3 where the model has no value), the angle in stance only.
Imported by `simulate` where `physics.lanes` runs compiled (the same cache folder).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from hopper_ros.physics import compiled as _physics_compiled   # noqa: F401  (the cache folder, numba's config)

SAMPLE = 1e-3        # [s] the lanes' output period
# rows of `sensors`: (delay, scale, offset) of y, z, theta
Y, Z, THETA = 0, 1, 2


@numba.njit(cache=True, error_model="numpy", parallel=True)
def _sse(y, z, theta, strides, t, measured, apex_time, apex_y, forward_speed, stance, since_liftoff, sigma, sensors,
         rings, variants, out):
    lanes_per_variant = apex_time.shape[0]
    samples = y.shape[1]
    for lane in numba.prange(variants * lanes_per_variant):
        v, i = lane // lanes_per_variant, lane % lanes_per_variant
        total = 0.0
        z_delay = sensors[Z, 0, lane]
        for ch in range(3):
            arr = y if ch == Y else z if ch == Z else theta
            delay, scale, offset = sensors[ch, 0, lane], sensors[ch, 1, lane], sensors[ch, 2, lane]
            sin_amp, cos_amp = (rings[ch, 0, v], rings[ch, 1, v]) if ch != THETA else (0.0, 0.0)
            ringing = sin_amp != 0.0 or cos_amp != 0.0
            w, decay = (2 * math.pi * rings[ch, 2, v], rings[ch, 3, v]) if ringing else (0.0, 0.0)
            for k in range(strides[0, i], strides[1, i]):
                if ch == THETA and not stance[k]:
                    continue
                lane_t = (t[k] - apex_time[i]) + z_delay - delay
                pos = min(max(lane_t / SAMPLE, 0.0), samples - 1.001)
                j0 = int(np.floor(pos))
                frac = pos - j0
                value = np.float64(arr[lane, j0]) * (1 - frac) + np.float64(arr[lane, j0 + 1]) * frac
                if ch == Y:
                    speed = forward_speed[i] / scale
                    value = value + speed * min(lane_t, 0.0)
                    value = value - (z_delay - delay) * forward_speed[i]
                    value = value * scale
                else:
                    value = value * scale + offset
                if ringing and since_liftoff[k] >= 0.0:
                    s = since_liftoff[k]
                    value = value + np.exp(-decay * s) * (sin_amp * np.sin(w * s) + cos_amp * np.cos(w * s))
                target = measured[ch, k] - apex_y[i] if ch == Y else measured[ch, k]
                r = (target - value) / sigma[ch]
                if not np.isfinite(r):
                    r = 1e3
                total += r * r
        out[v, i] = total


def trajectory_sse(res, data, sensors: dict, rings: dict, variants: int) -> np.ndarray:
    """(variants, strides) normalised trajectory SSE of the lanes `res` (`physics.lanes.LaneResult`) against
    `data`'s recording; `sensors` holds (lanes,) arrays per sensor key, `rings` per channel its ringing's
    (variants, 1) arrays per part (`simulate._simulate`)."""
    from . import ringing as ring_keys
    s, rec = data.strides, data.rec
    strides = np.ascontiguousarray(np.vstack([s.start, s.stop]).astype(np.int64))
    measured = np.ascontiguousarray(np.vstack([rec.y, rec.z, rec.theta]).astype(np.float64))
    stance = (data.phase == 1) | (data.phase == 2)
    since = ring_keys.since_liftoff(rec.t, data.liftoffs)
    sigma = np.array([data.sigma["y"], data.sigma["z"], data.sigma["theta"]], dtype=np.float64)
    lanes = len(res.y)
    table = np.empty((3, 3, lanes))
    for row, ch in enumerate(("y", "z", "theta")):
        table[row, 0] = sensors[f"{ch}_delay"]
        table[row, 1] = sensors[f"{ch}_scale"]
        table[row, 2] = sensors.get(f"{ch}_offset", 0.0)
    parts = np.zeros((3, 4, variants))
    for row, ch in enumerate(("y", "z")):
        if ch in rings:
            for p, part in enumerate(ring_keys.KEYS):
                parts[row, p] = np.ravel(rings[ch][ring_keys.key(ch, part)])
    out = np.empty((variants, len(s)))
    _sse(res.y, res.z, res.theta, strides, np.ascontiguousarray(rec.t, dtype=np.float64), measured,
         np.ascontiguousarray(s.apex_time, dtype=np.float64), np.ascontiguousarray(s.apex_y, dtype=np.float64),
         np.ascontiguousarray(s.forward_speed, dtype=np.float64), stance, since, sigma, table, parts, variants, out)
    return out
