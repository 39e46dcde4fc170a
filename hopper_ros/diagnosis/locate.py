"""Locate a mismatch by force, not by accumulated position.

For every stride the recorded positions are smoothed and differentiated (Savitzky-Golay, within
each phase, never across an event) and the model's accelerations are evaluated at the measured
state (`physics.laws`): what is left is the force the model lacks, in the phase's natural
directions: horizontal/vertical in flight, along the leg and about the hip in stance. At touchdown
and lift-off the velocity jump (polynomial fits on either side, extrapolated to the event) is
compared with the model's reset maps. The same is done on two twins of the recording made by the
model itself from the recorded apexes and inputs: a clean one (its residual is the smoothing's own
bias, subtracted) and one with the recording's noise and quantisation (what noise alone produces:
the yardstick). A site stands out when its residual, in bins over strides, is several times what
noise produces. Where a small effect's residual stays within the noise one stride at a time, the naming's
held-out re-simulations locate it (`fit_locations`: the sites of the changes that pass every guard).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hopper_ros.physics import lanes, laws

from .data import LEAD_RESOLVED, StrideData
from .foot import lane_ramps
from .ringing import ringing, since_liftoff
from .simulate import BACKLASH, SWING, Variant, hold_direction, variant_key
from .sites import CHANNEL_SITE, REGISTRY, RESIDUAL_SITES, TRAJECTORY_SITES
from .smoothing import smooth
from .swing import recoil

FLIGHT_WINDOW = 71     # samples of the Savitzky-Golay fit in flight
STANCE_WINDOW = 19     # ... in stance
EDGE = 3               # samples dropped next to an event
JUMP_SKIP = 2          # samples skipped next to an event for the velocity fits
JUMP_FLIGHT = 30       # samples of the flight side's quadratic fit
JUMP_STANCE = 14       # samples of the stance side's cubic fit
@dataclass
class StrideResiduals:
    """One stride's residuals per site: samples (values and their context) and per-bin means."""

    samples: dict = field(default_factory=dict)    # site -> (values, context dict of arrays, normalised time)
    bins: dict = field(default_factory=dict)       # site -> array of bin means (nan when missing)


def _crossings(t, g):
    """(touchdown, lift-off) times: the first down-crossing of g = z - rho_0 cos(theta), the next up-crossing."""
    below = g <= 0
    down = np.flatnonzero(~below[:-1] & below[1:])
    if down.size == 0:
        return None
    i = int(down[0])
    td = t[i] + (t[i + 1] - t[i]) * g[i] / (g[i] - g[i + 1])
    up = np.flatnonzero(below[i + 1:-1] & ~below[i + 2:]) + i + 1
    if up.size == 0:
        return None
    j = int(up[0])
    lo = t[j] + (t[j + 1] - t[j]) * g[j] / (g[j] - g[j + 1])
    return td, lo


def _velocity_at(t, x, t_event, degree):
    if len(t) < degree + 3:
        return np.nan
    poly = np.polyfit(t - t_event, x, degree)
    return poly[-2]


