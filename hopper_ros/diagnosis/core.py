"""The mismatch tool: locate (per phase/variable residuals), name (candidate effects, fitted
magnitude, cross-validated ranking with an information criterion), model (refit, before/after).

Plain Python (numpy/scipy); the recording is read by hopper_ros.identification.recordings and
cut into strides by hopper_ros.identification.strides (phases detected when not labelled).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar

from hopper_ros.config import load_yaml
from hopper_ros.identification.recordings import Recording, RecordingError
from hopper_ros.identification.strides import extract_strides
from hopper_ros.physics.exact import Phase
from hopper_ros.physics.metrics import position_error_pct, time_error_pct, velocity_error_pct
from hopper_ros.physics.params import ModelParams

from .engine import LANE_PARAMS, simulate_lanes

PHASES = ("descent", "compression", "decompression", "liftoff", "ascent")
VARIABLES = ("y", "z", "ydot", "zdot", "theta")


class DiagnosisError(ValueError):
    """A recording the tool cannot diagnose (the message says why)."""


@dataclass
class Candidate:
    name: str
    kind: str            # "physics" or "sensor"
    param: str           # lane parameter or sensor key
    low: float
    high: float
    unit: str
    words: str           # what it means
    to_magnitude: str = "identity"   # "inverse" for 1/x parameterisations

    def magnitude(self, value: float) -> float:
        if self.to_magnitude == "inverse":
            return math.inf if value <= 0 else 1.0 / value
        return value


@dataclass
class Settings:
    folds: int = 5
    grid: int = 9
    min_strides: int = 6
    max_effects: int = 2
    min_reduction: float = 0.15      # held-out SSE must fall by at least this share
    min_t: float = 3.0               # one-sided t of the per-stride held-out log-ratio
    ground_damping: float = 250.0
    friction_speed: float = 0.005
    liftoff_window: float = 0.003
    candidates: list = field(default_factory=list)


def load_settings(path="diagnosis.yaml") -> Settings:
    data = load_yaml(path)["diagnosis"]
    cands = [Candidate(**c) for c in data.pop("candidates")]
    return Settings(**data, candidates=cands)


# ---------------------------------------------------------------------------- data


def check_recording(rec: Recording) -> None:
    period = rec.period
    if not 0.99e-3 <= period <= 1.01e-3:
        raise DiagnosisError(f"{rec.source}: the samples are {period * 1e3:.3f} ms apart; the tool needs a 1 kHz "
                             "time base (resample the recording first)")
    steps = np.diff(rec.t)
    bad = np.flatnonzero((steps > 1.5e-3) & (steps < 3 * period))
    if bad.size > 0.01 * len(steps):
        raise DiagnosisError(f"{rec.source}: irregular time base ({bad.size} steps between 1.5 and 3 ms)")


def noise_level(x: np.ndarray, mask: np.ndarray) -> float:
    """Sensor noise std from the third differences over flight samples (robust, MAD)."""
    d3 = x[3:] - 3 * x[2:-1] + 3 * x[1:-2] - x[:-3]
    ok = mask[3:] & mask[:-3]
    d3 = d3[ok]
    if d3.size < 20:
        return float("nan")
    q = np.diff(np.unique(np.round(x, 12)))
    floor = float(np.median(q[q > 0]) / math.sqrt(12)) if np.any(q > 0) else 1e-7
    return max(1.4826 * float(np.median(np.abs(d3 - np.median(d3)))) / math.sqrt(20.0), floor, 1e-7)


@dataclass
class StrideData:
    rec: Recording
    strides: object
    params: ModelParams
    sigma: dict
    phase: np.ndarray        # per sample: index into PHASES, -1 outside strides
    duration: float
    sample_count: int = 0
    corr_length: float = 1.0


def prepare(rec: Recording, params: ModelParams, settings: Settings) -> StrideData:
    check_recording(rec)
    strides = extract_strides(rec, params.rest_length)
    if len(strides) < settings.min_strides:
        raise DiagnosisError(f"{rec.source}: only {len(strides)} complete apex-to-apex strides found "
                             f"(at least {settings.min_strides} needed; rejected: {strides.rejected[:3]})")
    labels = strides.phase
    phase = np.full(len(rec), -1)
    phase[labels == Phase.DESCENT] = 0
    phase[labels == Phase.COMPRESSION] = 1
    phase[labels == Phase.DECOMPRESSION] = 2
    phase[labels == Phase.ASCENT] = 4
    inside = np.zeros(len(rec), bool)
    for a, b in zip(strides.start, strides.stop):
        inside[a:b] = True
    for lo in strides.liftoff_time:
        phase[np.abs(rec.t - lo) <= settings.liftoff_window] = 3
    phase[~inside] = -1
    flight = (labels == Phase.DESCENT) | (labels == Phase.ASCENT)
    sigma = {v: noise_level(getattr(rec, v), flight) for v in ("y", "z", "theta")}
    stance = (labels == Phase.COMPRESSION) | (labels == Phase.DECOMPRESSION)
    if not np.isfinite(sigma["theta"]):
        sigma["theta"] = noise_level(rec.theta, stance)
    for v in sigma:
        if not np.isfinite(sigma[v]):
            sigma[v] = 1e-4
    duration = float(np.max(rec.t[strides.stop - 1] - strides.apex_time)) + 0.01
    return StrideData(rec, strides, params, sigma, phase, duration)


# ---------------------------------------------------------------------------- simulation


def base_params(params: ModelParams, settings: Settings) -> dict:
    return {"g": params.gravity, "dh": params.flight_damping_horizontal, "dv": params.flight_damping_vertical,
            "collision": params.body_mass / (params.body_mass + params.toe_mass), "friction": 0.0,
            "friction_speed": settings.friction_speed, "compliance": 0.0, "ground_damping": settings.ground_damping,
            "impact": 0.0, "inv_max_torque": 0.0, "delay": 0.0}


def _apply(variant: dict, cand: Candidate, value: float, params: ModelParams) -> None:
    if cand.kind == "sensor":
        variant.setdefault("_sensor", {})[cand.param] = value
    elif cand.param == "toe_mass":
        variant["collision"] = params.body_mass / (params.body_mass + value)
    else:
        variant[cand.param] = value


def simulate_variants(data: StrideData, variants: list[dict], keep_series: bool = False):
    """Every stride under every variant. Returns per (variant, stride): SSE (normalised), per-phase
    and per-variable sums, next-apex predictions; optionally the residual series."""
    s, rec, params = data.strides, data.rec, data.params
    ns, nv = len(s), len(variants)
    lanes = {k: np.empty(nv * ns) for k in LANE_PARAMS}
    z0 = np.empty(nv * ns)
    yd0 = np.tile(s.forward_speed, nv)
    shift = {c: np.zeros(nv * ns) for c in ("y", "z", "theta")}
    scale = {c: np.ones(nv * ns) for c in ("y", "z", "theta")}
    for i, var in enumerate(variants):
        sl = slice(i * ns, (i + 1) * ns)
        for kname in LANE_PARAMS:
            lanes[kname][sl] = var[kname]
        sensor = var.get("_sensor", {})
        for c in ("y", "z", "theta"):
            shift[c][sl] = sensor.get(f"{c}_delay", 0.0)
            scale[c][sl] = sensor.get(f"{c}_scale", 1.0)
        z0[sl] = s.apex_height / scale["z"][sl]
    res = simulate_lanes(z0, yd0 / scale["y"], np.tile(s.touchdown_angle, nv) / scale["theta"],
                         np.tile(s.tau_0, nv), np.tile(s.ramp_duration, nv), lanes, mass=params.body_mass,
                         stiffness=params.stiffness, damping=params.damping, rest_length=params.rest_length,
                         duration=data.duration + 0.02)
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
        lane_idx = np.arange(nv) * ns + i
        resid = {}
        for ci, c in enumerate(("y", "z", "theta")):
            # lane time: the recorded apex is the measured one; a delayed channel z puts the true apex earlier
            tau = (tk - s.apex_time[i])[None, :] + shift["z"][lane_idx, None] - shift[c][lane_idx, None]
            pos = np.clip(tau / 1e-3, 0, nsamp - 1.001)
            j0 = np.floor(pos).astype(int)
            w = pos - j0
            arr = getattr(res, c)[lane_idx]
            val = np.take_along_axis(arr, j0, 1) * (1 - w) + np.take_along_axis(arr, j0 + 1, 1) * w
            if c == "y":   # the measured apex y is where the sim starts; a delayed z moves that start
                val = val - (shift["z"][lane_idx, None] - shift["y"][lane_idx, None]) * s.forward_speed[i]
            val = val * scale[c][lane_idx, None]
            r = (meas[c][None, :] - val) / data.sigma[c]
            r = np.where(np.isfinite(r), r, 1e3)
            if c == "theta":
                r = np.where(stance[None, :], r, 0.0)
            resid[c] = r
            sse[:, i] += np.sum(r * r, axis=1)
            for pi in range(len(PHASES)):
                msk = ph == pi
                by_phase[:, i, pi, ci] = np.sum(r[:, msk] ** 2, axis=1)
                counts[i, pi, ci] = msk.sum() if c != "theta" else (msk & stance).sum()
        if keep_series:
            series.append({c: resid[c] * data.sigma[c] for c in resid})
    pred = {"height": res.next_apex_height.reshape(nv, ns) * scale["z"].reshape(nv, ns),
            "speed": res.next_forward_speed.reshape(nv, ns) * scale["y"].reshape(nv, ns),
            "time": res.stride_time.reshape(nv, ns),
            "length": res.stride_length.reshape(nv, ns) * scale["y"].reshape(nv, ns)}
    return {"sse": sse, "by_phase": by_phase, "counts": counts, "pred": pred, "series": series, "raw": res}


# ---------------------------------------------------------------------------- ranking


def _folds(n: int, k: int) -> np.ndarray:
    return np.arange(n) % max(2, min(k, n))


def rank_candidates(data: StrideData, current: dict, candidates: list[Candidate], settings: Settings, base_sse,
                    grids: dict | None = None):
    """Grid each candidate's magnitude on top of `current`, fit it per fold on the training strides,
    score on the held-out ones. Returns a list of result dicts, best first."""
    variants, index = [], []
    grids = grids or {c.name: np.linspace(c.low, c.high, settings.grid) for c in candidates}
    for c in candidates:
        for v in grids[c.name]:
            var = dict(current)
            var["_sensor"] = dict(current.get("_sensor", {}))
            _apply(var, c, float(v), data.params)
            variants.append(var)
            index.append(c.name)
    sim = simulate_variants(data, variants)
    sse_all = sim["sse"]
    n = sse_all.shape[1]
    fold = _folds(n, settings.folds)
    results = []
    row = 0
    for c in candidates:
        grid = grids[c.name]
        sse = sse_all[row:row + len(grid)]
        row += len(grid)
        logs = np.log(np.maximum(sse, 1e-12))
        spline_i = CubicSpline(grid, logs, axis=0)
        held = np.empty(n)
        mags = []
        for f in np.unique(fold):
            train = fold != f
            tot = CubicSpline(grid, np.log(sse[:, train].sum(axis=1)))
            best = int(np.argmin(tot(grid)))
            lo, hi = grid[max(0, best - 1)], grid[min(len(grid) - 1, best + 1)]
            m = minimize_scalar(tot, bounds=(lo, hi), method="bounded").x if hi > lo else grid[best]
            mags.append(m)
            held[~train] = np.exp(spline_i(m)[~train])
        tot = CubicSpline(grid, np.log(sse.sum(axis=1)))
        best = int(np.argmin(tot(grid)))
        lo, hi = grid[max(0, best - 1)], grid[min(len(grid) - 1, best + 1)]
        m_all = float(minimize_scalar(tot, bounds=(lo, hi), method="bounded").x) if hi > lo else float(grid[best])
        d = np.log(base_sse / held)
        t_stat = float(d.mean() / (d.std(ddof=1) / math.sqrt(n))) if d.std(ddof=1) > 0 else 0.0
        reduction = 1.0 - held.sum() / base_sse.sum()
        n_samples = data.sample_count
        n_eff = n_samples / data.corr_length
        llr = 0.5 * n_eff * math.log(base_sse.sum() / held.sum())
        delta_bic = -2 * llr + math.log(n_eff)
        results.append({"name": c.name, "candidate": c, "value": m_all, "fold_values": mags,
                        "magnitude": c.magnitude(m_all), "reduction": float(reduction), "t": t_stat,
                        "cv_llr": float(llr), "delta_bic": float(delta_bic), "held_sse": held,
                        "significant": bool(reduction >= settings.min_reduction and t_stat >= settings.min_t
                                            and delta_bic < 0), "grid": grid})
    results.sort(key=lambda r: r["delta_bic"])
    return results, fold


def correlation_length(resid: np.ndarray) -> float:
    r = resid - resid.mean()
    if r.size < 10 or np.dot(r, r) == 0:
        return 1.0
    ac = np.correlate(r, r, "full")[r.size - 1:] / np.dot(r, r)
    neg = np.flatnonzero(ac <= 0)
    cut = int(neg[0]) if neg.size else min(len(ac), 200)
    return float(max(1.0, 1.0 + 2.0 * ac[1:cut].sum()))


# ---------------------------------------------------------------------------- the pipeline


def _errors(data: StrideData, pred: dict) -> dict:
    s = data.strides
    ep = position_error_pct(s.next_apex_height, s.stride_length, pred["height"], pred["length"])
    ev = velocity_error_pct(s.next_forward_speed, pred["speed"])
    et = time_error_pct(s.stride_time, pred["time"])
    return {"E_p": float(np.nanmean(ep)), "E_v": float(np.nanmean(ev)), "E_t": float(np.nanmean(et))}


def _rms_table(sim: dict, row: int, data: StrideData) -> dict:
    bp = sim["by_phase"][row].sum(axis=0)          # phases x vars
    cnt = sim["counts"].sum(axis=0)
    out = {}
    for pi, ph in enumerate(PHASES):
        out[ph] = {v: (float(math.sqrt(bp[pi, ci] / cnt[pi, ci])) if cnt[pi, ci] else float("nan"))
                   for ci, v in enumerate(("y", "z", "theta"))}
    return out


def _held_out_variants(base: dict, chosen: list, fold_values: list, data: StrideData, fold: np.ndarray):
    """Per-stride model: the chosen effects at the magnitudes fitted without the stride's fold."""
    folds = np.unique(fold)
    variants = []
    for fi, _ in enumerate(folds):
        var = dict(base)
        var["_sensor"] = dict(base.get("_sensor", {}))
        for c, vals in zip(chosen, fold_values):
            _apply(var, c, float(vals[fi]), data.params)
        variants.append(var)
    sim = simulate_variants(data, variants)
    n = len(fold)
    pick = {k: np.array([sim["pred"][k][list(folds).index(fold[i]), i] for i in range(n)]) for k in sim["pred"]}
    return pick


