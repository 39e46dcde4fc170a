"""The mismatch tool's typed records: next-apex errors, a fitted candidate, a scored one, and the diagnosis."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields

import numpy as np

from hopper_ros.physics.metrics import position_error_pct, time_error_pct, velocity_error_pct

from .candidates import Candidate
from .data import StrideData
from .settings import Settings

APEX_ERRORS = ("E_p", "E_v", "E_t")


@dataclass(frozen=True)
class Errors:
    """Mean next-apex errors E_p, E_v, E_t (4.1)-(4.3) [%] over the strides the model completes; `fallen`
    counts those it does not (their errors cannot be computed: a model that drops strides is not better)."""

    E_p: float
    E_v: float
    E_t: float
    fallen: int

    @classmethod
    def of(cls, data: StrideData, pred: dict) -> "Errors":
        """The errors of predicted next apexes (per stride: height, length, speed, time) against the recording."""
        s = data.strides
        ep = position_error_pct(s.next_apex_height, s.stride_length, pred["height"], pred["length"])
        ev = velocity_error_pct(s.next_forward_speed, pred["speed"])
        et = time_error_pct(s.stride_time, pred["time"])
        done = np.isfinite(ep) & np.isfinite(ev) & np.isfinite(et)
        if not done.any():
            return cls(math.inf, math.inf, math.inf, int(done.size))
        return cls(float(np.mean(ep[done])), float(np.mean(ev[done])), float(np.mean(et[done])),
                   int(done.size - done.sum()))

    @property
    def total(self) -> float:
        """E_p + E_v + E_t."""
        return self.E_p + self.E_v + self.E_t

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass
class Fit:
    """A candidate's magnitude (search units) fitted on every stride and without each fold, with the magnitudes
    its partners (the effects accepted before it) were refitted to beside it."""

    value: float
    fold_values: list
    partner_values: list
    partner_fold_values: list
    grid: np.ndarray                 # the magnitudes simulated
    fit_reduction: float = 0.0       # in-sample share of the SSE removed at `value` (the profile's parabola)
    grid_reduction: float = 0.0      # ... at the best grid point


@dataclass(eq=False)
class Scored:
    """A fitted candidate judged on held-out strides against the model it was added to (`acceptance.score`);
    once accepted, also what it cannot be told from (`ties`), where it was located and its round's runners-up."""

    candidate: Candidate
    fit: Fit
    magnitude: float                 # the fitted value in the candidate's physical unit
    held_sse: np.ndarray             # per stride, at the magnitude fitted without the stride's fold
    errors: Errors                   # held-out next-apex errors
    reduction: float = 0.0           # held-out share of the reference's trajectory SSE removed
    total_reduction: float = 0.0     # ... as a share of the model's own SSE
    t: float = 0.0                   # one-sided t over strides of the per-stride log ratio
    delta_bic: float = 0.0
    rejected: list = field(default_factory=list)     # why it failed its guards
    significant: bool = False
    margin_only: bool = False        # passed its guards, lost its round on a naming margin
    ties: list = field(default_factory=list)         # Scored it cannot be told from on this data
    location: list = field(default_factory=list)     # locate.Location above the threshold in its round
    alternatives: list = field(default_factory=list)  # its round's runners-up (Candidate)

    @property
    def name(self) -> str:
        return self.candidate.name

    @property
    def value(self) -> float:
        return self.fit.value

    def adopt(self, other: "Scored") -> None:
        """Take `other`'s fit and scores (the same candidate refitted), keeping what was said of this one."""
        for name in ("candidate", "fit", "magnitude", "held_sse", "errors", "reduction", "total_reduction", "t",
                     "delta_bic", "rejected", "significant"):
            setattr(self, name, getattr(other, name))

    def move_to(self, value: float, fold_values) -> None:
        """The magnitude refitted beside a later effect (its partners' values stay as they were). A new `Fit`:
        copies of this record made before share the old one."""
        self.fit = dataclasses.replace(self.fit, value=value, fold_values=list(fold_values))
        self.magnitude = self.candidate.physical(value)