def stride_residuals(t, y, z, theta, theta_td, tau_0, t_f, c: laws.Coefficients) -> StrideResiduals | None:
    """Residual forces of one stride (t from its apex) under the model `c` (floats)."""
    period = float(np.median(np.diff(t)))
    events = _crossings(t, z - c.rest_length * np.cos(theta) - laws.foot_rise(c, theta))
    if events is None:
        return None
    td, lo = events
    out = StrideResiduals()
    m = float(c.mass)
    i_td = int(np.searchsorted(t, td))
    i_lo = int(np.searchsorted(t, lo))
    # ---- flight
    fh, fv, ctx_parts, u_parts, bins_h, bins_v = [], [], [], [], [], []
    for name, (a, b) in (("descent", (0, i_td)), ("ascent", (i_lo, len(t)))):
        sm_y, sm_z = smooth(y[a:b], FLIGHT_WINDOW, period), smooth(z[a:b], FLIGHT_WINDOW, period)
        if sm_y is None or sm_z is None or b - a <= 2 * EDGE + 5:
            bins_h.append(np.nan)
            bins_v.append(np.nan)
            continue
        keep = slice(EDGE, b - a - EDGE)
        yy, vy, ay = (v[keep] for v in sm_y)
        zz, vz, az = (v[keep] for v in sm_z)
        my, mz = laws.flight_acceleration(c, yy, zz, vy, vz)
        rh, rv = m * (ay - my), m * (az - mz)
        fh.append(rh)
        fv.append(rv)
        bins_h.append(float(np.mean(rh)))
        bins_v.append(float(np.mean(rv)))
        ctx_parts.append({"y": yy, "z": zz, "ydot": vy, "zdot": vz})
        tt = t[a:b][keep]
        u_parts.append((tt - tt[0]) / max(tt[-1] - tt[0], 1e-9) + (0 if name == "descent" else 2))
    if fh:
        ctx = {k: np.concatenate([p[k] for p in ctx_parts]) for k in ctx_parts[0]}
        u = np.concatenate(u_parts)
        out.samples["flight_horizontal"] = (np.concatenate(fh), ctx, u)
        out.samples["flight_vertical"] = (np.concatenate(fv), ctx, u)
    out.bins["flight_horizontal"] = np.array(bins_h)
    out.bins["flight_vertical"] = np.array(bins_v)
    # ---- stance
    a, b = i_td, i_lo
    toe_y = np.nan
    rolling = laws.is_on(c, "foot_radius")    # a round toe: its centre rolls back r_f per radian of the leg angle
    if b - a > 2 * EDGE + 9:
        if rolling:
            toe_y = float(np.median(_foot_centre(c, y[a:b], z[a:b], theta[a:b]) + c.foot_radius * theta[a:b]))
        else:
            toe_y = float(np.median(y[a:b] + z[a:b] * np.tan(theta[a:b])))
        sm_y, sm_z = smooth(y[a:b], STANCE_WINDOW, period), smooth(z[a:b], STANCE_WINDOW, period)
        if sm_y is not None and sm_z is not None:
            keep = slice(EDGE, b - a - EDGE)
            yy, vy, ay = (v[keep] for v in sm_y)
            zz, vz, az = (v[keep] for v in sm_z)
            tt = t[a:b][keep]
            since = tt - td
            toe = toe_y - c.foot_radius * theta[a:b][keep] if rolling else toe_y
            command = laws.ramp_torque(since - float(c.torque_delay), tau_0, t_f)
            applied = laws.actuator_torque(c, command)
            f = laws.stance_forces(c, yy, zz, vy, vz, 0.0, toe, applied, command=command, theta_td=theta_td,
                                   since_touchdown=since, hysteresis=_hysteresis(c, yy - toe, zz),
                                   relaxation=_relaxation(c, yy - toe, zz, tt))
            ry, rz = m * (ay - f.ydd), m * (az - f.zdd)
            ry = ry * (1.0 + float(c.horizontal_mass_ratio))
            along = -f.sin * ry + f.cos * rz
            across = -f.cos * ry - f.sin * rz
            hip = across * f.rho
            if rolling:     # the hip turns about the contact point (`laws.stance_forces`)
                dy, hz = laws.foot_offset(c, yy, zz, 0.0, toe)
                th = np.arctan2(-dy, hz)
                thd = (-vy * f.cos - vz * f.sin) / (f.rho - c.foot_radius + c.foot_radius * f.cos)
            else:
                th = np.arctan2(-(yy - toe_y), zz)
                thd = (-vy * zz + (yy - toe_y) * vz) / (f.rho * f.rho)
            ctx = {"rho": f.rho, "rho_dot": f.rho_dot if rolling else -f.sin * vy + f.cos * vz, "theta": th,
                   "theta_dot": thd,
                   "theta_td": np.full_like(th, theta_td), "since_touchdown": since, "torque": applied,
                   "command": command, "rest_length": float(c.rest_length)}
            u = (tt - td) / max(lo - td, 1e-9) + 1.0
            out.samples["stance_along"] = (along, ctx, u)
            out.samples["stance_hip"] = (hip, ctx, u)
            thirds = np.array_split(np.arange(len(along)), 3)
            out.bins["stance_along"] = np.array([np.mean(along[k]) if len(k) else np.nan for k in thirds])
            out.bins["stance_hip"] = np.array([np.mean(hip[k]) if len(k) else np.nan for k in thirds])
    for site in ("stance_along", "stance_hip"):
        out.bins.setdefault(site, np.full(3, np.nan))
    # ---- events: velocity jumps
    for event, t_ev, before, after in (("touchdown", td, (JUMP_FLIGHT, 2), (JUMP_STANCE, 3)),
                                       ("liftoff", lo, (JUMP_STANCE, 3), (JUMP_FLIGHT, 2))):
        pre = (t >= t_ev - (before[0] + JUMP_SKIP) * period) & (t <= t_ev - JUMP_SKIP * period)
        post = (t >= t_ev + JUMP_SKIP * period) & (t <= t_ev + (after[0] + JUMP_SKIP) * period)
        if event == "touchdown":
            post &= t < lo
        else:
            pre &= t > td
        if pre.sum() < before[0] * 0.7 or post.sum() < after[0] * 0.7:
            out.bins[f"{event}_along"] = out.bins[f"{event}_across"] = np.array([np.nan])
            continue
        v_pre = np.array([_velocity_at(t[pre], x[pre], t_ev, before[1]) for x in (y, z)])
        v_post = np.array([_velocity_at(t[post], x[post], t_ev, after[1]) for x in (y, z)])
        if event == "touchdown":
            ang = theta_td
            model = np.array(laws.touchdown_velocity(c, ang, v_pre[0], v_pre[1]), dtype=float)
        else:
            if rolling and np.isfinite(toe_y):
                last = theta[pre][-1]
                dy, hz = laws.foot_offset(c, y[pre][-1], z[pre][-1], 0.0, toe_y - c.foot_radius * last)
                ang = float(np.arctan2(-dy, hz))
            else:
                ang = float(np.arctan2(-(y[pre][-1] - toe_y), z[pre][-1])) if np.isfinite(toe_y) else theta_td
            model = np.array(laws.liftoff_velocity(c, ang, v_pre[0], v_pre[1]), dtype=float)
        d = v_post - model
        s_, c_ = np.sin(ang), np.cos(ang)
        along, across = -s_ * d[0] + c_ * d[1], -c_ * d[0] - s_ * d[1]
        pa, pc = -s_ * v_pre[0] + c_ * v_pre[1], -c_ * v_pre[0] - s_ * v_pre[1]
        ctx = {"along": np.array([pa]), "across": np.array([pc])}
        out.samples[f"{event}_along"] = (np.array([along]), ctx, np.array([0.0]))
        out.samples[f"{event}_across"] = (np.array([across]), ctx, np.array([0.0]))
        out.bins[f"{event}_along"] = np.array([along])
        out.bins[f"{event}_across"] = np.array([across])
    return out


