"""The deadbeat controller of chapter 5: at each apex, tau_0 and theta_td for the next one.

Section 5.1 splits the two-dimensional inversion of the return map (too slow for the thesis's
1 ms loop) into
- tau_0 from the energy balance (5.1)-(5.5), corrected (see physics/energy.py): the torque work
  W_tau must supply the apex energy change plus the stride's losses,
      W_tau(tau_0, theta) = m (y'*^2 - y'^2)/2 + m g (z* - z) + E_loss(tau_0, theta);
- theta_td by the one-dimensional inversion (5.6): the angle whose predicted next apex height is z*.

Both equations use a predictor's own stride: its next-apex energy already is E + W_tau - E_loss
(the energy budget closes, test_physics_energy), so the balance reads E_next(tau_0, theta) = E*,
solved together with z_next(tau_0, theta) = z* (5.6). Two stages, so that the 1 ms loop never
waits (the thesis's 2-D optimiser could not fit in it):

1. `first_decision`, within ~0.3 ms: Newton on the thesis's AAS (scalar closed forms, ~11 us per
   stride) from the last stride's inputs, aimed at the setpoint corrected by what the corrected
   predictor said about the AAS at the last stride (its defect). The leg starts moving at once.
2. `refine`, during the flight (~1 ms; the flight lasts >100 ms): the same inversion on the
   corrected AAS (`physics.corrected`, 40-250 times more accurate): one batched call evaluates a
   grid of touchdown angles around stage 1's at two torques; per angle the energy balance gives
   tau_0 (W_tau is linear in tau_0 over the step), and (5.6) is solved by interpolation along the
   angles. Stage 2's inputs are the stride's; it also renews the defect for the next stage 1.

Beyond the thesis (issue 7): stride-to-stride adaptation. The model's error on the last stride,
measured apex minus the model's prediction for the inputs applied, is averaged (gain
`adaptation_gain`) into an apex bias that the inversion then aims around: with gain 1 this is
pure integral action on the apex error. It removes the steady offset left by whatever the model
lacks (the simulated robot's extra effects, sensing bias). Switchable.

Beyond the thesis (issue 29): a setpoint out of reach. Where the energy balance needs more than
`max_torque` (or no angle gives z*), (5.6)'s rule, keep the height and let the speed go, is a trap:
the slower the leg sweeps in stance, the less work the hip torque does, and a robot slowed by a
disturbance settled at 0.29 m and 0.45 m/s for good (or, at the fold of z'(theta), was thrown back
or down). Stage 2 then takes the stride whose height and speed misses, weighed as the energies
they stand for (m g dz, m y'* dy'), are least, going the setpoint's way and aimed no lower than
`min_apex_height`: the robot gets back to the setpoint within a few strides. (Keeping the height
while that brings the apex energy nearer the setpoint's was tried: from 9 of 27 disturbed apexes
it oscillated or hung at 1.6 m/s under a 2 m/s setpoint for 8 strides and more.)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from hopper_ros.physics.params import ModelParams
from hopper_ros.physics.predictors import predict_stride

NEWTON_ITERATIONS = 6
HEIGHT_TOLERANCE = 5e-4     # [m] stage 1 stops when the AAS apex is this close ...
ENERGY_TOLERANCE = 5e-3     # [J] ... and the apex energy this close (stage 2 refines)
ANGLE_STEP = 1e-3           # [rad] finite-difference steps of the Jacobian
TORQUE_STEP = 0.05          # [N m]
MAX_ANGLE_STEP = 0.1        # [rad] Newton step limits
MAX_TORQUE_STEP = 3.0       # [N m]
SCAN_POINTS = 49            # touchdown angles of stage 2's last resort (`_scan`): 1 deg apart over 2-50 deg


@dataclass(frozen=True)
class DeadbeatSettings:
    predictor: str = "corrected"
    angle_span: float = 0.12          # [rad] the grid covers +/- this around the warm start
    angle_points: int = 13            # grid size along theta
    torque_step: float = 1.0          # [N m] second torque of the grid (W_tau linear over it)
    min_torque: float = 0.0           # [N m]
    max_torque: float = 12.0          # [N m] just below the drive's current limit (20 A: 12.5 N m)
    min_angle: float = math.radians(2.0)
    max_angle: float = math.radians(50.0)
    min_apex_height: float = 0.30     # [m] a stride off the setpoint is not aimed lower than this
    initial_torque: float = 4.0       # [N m] warm start of the first stride
    adaptation: bool = True
    adaptation_gain: float = 0.5      # share of the last stride's model error added to the bias
    max_bias_height: float = 0.03     # [m] bound on the learned height bias
    max_bias_speed: float = 0.3       # [m/s] bound on the learned speed bias
    adaptation_outlier: float = 4.0   # an error off the bias by more than this many typical ones is learned at that size
    adaptation_floor_height: float = 0.001   # [m] the typical height error taken at least this (0: no floor)
    adaptation_floor_speed: float = 0.01     # [m/s] ... the speed error's

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "deadbeat settings") -> "DeadbeatSettings":
        """Settings from a `deadbeat` section (missing keys: the defaults), checked by the schema of
        control.yaml (hopper_ros.config.schemas.CONTROL): types, ranges with units, min < max."""
        from hopper_ros.config.schemas import Deadbeat
        from hopper_ros.config.schema import validate

        defaults = {name: getattr(cls, name) for name in cls.__dataclass_fields__}
        return cls(**validate(Deadbeat, {**defaults, **dict(values)}, source, at="deadbeat"))


@dataclass
class StrideDecision:
    """What to do in the stride that starts at this apex, and what the model expects."""

    stride_index: int
    feasible: bool
    reason: str                      # "" when feasible and on target; else why (in words)
    tau_0: float                     # [N m]
    touchdown_angle: float           # [rad]
    ramp_duration: float             # [s] the ramp ends at the predicted lift-off (2.29)
    predicted_apex_height: float     # [m] next apex, model plus learned bias
    predicted_forward_speed: float   # [m/s]
    predicted_stride_time: float     # [s]
    target_height: float
    target_speed: float
    model_apex_height: float = math.nan   # [m] the model alone, for the adaptation
    model_forward_speed: float = math.nan
    compute_time: float = 0.0        # [s] wall time of this decision (stage 1 or stage 2)
    first_compute_time: float = math.nan   # [s] for a refined decision: stage 1's time
    bias: tuple[float, float] = field(default=(0.0, 0.0))


class DeadbeatController:
    """Chapter 5's controller as a plain object: `decide` at each apex, `observe` the next apex."""

    def __init__(self, params: ModelParams, settings: DeadbeatSettings | None = None) -> None:
        self.params = params
        self.settings = settings or DeadbeatSettings()
        self.bias_height = 0.0
        self.bias_speed = 0.0
        self._warm_angle: float | None = None
        self._warm_torque = self.settings.initial_torque
        self._defect = (0.0, 0.0)        # corrected minus AAS next apex at the last refined inputs
        self._jacobian = None            # stage 1's Jacobian, d(z', E')/d(theta, tau_0)
        self._pending: StrideDecision | None = None
        self._innovations: list[tuple[float, float]] = []   # the last strides' model errors off the bias

    def reset_adaptation(self) -> None:
        self.bias_height = self.bias_speed = 0.0
        self._innovations = []

    def neutral_angle(self, forward_speed: float) -> float:
        """Touchdown angle of a symmetric stance (Raibert): theta = asin(y' T_s / (2 rho_0))."""
        p = self.params
        stance_time = math.pi / math.sqrt(p.stiffness / p.body_mass)
        ratio = forward_speed * stance_time / (2.0 * p.rest_length)
        return math.asin(max(-0.9, min(0.9, ratio)))

    def prime(self, target_height: float, target_speed: float) -> None:
        """Before the first apex: solve the steady stride at the setpoint (apex = setpoint) once,
        so that the first real decision starts its Newton from near a solution with a Jacobian
        at hand instead of from the neutral angle and `initial_torque` (measured: 0.6 ms instead
        of 0.13 ms for the first stride). Learns nothing; a controller that has decided keeps its
        warm start."""
        if self._warm_angle is not None:
            return
        self.decide(target_height, target_speed, target_height, target_speed)
        self._pending = None

    # ------------------------------------------------------------------ decision
    def decide(self, apex_height: float, forward_speed: float, target_height: float, target_speed: float,
               stride_index: int = 0) -> StrideDecision:
        """Both stages: the fast decision, then its refinement (what the stride should use)."""
        first = self.first_decision(apex_height, forward_speed, target_height, target_speed, stride_index)
        return self.refine(first, apex_height, forward_speed)

    def first_decision(self, apex_height: float, forward_speed: float, target_height: float, target_speed: float,
                       stride_index: int = 0) -> StrideDecision:
        """Stage 1, within the 1 ms loop: (5.1)-(5.6) on the thesis's AAS (scalar closed forms,
        Newton with a finite-difference Jacobian from the last stride's inputs), aimed at the
        setpoint minus the learned bias minus the corrected predictor's last known defect."""
        started = time.perf_counter()
        s = self.settings
        bias = (self.bias_height, self.bias_speed) if s.adaptation else (0.0, 0.0)
        aim_height = target_height - bias[0] - self._defect[0]
        aim_speed = target_speed - bias[1] - self._defect[1]
        angle = self._warm_angle if self._warm_angle is not None else self.neutral_angle(forward_speed)
        warm_jacobian = self._jacobian
        evaluated = {}      # (theta, tau_0) -> AAS stride: both attempts below revisit points
        solved = self._newton(apex_height, forward_speed, aim_height, aim_speed, angle, self._warm_torque, evaluated)
        if (solved is None or solved[-1] == "height out of reach") and warm_jacobian is not None:
            # the last stride's Jacobian (Broyden-updated, then moved by stage 2's refinement) led
            # Newton astray: once more with a fresh finite-difference Jacobian at the warm start
            self._jacobian = None
            solved = self._newton(apex_height, forward_speed, aim_height, aim_speed, angle, self._warm_torque,
                                  evaluated)
        result = self._decision(stride_index, solved, target_height, target_speed, bias, forward_speed)
        if result.feasible:   # what the model (not the AAS) predicts is only known after stage 2
            result.predicted_apex_height, result.predicted_forward_speed = target_height, target_speed
        result.compute_time = time.perf_counter() - started
        self._pending = result if result.feasible else None
        return result

    def refine(self, first: StrideDecision, apex_height: float, forward_speed: float) -> StrideDecision:
        """Stage 2, during the flight (~1 ms): the inversion on the configured predictor (corrected
        AAS by default), one batched call around stage 1's inputs; also updates the defect that
        stage 1 uses next time. Where the setpoint is out of reach, stage 2's stride is the compromise
        of `_solve` (stage 1's keeps the height: the leg moves towards it for a millisecond). Where
        stage 1 found nothing, or the grid's best stride lies on its edge or runs the wrong way (Newton
        led astray: a stale Jacobian, the fold of z'(theta) near the torque limit), every touchdown
        angle is scanned once (`_scan`, 2-7 ms) before a stride is given up."""
        s = self.settings
        if s.predictor == "aas" and first.feasible:
            return first
        started = time.perf_counter()
        bias = first.bias
        aim_height, aim_speed = first.target_height - bias[0], first.target_speed - bias[1]
        solved = None
        if first.feasible:
            solved = self._solve(apex_height, forward_speed, aim_height, aim_speed, first.touchdown_angle, first.tau_0)
            if solved is not None and (solved[-1] == "outside" or abs(solved[0] - first.tau_0) > 1.5 * s.torque_step):
                # the solution left the grid (angle) or its linear range (torque): once more around it
                solved = self._solve(apex_height, forward_speed, aim_height, aim_speed, solved[1], solved[0])
        if solved is None or solved[-1] not in ("", "torque limit") or solved[4] * aim_speed < 0.0:
            scanned = self._scan(apex_height, forward_speed, aim_height, aim_speed,
                                 first.tau_0 if first.feasible else self._warm_torque)
            if scanned is not None and (solved is None or _better(scanned, solved, aim_height, aim_speed)):
                solved = scanned
        if solved is None:
            return first
        result = self._decision(first.stride_index, solved, first.target_height, first.target_speed, bias, forward_speed)
        seed = predict_stride(self.params, apex_height, forward_speed, result.touchdown_angle, result.tau_0,
                              result.ramp_duration, method="aas")
        if seed.ok:
            self._defect = (result.model_apex_height - seed.next_apex_height,
                            result.model_forward_speed - seed.next_forward_speed)
        result.first_compute_time = first.compute_time
        result.compute_time = time.perf_counter() - started
        self._pending = result
        return result

    def _scan(self, apex_height, forward_speed, aim_height, aim_speed, warm_torque):
        """The inversion over every touchdown angle (SCAN_POINTS from min_angle to max_angle), then on
        the ordinary grid around what it found, until the torque is within the grid's linear range
        (the scan's torques may be far from the one it needs): stage 2's last resort.
        (tau_0, theta, t_f, z, v, stride_time, status) or None."""
        s = self.settings
        found = self._solve(apex_height, forward_speed, aim_height, aim_speed, 0.5 * (s.min_angle + s.max_angle),
                            warm_torque, angles=np.linspace(s.min_angle, s.max_angle, SCAN_POINTS))
        torque = warm_torque
        for _ in range(3):
            if found is None or (found[-1] != "outside" and abs(found[0] - torque) <= 1.5 * s.torque_step):
                break
            torque = found[0]
            found = self._solve(apex_height, forward_speed, aim_height, aim_speed, found[1], torque) or found
        return found

    def _newton(self, apex_height, forward_speed, aim_height, aim_speed, angle, torque, evaluated=None):
        """Stage 1's solve of z'(theta, tau_0) = z*, E'(theta, tau_0) = E* on the scalar AAS.

        `evaluated` {(theta, tau_0): prediction} keeps the AAS strides from this apex: a point met
        again (the warm start of a second attempt, a Newton step that cycles) is not predicted twice."""
        s, p = self.settings, self.params
        m, g = p.body_mass, p.gravity
        target_energy = m * (0.5 * aim_speed ** 2 + g * aim_height)
        evaluated = {} if evaluated is None else evaluated

        def residual(theta, tau):
            r = evaluated.get((theta, tau))
            if r is None:
                r = evaluated[theta, tau] = predict_stride(p, apex_height, forward_speed, theta, tau, method="aas")
            if not r.ok:
                return None
            energy = m * (0.5 * r.next_forward_speed ** 2 + g * r.next_apex_height)
            return r.next_apex_height - aim_height, energy - target_energy, r

        def jacobian(theta, tau, at):
            d_angle = residual(theta + ANGLE_STEP, tau)
            d_torque = residual(theta, tau + TORQUE_STEP)
            if d_angle is None or d_torque is None:
                return None
            return [[(d_angle[0] - at[0]) / ANGLE_STEP, (d_torque[0] - at[0]) / TORQUE_STEP],
                    [(d_angle[1] - at[1]) / ANGLE_STEP, (d_torque[1] - at[1]) / TORQUE_STEP]]

        status = ""
        at = residual(angle, torque)
        # the last stride's Jacobian, kept up to date by Broyden's rule: ~2 predictions per apex
        J = self._jacobian
        for _ in range(NEWTON_ITERATIONS):
            if at is None:
                angle = 0.5 * (angle + self.neutral_angle(forward_speed))   # back towards a safe stride
                at, J = residual(angle, torque), None
                continue
            if abs(at[0]) < HEIGHT_TOLERANCE and abs(at[1]) < ENERGY_TOLERANCE:
                break
            if J is None:
                J = jacobian(angle, torque, at)
                if J is None:
                    return None
            (a, b), (c, d) = J
            det = a * d - b * c
            if det == 0.0:
                J = None
                continue
            step_angle = -max(-MAX_ANGLE_STEP, min(MAX_ANGLE_STEP, (d * at[0] - b * at[1]) / det))
            wanted = torque - max(-MAX_TORQUE_STEP, min(MAX_TORQUE_STEP, (a * at[1] - c * at[0]) / det))
            new_torque = max(s.min_torque, min(s.max_torque, wanted))
            if new_torque != wanted and a != 0.0:   # at the limit: keep the height (5.6), give up on the energy
                status = "torque limit"
                step_angle = -(at[0] + b * (new_torque - torque)) / a
            new_angle = max(s.min_angle, min(s.max_angle, angle + step_angle))
            step = (new_angle - angle, new_torque - torque)
            after = residual(new_angle, new_torque)
            if after is not None and (step[0] or step[1]):                       # Broyden's update
                norm = step[0] ** 2 + step[1] ** 2
                for row in (0, 1):
                    miss = after[row] - at[row] - (J[row][0] * step[0] + J[row][1] * step[1])
                    J[row] = [J[row][0] + miss * step[0] / norm, J[row][1] + miss * step[1] / norm]
            angle, torque, at = new_angle, new_torque, after
            if status and at is not None and abs(at[0]) < HEIGHT_TOLERANCE:
                break
        self._jacobian = J
        if at is None:
            return None
        r = at[2]
        if abs(at[0]) > 10 * HEIGHT_TOLERANCE and not status:
            status = "height out of reach"
        return (torque, angle, r.ramp_duration, r.next_apex_height, r.next_forward_speed, r.stride_time, status)

    def _solve(self, apex_height, forward_speed, aim_height, aim_speed, center, warm_torque, angles=None):
        """One batched predictor call over `angles` (default: the grid of `angle_span` around `center`);
        (tau_0, theta, t_f, z, v, stride_time, status) or None."""
        s, p = self.settings, self.params
        if angles is None:
            angles = np.clip(center + np.linspace(-s.angle_span, s.angle_span, s.angle_points), s.min_angle, s.max_angle)
        low = min(max(warm_torque - 0.5 * s.torque_step, s.min_torque), s.max_torque - s.torque_step)
        torques = np.array([low, low + s.torque_step])
        theta = np.tile(angles, 2)
        tau = np.repeat(torques, angles.size)
        n = angles.size
        prediction = predict_stride(p, np.full(2 * n, apex_height), np.full(2 * n, forward_speed), theta, tau,
                                    method=s.predictor)
        ok = np.asarray(prediction.ok, dtype=bool)
        z, v = np.asarray(prediction.next_apex_height), np.asarray(prediction.next_forward_speed)
        energy = p.body_mass * (0.5 * v * v + p.gravity * z)
        target_energy = p.body_mass * (0.5 * aim_speed ** 2 + p.gravity * aim_height)
        valid = ok[:n] & ok[n:]
        if not valid.any():
            return None
        gain = energy[n:] - energy[:n]                                  # W_tau per torque step
        fraction = np.where(valid & (gain > 1e-9), (target_energy - energy[:n]) / np.where(gain > 1e-9, gain, 1.0), np.nan)
        tau_needed = low + fraction * s.torque_step                    # energy balance (5.1)-(5.5) per angle
        tau_used = np.clip(tau_needed, s.min_torque, s.max_torque)
        share = (tau_used - low) / s.torque_step
        height = z[:n] + share * (z[n:] - z[:n])
        speed = v[:n] + share * (v[n:] - v[:n])
        ramp = np.asarray(prediction.ramp_duration)
        ramp = ramp[:n] + share * (ramp[n:] - ramp[:n])
        stride_time = np.asarray(prediction.stride_time)
        stride_time = stride_time[:n] + share * (stride_time[n:] - stride_time[:n])
        miss = height - aim_height
        usable = np.isfinite(miss)
        if not usable.any():
            return None
        # (5.6): the angle where the predicted height crosses z* with the energy balanced (no torque
        # clipping); of two, the one whose speed is nearest y'* (z'(theta) has a fold: past it the
        # robot is thrown back)
        clipped = tau_needed != tau_used
        wrong_way = usable & (speed * aim_speed < 0.0)
        crossings = [i for i in range(n - 1) if usable[i] and usable[i + 1] and miss[i] * miss[i + 1] <= 0.0
                     and not (wrong_way[i] or wrong_way[i + 1])]
        if crossings:
            i = min(crossings, key=lambda j: (bool(clipped[j] or clipped[j + 1]),
                                              abs(speed[j] - aim_speed) + abs(speed[j + 1] - aim_speed)))
            w = miss[i] / (miss[i] - miss[i + 1]) if miss[i] != miss[i + 1] else 0.0
            pick = lambda a: float(a[i] + w * (a[i + 1] - a[i]))  # noqa: E731
            if not (clipped[i] or clipped[i + 1]):
                return (pick(tau_used), pick(angles), pick(ramp), pick(height), pick(speed), pick(stride_time), "")
        # the setpoint's energy out of the torque's reach, or its height out of every angle's: not (5.6)'s
        # height kept and speed let go (the slower the leg sweeps, the less work the torque does: a trap),
        # but the stride nearest the setpoint, its height and speed misses weighed as the energies they
        # stand for (m g dz, m y'* dy'), among those that go the setpoint's way and stay above min_apex_height
        candidates = usable & ~wrong_way if (usable & ~wrong_way).any() else usable
        safe = candidates & (height >= s.min_apex_height)
        candidates = safe if safe.any() else candidates
        height_miss, speed_miss = p.gravity * miss, aim_speed * (speed - aim_speed)
        cost = height_miss ** 2 + speed_miss ** 2
        best = int(np.nanargmin(np.where(candidates, cost, np.nan)))
        # the least cost along theta, not only at the grid's angles (0.02 rad apart: up to 0.6 cm of height
        # at the step to 0.42 m): on a segment between two candidates the misses are linear in theta, so
        # the cost is a parabola whose least value is in closed form
        least, segment, w = cost[best], best, 0.0
        for j in (best - 1, best):
            if 0 <= j < n - 1 and candidates[j] and candidates[j + 1]:
                d_height, d_speed = height_miss[j + 1] - height_miss[j], speed_miss[j + 1] - speed_miss[j]
                span = d_height ** 2 + d_speed ** 2
                along = min(max(-(height_miss[j] * d_height + speed_miss[j] * d_speed) / span, 0.0), 1.0) if span > 0 else 0.0
                value = (height_miss[j] + along * d_height) ** 2 + (speed_miss[j] + along * d_speed) ** 2
                if value < least:
                    least, segment, w = value, j, along
        pick = lambda a: float(a[segment] + w * (a[min(segment + 1, n - 1)] - a[segment]))  # noqa: E731
        at_edge = segment + w in (0, n - 1) and s.min_angle < angles[best] < s.max_angle
        status = "outside" if at_edge else "torque limit" if clipped[best] else "height out of reach"
        return (pick(tau_used), pick(angles), pick(ramp), pick(height), pick(speed), pick(stride_time), status)

    def _decision(self, stride_index, solved, target_height, target_speed, bias, forward_speed) -> StrideDecision:
        if solved is None:
            angle = self.neutral_angle(forward_speed)
            return StrideDecision(stride_index, False, "no touchdown angle gives a stride the model can complete",
                                  0.0, angle, 0.0, math.nan, math.nan, math.nan, target_height, target_speed, bias=bias)
        tau_0, angle, ramp, height, speed, stride_time, status = solved
        if status == "outside":
            status = "height out of reach"
        self._warm_angle, self._warm_torque = angle, tau_0
        return StrideDecision(stride_index, True, status, tau_0, angle, ramp, height + bias[0], speed + bias[1],
                              stride_time, target_height, target_speed, height, speed, bias=bias)

    # ------------------------------------------------------------------ adaptation
    def forget_stride(self) -> None:
        """The stride last decided did not run as decided (a drive fault took its torque): its apex
        says nothing of the model's error. (Learned, one such apex drove the bias to its bound and the
        robot fell strides later.)"""
        self._pending = None

    def observe(self, apex_height: float, forward_speed: float) -> None:
        """The apex that ends the stride last decided: learn the model's error (if adaptation is on)."""
        decision, self._pending = self._pending, None
        s = self.settings
        if decision is None or not s.adaptation:
            return
        error_height = apex_height - decision.model_apex_height
        error_speed = forward_speed - decision.model_forward_speed
        if not (math.isfinite(error_height) and math.isfinite(error_speed)):
            return
        step_height, step_speed = self._robust(error_height - self.bias_height, error_speed - self.bias_speed)
        gain = s.adaptation_gain
        self.bias_height = _clip(self.bias_height + gain * step_height, s.max_bias_height)
        self.bias_speed = _clip(self.bias_speed + gain * step_speed, s.max_bias_speed)

    def _robust(self, height: float, speed: float) -> tuple[float, float]:
        """The model's error off the bias, each part clipped at `adaptation_outlier` times its typical size (the
        median over the last OUTLIER_WINDOW strides, at least its floor; from OUTLIER_MIN strides on): a stride
        that did not run as the model runs (its ramp late behind a stalled loop, a slip, a push) moves the bias
        by a few typical errors at most, where learned whole it came back as an error of half its size, the other way,
        in the next stride (make demo at 500 Hz: +1.06 cm, then -0.66 cm). A lasting change is still learned:
        its errors become the typical ones within a few strides."""
        s, recent = self.settings, self._innovations
        self._innovations = (recent + [(abs(height), abs(speed))])[-OUTLIER_WINDOW:]
        if s.adaptation_outlier <= 0.0 or len(recent) < OUTLIER_MIN:
            return height, speed
        bound_height = s.adaptation_outlier * max(float(np.median([h for h, _ in recent])), s.adaptation_floor_height)
        bound_speed = s.adaptation_outlier * max(float(np.median([v for _, v in recent])), s.adaptation_floor_speed)
        return _clip(height, bound_height), _clip(speed, bound_speed)


def _better(one, other, aim_height, aim_speed) -> bool:
    """Is solution `one` better than `other` (tuples of `_solve`)? A stride reaching z* beats one that does
    not; then the smaller height miss, the smaller speed miss."""
    def rank(solved):
        reaches = solved[-1] in ("", "torque limit")
        return (not reaches, 0.0 if reaches else abs(solved[3] - aim_height), abs(solved[4] - aim_speed))
    return rank(one) < rank(other)


OUTLIER_WINDOW = 8      # strides whose errors set the typical size (`DeadbeatController._robust`)
OUTLIER_MIN = 3         # ... needed before any error is clipped


def _clip(value: float, bound: float) -> float:
    return max(-bound, min(bound, value))