def diagnose(rec: Recording, params: ModelParams, settings: Settings) -> dict:
    data = prepare(rec, params, settings)
    base = base_params(params, settings)
    base_sim = simulate_variants(data, [base], keep_series=True)
    base_sse = base_sim["sse"][0]
    allres = np.concatenate([r["z"][0] / data.sigma["z"] for r in base_sim["series"]])
    data.sample_count = int(sum(int(b - a) for a, b in zip(data.strides.start, data.strides.stop)))
    # correlation length of the normalised residual under pure noise: measured on flight residual diffs
    data.corr_length = float(np.median([correlation_length(r["z"][0]) for r in base_sim["series"]]))
    data.corr_length = max(data.corr_length, 1.0)
    chosen, chosen_res, current = [], [], dict(base)
    current["_sensor"] = {}
    current_sse = base_sse
    rounds = []
    remaining = list(settings.candidates)
    for _ in range(settings.max_effects):
        ranking, fold = rank_candidates(data, current, remaining, settings, current_sse)
        top = ranking[0]
        if top["significant"]:  # refine its magnitude on a fine grid around the coarse fit
            step = top["grid"][1] - top["grid"][0]
            fine = np.linspace(max(top["candidate"].low, top["value"] - step), min(top["candidate"].high,
                                                                                  top["value"] + step), settings.grid)
            refined, fold = rank_candidates(data, current, [top["candidate"]], settings, current_sse,
                                            grids={top["name"]: fine})
            refined[0]["significant"] = refined[0]["significant"] or top["significant"]
            ranking[0] = top = refined[0]
        rounds.append(ranking)
        if not top["significant"]:
            break
        chosen.append(top["candidate"])
        chosen_res.append(top)
        _apply(current, top["candidate"], top["value"], params)
        current_sse = top["held_sse"]
        remaining = [c for c in remaining if c.name != top["name"]]
    final_sim = simulate_variants(data, [base, current], keep_series=True)
    fold = _folds(len(data.strides), settings.folds)
    before = _errors(data, {k: v[0] for k, v in final_sim["pred"].items()})
    if chosen:
        after = _errors(data, _held_out_variants(base, chosen, [r["fold_values"] for r in chosen_res], data, fold))
    else:
        after = before
    # SINDy-like fall-back on the residual accelerations in stance (what remains after the chosen effects)
    sparse = sparse_terms(data, final_sim, 1 if chosen else 0)
    locate = locate_mismatch(data, base_sim)
    return {"data": data, "rounds": rounds, "chosen": chosen_res, "before_phase": _rms_table(final_sim, 0, data),
            "after_phase": _rms_table(final_sim, 1, data), "before": before, "after": after,
            "base_series": base_sim["series"], "after_series": final_sim["series"], "locate": locate,
            "sparse": sparse, "verdict": _verdict(chosen_res), "final_sim": final_sim}