def twins(data: StrideData, variant: Variant, seed: int = 0):
    """The model's own versions of the recorded strides: (clean, noisy) lists of (t, y, z, theta) per stride,
    t from the apex, with the recording's sensor noise and quantisation on the noisy one."""
    s, sensors = data.strides, variant.sensors
    coefficients, held = variant.lane_coefficients(len(s)), _held_angles(data, sensors)
    apex = (s.apex_height - sensors["z_offset"]) / sensors["z_scale"]
    tau_0, ramp_duration = lane_ramps(data, coefficients, apex, held, s.tau_0, s.ramp_duration)
    res = lanes.simulate_lanes(coefficients, apex, s.forward_speed / sensors["y_scale"], held, tau_0, ramp_duration,
                               duration=data.duration + 0.02)
    rng = np.random.default_rng(seed)
    clean, noisy = [], []
    for i in range(len(s)):
        end = res.stride_time[i]
        if not np.isfinite(end):
            clean.append(None)
            noisy.append(None)
            continue
        n = int(np.floor(end / 1e-3)) + 1
        t = np.arange(n) * 1e-3
        chans = [res.y[i, :n].astype(float), res.z[i, :n].astype(float), res.theta[i, :n].astype(float)]
        clean_ch, noisy_ch = [], []
        for name, x in zip(("y", "z", "theta"), chans):
            q = data.quantum[name]
            extra = max(data.sigma[name] ** 2 - q * q / 12.0, 0.0) ** 0.5
            xn = x + rng.normal(0.0, extra, size=x.shape)
            if q > 0:
                clean_ch.append(np.round(x / q) * q)
                noisy_ch.append(np.round(xn / q) * q)
            else:
                clean_ch.append(x)
                noisy_ch.append(xn)
        clean.append((t, *clean_ch))
        noisy.append((t, *noisy_ch))
    return clean, noisy


