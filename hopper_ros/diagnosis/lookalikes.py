"""What else the data allow beside a round's choice: an entry with a secondary parameter (a compliant ground's
damping) fitted when it competes or is accepted, and the term sets discovered where an accepted library effect
acts that fit as well."""

from __future__ import annotations

import copy

import numpy as np

from . import acceptance
from .candidates import candidate_sites, discovered_candidate
from .discover import discover_site
from .locate import locate
from .records import Reference, Scored
from .search import Search, Stack
from .sites import RESIDUAL_SITES


def with_secondary(search: Search, stack: Stack, r: Scored, p, reference: Reference,
                   guarded: bool = True) -> Scored | None:
    """`r`'s candidate with its secondary parameter `p` on a grid, geometric between its bounds, with the
    model's own value in place of a grid value within half a step of it, the magnitude refitted at each (on
    top of `stack`); the best value other than the model's when held-out strides prefer it (paired t of at
    least `min_t`) and (`guarded`) it passes its guards, else None."""
    settings = search.settings
    own = float(getattr(stack.variant().coefficients, p.coefficient))
    grid = np.geomspace(p.low, p.high, settings.secondary_grid)
    step = (p.high / p.low) ** (0.5 / max(settings.secondary_grid - 1, 1))   # half a grid step
    values = [own] + [float(v) for v in grid if not own / step < v < own * step]
    tried = {v: search.search(stack, [r.candidate.holding(p, v)], reference)[0] for v in values}
    value = min(tried, key=lambda v: tried[v].held_sse.sum())
    best = tried[value]
    if value == own or (guarded and not best.significant) or \
            acceptance.paired_t(tried[own].held_sse, best.held_sse) < settings.min_t:
        return None
    return best


def secondary_look_alikes(search: Search, stack: Stack, ranking: list[Scored], reference: Reference
                          ) -> list[Scored]:
    """A round's look-alikes of its best (`acceptance.look_alike`) that have a secondary parameter compete with
    it fitted: a compliant ground with its own damping against a softer leg. Returns the ranking, re-sorted."""
    passed = [r for r in ranking if r.significant]
    if not passed:
        return ranking
    top = max(passed, key=lambda r: r.reduction)
    out = []
    for r in ranking:
        alike = r is top or acceptance.look_alike(r, top, search.settings)
        for p in r.candidate.secondary if r.significant and alike else ():
            search.progress.say(f"fitting {r.name}'s {p.name}")
            r = with_secondary(search, stack, r, p, reference) or r
        out.append(r)
    return sorted(out, key=lambda r: -r.reduction)


def fit_secondary(search: Search, chosen: list[Scored], only=None, guarded: bool = True) -> None:
    """Each accepted entry's secondary parameters (`with_secondary`), beside the other accepted effects (`only`:
    those of these indices)."""
    for i in range(len(chosen)) if only is None else only:
        for p in chosen[i].candidate.secondary:
            r, others = chosen[i], chosen[:i] + chosen[i + 1:]
            stack = search.stack(others)
            reference = search.reference(stack)
            search.progress.say(f"fitting {r.name}'s {p.name}")
            best = with_secondary(search, stack, r, p, reference, guarded)
            if best is None:
                continue
            search.polish(others, best, reference)
            best.location, best.ties, best.alternatives = r.location, r.ties, r.alternatives
            chosen[i] = best


def discovered_look_alikes(search: Search, chosen: list[Scored], discoveries: list) -> None:
    """Each accepted library effect beside the term sets discovered where it acts, with the other accepted effects
    in place, or one of them replaced by a look-alike of its own (a softer leg by the compliant ground it could not
    be told from): a set that passes its guards there and is `acceptance.not_worse` than it is reported as its
    look-alike. The rounds that found the set decided the name; this says what else the data allow (a flight-only
    lift beside the lower gravity it looks like in flight, once a compliant ground has been explained in stance by
    the ground itself rather than by a softer leg). New term sets are added to `discoveries`."""
    for i, r in enumerate(chosen):
        c = r.candidate
        if c.kind == "discovered":
            continue
        ties = r.ties
        others = chosen[:i] + chosen[i + 1:]
        contexts = [others] + [others[:j] + [copy.copy(t)] + others[j + 1:] for j, o in enumerate(others)
                               for t in o.ties if t.candidate.kind != "discovered"]
        for context in contexts:
            known = {t.name for t in ties}
            sites = [site for site in candidate_sites(c) if site in RESIDUAL_SITES and f"discovered_{site}" not in known]
            if not sites:
                break
            stack = search.stack(context)
            search.progress.say(f"terms beside {r.name}")
            _, sets = locate(search.data, stack.variant())
            found = [f for f in (discover_site(site, sets) for site in sites) if f is not None]
            if not found:
                continue
            discoveries.extend(found)
            ranking = search.search(stack, [c] + [discovered_candidate(f) for f in found], search.reference(stack))
            own = next(x for x in ranking if x.name == c.name)
            ties += [x for x in ranking if x is not own and x.significant and acceptance.not_worse(x, own, search.settings)]