def _verdict(chosen) -> str:
    if not chosen:
        return "no significant mismatch"
    parts = []
    for r in chosen:
        c = r["candidate"]
        parts.append(f"{c.name} = {r['magnitude']:.4g} {c.unit}")
    return "missing: " + ", ".join(parts)


def locate_mismatch(data: StrideData, base_sim: dict) -> dict:
    """Where the baseline residual lives: per phase and variable, RMS against the noise, the worst window."""
    s, rec = data.strides, data.rec
    from scipy.signal import savgol_filter
    table = {}
    acc = {ph: {v: [] for v in VARIABLES} for ph in PHASES}
    raw = base_sim["raw"]
    worst = (0.0, None)
    for i, series in enumerate(base_sim["series"]):
        a, b = int(s.start[i]), int(s.stop[i])
        ph = data.phase[a:b]
        tk = rec.t[a:b] - s.apex_time[i]
        j = np.clip(np.round(tk / 1e-3).astype(int), 0, raw.y.shape[1] - 1)
        vel = {}
        for v, src, sim_arr in (("ydot", rec.y, raw.ydot), ("zdot", rec.z, raw.zdot)):
            if b - a > 15:
                d = savgol_filter(src[a:b], 11, 2, deriv=1, delta=1e-3)
                vel[v] = d - sim_arr[i, j]
        for pi, name in enumerate(PHASES):
            msk = ph == pi
            for v in ("y", "z", "theta"):
                acc[name][v].append(series[v][0][msk])
            for v in vel:
                acc[name][v].append(vel[v][msk])
        zr = np.abs(series["z"][0]) / data.sigma["z"] + np.abs(series["y"][0]) / data.sigma["y"]
        k = int(np.argmax(zr))
        if zr[k] > worst[0]:
            worst = (float(zr[k]), (i, float(tk[k]), PHASES[ph[k]] if ph[k] >= 0 else "?"))
    for name in PHASES:
        table[name] = {}
        for v in VARIABLES:
            x = np.concatenate(acc[name][v]) if acc[name][v] else np.empty(0)
            x = x[np.isfinite(x)]
            table[name][v] = float(np.sqrt(np.mean(x * x))) if x.size else float("nan")
    ratio = {(ph, v): table[ph][v] / data.sigma[v] for ph in PHASES for v in ("y", "z", "theta")
             if np.isfinite(table[ph][v]) and not (v == "theta" and ph in ("descent", "liftoff", "ascent"))}
    where = max(ratio, key=ratio.get)
    # time window: where |z residual| exceeds 3 sigma, median first/last times from apex
    first = []
    for series in base_sim["series"]:
        big = np.flatnonzero(np.abs(series[where[1]][0]) > 3 * data.sigma[where[1]])
        if big.size:
            first.append(big[0] * 1e-3)
    return {"table": table, "sigma": data.sigma, "where": where, "ratio": ratio[where],
            "onset": float(np.median(first)) if first else float("nan"), "worst": worst}


