"""What the mismatch tool accepts, each rule written once: a candidate's held-out statistics and guards, the
naming margins (a sensor fault against physics, discovered terms against the library), the look-alike test,
a real sensor's fault, the apex tolerance, and when a restarted set replaces the accepted one."""

from __future__ import annotations

import math

import numpy as np

from .data import StrideData
from .records import APEX_ERRORS, Errors, Reference, Scored
from .settings import Settings


def paired_t(worse: np.ndarray, better: np.ndarray) -> float:
    """One-sided t over strides that `worse` fits held-out strides worse than `better` (per-stride log ratio)."""
    d = np.log(worse / better)
    sd = d.std(ddof=1)
    return float(d.mean() / (sd / math.sqrt(len(d)))) if sd > 0 else (math.inf if d.mean() > 0 else 0.0)


def worse_errors(errors: Errors, reference: Errors, tolerance: float, slack: float = 0.0) -> list[str]:
    """The next-apex errors grown by more than `tolerance` (a share) over `reference`'s (plus `slack`, in %)."""
    return [k for k in APEX_ERRORS if not getattr(errors, k) <= getattr(reference, k) * (1 + tolerance) + slack]


def plausible(r: Scored) -> bool:
    """A sensor fault of a size a real sensor has and this data resolves."""
    c = r.candidate
    return c.plausible[0] <= abs(r.magnitude - c.off) <= c.plausible[1]


def resolved(r: Scored) -> bool:
    """Not refitted past the range this recording resolves on the side where the candidate changes nothing (a
    torque limit is searched between 0.3 and 1 x the largest commanded torque: above them all it clips nothing)."""
    c = r.candidate
    low, high = sorted((c.low, c.high))
    return not ((c.origin < low and r.value < low) or (c.origin > high and r.value > high))


def real(r: Scored) -> bool:
    """Physics or discovered terms that are `resolved`, or a sensor fault that is `plausible`."""
    return plausible(r) if r.candidate.kind == "sensor" else resolved(r)


def not_worse(r: Scored, best: Scored, settings: Settings) -> bool:
    """`r` fits held-out strides not clearly worse than `best` (paired t below `tie_t`)."""
    return paired_t(r.held_sse, best.held_sse) < settings.tie_t


def look_alike(r: Scored, best: Scored, settings: Settings) -> bool:
    """`r` cannot be told from `best` on this data: not clearly worse, or its reduction within `tie_share`."""
    return not_worse(r, best, settings) or r.reduction >= best.reduction * (1 - settings.tie_share)


def score(r: Scored, data: StrideData, reference: Reference, settings: Settings) -> Scored:
    """`r`'s statistics from its held-out SSE per stride against the reference's, then its guards."""
    held, base_sse = r.held_sse, reference.sse
    d = np.log(base_sse / held)
    sd = d.std(ddof=1)
    n_eff = data.sample_count / data.corr_length
    r.total_reduction = float((base_sse.sum() - held.sum()) / data.model_sse)
    r.t = float(d.mean() / (sd / math.sqrt(len(d)))) if sd > 0 else 0.0
    r.reduction = float(1.0 - held.sum() / base_sse.sum())
    r.delta_bic = float(-2 * 0.5 * n_eff * math.log(base_sse.sum() / held.sum()) + math.log(n_eff))
    guard(r, reference.errors, settings)
    return r


def guard(r: Scored, base_errors: Errors, settings: Settings) -> None:
    """Trajectory and next-apex criteria on held-out strides; a sensor's magnitude must be a real sensor's."""
    why = []
    if r.reduction < settings.min_reduction:
        why.append(f"held-out trajectory residual falls only {100 * r.reduction:.1f} %")
    elif r.total_reduction < settings.min_total_reduction:
        why.append(f"it explains only {100 * r.total_reduction:.1f} % of the model's residual")
    if r.t < settings.min_t:
        why.append(f"not consistent over strides (t {r.t:.1f})")
    if r.delta_bic >= 0:
        why.append("information criterion against it")
    e, b = r.errors, base_errors
    worse = worse_errors(e, b, settings.apex_tolerance, slack=1e-6)
    if worse:
        why.append("held-out " + ", ".join(worse) + " worse")
    # a sensor fault changes what is measured, not the motion: the next apex it predicts is the same (a delay)
    # or moves with the measurement, so it must not be worse; physics must predict it better
    # (then the fault must account for most of the model's residual: a small one fits what the physics left;
    # a discovered ringing need not: its discovery already showed an oscillation the smooth residual cannot make)
    c = r.candidate
    measured = c.kind == "sensor" or getattr(c.discovery, "measurement", False)
    better = e.total <= b.total * (1 - settings.apex_improvement)
    if not measured and not better:
        why.append("the next apex is not predicted better")
    elif c.kind == "sensor" and not better and r.total_reduction < settings.sensor_alone:
        why.append(f"the next apex is not predicted better and it explains only {100 * r.total_reduction:.0f} % "
                   "of the model's residual")
    if e.fallen > b.fallen:
        why.append(f"{e.fallen - b.fallen} more strides fall")
    if c.kind == "sensor" and not plausible(r):
        why.append(f"{r.magnitude:.4g} {c.unit} is not a fault a real sensor has and this data resolves")
    r.rejected = why
    r.significant = not why


