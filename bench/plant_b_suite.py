"""Scores `hopper diagnose` on recordings of plant B (test/plant_b/): a second plant written blind, from the
thesis alone, by an author who read neither the diagnosis code, the effect library nor the first independent
plant, with effects in its own parameterisation, many of them no library entry has.

What counts as right, per plant-B effect: a library entry that models the same law, named (or listed as not
separable from the one named) with its magnitude within 20 % once converted; where the plant's law is not a
library law, the library entry that is its nearest look-alike (its magnitude is not comparable) or terms
discovered where it acts (by mechanism where those terms are the plant's own law with its magnitude within 25 %,
`DISCOVERED_LAWS`). A verdict matching no concealed effect is a false positive. The rows feed
`diagnosis_suite.summarise`.
"""

from __future__ import annotations

import sys

from diagnosis_suite import dependence_found, main, suite, summarise  # bench/ is on sys.path

G, TOE_MASS, BODY_MASS, REST_LENGTH = 11.42, 0.03, 2.20, 0.205   # config/model.yaml, the plant's nominal model


# plant-B effect id -> ({library entry: magnitude converter, or None for a look-alike of another law},
#                       discovered sites that are right for it)
MATCH = {
    "quadratic_air_drag": ({"quadratic_drag": lambda m: m}, set()),
    "boom_descent_drag": ({"flight_damping_vertical": None}, {"flight_vertical"}),
    "effective_gravity_error": ({"effective_gravity": lambda m: G * (1 + m)}, set()),
    "softening_leg_spring": ({"spring_quadratic": lambda m: -m, "spring_cubic": None, "leg_stiffness": None},
                             {"stance_along"}),
    "extension_extra_damping": ({"leg_damping": None, "quadratic_leg_damping": None}, {"stance_along"}),
    # an unsprung toe stopped at touchdown: v_along+ = v_along- m_b / (m_b + m_u)
    "unsprung_toe_impact": ({"touchdown_loss_along": lambda m: m / (BODY_MASS + m)}, {"touchdown_along"}),
    "undulating_floor": ({"ground_height": None}, {"touchdown_along", "touchdown_timing"}),
    "backemf_torque_speed": ({"torque_speed_slope": lambda m: 1.0 / m, "hip_viscous_friction": None,
                              "torque_gain": None}, {"stance_hip"}),
    "torque_deadband": ({"torque_dead_band": lambda m: m, "torque_offset": None, "hip_dry_friction": None,
                         "torque_gain": None}, {"stance_hip"}),
    "harder_liftoff_collision": ({"liftoff_collision": lambda m: TOE_MASS + m}, {"liftoff_along", "liftoff_across"}),
    "z_sensor_scale": ({"z_scale": lambda m: 1 + m}, set()),
    "theta_sensor_delay": ({"theta_delay": lambda m: m}, set()),
    "theta_encoder_backlash": ({"theta_backlash": lambda m: m, "theta_delay": None, "theta_offset": None},
                               {"stance_hip"}),
    "hip_cogging_ripple": ({"hip_ripple": lambda m: m}, {"stance_hip"}),
    "spring_stiffness_drift": ({"leg_stiffness": None}, {"stance_along"}),
    "hip_torque_axial_coupling": ({}, {"stance_along"}),
    "boom_ringing_after_liftoff": ({}, {"flight_vertical", "flight_horizontal"}),
    "umbilical_tether_pull": ({"boom_bearing_friction": lambda m: m / BODY_MASS, "boom_friction_horizontal": None,
                               "flight_damping_horizontal": None},
                              {"flight_horizontal"}),
}


def _one_way(toward: float, against: float, scale: float):
    """A law acting one way of the motion only: its magnitude (`toward` x `scale`) where the other way's
    coefficient is at most a quarter of it, else None (a law both ways is another law)."""
    return toward * scale if abs(against) <= 0.25 * abs(toward) else None


# plant-B mechanism -> (the discovered terms that are its law, the plant's magnitude from their fitted coefficients
# or None). A discovered law with exactly these terms and that magnitude within 25 % is the mechanism named, not a
# look-alike (issue 28: "a law with fitted coefficients and words"). The terms' coefficients (`physics.terms`):
# flight, vertical a zdot + b |zdot| (a force [N]: a + b rising, a - b descending); along the leg
# -a rho' - b |rho'| (a + b in extension, a - b in compression), c x^2 and c tau/rho.
DISCOVERED_LAWS = {
    # z'' += -b z' while descending (an acceleration [1/s]): the descending force over the body's mass
    "boom_descent_drag": ({"zdot", "|zdot|"},
                          lambda t: _one_way(t["zdot"] - t["|zdot|"], t["zdot"] + t["|zdot|"], -1.0 / BODY_MASS)),
    # F_damp = -dd rho' in extension only [N s/m]
    "extension_extra_damping": ({"rho'", "|rho'|"},
                                lambda t: _one_way(t["rho'"] + t["|rho'|"], t["rho'"] - t["|rho'|"], 1.0)),
    # F_leg += kappa tau [1/m], the plant's torque of the same sign as the model's: the term tau/rho at the leg's
    # rest length (the leg is within 20 % of it in stance)
    "hip_torque_axial_coupling": ({"tau/rho"}, lambda t: t["tau/rho"] / REST_LENGTH),
    # F_spring = k x - k2 x^2 [N/m^2]: the term x^2 with the coefficient -k2
    "softening_leg_spring": ({"x^2"}, lambda t: -t["x^2"]),
}