def _held_angles(data: StrideData, sensors: dict) -> np.ndarray:
    return (data.strides.touchdown_angle - sensors["theta_offset"]) / sensors["theta_scale"]


def _recorded(data: StrideData, sensors: dict):
    """The recorded strides with the variant's sensor faults undone (offset, scale, delay per channel, a
    ringing after lift-off)."""
    s, rec = data.strides, data.rec
    channels = []
    for name in ("y", "z", "theta"):
        x = (getattr(rec, name) - sensors.get(f"{name}_offset", 0.0)) / sensors[f"{name}_scale"]
        delay = sensors[f"{name}_delay"]
        channels.append(np.interp(rec.t + delay, rec.t, x) if delay else x)
    out = []
    for i in range(len(s)):
        a, b = int(s.start[i]), int(s.stop[i])
        parts = [x[a:b] - ringing(sensors, name, since_liftoff(rec.t[a:b], data.liftoffs)) if name in CHANNEL_SITE
                 else x[a:b]
                 for name, x in zip(("y", "z", "theta"), channels)]
        if sensors.get(SWING, 0.0):     # in flight, the centre of mass of body and swinging leg (`swing`), the
            # same as the body's at touchdown and lift-off, so that no phase's smoothing sees a step
            t, theta = rec.t[a:b], parts[2]
            dy, dz = recoil(t, theta, s.touchdown_time[i], s.liftoff_time[i], s.touchdown_angle[i],
                            np.interp(s.liftoff_time[i], t, theta))
            parts[0], parts[1] = parts[0] + sensors[SWING] * dy, parts[1] + sensors[SWING] * dz
        out.append((rec.t[a:b] - s.apex_time[i], *parts))
    return out


def residual_sets(data: StrideData, variant: Variant):
    """Residuals of the recording and of its clean and noisy twins under `variant` (lists per stride)."""
    s = data.strides
    held = _held_angles(data, variant.sensors)
    clean, noisy = twins(data, variant)
    result = []
    for series in (_recorded(data, variant.sensors), clean, noisy):
        rows = []
        for i, item in enumerate(series):
            if item is None:
                rows.append(None)
                continue
            t, y, z, th = item
            rows.append(stride_residuals(t, y, z, th, float(held[i]), float(s.tau_0[i]),
                                         float(s.ramp_duration[i]), variant.stride_coefficients(i)))
        result.append(rows)
    return result


@dataclass
class Location:
    site: str
    ratio: float          # residual over what noise alone produces (1 = nothing)
    window: str           # the bin where the residual is largest
    size: float           # its mean over strides, bias corrected, in `unit`
    unit: str
    strides: int
    basis: str = "force"  # force: residual forces and jumps against noise; fit: a change there, fitted and held out;
    #                       trajectory: where the re-simulated strides first leave the recording
    t: float = 0.0        # (fit) one-sided t over strides of the held-out residual's fall

    @property
    def phase(self) -> str:
        return REGISTRY[self.site].phase

    @property
    def direction(self) -> str:
        return REGISTRY[self.site].direction

    def words(self) -> str:
        if self.basis == "trajectory":
            return (f"{self.phase}, {self.direction} (by trajectory: {self.window} leaves the recording, "
                    f"{self.size:.0f} x the noise level)")
        if self.basis == "fit":
            return (f"{self.phase}, {self.direction} (by fit: {self.window} removes {self.size:.0f} % of the "
                    f"held-out residual, t {self.t:.1f})")
        return (f"{self.phase}, {self.direction}, {self.window}: {self.size:+.3g} {self.unit} "
                f"({self.ratio:.1f} x the noise level)")