def choose(ranking: list[Scored], settings: Settings) -> tuple[Scored | None, list[Scored]]:
    """The accepted effect of a round and those it cannot be told apart from on this data.

    A sensor fault must beat the best physics effect, a discovered term set the best library effect,
    by a margin. Any other effect that passed its guards (with or without a margin) that is a `look_alike`
    of the accepted one is reported beside it as not separable."""
    passed = [r for r in ranking if r.significant]
    best_physics = max((r for r in passed if r.candidate.kind == "physics"), key=lambda r: r.reduction, default=None)
    best_library = max((r for r in passed if r.candidate.kind != "discovered"), key=lambda r: r.reduction,
                       default=None)
    for r in passed:
        c = r.candidate
        if c.kind == "sensor" and not beats(r, best_physics, settings.sensor_margin, settings):
            r.significant, r.margin_only = False, True
            r.rejected.append("a physics effect explains the same residual about as well")
        if c.kind == "discovered" and best_library is not None and \
                r.reduction < best_library.reduction + settings.discovery_margin * r.reduction:
            r.significant, r.margin_only = False, True
            r.rejected.append("a library effect explains it about as well")
    ok = [r for r in ranking if r.significant]
    if not ok:
        return None, []
    top = max(ok, key=lambda r: r.reduction)
    return top, [r for r in passed if r is not top and look_alike(r, top, settings)]


def beats(r: Scored, rival: Scored | None, margin: float, settings: Settings) -> bool:
    """A sensor fault `r` beats the best physics effect `rival` by a margin: its reduction by `margin` of its own,
    or (near a full reduction, `near_full`, where reductions differ little) it leaves at most `margin_residual` of
    what the rival leaves on held-out strides, consistently over strides (paired t >= min_t). A discovered term set
    against a library entry has only the first: the same law written as terms (a constant force where the
    speed never changes sign) can fit closer than the entry's grid, and the entry's name is the answer."""
    if rival is None or r.reduction >= rival.reduction + margin * r.reduction:
        return True
    return bool(r.reduction >= settings.near_full
                and r.held_sse.sum() <= settings.margin_residual * rival.held_sse.sum()
                and paired_t(rival.held_sse, r.held_sse) >= settings.min_t)


def lost_on_a_margin(ranking: list[Scored]) -> list[Scored]:
    """First-round candidates that passed every guard and fitted better than the round's choice but lost to it on
    a naming margin (a sensor fault against physics, discovered terms against the library): the choice may need
    more effects to fit what one of them fits alone (a torque offset and a theta scale for a torsion spring)."""
    chosen = max((r.reduction for r in ranking if r.significant), default=math.inf)
    return [r for r in ranking if r.margin_only and r.reduction > chosen]


def runner_up(r: Scored, settings: Settings) -> bool:
    """A first-round candidate strong enough to start the rounds again or to be exchanged in: it fits held-out
    strides by `min_reduction`, consistently (`min_t`)."""
    return r.reduction >= settings.min_reduction and r.t >= settings.min_t


def replaces(trial: Reference, best: Reference, base_errors: Errors, settings: Settings) -> bool:
    """A restarted set (`trial`) beats the accepted one (`best`) as a whole explanation: the held-out trajectory
    SSE lower by `min_reduction` with a paired t of at least `min_t`, the sum of the held-out E_p, E_v, E_t not
    worse by more than `apex_tolerance`, none of them worse than the model's own (two explanations trade a little
    E_t for E_p; each compared alone, the guard would keep the wrong one), and no more strides fallen."""
    e, b = trial.errors, best.errors
    return (1.0 - trial.sse.sum() / best.sse.sum() >= settings.min_reduction
            and paired_t(best.sse, trial.sse) >= settings.min_t
            and e.total <= b.total * (1 + settings.apex_tolerance)
            and not worse_errors(e, base_errors, settings.apex_tolerance)
            and e.fallen <= b.fallen)
