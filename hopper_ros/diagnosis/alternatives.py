"""Laws of the same part told apart from an accepted library effect (issue 28, point 1: the size of the commanded
torque, a dead band against friction; point 3: torque x speed; a spring's shape).

An accepted library effect may be the nearest library law of a mechanism the library does not hold. Each accepted
effect with a law of its part here (`ALTERNATIVES`) is searched again beside the others, against that law in its
place. The law replaces it where held-out strides tell the two apart in its favour (paired t of at least `tie_t`,
below which two effects are not separable: both are laws of one magnitude, neither has a naming margin), it passes
every guard of an effect, and its next apex is not worse (`apex_tolerance`; an error within `floor_factor` of its
noise floor, where the recording counts as explained, is not worse: plant B's tether pull, E_t 0.0448 % for 0.0424 %,
floor 0.0405 %, beside E_p 0.076 % for 0.087 %). Where discovered terms were accepted
at the law's site (they patched what the look-alike left), the law is also tried in place of both: it replaces them
where the smaller set fits held-out strides not clearly worse (paired t below `tie_t`) with its next apex not worse.
The library effect then stays beside the law as its look-alike. The laws are not in the library's rounds: a larger
library moves which candidates reach the full search (docs/diagnosis_measured.md, the screening's price); here one
is tried only where its look-alike won.

- `hip_dry_friction` -> `torque_dead_band`: a torque lost against the hip's sweep, or the first delta of every
  command lost, tau = sign(tau_cmd) max(|tau_cmd| - delta, 0) (a gearbox's static friction seen through the
  command). Alike while the stance ramp (2.32) is above delta; the dead band gives nothing once the ramp has
  fallen below delta and after it ends, where dry friction still brakes the sweep until lift-off.
- `torque_gain` -> `torque_speed_slope`: a fixed share of every command lost, or a share that grows with the leg's
  sweep, tau = tau_cmd (1 - s |theta'|) (a torque-speed line: a drive that derates with the back-EMF; issue 28
  point 3's torque x speed). Alike where the sweeps of all stances are alike; told apart by the fast ones.
- `boom_friction_horizontal` -> `boom_bearing_friction`: the dry friction of the boom's vertical axis, y'' -= a
  sign(y'), in flight only (the library's law) or whenever the body moves forward, in stance too (issue 28 point 4:
  a bearing turns in every phase; a constant drag of a cable behind the robot acts alike). Alike in flight; told
  apart by the stances, where the one brakes the forward motion and the other does not.
- `leg_stiffness` -> `spring_quadratic`: the spring's force k x + k_2 x^2 (x = rho_0 - rho, (2.9)'s spring with a
  term of its square: a spring that softens, k_2 < 0, or stiffens as it compresses, one way only), where a
  stiffness alone is the nearest straight line.
"""

from __future__ import annotations

import copy

import numpy as np

from hopper_ros.physics import effects as library

from . import acceptance
from .backemf import sweep_bound
from .candidates import Candidate
from .records import Errors, Scored
from .search import Search
from .simulate import Variant

DEAD_BAND = "torque_dead_band"
QUADRATIC = "spring_quadratic"
SPEED_SLOPE = "torque_speed_slope"
BEARING = "boom_bearing_friction"
STANCE_FRICTION = "stance_friction_y"
DEAD_BAND_SHARE = 0.5          # the dead band searched up to this share of the largest command (above, most strides'
#                                commands would give nothing)
QUADRATIC_LENGTH = 0.1         # [m] k_2 searched within +-k / this: at 5 cm of compression, half the spring's force


def dead_band_candidate(search: Search) -> Candidate | None:
    """The torque dead band, searched from none to `DEAD_BAND_SHARE` of the recording's largest command [N m]; None
    where nothing was commanded."""
    command = float(np.max(np.abs(search.data.strides.tau_0), initial=0.0))
    if command <= 0.0:
        return None

    def build(variant: Variant, delta: float) -> Variant:
        return variant.with_changes(coefficients={DEAD_BAND: float(delta)})

    return Candidate(DEAD_BAND, "physics", "actuator", "stance_hip", "N m",
                     "the hip loses the first delta of every commanded torque: commands smaller than delta give no "
                     "torque, larger ones delta less (a dead band: the gearbox's static friction seen through the "
                     "command, not a friction against the leg's sweep)", 0.0, DEAD_BAND_SHARE * command, build, float,
                     "strides whose commanded torque ends early in the stance, or small commands (a dead band gives "
                     "nothing where the command is below it; a dry friction brakes the sweep until lift-off)",
                     equation="tau = sign(tau_cmd) max(|tau_cmd| - delta, 0)")


def quadratic_spring_candidate(search: Search) -> Candidate:
    """The spring's quadratic term k_2 [N/m^2], searched within +-k / `QUADRATIC_LENGTH` about none."""
    bound = float(search.base.coefficients.stiffness) / QUADRATIC_LENGTH

    def build(variant: Variant, k_2: float) -> Variant:
        return variant.with_changes(coefficients={QUADRATIC: float(k_2)})

    return Candidate(QUADRATIC, "physics", "leg", "stance_along", "N/m^2",
                     "the leg spring's force has a term in the square of its compression, F = k x + k_2 x^2 (it "
                     "softens as it compresses where k_2 < 0, stiffens where k_2 > 0; not a stiffer or softer "
                     "straight line)", -bound, bound, build, float,
                     "the leg compressed statically by known loads (a force-compression curve)",
                     equation="F = k x + k_2 x^2 - d rho'  (2.9), x = rho_0 - rho")