@dataclass(repr=False)
class Diagnosis:
    """What `diagnose` found: the accepted effects, the rounds that chose them, the locations, the held-out
    errors before and after, the per-phase residuals, and the `verdict` line."""

    data: StrideData
    rounds: list                     # per round, the ranking (Scored, best first)
    chosen: list                     # the accepted effects (Scored)
    before: Errors                   # held-out next-apex errors of the model
    after: Errors                    # ... with the accepted effects
    before_phase: dict               # RMS residual per phase and channel of the model
    after_phase: dict
    base_series: list                # per stride, the residual series of the model ...
    after_series: list               # ... and with the accepted effects
    location: list                   # locate.Location of the model's residual (and the accepted effects' fits)
    residual_location: list          # ... of what the accepted effects leave
    discoveries: list
    verdict: str
    settings: Settings
    model_effects: dict
    completeness: "Completeness | None" = None   # what the accepted effects leave against the noise floor
    drifts: list = field(default_factory=list)   # drift.Drift of a main parameter over the recording, modelled
    dependences: list = field(default_factory=list)   # dependence.Dependence on the track position, modelled
    wall_time: float = 0.0
    report: object = None            # path of diagnosis.md when written
    json: object = None              # path of the JSON when written

    def __repr__(self) -> str:       # the arrays it holds are large: a failing test prints this
        return f"Diagnosis({len(self.data.strides)} strides: {self.verdict!r})"


@dataclass(frozen=True)
class Reference:
    """The model a candidate is judged against (the base with the effects accepted so far): per stride its
    held-out trajectory SSE, and its held-out next-apex errors."""

    sse: np.ndarray
    errors: Errors


@dataclass(frozen=True)
class Completeness:
    """What the accepted effects leave: the held-out next-apex errors against those of a model without any
    mismatch on this recording (`yardstick.noise_floor`), the share of the model's excess over that floor left,
    and the strongest located residual left."""

    floor: Errors
    over_floor: dict                 # E_p, E_v, E_t after the accepted effects over their floor
    left_pct: float                  # share of the model's excess over the floor left [%]
    explained: bool                  # nothing located, and every error within floor_factor x its floor or at
    #                                  most explained_left_pct of the model's excess left
    site: str                        # where the residual left stands out ("" when nowhere)
    path_only: bool = False          # the model's own next apexes are within floor_factor x the floor: what is
    #                                  found changes the path between apexes, not the next apex

    def words(self) -> str:
        ratios = "/".join(f"{self.over_floor[k]:.1f}" for k in APEX_ERRORS)
        if self.path_only:
            return (("explained" if self.explained else f"partly explained, at {self.site or 'the next apex'}")
                    + "; it changes the path between apexes, not the next apex (the model's held-out next apexes "
                    "are at the noise floor)")
        if self.explained:
            return (f"explained (held-out E_p/E_v/E_t at {ratios} x the noise floor, {self.left_pct:.0f} % of the "
                    "model's excess over it left)")
        where = self.site or f"the next apex (E_p/E_v/E_t at {ratios} x the noise floor), not located"
        return f"partly explained: {self.left_pct:.0f} % of the residual left, at {where}"

    def as_dict(self) -> dict:
        return {"explained": self.explained, "residual_left_pct": self.left_pct, "at": self.site,
                "path_only": self.path_only,
                "noise_floor": self.floor.as_dict(), "over_noise_floor": dict(self.over_floor)}


def completeness(before: Errors, after: Errors, floor: Errors, left: list, settings: Settings) -> Completeness:
    """How much of the mismatch the accepted effects explain (`left`: the located residual they leave)."""
    over = {k: getattr(after, k) / max(getattr(floor, k), 1e-9) for k in APEX_ERRORS}
    above = [loc for loc in left if loc.ratio >= settings.locate_threshold]
    excess = max(before.total - floor.total, 1e-9)
    share = 100.0 * min(max(after.total - floor.total, 0.0) / excess, 1.0) if math.isfinite(after.total) else 100.0
    explained = not above and (all(r <= settings.floor_factor for r in over.values())
                               or share <= settings.explained_left_pct)
    path_only = all(getattr(before, k) <= settings.floor_factor * getattr(floor, k) for k in APEX_ERRORS)
    return Completeness(floor, over, share, explained, above[0].words() if above else "", path_only)
