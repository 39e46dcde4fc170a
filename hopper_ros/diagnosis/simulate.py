"""Every recorded stride re-simulated under model variants, compared with the recording.

A variant is the model's coefficients (`physics.laws.Coefficients`, effects included) plus sensor
faults (delay, scale, offset per channel, a discovered ringing after lift-off: `ringing`). All (variant, stride) pairs run as lanes of one
vectorised integration (`physics.lanes`), from the recorded apex with the recorded inputs.

A search asks for the same variant more than once (a candidate at its "off" value is the model it
searches on; a fine grid shares its ends with the coarse one): each variant's per-stride SSE and
next apex are kept on the `StrideData` (`StrideData.simulated`) and simulated once. Where the lanes
run compiled, so does the SSE (`diagnosis.compiled`); the numpy reference here also gives the
per-phase sums and the residual series (`keep_series`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from hopper_ros.physics import lanes, laws
from hopper_ros.physics.effects import SENSOR_OFF

from . import ringing
from .data import PHASES, StrideData
from .sites import CHANNEL_SITE

CHANNELS = ("y", "z", "theta")
BATCH_LANES = 4000      # lanes per integration call (memory: 5 x lanes x samples float32)
KEPT_VARIANTS = 20000   # variants whose results a StrideData keeps (about 2 kB each for 50 strides)
FIELDS = laws.Coefficients.scalar_names() + laws.Coefficients.term_names()
BACKLASH = "theta_backlash"   # the sensors' key of the leg angle encoder's backlash [rad] (`backlash_reading`)
# the sensors' keys of an error of the forward position's reading periodic in the boom's angle (`periodic_y`) [m, m, m]
Y_PERIODIC = ("y_periodic_sin", "y_periodic_cos", "y_periodic_period")
SWING = "leg_swing"     # the sensors' key of the leg's swing reacting on the body in flight, mu r_c [m] (`swing`)
FALL_SAMPLES = 5        # the height samples before touchdown its fall's speed is taken over (`backlash_ramps`)
MIN_FALL = 0.05         # [m/s] ... at least this (a touchdown at the top of a hop's flight: no timing to move)


def periodic_y(y, a, b, period):
    """(error, its slope d error/dy) of a forward-position reading y_meas = y + a sin(2 pi y/P) + b cos(2 pi y/P)
    (an encoder's pulley or gear eccentric about its shaft, turning with the boom: periodic in the boom's angle)."""
    k = 2.0 * np.pi / period
    s, c = np.sin(k * y), np.cos(k * y)
    return a * s + b * c, k * (a * c - b * s)


def backlash_reading(theta: np.ndarray, start: np.ndarray, half: np.ndarray) -> np.ndarray:
    """What an encoder with play 2 `half` between it and the leg reads of the angles `theta` (lanes, samples):
    the reading stands still after each reversal until the leg has turned the whole play, then follows it
    `half` behind (the play operator, r = clamp(r_prev, theta - half, theta + half)), from the reading `start`."""
    out = np.empty_like(theta)
    r = np.asarray(start, dtype=theta.dtype).copy()
    h = np.asarray(half, dtype=theta.dtype)
    for j in range(theta.shape[1]):
        r = np.where(np.isfinite(theta[:, j]), np.clip(r, theta[:, j] - h, theta[:, j] + h), theta[:, j])
        out[:, j] = r
    return out


def backlash_ramps(data: StrideData, tau_0: np.ndarray, ramp_duration: np.ndarray, read: np.ndarray,
                   held: np.ndarray, play: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (2.32) ramps of lanes whose leg was held at `held` where the encoder read `read`, through a `play` (a
    backlash; other lanes unchanged). The stride extraction timed touchdown where z - rho_0 cos(theta) crossed zero
    with the reading, earlier than the held leg by the toe's height difference rho_0 (cos read - cos held) over the
    fall's speed, and read the ramp's line from there, or where the torque was still zero there, from between its
    last zero and first sample on (`strides.ramp_from_torque`). The drive started it where the held leg met the
    ground: the line is kept, started there (`data.earlier_ramps` by minus the difference; plant B's backlash of 9.3
    mrad: 0.17 ms, and a torque gain of 0.9955 was named beside it). Recordings that log the commands give the ramps
    as the drive ran them: unchanged."""
    if data.rec.commands:
        return tau_0, ramp_duration
    from hopper_ros.identification.strides import ExtractionSettings, torque_start

    from .data import earlier_ramps
    s, rec = data.strides, data.rec
    settings = ExtractionSettings()
    at = np.clip(np.searchsorted(rec.t, s.touchdown_time), FALL_SAMPLES + 1, len(rec.t) - 1)
    before = at - 1 - FALL_SAMPLES
    fall = (rec.z[at - 1] - rec.z[before]) / (rec.t[at - 1] - rec.t[before])     # [m/s], negative
    end = np.searchsorted(rec.t, s.touchdown_time + settings.late_torque, side="right") + 1
    # [s] where after the reading's touchdown the extraction started the ramp (none started: 0, no ramp to move)
    read_from = np.array([torque_start(rec.t[a:b] - touchdown, rec.tau[a:b], settings) or 0.0
                          for a, b, touchdown in zip(at, end, s.touchdown_time)])
    lanes = len(read) // len(s)
    delay = data.params.rest_length * (np.cos(read) - np.cos(held)) / np.tile(np.maximum(-fall, MIN_FALL), lanes)
    later = np.where(play > 0.0, delay - np.tile(read_from, lanes), 0.0)
    return earlier_ramps(tau_0, ramp_duration, -later)