def sparse_terms(data: StrideData, sim: dict, row: int, threshold: float = 0.1) -> list[str]:
    """Sequentially thresholded least squares of the stance residual acceleration along the leg on a
    small library (1, rho', sign(rho'), rho - rho_0, t); returned in physical words when a term stands out."""
    s, rec, raw = data.strides, data.rec, sim["raw"]
    from scipy.signal import savgol_filter
    rows, target = [], []
    ns = len(s)
    for i in range(ns):
        a, b = int(s.start[i]), int(s.stop[i])
        ph = data.phase[a:b]
        st = (ph == 1) | (ph == 2)
        if st.sum() < 25:
            continue
        tk = rec.t[a:b] - s.apex_time[i]
        j = np.clip(np.round(tk / 1e-3).astype(int), 0, raw.y.shape[1] - 2)
        lane = row * ns + i
        ry = rec.y[a:b] - s.apex_y[i] - raw.y[lane, j]
        rz = rec.z[a:b] - raw.z[lane, j]
        ay = savgol_filter(ry, 21, 3, deriv=2, delta=1e-3)[st]
        az = savgol_filter(rz, 21, 3, deriv=2, delta=1e-3)[st]
        th = raw.theta[lane, j][st]
        along = -np.sin(th) * ay + np.cos(th) * az
        vz = savgol_filter(rec.z[a:b], 21, 3, deriv=1, delta=1e-3)[st]
        vy = savgol_filter(rec.y[a:b], 21, 3, deriv=1, delta=1e-3)[st]
        rhod = -np.sin(th) * vy + np.cos(th) * vz
        rows.append(np.column_stack([np.ones_like(rhod), rhod, np.sign(rhod), tk[st] - tk[st][0]]))
        target.append(along)
    if not rows:
        return []
    X, yv = np.vstack(rows), np.concatenate(target)
    names = ["constant force", "force proportional to rho' (extra leg damping)", "force proportional to -sign(rho') "
             "(Coulomb friction)", "force growing with time since touchdown"]
    scale = X.std(axis=0) + 1e-12
    scale[0] = 1.0
    Xs = X / scale
    coef, *_ = np.linalg.lstsq(Xs, yv, rcond=None)
    resid_var = np.var(yv)
    for _ in range(5):
        small = np.abs(coef) * np.where(np.arange(len(coef)) == 0, 1, 1) < threshold * np.sqrt(resid_var)
        coef[small] = 0
        big = ~small
        if not big.any():
            break
        coef[big], *_ = np.linalg.lstsq(Xs[:, big], yv, rcond=None)
    coef = coef / scale
    explained = 1 - np.var(yv - X @ coef) / resid_var if resid_var > 0 else 0.0
    if explained < 0.2:
        return []
    m = data.params.body_mass
    words = []
    for c, name in zip(coef, names):
        if c:
            words.append(f"an extra stance force along the leg, {name}: coefficient {m * c:.3g} (N, N s/m or N/s) "
                         f"(explains {100 * explained:.0f} % of the residual acceleration along the leg)")
    return words
