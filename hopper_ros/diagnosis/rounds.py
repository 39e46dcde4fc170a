"""The mismatch tool's rounds: one effect accepted per round on top of those before (refitted beside it), the
earlier ones revisited and exchanged, and restarts from the first round's runners-up where the accepted set
may stand in for a pair it is not part of."""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field

from hopper_ros.physics import effects as library

from . import acceptance
from .candidates import discovered_candidate, library_candidate, ringing_candidates
from .discover import discover_site
from .locate import locate
from .records import Reference, Scored
from .search import Search
from .lookalikes import fit_secondary, secondary_look_alikes
from .sites import RESIDUAL_SITES


@dataclass
class Log:
    """What the rounds saw: every round's ranking, the term sets discovered, the first round's locations and
    ranking."""
    rounds: list = field(default_factory=list)
    discoveries: list = field(default_factory=list)
    first_location: list | None = None
    first_ranking: list | None = None


def rounds(search: Search, excited: dict, chosen: list[Scored], current: Reference, log: Log
           ) -> tuple[list[Scored], Reference]:
    """Greedy rounds from the effects in `chosen` (their held-out SSE and errors `current`) up to `max_effects`:
    locate, screen the library, discover at the located sites, search, accept the best that passes every guard
    (or exchange an accepted one), refit jointly and revisit. Returns the accepted effects and their reference."""
    settings, progress = search.settings, search.progress
    for number in range(len(chosen), settings.max_effects):
        stack = search.stack(chosen)
        variant = stack.variant()
        progress.say(f"round {number + 1}: locating")
        locations, sets = locate(search.data, variant)
        located = {loc.site for loc in locations if loc.ratio >= settings.locate_threshold}
        taken = {r.name for r in chosen}
        candidates = [library_candidate(e, variant.coefficients, excited) for e in library.LIBRARY + library.SENSORS
                      if e.name not in taken]
        progress.say(f"round {number + 1}: screening {len(candidates)} candidates")
        candidates = search.screen(stack, candidates, located)
        for site in sorted(located & set(RESIDUAL_SITES)):     # (touchdown timing has no residual samples)
            found = discover_site(site, sets)
            if found is not None and f"discovered_{site}" not in taken:
                log.discoveries.append(found)
                candidates.append(discovered_candidate(found))
        candidates += ringing_candidates(search.data, located, taken, log.discoveries)
        progress.say(f"round {number + 1}: searching {len(candidates)} candidates")
        ranking = search.search(stack, candidates, current)
        ranking = secondary_look_alikes(search, stack, ranking, current)
        if log.first_location is None:
            log.first_location, log.first_ranking = locations, ranking
        top, ties = acceptance.choose(ranking, settings)
        log.rounds.append(ranking)
        if top is None and chosen:
            progress.say(f"round {number + 1}: nothing passes; exchanging an accepted effect")
            trial = exchange(search, chosen, ranking, current)
            if trial is not None:
                chosen, current = trial
                continue
        if top is None:
            break
        progress.say(f"round {number + 1}: {top.name} = {top.magnitude:.4g} {top.candidate.unit}".rstrip())
        top.ties = ties
        top.location = [loc for loc in locations if loc.ratio >= settings.locate_threshold]
        top.alternatives = [r.candidate for r in ranking[:settings.screen] if r is not top]
        search.polish(chosen, top, current)
        chosen.append(top)
        # its secondary parameters now, so that the next rounds search on top of it as the data have it (a
        # compliant ground at the model's damping makes a flight-only lift look like a lower gravity)
        fit_secondary(search, chosen, only=[len(chosen) - 1])
        top = chosen[-1]
        current = Reference(top.held_sse, top.errors)
        if len(chosen) > 1:
            current = revisit(search, chosen, current)
    return chosen, current


def revisit(search: Search, chosen: list[Scored], current: Reference) -> Reference:
    """Each earlier effect tried again beside the later ones, against its round's runners-up: one that
    stood in for a pair (a lower gain for a gain and drag) is replaced, one no longer needed is dropped."""
    settings = search.settings
    i = 0
    while i < len(chosen) - 1 and len(chosen) > 1:
        old = chosen[i]
        others = chosen[:i] + chosen[i + 1:]
        stack = search.stack(others)
        reference = search.reference(stack)
        taken = {r.name for r in others}
        pool = [old.candidate] + [c for c in old.alternatives if c.name not in taken]
        search.progress.say(f"revisiting {old.name} beside the later effects")
        ranking = search.search(stack, pool, reference)
        best, ties = acceptance.choose(ranking, settings)
        if best is None:
            chosen.pop(i)
            current = reference
            continue
        again = next(r for r in ranking if r.name == old.name)
        if best is not again and again.significant and acceptance.not_worse(again, best, settings):
            ties = [best] + [r for r in ties if r is not again]
            best = again                  # not clearly better: keep the first
        best.ties = ties                  # the look-alikes beside the later effects, where they are told apart best
        best.location = old.location
        best.alternatives = [c for c in pool if c.name != best.name]
        search.polish(others, best, reference)
        chosen[i] = best
        current = Reference(best.held_sse, best.errors)
        i += 1
    return current


