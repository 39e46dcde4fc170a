"""The leg's swing in flight reacting on the body (issue 28): a leg with mass m_l, its centre r_c below the hip,
swung in flight from its lift-off angle to the next touchdown's. The centre of mass of body and leg follows the
flight's law (2.8); the body, which the encoders read, recoils against the swing (`laws.swing_offset`):

    p = c - mu r_c (sin theta - sin theta_ref, cos theta_ref - cos theta),   mu = m_l / (m_b + m_l),

theta the recorded leg angle, theta_ref the angle at the flight's end where body and centre of mass move together
(the leg held for touchdown in descent, caught at lift-off in ascent). In stance the model is the body's.

The lanes integrate the centre of mass: started from the apex as read moved by the recoil (the apex speed's fit,
a quadratic over `speed_window` of y, read the body's: the same fit of sin theta times mu r_c is added back), their
flight read back as the body's, the next apex as its fits would read it. The swing changes the path read and the
apex speed read, not the centre of mass's motion. One magnitude, mu r_c [m], searched like any effect.
"""

from __future__ import annotations

import numpy as np

from hopper_ros.identification.strides import ExtractionSettings
from hopper_ros.physics.laws import swing_offset

from .candidates import Candidate

NAME = "leg_swing"          # the candidate's name and the sensors' key of mu r_c [m] (`simulate`)
REACH = 0.04                # [m] the largest mu r_c searched (a leg of a third of the mass, its centre 12 cm down)
FLIGHT_GAP = 0.005          # [s] samples further apart than this are not one flight


class Swing:
    """The words of the law at a magnitude mu r_c."""

    def words(self, value: float) -> str:
        return (f"in flight, the leg's swing reacts on the body: the centre of mass of body and leg follows the "
                f"flight's law and the body recoils against the leg swung from lift-off to the next touchdown's "
                f"angle, mu r_c = {1e3 * value:.3g} mm (the leg's share of the mass m_l/(m_b + m_l) times the "
                f"distance of its centre below the hip: a leg of {1e3 * value:.3g} % of the mass, its centre 10 cm down)")

    def terms(self) -> list:
        return [("mu r_c (sin theta, -cos theta)", 1.0, "the body's recoil against the leg's swing in flight", "m")]


def swing_candidate() -> Candidate:
    def build(variant, value: float):
        return variant.with_changes(sensors={NAME: float(value)})

    return Candidate(NAME, "physics", "flight", "flight_horizontal", "m", Swing().words(0.0), 0.0, REACH, build,
                     float, "the leg swung in flight with the body held on the boom (the body's recoil), or flights "
                     "with the leg held still", discovery=Swing(),
                     equation="p = c - mu r_c (sin theta, -cos theta) + const in flight, c by (2.8)")


def _fit_slope(t: np.ndarray, x: np.ndarray, phase: np.ndarray, t0: float, half: float) -> float:
    """The linear coefficient at t0 of a quadratic fit of x over the flight samples within `half` of t0 (the apex
    speed's fit, `strides._apex`); 0 where fewer than 5 samples."""
    n = len(t)
    k = int(np.clip(np.searchsorted(t, t0), 0, n - 1))
    lo = hi = k
    while lo > 0 and t[lo - 1] >= t0 - half and t[lo] - t[lo - 1] < FLIGHT_GAP and phase[lo - 1] not in (1, 2, 3):
        lo -= 1
    while hi < n - 1 and t[hi + 1] <= t0 + half and t[hi + 1] - t[hi] < FLIGHT_GAP and phase[hi + 1] not in (1, 2, 3):
        hi += 1
    if hi - lo < 4:
        return 0.0
    return float(np.polyfit(t[lo:hi + 1] - t0, x[lo:hi + 1], 2)[1])


def recoil(times, angle, touchdown_time: float, liftoff_time: float, touchdown_angle: float, caught: float):
    """(dy, dz) per metre of mu r_c at `times`, the leg at `angle` there: the centre of mass of body and leg less
    the body's (`laws.swing_offset`), in descent from the angle held for touchdown, in ascent from the angle caught
    at lift-off (where body and centre of mass move together), 0 in stance."""
    dy, dz = np.zeros(len(times)), np.zeros(len(times))
    for flight, ref in ((times < touchdown_time, touchdown_angle), (times >= liftoff_time, caught)):
        dy[flight], dz[flight] = swing_offset(angle[flight], ref)
    return dy, dz


def geometry(data, samples: int, sample: float = 1e-3) -> dict:
    """Per stride, at unit mu r_c: the offset of the centre of mass from the body on the lanes' grid (`dy`, `dz`,
    strides x samples; 0 in stance), the apex speed fit's share at the start and next apex (`start_slope`,
    `next_slope`) and the offsets at the next apex (`next_dy`, `next_dz`). Computed once per recording."""
    cache = data.swing
    if samples in cache:
        return cache[samples]
    s, rec = data.strides, data.rec
    t, theta = np.asarray(rec.t, float), np.asarray(rec.theta, float)
    half = ExtractionSettings().speed_window
    sin = np.sin(theta)
    ns = len(s)
    dy, dz = np.zeros((ns, samples)), np.zeros((ns, samples))
    out = {k: np.zeros(ns) for k in ("start_slope", "next_slope", "next_dy", "next_dz")}
    for i in range(ns):
        a, b = int(s.start[i]), min(len(t), int(s.stop[i]) + 50)
        lane_t = s.apex_time[i] + sample * np.arange(samples)
        angle = np.interp(lane_t, t[a:b], theta[a:b])
        caught = np.interp(s.liftoff_time[i], t[a:b], theta[a:b])
        dy[i], dz[i] = recoil(lane_t, angle, s.touchdown_time[i], s.liftoff_time[i], s.touchdown_angle[i], caught)
        out["next_dy"][i], out["next_dz"][i] = swing_offset(np.interp(s.next_apex_time[i], t[a:b], theta[a:b]),
                                                            caught)
        out["start_slope"][i] = _fit_slope(t, sin, data.phase, s.apex_time[i], half)
        out["next_slope"][i] = _fit_slope(t, sin, data.phase, s.next_apex_time[i], half)
    cache[samples] = {"dy": dy, "dz": dz, **out}
    return cache[samples]
