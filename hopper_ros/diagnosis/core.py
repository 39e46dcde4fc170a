"""The mismatch tool: locate (residual forces per phase and event), name (library effects and discovered terms,
fitted and ranked on held-out strides, with guards), model (refit, before/after).

Plain Python (numpy/scipy, numba where installed). Candidates are the entries of `physics.effects` and the
term sets that `discover` finds where `locate` sees a residual above noise; both are searched the same way
(`search`): one magnitude on a grid, every (grid point, stride) a lane of one integration, fitted per fold on
the training strides, scored on the held-out ones (trajectory SSE and the next apex, E_p, E_v, E_t) and
accepted by the rules of `acceptance`, one effect a round (`rounds`).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from hopper_ros.physics import effects as library
from hopper_ros.physics import laws
from hopper_ros.physics.params import ModelParams
from hopper_ros.recording.recordings import Recording

from . import acceptance
from .alternatives import told_apart
from .angle import find_angle_law
from .candidates import candidate_sites
from .data import PHASES, StrideData, own_ramps, prepare
from .dependence import find_dependence, lap_length
from .drift import drift_data, find_drift, with_drift
from .locate import Location, fit_locations, locate
from .lookalikes import discovered_look_alikes, fit_secondary
from .progress import QUIET, Progress
from .records import APEX_ERRORS, Diagnosis, Errors, Reference, Scored, completeness
from .report import verdict
from .rounds import Log, restarts, revisit, rounds
from .search import Search, refit_jointly
from .settings import Settings, load_settings  # noqa: F401  (the engine's settings, read here by callers)
from .simulate import Variant, simulate_variants
from .unused import find_unused_law, refitted, rescaled
from .yardstick import locate_by_trajectory, noise_floor, start_moves


def base_variant(params: ModelParams, model_effects: dict | None = None) -> Variant:
    coefficients, sensors = library.apply(laws.Coefficients.from_model(params), model_effects or {})
    return Variant(coefficients, sensors)


def diagnose(rec: Recording, params: ModelParams, settings: Settings, model_effects: dict | None = None,
             progress: Progress = QUIET) -> Diagnosis:
    progress.say("preparing the strides")
    search, base_sim, model = start(rec, params, settings, model_effects, progress)
    data, base = search.data, search.base
    moves = start_moves(data, base, base_sim)
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
    floor = noise_floor(data, moves)
    chosen = told_apart(search, chosen, floor)    # a library effect that is the look-alike of a law of the same part
    state = _accepted(search, chosen, log, model, base_sim["series"], moves)
    drifts = find_drift(data, state.current, settings)[:1]
    after = drifts[0].after if drifts else state.after     # the model with the drift
    residual_location = _drifted_location(data, state, drifts)
    left = completeness(model.errors, after, floor, residual_location, settings)
    def unused_law():
        scaled, scaled_model = rescaled(search, base_sim["series"], moves)
        return _with_angle_law(scaled, chosen, scaled_model, find_unused_law, floor, refitted, settings.unused_laws)

    # what the accepted effects leave may depend on the leg angle or its reversals, or on the boom's angle, or on
    # the leg's compression since its last reversal
    for words, stage in (("the leg angle's periodic dependence and the direction since the last reversal",
                          lambda: _with_angle_law(search, chosen, model)),
                         ("the boom's angle and the leg's compression since its last reversal", unused_law)):
        if left.explained:
            break
        progress.say(words)
        found = stage()
        if found is not None:
            chosen = found
            state = _accepted(search, chosen, log, model, base_sim["series"], moves)
            drifts = find_drift(data, state.current, settings)[:1]
            after, residual_location = (drifts[0].after if drifts else state.after), _drifted_location(data, state,
                                                                                                        drifts)
            left = completeness(model.errors, after, floor, residual_location, settings)
    dependences = []
    if not left.explained:      # what the accepted effects leave may depend on where along the track a stride is
        progress.say("the floor's dependence on the place along the track")
        own = own_ramps(data)      # a floor at another height per stride moves each stance's start
        kept, modelled, dependences = _with_dependence(search, own, chosen, drifts, lap_length(settings))
        if dependences:
            if len(kept) < len(chosen):
                chosen, state = kept, _accepted(search, kept, log, model, base_sim["series"], moves)
            after = dependences[0].after
            residual_location = locate(own, modelled)[0]
            left = completeness(model.errors, after, floor, residual_location, settings)
    return Diagnosis(data, log.rounds, chosen, model.errors, after, _rms_table(state.final_sim, 0, data),
                     _rms_table(state.final_sim, 1, data), base_sim["series"], state.final_sim["series"],
                     state.first_location, residual_location, log.discoveries,
                     verdict(chosen, residual_location if chosen or dependences or drifts else state.first_location,
                             settings.locate_threshold, left, drifts, dependences),
                     settings, dict(model_effects or {}), completeness=left, drifts=drifts, dependences=dependences)


def start(rec: Recording, params: ModelParams, settings: Settings, model_effects: dict | None = None,
          progress: Progress = QUIET) -> tuple[Search, dict, Reference]:
    """The recording made ready and the model simulated on it: the search every step shares, the model's
    simulation with its series, and its reference (per-stride SSE, held-out errors)."""
    data = prepare(rec, params, settings.min_strides, settings.liftoff_window)
    base = base_variant(params, model_effects)
    base_sim = simulate_variants(data, [base], keep_series=True)
    data.corr_length = max(1.0, float(np.median([correlation_length(r["z"][0]) for r in base_sim["series"]])))
    data.model_sse = float(base_sim["sse"][0].sum())
    model = Reference(base_sim["sse"][0], Errors.of(data, {k: v[0] for k, v in base_sim["pred"].items()}))
    return Search(data, base, settings, progress), base_sim, model


@dataclass
class Accepted:
    current: Variant                 # the model with the accepted effects
    final_sim: dict                  # the model and it, simulated with their series
    after: Errors                    # its held-out next-apex errors
    first_location: list             # the model's locations, the accepted effects' fits among them
    residual_location: list          # what the accepted effects leave located


def _accepted(search: Search, chosen: list[Scored], log: Log, model: Reference, base_series: list,
              moves) -> Accepted:
    """What the accepted effects give (each one's cumulative held-out errors set on it); where nothing is accepted
    nor located, the trajectory's location."""
    data, settings = search.data, search.settings
    current = search.stack(chosen).variant()
    for r, errors in zip(chosen, search.cumulative_errors(chosen)):
        r.errors = errors
    final_sim = simulate_variants(data, [search.base, current], keep_series=True)
    after = search.held_out(chosen).errors if chosen else model.errors
    first_location = _with_chosen_sites(log.first_location, chosen, settings)
    if not chosen and all(loc.ratio < settings.locate_threshold for loc in first_location):
        found = locate_by_trajectory(data, base_series, moves, settings)
        first_location = [found] + first_location if found else first_location
    residual_location = locate(data, current)[0] if chosen else first_location
    return Accepted(current, final_sim, after, first_location, residual_location)


def _drifted_location(data: StrideData, state: Accepted, drifts: list) -> list:
    """The residual the accepted effects leave, located with the drift modelled where there is one (on the strides
    it was fitted on, `drift.drift_data`)."""
    if not drifts:
        return state.residual_location
    return locate(drift_data(data, drifts[0].parameter), with_drift(state.current, drifts))[0]


def _with_dependence(search: Search, own: StrideData, chosen: list[Scored], drifts: list, lap: float):
    """(the accepted effects kept, the model with them, the drift and the dependence, the dependence): the floor's
    dependence on the track position beside the accepted effects, and without each effect that it makes
    redundant, one at a time: an effect whose removal (the dependence refitted) leaves the held-out next apex
    worse by less than `apex_improvement` stood in for the dependence (plant B's undulating floor: a horizontal
    inertia of the boom)."""
    settings = search.settings

    def with_it(effects):
        v = with_drift(search.stack(effects).variant(), drifts)
        found = find_dependence(own, v, settings, lap)
        return effects, v, found

    kept, variant, found = with_it(chosen)
    while found and kept:
        limit = found[0].after.total * (1.0 + settings.apex_improvement)
        trials = [with_it([c for c in kept if c is not r]) for r in kept]
        trials = [t for t in trials if t[2] and t[2][0].after.total <= limit]
        if not trials:
            break
        kept, variant, found = min(trials, key=lambda t: t[2][0].after.total)
    if found:
        variant = Variant(variant.coefficients, variant.sensors, {**variant.per_stride, **found[0].per_stride})
    return kept, variant, found


def _with_angle_law(search: Search, chosen: list[Scored], model: Reference, find=find_angle_law,
                    floor: Errors | None = None, refit=None, laws: int = 1):
    """The accepted effects with a law of the leg angle or its reversals (`angle.find_angle_law`; or of the boom's
    angle and the leg's reversals, `unused.find_unused_law`, on its search and model reference) beside them all,
    and in place of each of them (that one may have stood in for it: plant B's backlash was named an actuator lag),
    and of two or more in place of them all (plant C's servo released late was a hip viscous friction with the
    rotor's inertia beside it, two stand-ins), each earlier effect revisited beside the law. Of the sets found, the
    smallest whose held-out fit is not clearly worse (paired t below `tie_t`, the sum of E_p, E_v, E_t not worse by
    `apex_tolerance`, or, given the noise `floor`, each within `floor_factor` of it: an effect kept beside the law
    for a next apex already at the noise floor is a stand-in, plant C's leg hysteresis beside a boom friction of
    0.007 m/s^2) than the best's; one found in place of an effect only where it `replaces` the accepted set as a
    whole explanation. With `laws` > 1, each set that found a law is searched again for another beside it, up to
    `laws` laws where one of its next apex's errors is still over `second_law_floor` times its noise floor (several
    act at once on a robot: plant C's round toe in place of a leg angle offset, 16 x the floor, then the drive's
    voltage limit beside it; the search costs a stage again, so not where the set is nearly explained); a set with
    more laws is kept only where it fits clearly better, as any. Each trial of two or more effects has its magnitudes
    refitted together (`search.refit_jointly`). None where no law passes its guards."""
    settings, data = search.settings, search.data
    accepted, found = (search.held_out(chosen) if chosen else model), []
    if refit is not None:       # the accepted effects refitted on this search's yardstick (`unused.refitted`)
        accepted = refit(search, chosen, accepted)
    # beside them all, in place of each, and (two or more) in place of them all: each may have stood in for it
    leave = [()] + [(k,) for k in range(len(chosen))] + ([tuple(range(len(chosen)))] if len(chosen) > 1 else [])

    def within(errors, factor):     # each next-apex error within `factor` of its noise floor
        return floor is not None and all(getattr(errors, k) <= factor * getattr(floor, k) for k in APEX_ERRORS)

    for left_out in leave:
        kept = copy.deepcopy([r for k, r in enumerate(chosen) if k not in left_out])    # a trial moves magnitudes
        for _ in range(laws):
            locations, sets = locate(data, search.stack(kept).variant())
            located = {loc.site for loc in locations if loc.ratio >= settings.locate_threshold}
            top = find(search, kept, search.held_out(kept) if kept else model, sets, located)
            if top is None:
                break
            trial = kept + [top]
            if len(trial) > 1:
                revisit(search, trial, Reference(top.held_sse, top.errors))
                refit_jointly(search, trial)
            held = search.held_out(trial)
            if not left_out or acceptance.replaces(held, accepted, model.errors, settings):
                found.append((held, trial))
            if floor is None or within(held.errors, settings.second_law_floor):   # a second law only far from explained
                break
            kept = copy.deepcopy(trial)
    if not found:
        return None
    best = min(found, key=lambda f: f[0].sse.sum())[0]
    alike = [(len(trial), held.sse.sum(), trial) for held, trial in found
             if acceptance.paired_t(held.sse, best.sse) < settings.tie_t
             and (held.errors.total <= best.errors.total * (1 + settings.apex_tolerance)
                  or within(held.errors, settings.floor_factor))]
    return min(alike, key=lambda f: f[:2])[2]


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