def exchange(search: Search, chosen: list[Scored], ranking: list[Scored], current: Reference
             ) -> tuple[list[Scored], Reference] | None:
    """When no effect passes on top of the accepted ones, an accepted one may be standing in for a pair
    (it fitted both alone): each strong runner-up is added, the earlier effects revisited beside it (and
    swapped for their rounds' runners-up), and the set kept if every effect in it then passes its guards
    against the model without it. Returns (effects, their reference) or None."""
    settings = search.settings
    strong = [r for r in ranking if acceptance.runner_up(r, settings)]
    for r in strong[:settings.exchange]:
        trial = [copy.copy(e) for e in chosen]
        added = copy.copy(r)
        search.polish(trial, added, current)
        trial.append(added)
        revisit(search, trial, Reference(added.held_sse, added.errors))
        if [e.name for e in trial[:-1]] == [e.name for e in chosen] or len(trial) <= len(chosen):
            continue                      # nothing was exchanged: the runner-up failed on its own already
        others = trial[:-1]
        without = search.reference(search.stack(others))
        last = search.search(search.stack(others), [trial[-1].candidate], without)[0]
        if not last.significant:
            continue
        search.polish(others, last, without)
        against = acceptance.score(dataclasses.replace(last, rejected=[], significant=False), search.data, current,
                                   settings)
        if not against.significant:
            continue                      # the exchanged set must beat the accepted one as an added effect would
        last.location, last.alternatives = trial[-1].location, trial[-1].alternatives
        last.ties = []
        return others + [last], Reference(last.held_sse, last.errors)
    return None


def restarts(search: Search, excited: dict, chosen: list[Scored], log: Log, base: Reference) -> list[Scored]:
    """When the accepted set leaves a residual clearly above the noise (`restart_threshold`), fills every round
    (`max_effects`), or holds two or more where the first won on a naming margin against a candidate that fitted
    better (`acceptance.lost_on_a_margin`), its first effect may stand in for a pair it is not part of (a gain fits
    a toe mass and a delay together better than either alone; a torque offset stands for a theta encoder's offset
    beside a stiffer leg, and two more effects patch what it leaves): the first round's next-best candidates (a
    sensor fault among them if its magnitude is a real sensor's), those that failed only an apex guard alone as
    well (their partner is missing), each start the rounds again, the candidates that lost on a margin first. A
    set found so replaces the accepted one when it holds two effects or more (or, started from a candidate that
    lost on a margin, fewer than the accepted set: the margin gives a library entry its name where it does the
    job alone, not where it needs another effect to patch it), each of which passed its guards beside the
    others, and `acceptance.replaces` the accepted set as a whole explanation. `base`: the model's own held-out
    reference."""
    settings = search.settings
    first = chosen[0].name
    margin = acceptance.lost_on_a_margin(log.first_ranking) if len(chosen) > 1 else []
    lost = {r.name for r in margin}
    # (a sensor fault that lost its round on the sensor margin without fitting better is a runner-up as well: a
    # theta encoder's offset behind the torque offset that stands in for it)
    pool = [(r, True) for r in margin] + [
        (r, False) for r in [r for r in log.first_ranking if r.name != first and r.name not in lost
                             and acceptance.runner_up(r, settings) and acceptance.real(r)][:settings.restarts]]
    best, best_reference = chosen, search.held_out(chosen)
    for r, smaller in pool:
        search.progress.say(f"restart from {r.name}")
        start = [dataclasses.replace(r, ties=[], location=[], alternatives=[
            x.candidate for x in log.first_ranking[:settings.screen] if x.name != r.name])]
        # (its secondary parameters fitted first, unguarded: alone it may fail an apex guard for want of a partner)
        fit_secondary(search, start, guarded=False)
        trial, _ = rounds(search, excited, start, Reference(start[0].held_sse, start[0].errors), Log())
        trial = [e for e in trial if acceptance.real(e)]
        fewest, most = (1, len(chosen) - 1) if smaller else (2, settings.max_effects)
        if not fewest <= len(trial) <= most:
            continue
        reference = search.held_out(trial)
        if acceptance.replaces(reference, best_reference, base.errors, settings):
            best, best_reference = trial, reference
    return best