def hold_direction(data: StrideData) -> np.ndarray:
    """Per stride, the way the leg last turned before it was held for touchdown (+1 where the angle rose, -1
    where it fell, 0 where it did not swing by 4 noise levels): the way an encoder with play lags the hold."""
    s, theta = data.strides, data.rec.theta
    swing = s.touchdown_angle - theta[np.asarray(s.start, dtype=int)]
    return np.where(np.abs(swing) > 4.0 * data.sigma["theta"], np.sign(swing), 0.0)


@dataclass
class Variant:
    coefficients: laws.Coefficients
    sensors: dict = field(default_factory=lambda: dict(SENSOR_OFF))
    per_stride: dict = field(default_factory=dict)   # scalar coefficient -> its value per stride (`perstride`)

    def with_changes(self, coefficients: dict | None = None, sensors: dict | None = None) -> "Variant":
        c = self.coefficients.replace(**coefficients) if coefficients else self.coefficients
        return Variant(c, {**self.sensors, **(sensors or {})}, dict(self.per_stride))

    def stride_coefficients(self, i: int) -> laws.Coefficients:
        """The coefficients of stride i (its per-stride values in place)."""
        if not self.per_stride:
            return self.coefficients
        return self.coefficients.replace(**{name: float(values[i]) for name, values in self.per_stride.items()})

    def lane_coefficients(self, strides: int) -> laws.Coefficients:
        """One lane per stride, each with its per-stride values."""
        coef = lanes.broadcast(self.coefficients, strides)
        for name, values in self.per_stride.items():
            getattr(coef, name)[:] = values
        return coef


def variant_key(variant: Variant) -> tuple:
    """What a variant's simulation depends on: every coefficient and sensor value."""
    c = variant.coefficients
    return (tuple(getattr(c, name) for name in FIELDS) + tuple(sorted(variant.sensors.items()))
            + tuple((name, np.asarray(values, float).tobytes()) for name, values in sorted(variant.per_stride.items())))