def fit_locations(results: list, sites, threshold: float, min_t: float) -> list[Location]:
    """Locate by fit: per site, the best change acting there among `results` (the accepted changes of the model,
    each fitted on training strides and judged on held-out ones against the model without it: `records.Scored`). Re-simulations
    say where a correction of the model removes the residual when the force residuals, one stride at a time,
    are too weak to stand above the noise (a 6 % touchdown loss across the leg, a dry friction). `sites` maps a
    candidate to its located sites; the ratio is t scaled so that t = `min_t` is `threshold`."""
    best = {}
    for r in results:
        for site in sites(r.candidate):
            if site not in best or r.t > best[site].t:
                best[site] = r
    return [Location(site, r.t * threshold / min_t, r.name, 100.0 * r.reduction, "%", len(r.held_sse), basis="fit",
                     t=r.t) for site, r in best.items()]


CHANNEL_WORDS = {"y": "the forward position", "z": "the height", "theta": "the leg angle"}


def trajectory_location(by_phase: np.ndarray, counts: np.ndarray, threshold: float, scale: float,
                        phases, channels) -> Location | None:
    """Locate by trajectory: the first phase of the stride where a re-simulated channel misses the recording
    by `scale` noise levels RMS or more (per phase and channel over strides, `by_phase` (strides, phases,
    channels) of normalised squared residuals, `counts` their samples). Errors made early carry into every
    later phase, so the first one is where the model leaves the robot. Used where no force residual stands
    above the noise one stride at a time (a toe that slips under large hip torques). The ratio is the RMS
    scaled so that `scale` is `threshold`."""
    rms = np.sqrt(by_phase.sum(axis=0) / np.maximum(counts.sum(axis=0), 1))
    for i, phase in enumerate(phases):
        pairs = [(rms[i, j], ch) for j, ch in enumerate(channels) if (phase, ch) in TRAJECTORY_SITES]
        size, channel = max(pairs, default=(0.0, ""))
        if size >= scale:
            return Location(TRAJECTORY_SITES[(phase, channel)], threshold * size / scale,
                            f"{CHANNEL_WORDS[channel]} in {phase}", float(size), "x noise (RMS)",
                            int(by_phase.shape[0]), basis="trajectory")
    return None


def locate(data: StrideData, variant: Variant) -> tuple[list[Location], tuple]:
    """Every site with its residual over the noise level, largest first; and the residual sets for discovery.
    Found once per variant of a recording (`StrideData.located`: the twins' noise has a fixed seed)."""
    key = variant_key(variant)
    if key not in data.located:
        data.located[key] = _locate(data, variant)
    return data.located[key]


def _locate(data: StrideData, variant: Variant) -> tuple[list[Location], tuple]:
    rec, clean, noisy = sets = residual_sets(data, variant)
    found = []
    for site in RESIDUAL_SITES:
        R, B, N = [], [], []
        for r, c0, n1 in zip(rec, clean, noisy):
            if r is None or c0 is None or n1 is None:
                continue
            R.append(r.bins.get(site))
            B.append(c0.bins.get(site))
            N.append(n1.bins.get(site))
        if not R:
            continue
        R, B, N = np.array(R, float), np.array(B, float), np.array(N, float)
        ok = np.isfinite(R) & np.isfinite(B) & np.isfinite(N)
        if ok.sum() < 5:
            continue
        signal = np.where(ok, R - B, np.nan)
        null = np.where(ok, N - B, np.nan)
        noise_rms = float(np.sqrt(np.nanmean(null ** 2)))
        rms = float(np.sqrt(np.nanmean(signal ** 2)))
        means = np.nanmean(signal, axis=0)
        counts = ok.sum(axis=0)
        null_sd = np.nanstd(null, axis=0) / np.sqrt(np.maximum(counts, 1))
        # size over noise: the RMS ratio, or the bias of the best bin in units of its standard error
        k = int(np.nanargmax(np.abs(means) / np.maximum(null_sd, 1e-12)))
        t_bias = float(abs(means[k]) / max(null_sd[k], 1e-12)) / 3.0
        ratio = max(rms / max(noise_rms, 1e-12), t_bias)
        bins = REGISTRY[site].bins
        found.append(Location(site, ratio, bins[k] if k < len(bins) else "", float(means[k]), REGISTRY[site].unit,
                              int(ok.any(axis=1).sum())))
    timing = timing_location(data, variant)
    if timing is not None:
        found.append(timing)
    found.sort(key=lambda loc: -loc.ratio)
    return found, sets


