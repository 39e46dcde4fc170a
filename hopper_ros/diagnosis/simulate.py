"""Every recorded stride re-simulated under model variants, compared with the recording.

A variant is the model's coefficients (`physics.laws.Coefficients`, effects included) plus sensor
faults (delay, scale, offset per channel, a discovered ringing after lift-off: `ringing`). All (variant, stride) pairs run as lanes of one
vectorised integration (`physics.lanes`), from the recorded apex with the recorded inputs.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hopper_ros.physics import lanes, laws
from hopper_ros.physics.effects import SENSOR_OFF

from . import ringing
from .data import PHASES, StrideData

CHANNELS = ("y", "z", "theta")
BATCH_LANES = 4000      # lanes per integration call (memory: 5 x lanes x samples float32)


@dataclass
class Variant:
    coefficients: laws.Coefficients
    sensors: dict = field(default_factory=lambda: dict(SENSOR_OFF))

    def with_changes(self, coefficients: dict | None = None, sensors: dict | None = None) -> "Variant":
        c = self.coefficients.replace(**coefficients) if coefficients else self.coefficients
        return Variant(c, {**self.sensors, **(sensors or {})})


def simulate_variants(data: StrideData, variants: list[Variant], keep_series: bool = False) -> dict:
    """Per (variant, stride): normalised SSE (y, z all samples, theta in stance), per-phase sums and
    next-apex predictions; with `keep_series` the residual series and the raw lanes."""
    ns = len(data.strides)
    per_call = max(1, BATCH_LANES // ns)
    parts = [_simulate(data, variants[i:i + per_call], keep_series) for i in range(0, len(variants), per_call)]
    if len(parts) == 1:
        return parts[0]
    out = {"sse": np.vstack([p["sse"] for p in parts]), "by_phase": np.vstack([p["by_phase"] for p in parts]),
           "counts": parts[0]["counts"], "series": [], "raw": None,
           "pred": {k: np.vstack([p["pred"][k] for p in parts]) for k in parts[0]["pred"]}}
    return out


def _simulate(data: StrideData, variants: list[Variant], keep_series: bool) -> dict:
    s, rec = data.strides, data.rec
    ns, nv = len(s), len(variants)
    coef = lanes.stack([v.coefficients for v in variants], ns)
    sens = {k: np.repeat(np.array([v.sensors.get(k, SENSOR_OFF[k]) for v in variants]), ns) for k in SENSOR_OFF}
    rings = {ch: {ringing.key(ch, p): np.array([v.sensors.get(ringing.key(ch, p), 0.0) for v in variants])[:, None]
                  for p in ringing.KEYS} for ch in ringing.CHANNEL_SITE}
    z0 = (np.tile(s.apex_height, nv) - sens["z_offset"]) / sens["z_scale"]
    theta_td = (np.tile(s.touchdown_angle, nv) - sens["theta_offset"]) / sens["theta_scale"]
    res = lanes.simulate_lanes(coef, z0, np.tile(s.forward_speed, nv) / sens["y_scale"], theta_td,
                               np.tile(s.tau_0, nv), np.tile(s.ramp_duration, nv), duration=data.duration + 0.02)
    nsamp = res.y.shape[1]
    sse = np.zeros((nv, ns))
    by_phase = np.zeros((nv, ns, len(PHASES), 3))
    counts = np.zeros((ns, len(PHASES), 3))
    series = []
    for i in range(ns):
        a, b = int(s.start[i]), int(s.stop[i])
        tk = rec.t[a:b]
        ph = data.phase[a:b]
        meas = {"y": rec.y[a:b] - s.apex_y[i], "z": rec.z[a:b], "theta": rec.theta[a:b]}
        stance = (ph == 1) | (ph == 2)
        li = np.arange(nv) * ns + i
        resid = {}
        for ci, ch in enumerate(CHANNELS):
            # lane time: the recorded apex is the measured one; a delayed z puts the true apex earlier
            lane_t = (tk - s.apex_time[i])[None, :] + sens["z_delay"][li, None] - sens[f"{ch}_delay"][li, None]
            pos = np.clip(lane_t / 1e-3, 0, nsamp - 1.001)
            j0 = np.floor(pos).astype(int)
            w = pos - j0
            arr = getattr(res, ch)[li]
            val = np.take_along_axis(arr, j0, 1) * (1 - w) + np.take_along_axis(arr, j0 + 1, 1) * w
            if ch == "y":   # the measured apex y is where the lane starts; a delayed z moves that start
                # (a y channel later than z reads samples from before the lane's start: the apex speed carries on)
                speed = s.forward_speed[i] / sens["y_scale"][li, None]
                val = val + speed * np.minimum(lane_t, 0.0)
                val = val - (sens["z_delay"][li, None] - sens["y_delay"][li, None]) * s.forward_speed[i]
                val = val * sens["y_scale"][li, None]
            else:
                val = val * sens[f"{ch}_scale"][li, None] + sens[f"{ch}_offset"][li, None]
            if ch in rings:
                val = val + ringing.ringing(rings[ch], ch, ringing.since_liftoff(tk, data.liftoffs))
            r = (meas[ch][None, :] - val) / data.sigma[ch]
            r = np.where(np.isfinite(r), r, 1e3)
            if ch == "theta":
                r = np.where(stance[None, :], r, 0.0)
            resid[ch] = r
            sse[:, i] += np.sum(r * r, axis=1)
            for pi in range(len(PHASES)):
                msk = ph == pi
                by_phase[:, i, pi, ci] = np.sum(r[:, msk] ** 2, axis=1)
                counts[i, pi, ci] = msk.sum() if ch != "theta" else (msk & stance).sum()
        if keep_series:
            series.append({ch: resid[ch] * data.sigma[ch] for ch in resid})
    shape = (nv, ns)
    pred = {"height": res.next_apex_height.reshape(shape) * sens["z_scale"].reshape(shape) + sens["z_offset"].reshape(shape),
            "speed": res.next_forward_speed.reshape(shape) * sens["y_scale"].reshape(shape),
            "time": res.stride_time.reshape(shape),
            "length": res.stride_length.reshape(shape) * sens["y_scale"].reshape(shape)}
    return {"sse": sse, "by_phase": by_phase, "counts": counts, "pred": pred, "series": series,
            "raw": res if keep_series else None}