def discovered_law(effect_id: str, option) -> float | None:
    """The plant's magnitude read from a discovered entry that is the mechanism's own law, else None."""
    law = DISCOVERED_LAWS.get(effect_id)
    if law is None:
        return None
    keys, magnitude = law
    terms = {key: coef * option.value for key, coef, _, _ in option.candidate.discovery.terms()}
    return magnitude(terms) if set(terms) == keys else None


# the laws of `diagnosis.angle` (a backlash, a ripple periodic in the leg angle) count within 25 %, as a dependence
TOLERANCE = {"theta_backlash": 0.25, "hip_ripple": 0.25}
MECHANISM_TOLERANCE = 0.25    # issue 28's acceptance: by mechanism with the magnitude within 25 % (a hit: 20 %)
# plant-B mechanism -> the main parameter whose drift (`diagnosis.drift`) is that mechanism, and the library entry
# that holds the same parameter's level beside the trend (part of the same finding, not a verdict of its own)
DRIFTS = {"spring_stiffness_drift": "stiffness"}
# plant-B mechanism -> the forms of a dependence on the track position (`diagnosis.dependence`) that are it
DEPENDENCES = {"undulating_floor": {"wave", "tilt"}}
DRIFT_LEVEL = {"stiffness": "leg_stiffness", "damping": "leg_damping", "gravity": "effective_gravity",
               "rest_length": "rest_length"}


def score(result, truth: dict) -> dict:
    """Hits (with how: magnitude within 20 %, look-alike or discovered), misses and false positives; for issue 28
    also by mechanism (a law of its own with the magnitude within 25 %: a converted entry, a drift of the parameter
    that drifts) against look-alikes (an entry without a conversion, discovered terms at a site where it acts),
    false verdicts (drifts included) and whether a clean recording was flagged."""
    used, hits, misses, by_mechanism = set(), [], [], []
    drifts_used, dependences_used = set(), set()
    for effect in truth["effects"]:
        names, sites = MATCH.get(effect["id"], ({}, set()))
        found = None
        dependence = dependence_found(result, effect, DEPENDENCES.get(effect["id"], set()), dependences_used)
        if dependence:
            by_mechanism.append(effect["id"])
            found = (None, dependence[1])
        for k, drift in enumerate(result.drifts):
            if DRIFTS.get(effect["id"]) == drift.parameter:
                want = float(effect["magnitude"])
                if abs(drift.change_pct / 100.0 - want) <= 0.25 * abs(want):
                    drifts_used.add(k)
                    used.update(j for j, r in enumerate(result.chosen) if r.name == DRIFT_LEVEL[drift.parameter])
                    by_mechanism.append(effect["id"])
                    found = (None, f"drift of {drift.parameter} {drift.change_pct:+.1f} % (true {100 * want:+.1f} %)")
        near = None
        for k, r in enumerate(result.chosen):
            if found:
                break
            for option in [r] + list(r.ties):
                c = option.candidate
                if c.name in names:
                    convert = names[c.name]
                    if convert is None:
                        found = (k, f"{c.name} {option.magnitude:.4g} (look-alike)")
                    else:
                        want = convert(float(effect["magnitude"]))
                        off = abs(option.magnitude - want)
                        if off <= TOLERANCE.get(c.name, 0.2) * abs(want):
                            found = (k, f"{c.name} {option.magnitude:.4g} (true {want:.4g})")
                            by_mechanism.append(effect["id"])
                        elif off <= MECHANISM_TOLERANCE * abs(want) and near is None:
                            near = k      # issue 28's by mechanism (25 %), not a hit (20 %)
                elif c.kind == "discovered" and c.site in sites:
                    found = (k, f"{c.name}: {c.describe(option.value)}")
                    law, want = discovered_law(effect["id"], option), float(effect["magnitude"])
                    if law is not None and abs(law - want) <= MECHANISM_TOLERANCE * abs(want):
                        found = (k, f"{c.name}, its law {law:.4g} (true {want:.4g})")
                        by_mechanism.append(effect["id"])
                if found:
                    break
        if found:
            used.add(found[0])
            hits.append((effect["id"], found[1]))
        else:
            misses.append((effect["id"], effect["magnitude"]))
            if near is not None:
                used.add(near)
                by_mechanism.append(effect["id"])
    false = [r.name for k, r in enumerate(result.chosen) if k not in used]
    false_drifts = [f"drift of {d.parameter}" for k, d in enumerate(result.drifts) if k not in drifts_used]
    false_drifts += [f"dependence ({d.form})" for k, d in enumerate(result.dependences) if k not in dependences_used]
    return {"hits": hits, "misses": misses, "false_positives": false, "located": [], "effects": len(truth["effects"]),
            "clean": not truth["effects"], "physics_only": not any(e["site"].startswith("sensor")
                                                                    for e in truth["effects"]),
            "by_mechanism": by_mechanism, "false_verdicts": false + false_drifts,
            "flagged": bool(result.chosen or result.drifts or result.dependences)
            or result.verdict != "no significant mismatch"}


run = suite(score, summarise, lambda s: (
    f"{s['name']}: {len(s['hits'])}/{s['effects']} {s['hits']} missed {s['misses']} false "
    f"{s['false_positives']}, {s['seconds']:.0f} s | {s['verdict']}"))

if __name__ == "__main__":
    main(run, sys.argv)
