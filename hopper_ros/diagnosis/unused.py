"""Laws of what the model does not use, judged on the trajectory test's noise level (issue 28, point 1): the boom's
angle about its vertical axis (`azimuth`: the forward position read with an error periodic in it), the leg's
compression since its last reversal (`hysteresis`: a hysteretic leg force), the leg's compression rate over its
history (`relaxation`: a leg force that relaxes, a Maxwell element), the leg's angle in flight (`swing`:
the body's recoil against the leg swung in flight), the leg's speed beside the command (`backemf`: the drive's
voltage limiting the motor's current against its back-EMF), the time since touchdown beside the leg angle
(`servo`: the flight's position servo released late), the contact point's motion in stance (`foot`: a round
toe rolling on the ground) and the height above the boom's pivot beside the forward speed (`sphere`: the body carried
on the boom's sphere, not a plane).

Where the accepted effects, the leg angle's laws (`angle`) and a drift leave the recording not explained, each law
is fitted (the period by a frequency scan, the yield on a grid, the trajectories choosing) and put in a round with
the library's effects (screened as in a round; `angle.win_round`): it is said only where it wins that round (a
sensor fault by the sensor margin), with every guard of an effect, on held-out strides. The round scores the
re-simulated strides against the noise level each channel's samples have as re-simulations from an estimated apex
(`yardstick.trajectory_sd`, its mean square per channel: the sensor's noise and the start's uncertainty carried
through the model), not the sensor's alone: on a leg angle that is only quantised (2 pi / 52,000 rad, 35 urad) the
sensor's level makes every stride's stance angle, moved by its apex's estimate (0.5 mrad for 0.1 mm), outweigh
the rest of the recording, and a law that brings the next apex to the noise floor (plant C's leg hysteresis: held-out
E_p 1.70 -> 0.09 %) then scores worse than the model by trajectory.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from . import backemf, hysteresis, relaxation, servo
from .angle import best_candidate, win_round
from .azimuth import eccentricity_candidate, find_eccentricity
from .candidates import Candidate
from .dependence import lap_length
from .foot import foot_candidate
from .locate import locate
from .records import Errors, Reference, Scored
from .search import Search
from .simulate import CHANNELS, simulate_variants
from .sphere import sphere_candidates
from .swing import swing_candidate
from .yardstick import trajectory_sd

WHAT = "the boom's angle and the leg's reversals"


def rescaled(search: Search, base_series: list, moves: list) -> tuple[Search, Reference]:
    """A search on the recording with each channel's noise level the trajectory test's (the mean square of
    `trajectory_sd` over the samples a search scores), and the model's reference on it."""
    data = search.data
    sd = trajectory_sd(data, base_series, moves)
    s = data.strides
    sigma = {}
    for ch in CHANNELS:
        squares = []
        for i in range(len(s)):
            ph = data.phase[int(s.start[i]):int(s.stop[i])]
            use = ((ph == 1) | (ph == 2)) if ch == "theta" else np.ones(len(ph), bool)
            squares.append(sd[i][ch][use] ** 2)
        mean = float(np.mean(np.concatenate(squares))) if squares else 0.0
        sigma[ch] = max(float(np.sqrt(mean)), data.sigma[ch]) if np.isfinite(mean) else data.sigma[ch]
    scaled = dataclasses.replace(data, sigma=sigma)
    scaled.sample_count, scaled.corr_length = data.sample_count, data.corr_length
    scaled.stance_start, scaled.touchdown_lead = data.stance_start, data.touchdown_lead
    sim = simulate_variants(scaled, [search.base])
    scaled.model_sse = float(sim["sse"][0].sum())
    model = Reference(sim["sse"][0], Errors.of(scaled, {k: v[0] for k, v in sim["pred"].items()}))
    return Search(scaled, search.base, search.settings, search.progress), model


def refitted(search: Search, chosen: list[Scored], current: Reference) -> Reference:
    """The accepted effects' held-out reference with them refitted on this search's noise levels (they were fitted
    on the sensors'): a candidate's search refits them beside it, and that refit alone must not count as the
    candidate's (on the independent plant's toe slip it took 39 % off with no hysteresis at all). `current` where
    there are none."""
    if not chosen:
        return current
    null = Candidate("refit", "physics", "none", "", "", "the accepted effects refitted", 0.0, 1.0,
                     lambda variant, value: variant, float)
    again = search.search(search.stack(chosen), [null], current)[0]
    return Reference(again.held_sse, again.errors)


def find_unused_law(search: Search, chosen: list[Scored], current: Reference, sets, located: set) -> Scored | None:
    """The boom angle's periodic reading error (where its scan stands on held-out strides), the leg's hysteresis, its
    relaxing force, the leg's swing in flight, the drive's voltage limit, the servo released late, a round toe rolling
    in stance or the boom's sphere, where it wins a round beside the accepted effects against the library's (each
    judged against the accepted effects `refitted` on this search); None otherwise."""
    settings = search.settings
    stack = search.stack(chosen)
    current = refitted(search, chosen, current)
    laws = []
    eccentric = find_eccentricity(search.data, stack.variant(), settings, lap_length(settings))
    if eccentric:       # the period the trajectories fit best
        laws.append(best_candidate(search, stack, [eccentricity_candidate(e) for e in eccentric], current))
    yields = hysteresis.yields(settings)
    laws.append(best_candidate(search, stack, [hysteresis.hysteresis_candidate(x) for x in yields], current))
    laws.append(relaxation.best_relaxation(search, stack, current, settings))
    laws.append(swing_candidate())
    constant, command = backemf.motor_constant(), float(np.max(np.abs(search.data.strides.tau_0), initial=0.0))
    if command > 0.0:
        sweep = backemf.sweep_bound(search.data)
        laws.append(best_candidate(search, stack, [backemf.back_emf_candidate(r, constant, command, sweep)
                                                   for r in backemf.resistances(settings)], current))
    laws.append(servo.best_release(search, stack, current, settings))
    laws.append(foot_candidate())
    laws.append(best_candidate(search, stack, sphere_candidates(), current))
    taken = {r.name for r in chosen}      # a law found by an earlier pass is not offered again
    return win_round(search, chosen, current, [c for c in laws if c.name not in taken], located, WHAT)


def on_plain_model(rec, params, settings) -> Scored | None:
    """The stage forced on the plain model, whatever the rounds would accept and whether or not it is explained:
    the check that it finds its law only where a recording has it."""
    from .core import start
    from .yardstick import start_moves
    search, base_sim, _ = start(rec, params, settings)
    scaled, model = rescaled(search, base_sim["series"], start_moves(search.data, search.base, base_sim))
    locations, sets = locate(scaled.data, scaled.base)
    located = {loc.site for loc in locations if loc.ratio >= settings.locate_threshold}
    return find_unused_law(scaled, [], model, sets, located)