def simulate_variants(data: StrideData, variants: list[Variant], keep_series: bool = False) -> dict:
    """Per (variant, stride): normalised SSE (y, z all samples, theta in stance) and next-apex predictions
    ("sse", "pred"); with `keep_series` also the per-phase sums ("by_phase", "counts"), the residual series
    and the raw lanes, always simulated anew."""
    if keep_series:
        return _batched(data, variants, True)
    if not variants:
        return {"sse": np.zeros((0, len(data.strides))), "pred": {}}
    kept = data.simulated
    keys = [variant_key(v) for v in variants]
    new = {}
    for key, variant in zip(keys, variants):
        if key not in kept and key not in new:
            new[key] = variant
    if new:
        sim = _batched(data, list(new.values()), False)
        for row, key in enumerate(new):
            kept[key] = (sim["sse"][row], {k: v[row] for k, v in sim["pred"].items()})
        while len(kept) > KEPT_VARIANTS:
            del kept[next(iter(kept))]
    rows = [kept[key] for key in keys]
    return {"sse": np.array([r[0] for r in rows]), "pred": {k: np.array([r[1][k] for r in rows]) for k in rows[0][1]}}


def _batched(data: StrideData, variants: list[Variant], keep_series: bool) -> dict:
    ns = len(data.strides)
    per_call = max(1, BATCH_LANES // ns)
    parts = [_simulate(data, variants[i:i + per_call], keep_series) for i in range(0, len(variants), per_call)]
    if len(parts) == 1:
        return parts[0]
    out = {"sse": np.vstack([p["sse"] for p in parts]),
           "pred": {k: np.vstack([p["pred"][k] for p in parts]) for k in parts[0]["pred"]}}
    if keep_series:
        out.update({"by_phase": np.vstack([p["by_phase"] for p in parts]), "counts": parts[0]["counts"],
                    "series": [x for p in parts for x in p["series"]], "raw": None})
    return out


def _simulate(data: StrideData, variants: list[Variant], keep_series: bool) -> dict:
    s, rec = data.strides, data.rec
    ns, nv = len(s), len(variants)
    coef = lanes.stack([v.coefficients for v in variants], ns)
    for k, variant in enumerate(variants):
        for name, values in variant.per_stride.items():
            getattr(coef, name)[k * ns:(k + 1) * ns] = values
    sens = {k: np.repeat(np.array([v.sensors.get(k, SENSOR_OFF[k]) for v in variants]), ns) for k in SENSOR_OFF}
    rings = {ch: {ringing.key(ch, p): np.array([v.sensors.get(ringing.key(ch, p), 0.0) for v in variants])[:, None]
                  for p in ringing.KEYS} for ch in CHANNEL_SITE}
    z0 = (np.tile(s.apex_height, nv) - sens["z_offset"]) / sens["z_scale"]
    held = (np.tile(s.touchdown_angle, nv) - sens["theta_offset"]) / sens["theta_scale"]
    play = 0.5 * np.repeat(np.array([v.sensors.get(BACKLASH, 0.0) for v in variants]), ns)
    theta_td = held + play * np.tile(hold_direction(data), nv)     # the reading lags the swing into the hold
    duration = data.duration + 0.02
    needed = None if keep_series else _needed_samples(data, sens, nv, int(np.floor(duration / 1e-3)) + 1)
    periodic = np.array([[v.sensors.get(k, 0.0 if k != Y_PERIODIC[2] else 1.0) for k in Y_PERIODIC] for v in variants])
    wavy = bool(np.any(periodic[:, :2] != 0.0))
    speed_read = np.ones(nv * ns)
    speed0 = np.tile(s.forward_speed, nv)
    lift = np.repeat(np.array([v.sensors.get(SWING, 0.0) for v in variants]), ns)   # mu r_c [m] (`swing`)
    if np.any(lift != 0.0):     # the lanes are the centre of mass of body and swinging leg: started from it
        from .swing import geometry
        geo = {k: np.tile(v, (nv, 1)) if v.ndim == 2 else np.tile(v, nv)
               for k, v in geometry(data, int(np.floor(duration / 1e-3)) + 1).items()}
        z0 = z0 + lift * geo["dz"][:, 0]
        speed0 = speed0 + lift * geo["start_slope"]
    if wavy:        # the apex's place and speed as read: y_0 + e(y_0) and v_0 (1 + e'(y_0))
        a, b, period = (np.repeat(periodic[:, k], ns) for k in range(3))
        apex_read = np.tile(s.apex_y, nv)
        y0 = apex_read - periodic_y(apex_read, a, b, period)[0]
        e0, slope0 = periodic_y(y0, a, b, period)
        speed_read = 1.0 + slope0
    tau_0, ramp_duration = np.tile(s.tau_0, nv), np.tile(s.ramp_duration, nv)
    if np.any(play > 0.0):
        tau_0, ramp_duration = backlash_ramps(data, tau_0, ramp_duration, held, theta_td, play)
    if np.any(coef.foot_radius != 0.0):     # a round toe lands before the point toe the ramps were timed from
        from .foot import lane_ramps
        tau_0, ramp_duration = lane_ramps(data, coef, z0, theta_td, tau_0, ramp_duration)
    res = lanes.simulate_lanes(coef, z0, speed0 / sens["y_scale"] / speed_read, theta_td, tau_0, ramp_duration,
                               duration=duration, needed=needed)
    if np.any(lift != 0.0):     # ... and read back as the body's, its next apex as the apex fits read it
        m, dy = lift[:, None], geo["dy"]
        res = dataclasses.replace(res, y=(res.y - m * (dy - dy[:, :1])).astype(res.y.dtype),
                                  z=(res.z - m * geo["dz"]).astype(res.z.dtype),
                                  next_apex_height=res.next_apex_height - lift * geo["next_dz"],
                                  next_forward_speed=res.next_forward_speed - lift * geo["next_slope"],
                                  stride_length=res.stride_length - lift * (geo["next_dy"] - dy[:, 0]))
    if np.any(play > 0.0):
        res = dataclasses.replace(res, theta=backlash_reading(res.theta, held, play))
    length_read, next_speed_read = res.stride_length, 1.0
    if wavy:        # the lanes' forward position (from the apex) as read: y + e(y_0 + y) - e(y_0)
        lane_y = res.y.astype(float)
        error = periodic_y(y0[:, None] + lane_y, a[:, None], b[:, None], period[:, None])[0]
        res = dataclasses.replace(res, y=(lane_y + error - e0[:, None]).astype(res.y.dtype))
        e1, slope1 = periodic_y(y0 + res.stride_length, a, b, period)
        length_read, next_speed_read = res.stride_length + e1 - e0, 1.0 + slope1
    shape = (nv, ns)
    pred = {"height": res.next_apex_height.reshape(shape) * sens["z_scale"].reshape(shape) + sens["z_offset"].reshape(shape),
            "speed": (res.next_forward_speed * next_speed_read).reshape(shape) * sens["y_scale"].reshape(shape),
            "time": res.stride_time.reshape(shape),
            "length": length_read.reshape(shape) * sens["y_scale"].reshape(shape)}
    if not keep_series and lanes.compiled_backend() is not None:
        from .compiled import trajectory_sse
        return {"sse": trajectory_sse(res, data, sens, rings, nv), "pred": pred}
    return {**_residuals(data, res, sens, rings, nv, keep_series), "pred": pred}


def _needed_samples(data: StrideData, sens: dict, nv: int, samples: int) -> np.ndarray:
    """Per lane, the lane samples its recorded stride reads: up to the one after the last recorded sample's
    time on the lane's clock, the latest of its channels (their delays shift it)."""
    s, rec = data.strides, data.rec
    end = np.tile(rec.t[s.stop - 1] - s.apex_time, nv)
    earliest = np.minimum(np.minimum(sens["y_delay"], sens["z_delay"]), sens["theta_delay"])
    pos = np.clip((end + sens["z_delay"] - earliest) / 1e-3, 0, samples - 1.001)
    return np.floor(pos).astype(int) + 2


def _residuals(data: StrideData, res, sens: dict, rings: dict, nv: int, keep_series: bool) -> dict:
    """The reference: per (variant, stride) the normalised SSE, per phase and channel; the series."""
    s, rec = data.strides, data.rec
    ns = len(s)
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
    return {"sse": sse, "by_phase": by_phase, "counts": counts, "series": series, "raw": res if keep_series else None}
