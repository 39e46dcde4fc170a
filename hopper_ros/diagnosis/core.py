"""The mismatch tool: locate (residual forces per phase and event), name (library effects and discovered terms,
fitted and ranked on held-out strides, with guards), model (refit, before/after).

Plain Python (numpy/scipy, numba where installed). Candidates are the entries of `physics.effects` and the
term sets that `discover` finds where `locate` sees a residual above noise; both are searched the same way
(`search`): one magnitude on a grid, every (grid point, stride) a lane of one integration, fitted per fold on
the training strides, scored on the held-out ones (trajectory SSE and the next apex, E_p, E_v, E_t) and
accepted by the rules of `acceptance`, one effect a round (`rounds`).
"""

from __future__ import annotations

import math

import numpy as np

from hopper_ros.physics import effects as library
from hopper_ros.physics import laws
from hopper_ros.physics.params import ModelParams
from hopper_ros.recording.recordings import Recording

from . import acceptance
from .candidates import candidate_sites
from .data import PHASES, StrideData, prepare
from .drift import find_drift
from .locate import Location, fit_locations, locate
from .lookalikes import discovered_look_alikes, fit_secondary
from .progress import QUIET, Progress
from .records import Diagnosis, Errors, Reference, Scored, completeness
from .report import verdict
from .rounds import Log, restarts, rounds
from .search import Search
from .settings import Settings, load_settings  # noqa: F401  (the engine's settings, read here by callers)
from .simulate import Variant, simulate_variants
from .yardstick import locate_by_trajectory, noise_floor, start_moves


def base_variant(params: ModelParams, model_effects: dict | None = None) -> Variant:
    coefficients, sensors = library.apply(laws.Coefficients.from_model(params), model_effects or {})
    return Variant(coefficients, sensors)


def diagnose(rec: Recording, params: ModelParams, settings: Settings, model_effects: dict | None = None,
             progress: Progress = QUIET) -> Diagnosis:
    progress.say("preparing the strides")
    data = prepare(rec, params, settings.min_strides, settings.liftoff_window)
    base = base_variant(params, model_effects)
    base_sim = simulate_variants(data, [base], keep_series=True)
    moves = start_moves(data, base, base_sim)
    data.corr_length = max(1.0, float(np.median([correlation_length(r["z"][0]) for r in base_sim["series"]])))
    data.model_sse = float(base_sim["sse"][0].sum())
    search = Search(data, base, settings, progress)
    model = Reference(base_sim["sse"][0], Errors.of(data, {k: v[0] for k, v in base_sim["pred"].items()}))
    excited = {"command": float(np.max(np.abs(data.strides.tau_0), initial=0.0))}
    log = Log()
    chosen, _ = rounds(search, excited, [], model, log)
    # a refit beside later effects may move a sensor fault to where no real sensor has one: then it is not one
    chosen = [r for r in chosen if acceptance.real(r)]
    left = locate(data, search.stack(chosen).variant())[0] if chosen else []
    if (any(loc.ratio >= settings.restart_threshold for loc in left) or len(chosen) >= settings.max_effects
            or (len(chosen) > 1 and acceptance.lost_on_a_margin(log.first_ranking))):
        chosen = restarts(search, excited, chosen, log, model)
    progress.say("the accepted effects' secondary parameters and look-alikes")
    fit_secondary(search, chosen)
    discovered_look_alikes(search, chosen, log.discoveries)
    current = search.stack(chosen).variant()
    for r, errors in zip(chosen, search.cumulative_errors(chosen)):
        r.errors = errors
    final_sim = simulate_variants(data, [base, current], keep_series=True)
    after = search.held_out(chosen).errors if chosen else model.errors
    first_location = _with_chosen_sites(log.first_location, chosen, settings)
    if not chosen and all(loc.ratio < settings.locate_threshold for loc in first_location):
        found = locate_by_trajectory(data, base_sim["series"], moves, settings)
        first_location = [found] + first_location if found else first_location
    residual_location = locate(data, current)[0] if chosen else first_location
    drifts = find_drift(data, current, settings)[:1]
    after = drifts[0].after if drifts else after     # the model with the drift
    left = completeness(model.errors, after, noise_floor(data, moves), residual_location, settings)
    return Diagnosis(data, log.rounds, chosen, model.errors, after, _rms_table(final_sim, 0, data),
                     _rms_table(final_sim, 1, data), base_sim["series"], final_sim["series"], first_location,
                     residual_location, log.discoveries,
                     verdict(chosen, residual_location if chosen else first_location, settings.locate_threshold, left,
                             drifts),
                     settings, dict(model_effects or {}), completeness=left, drifts=drifts)


def correlation_length(resid: np.ndarray) -> float:
    r = resid - resid.mean()
    if r.size < 10 or np.dot(r, r) == 0:
        return 1.0
    ac = np.correlate(r, r, "full")[r.size - 1:] / np.dot(r, r)
    neg = np.flatnonzero(ac <= 0)
    cut = int(neg[0]) if neg.size else min(len(ac), 200)
    return float(max(1.0, 1.0 + 2.0 * ac[1:cut].sum()))


def _with_chosen_sites(locations: list[Location], chosen: list[Scored], settings: Settings) -> list[Location]:
    """The force locations with each accepted effect located by its own fit (its held-out gain over the model
    without it, the others kept; the second effect of a pair is judged beside the first) where no force
    location stands stronger at its site."""
    strongest = {}
    for loc in locations:
        strongest[loc.site] = max(strongest.get(loc.site, -math.inf), loc.ratio)
    added = [loc for loc in fit_locations(chosen, candidate_sites, settings.locate_threshold, settings.min_t)
             if loc.ratio > strongest.get(loc.site, -math.inf)]
    return sorted(locations + added, key=lambda loc: -loc.ratio)


def _rms_table(sim: dict, row: int, data: StrideData) -> dict:
    bp = sim["by_phase"][row].sum(axis=0)
    cnt = sim["counts"].sum(axis=0)
    return {ph: {v: (float(math.sqrt(bp[pi, ci] / cnt[pi, ci])) if cnt[pi, ci] else float("nan"))
                 for ci, v in enumerate(("y", "z", "theta"))} for pi, ph in enumerate(PHASES)}