def _foot_centre(c, y, z, theta):
    """A round toe's centre's forward position (`laws.stance_forces`) from the recorded hip and leg angle in stance:
    r_f above the ground, the hip (rho - r_f) e_rho from it."""
    return y + (z - c.ground_height - c.foot_radius) * np.tan(theta)


def _hysteresis(c, dy: np.ndarray, hz: np.ndarray):
    """The leg's hysteresis state (`laws.hysteresis_rate`) along a stance's recorded compression, from 0 at its first
    sample (0 where the law is off)."""
    if not laws.is_on(c, "leg_hysteresis"):
        return 0.0
    x = float(c.rest_length) - np.sqrt(dy * dy + hz * hz)
    q = np.zeros_like(x)
    for k in range(1, len(x)):      # rate-independent: the rate of a compression step is the state's step
        q[k] = float(np.clip(q[k - 1] + laws.hysteresis_rate(c, q[k - 1], x[k] - x[k - 1]), -1.0, 1.0))
    return q


def _relaxation(c, dy: np.ndarray, hz: np.ndarray, t: np.ndarray):
    """The leg's relaxing force (`laws.relaxation_rate`) along a stance's recorded compression, from 0 at its first
    sample (0 where the law is off): RK2 steps between samples, the compression's rate constant over each."""
    if not laws.is_on(c, "leg_relaxing_stiffness"):
        return 0.0
    x = float(c.rest_length) - np.sqrt(dy * dy + hz * hz)
    force = np.zeros_like(x)
    for k in range(1, len(x)):
        dt = max(float(t[k] - t[k - 1]), 1e-9)
        rate = (x[k] - x[k - 1]) / dt
        half = force[k - 1] + 0.5 * dt * laws.relaxation_rate(c, force[k - 1], x[k - 1], rate)
        force[k] = force[k - 1] + dt * laws.relaxation_rate(c, half, 0.5 * (x[k - 1] + x[k]), rate)
    return force


def timing_location(data: StrideData, variant: Variant) -> Location | None:
    """Touchdown in time: stance begins (the held leg starts to turn, `data.held_touchdown_angles`) away from
    where the variant's leg at rest length meets its ground in the recorded height and angle (its sensor
    faults undone); size over noise as the median's t / 3."""
    rec, sensors = data.rec, variant.sensors
    height = (rec.z - sensors["z_offset"]) / sensors["z_scale"]
    play, swing = sensors.get(BACKLASH, 0.0), hold_direction(data)
    leads = []
    for i, (td, start, angle) in enumerate(zip(data.strides.touchdown_time, data.stance_start,
                                               data.strides.touchdown_angle)):
        c = variant.stride_coefficients(i)
        a = int(np.searchsorted(rec.t, td))
        k = np.arange(max(a - 40, 1), min(a + 10, len(rec.t)))
        held = (angle - sensors["theta_offset"]) / sensors["theta_scale"] + 0.5 * play * swing[i]
        if play > 0.0:      # through a backlash the reading starts to turn once the leg has turned the play
            b = int(np.searchsorted(rec.t, start))
            speed = abs(rec.theta[min(b + 5, len(rec.t) - 1)] - rec.theta[b]) / 0.005
            start = start - play / max(speed, play / 0.02)
        toe = height[k] - float(c.rest_length) * math.cos(held) - float(c.ground_height) - laws.foot_rise(c, held)
        below = np.flatnonzero((toe[1:] <= 0.0) & (toe[:-1] > 0.0))
        if below.size:
            j = below[0]
            touchdown = rec.t[k[j]] + (rec.t[k[j + 1]] - rec.t[k[j]]) * toe[j] / (toe[j] - toe[j + 1])
            leads.append(touchdown - sensors["z_delay"] - (start - sensors["theta_delay"]))
    leads = np.array(leads)
    if leads.size < 5:
        return None
    median = float(np.median(leads))
    spread = 1.4826 * float(np.median(np.abs(leads - median))) / math.sqrt(leads.size)
    ratio = abs(median) / max(spread, 1e-5) / 3.0 if abs(median) > LEAD_RESOLVED else 0.0
    window = "stance begins early" if median > 0 else "stance begins late"
    return Location("touchdown_timing", ratio, window, median * 1e3, "ms", int(leads.size))