def speed_line_candidate(search: Search) -> Candidate:
    """The torque's fall with the leg's sweep, s [s/rad], searched from none to where the fastest sweep of the
    recording (`backemf.sweep_bound`) would leave no torque."""
    def build(variant: Variant, slope: float) -> Variant:
        return variant.with_changes(coefficients={SPEED_SLOPE: float(slope)})

    return Candidate(SPEED_SLOPE, "physics", "actuator", "stance_hip", "s/rad",
                     "the hip's torque falls linearly with the leg's sweep, tau = tau_cmd (1 - s |theta'|), none at "
                     "the no-load sweep 1/s (a torque-speed line: a drive derating with the motor's back-EMF, not a "
                     "fixed share of every command)", 0.0, 1.0 / sweep_bound(search.data), build, float,
                     "the leg swept by hand at several speeds against a fixed torque command (a torque-speed line "
                     "loses more the faster; a gain the same share at any speed)",
                     equation="tau = tau_cmd (1 - s |theta'|), 0 past 1/s")


def bearing_friction_candidate(search: Search) -> Candidate:
    """The boom's dry friction about its vertical axis in every phase, a [m/s^2] on the forward motion, searched
    over the library's flight-only law's bounds."""
    effect = library.get("boom_friction_horizontal")
    low, high = effect.data_bounds(search.base.coefficients, {})

    def build(variant: Variant, value: float) -> Variant:
        return variant.with_changes(coefficients={"flight_friction_y": float(value), STANCE_FRICTION: float(value)})

    return Candidate(BEARING, "physics", effect.family, "flight_horizontal", effect.primary.unit,
                     "a dry friction brakes the forward motion in every phase, y'' -= a sign(y') in stance as in "
                     "flight (the boom's bearing about its vertical axis turns whenever the body moves forward; a "
                     "cable dragged behind the robot pulls alike)", low, high, build, float,
                     "the boom pushed round slowly by hand with the leg off the ground and on it (the drag is the "
                     "same in both)", equation="y'' += -a sign(y') in flight and in stance")


# accepted library effect -> the law of the same part to tell it from
ALTERNATIVES = {"hip_dry_friction": dead_band_candidate, "torque_gain": speed_line_candidate,
                "leg_stiffness": quadratic_spring_candidate, "boom_friction_horizontal": bearing_friction_candidate}


def told_apart(search: Search, chosen: list[Scored], floor: Errors | None = None) -> list[Scored]:
    """`chosen` with each effect that has a law in `ALTERNATIVES` replaced by it (and the discovered terms at the
    law's site with it, where the smaller set does as well) where held-out strides tell the law apart as the better
    (its look-alike kept as a tie); unchanged elsewhere."""
    settings = search.settings
    out = list(chosen)
    for accepted in chosen:
        make = ALTERNATIVES.get(accepted.name)
        candidate = make(search) if make is not None else None
        if candidate is None or all(r is not accepted for r in out):
            continue
        search.progress.say(f"{accepted.name} against a law of the same part in its place")
        patches = [r for r in out if r.candidate.kind == "discovered" and r.candidate.site == candidate.site]
        whole = search.held_out(out) if patches else None      # what a smaller set in place of the patches is held to
        for leave in ([accepted] + patches, [accepted]) if patches else ([accepted],):
            position = next(k for k, r in enumerate([r for r in out if all(r is not x for x in leave[1:])])
                            if r is accepted)
            others = copy.deepcopy([r for r in out if all(r is not x for x in leave)])   # a trial moves magnitudes
            stack = search.stack(others)
            reference = search.reference(stack)
            ranking = search.search(stack, [accepted.candidate, candidate], reference)
            again = next(r for r in ranking if r.name == accepted.name)
            law = next(r for r in ranking if r.name == candidate.name)
            if not (law.significant and acceptance.real(law)):
                continue
            law = search.polish(others, law, reference)
            held = search.held_out(others + [law])
            if len(leave) > 1:      # in place of the look-alike and its patches: a smaller set not clearly worse
                better = (acceptance.paired_t(held.sse, whole.sse) < settings.tie_t
                          and not acceptance.worse_errors(held.errors, whole.errors, settings.apex_tolerance))
            else:
                worse = [k for k in acceptance.worse_errors(law.errors, again.errors, settings.apex_tolerance)
                         if floor is None or getattr(law.errors, k) > settings.floor_factor * getattr(floor, k)]
                better = acceptance.paired_t(again.held_sse, law.held_sse) >= settings.tie_t and not worse
            if not better:
                continue
            law.ties = [again] + [r for r in accepted.ties if r.name != law.name]
            law.location, law.alternatives = accepted.location, [accepted.candidate] + accepted.alternatives
            out = others[:position] + [law] + others[position:]
            break
    return out
