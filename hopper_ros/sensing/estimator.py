"""The state estimator as plain Python: appendix A's Kalman filters on filterpy (no ROS).

Per axis y and z the constant-acceleration model of A.1.1 (lines 24-34, 41-51), state
[p, p', p''], driven by white jerk of spectral density sigma_w^2:

    Fd(dt) = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]                          (line 29)
    Qd(dt) = [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2],
              [dt^3/6, dt^2/2, dt]] sigma_w^2                                   (lines 32-34)
    Hd = [1, 0, 0]                                                              (line 31)

with sigma_w = 500 m s^-2.5 vertically and 100 horizontally (lines 13, 17). The leg angle gets a
small filter of its own (the thesis differentiates it, line 91): constant velocity, state
[theta, theta'], Fd = [[1, dt], [0, 1]], Qd = [[dt^3/3, dt^2/2], [dt^2/2, dt]] q_theta^2.

Measurement noise Rd. A.1.1 sets Rd = sigma_v^2 / dt (lines 35, 52) with sigma_v one encoder
count: that is the discrete equivalent of a *continuous-time* measurement whose noise has
spectral density sigma_v^2 (an integrating sensor). An encoder sampled once per period is a
discrete measurement of position whose error is the quantisation, uniform over one count:
Rd = (count)^2 / 12, dimensionally a variance [m^2] (sigma_v^2 / dt is m^2/s). At dt = 1 ms the
thesis's value is 12000 times larger, which makes the filter lag (docs/sensing.md has the
measured difference). `measurement_noise: quantization` (default) uses count^2 x
quantization_std_counts^2, `thesis` reproduces lines 35 and 52.

The three filters are independent, so they run as one filterpy `KalmanFilter` of 8 states with
block-diagonal Fd, Qd and one row of Hd per measured axis (identical to three filters, one
predict and one update call per sample). Update in Joseph form, A.1.2 line 11 (filterpy's
`update` is exactly that). Deviations from A.1, all for robustness:

- initialised from the first measurement (velocities and accelerations zero with the
  `initial_*_std` uncertainty) instead of a zero state with zero covariance;
- dt comes from the microcontroller clock; a gap of dropped samples is bridged by predictions,
  one per missing sample, each published with `measurement_used` false; a gap longer than
  `max_prediction_gap` restarts the filter;
- each axis's innovation is gated by its Mahalanobis distance |nu| / sqrt(S), S = H P H' + R;
  a rejected axis is not updated (`outlier_rejected`), `reinitialise_after` rejections in a row
  (the robot was moved by hand, the simulator threw it) restart the filter from the measurement.

Host stamps: the state's instant on the host clock is mcu_time + offset, the offset following the
lower envelope of (receive time - mcu time) by at most `clock_drift_rate`, re-anchored, up or down,
after `clock_reanchor_after` seconds of host time in which the packets all arrived more than
`clock_max_error` late, or the envelope stayed `clock_max_lag` below it, at real-time pace
(`ClockOffset`).
"""

from __future__ import annotations

import math

import numpy as np
from filterpy.kalman import KalmanFilter

from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.hardware.encoders import BoomKinematics

from .config import EstimatorSettings
from .samples import Estimate, Measurement

# state layout
Y, Y_DOT, Y_DDOT, Z, Z_DOT, Z_DDOT, THETA, THETA_DOT = range(8)
MEASURED = (Y, Z, THETA)          # rows of Hd: y, z, leg angle
AXES = ("y", "z", "leg_angle")
NOMINAL_HEIGHT = 0.3              # [m] where the z resolution is taken (it varies by < 1 % over a hop)
COUNTER_NAMES = ("measurements", "predicted_samples", "outliers_y", "outliers_z", "outliers_leg_angle",
                 "reinitialisations", "stale_measurements")


def constant_acceleration(dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Fd and Qd / sigma_w^2 of A.1.1 lines 29 and 32-34."""
    F = np.array([[1.0, dt, dt * dt / 2.0], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q = np.array([[dt ** 5 / 20.0, dt ** 4 / 8.0, dt ** 3 / 6.0],
                  [dt ** 4 / 8.0, dt ** 3 / 3.0, dt ** 2 / 2.0],
                  [dt ** 3 / 6.0, dt ** 2 / 2.0, dt]])
    return F, Q


def constant_velocity(dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Fd and Qd / q^2 of the leg angle filter (white angular acceleration)."""
    return np.array([[1.0, dt], [0.0, 1.0]]), np.array([[dt ** 3 / 3.0, dt ** 2 / 2.0], [dt ** 2 / 2.0, dt]])


def _diagonal_inverse(matrix: np.ndarray) -> np.ndarray:
    return np.diag(1.0 / matrix.diagonal())


class _LoopKalmanFilter(KalmanFilter):
    """filterpy's filter with its `predict` and `update` computed as filterpy computes them (the same
    operations in the same order: the same numbers), without what a 1 kHz loop never reads: the
    copies of the prior and posterior, the measurement's deep copy, the likelihoods' reset, the
    control input and the fading memory (alpha 1). With the gate reading the state once, 101 -> 45 us a sample
    (test_sensing_estimator holds it to filterpy's numbers, bit for bit)."""

    def predict(self, u=None, B=None, F=None, Q=None):
        """x = F x, P = F P F' + Q (A.1.2 lines 3, 5)."""
        F = self.F if F is None else F
        self.x = np.dot(F, self.x)
        self.P = np.dot(np.dot(F, self.P), F.T) + (self.Q if Q is None else Q)

    def update(self, z, R=None, H=None):
        """A.1.2 lines 7-11, the covariance in Joseph form (line 11), for a column `z` of H's rows."""
        R = self.R if R is None else R
        H = self.H if H is None else H
        self.y = z - np.dot(H, self.x)
        PHT = np.dot(self.P, H.T)
        self.S = np.dot(H, PHT) + R
        self.SI = self.inv(self.S)
        self.K = np.dot(PHT, self.SI)
        self.x = self.x + np.dot(self.K, self.y)
        I_KH = self._I - np.dot(self.K, H)
        self.P = np.dot(np.dot(I_KH, self.P), I_KH.T) + np.dot(np.dot(self.K, R), self.K.T)


class ClockOffset:
    """Host time minus microcontroller time, changing slowly so that stamps keep the
    microcontroller's spacing, never more than `max_error` early nor `max_lag` late for longer than
    `reanchor_after`. A packet earlier than the mapping allows is proof, so the late side's bound is
    tight (0.5 ms: the stance ramp's timing moves the apex ~2 mm per ms); lateness alone is not.

    A packet can only arrive after it was sampled, so the least-delayed packets bound the offset:
    `envelope` drops at once to a smaller (receive - mcu time) and otherwise rises by at most
    `max_drift_rate` seconds per second. The offset used for the stamps follows the envelope at
    that rate, up or down: stamp differences equal the microcontroller's to within the rate (the
    event detector's flight fit relies on it).

    Re-anchoring, in both directions: when for `reanchor_after` seconds of host time every packet
    arrived more than `max_error` later than the offset says (the simulated robot skipped time,
    the host clock stepped forward), or the envelope stayed more than `max_lag` below it (the
    first packets came late and the mapping was anchored on them, the host clock stepped back), the
    offset jumps to the least delay of that span (`anchors` counts them). The span is host time, and
    it starts again wherever the stream ran faster than real time (its microcontroller time
    advancing more than `PACE` x the host's, plus `max_error`) or fell silent, so neither a burst
    of packets queued while the host stalled (late, but read within milliseconds; the next ones are
    on time) nor a lockstep simulation
    (faster than real time: its stamps run ahead, spaced as the microcontroller's) moves the
    mapping. After a silence longer than `reanchor_after` (no packet at all: the simulated robot
    stalled) two late packets arriving as far apart as they were sampled are enough: the stream goes
    on at its pace, later by the time it missed. Before issue 29 only packets 0.1 s late for 1 s of
    microcontroller time re-anchored it and only upwards: a simulated robot that skipped 50-150 ms
    left every stamp that much old for minutes (every stance ramp cancelled), late first packets
    left them ahead (every ramp held).

    A mapping anchored within the last `reanchor_after` is brought down at once to the envelope when two
    packets in a row, the second as far after the first as it was sampled, came more than `max_lag`
    earlier than it allows: it was anchored on late packets (the first after a stand-still read by a
    starved host; waiting `reanchor_after` for them left the stamps 6 ms late over a touchdown, its ramp
    as late: bench_demo_load, the apex 1.09 cm off). Neither a lockstep stream nor a burst is at pace.
    """

    PACE = 1.1   # [1] a span whose microcontroller time advanced faster than this x host time is no real-time stream

    def __init__(self, max_drift_rate: float, max_error: float, reanchor_after: float,
                 max_lag: float | None = None) -> None:
        self.max_drift_rate = max_drift_rate
        self.max_error = max_error
        self.max_lag = max_error if max_lag is None else max_lag
        self.reanchor_after = reanchor_after
        self.offset = 0.0
        self.envelope = 0.0
        self.anchors = 0
        self._last_mcu: float | None = None
        self._side = 0                           # +1: packets late beyond max_error, -1: envelope early beyond max_lag
        self._since = (0.0, 0.0)                 # (mcu, receive time) of the span's first packet
        self._least = math.inf                   # the span's least delay
        self._last_receive = 0.0
        self._after_silence: float | None = None  # delay of a late packet that ended a silence
        self._anchored_at = -math.inf            # receive time of the last anchor
        self._early = False                      # the last packet came earlier than a fresh anchor allows

    def update(self, mcu_time: float, receive_time: float) -> float:
        delay = receive_time - mcu_time
        if self._last_mcu is None:
            self._anchor(delay, receive_time)
            self._last_mcu, self._last_receive = mcu_time, receive_time
            return self.offset
        mcu_step, host_step = mcu_time - self._last_mcu, receive_time - self._last_receive
        step = self.max_drift_rate * max(0.0, mcu_step)
        self._last_mcu, self._last_receive = mcu_time, receive_time
        self.envelope = min(self.envelope + step, delay)
        side = 1 if delay - self.offset > self.max_error else -1 if self.offset - self.envelope > self.max_lag else 0
        early = side < 0 and receive_time - self._anchored_at < self.reanchor_after
        if early and self._early and mcu_step > 0.0 and host_step >= 0.5 * mcu_step:
            self._anchor(self.envelope, receive_time)     # the fresh anchor was made on late packets
            return self.offset
        self._early = early
        if side > 0 and self._after_silence is not None and mcu_step > 0.0 and host_step >= 0.5 * mcu_step:
            # late after a silence, and the next packet came as far after it as it was sampled: the
            # stream goes on at its pace (a burst of queued packets comes within microseconds)
            self._anchor(min(self._after_silence, delay), receive_time)
            return self.offset
        self._after_silence = delay if side > 0 and host_step > self.reanchor_after else None
        if (side != self._side or host_step > self.reanchor_after
                or mcu_time - self._since[0] > self.PACE * (receive_time - self._since[1]) + self.max_error):
            # a new side, a silence, or faster than real time (a burst, lockstep): the span starts here
            self._side, self._since, self._least = side, (mcu_time, receive_time), math.inf
        self._least = min(self._least, delay if side > 0 else self.envelope)
        if side and receive_time - self._since[1] >= self.reanchor_after:
            self._anchor(self._least, receive_time)
            return self.offset
        self.offset += max(-step, min(step, self.envelope - self.offset))
        return self.offset

    @property
    def undecided(self) -> bool:
        """The last packet ended a silence late on the mapping: only the next one tells whether the
        stream goes on later by the time it missed (re-anchored then) or came in a burst (not)."""
        return self._after_silence is not None

    def _anchor(self, delay: float, receive_time: float) -> None:
        self.offset = self.envelope = delay
        self.anchors += 1
        self._side, self._least, self._after_silence, self._early = 0, math.inf, None, False
        self._anchored_at = receive_time

    def reset(self) -> None:
        self._last_mcu = None


class StateEstimator:
    """`update(measurement)` -> the estimates it produces (predictions across a gap, then the update; a
    sample held for its clock mapping comes out with the next one)."""

    def __init__(self, settings: EstimatorSettings, kinematics: BoomKinematics, sample_period: float) -> None:
        self.settings = settings
        self.period = sample_period
        resolution_y, resolution_z = kinematics.position_resolution(NOMINAL_HEIGHT)
        resolution_leg = kinematics.motor.resolution
        if settings.measurement_noise == "thesis":       # A.1.1 lines 35, 52: sigma_v^2 / dt
            r_y, r_z = resolution_y ** 2 / sample_period, resolution_z ** 2 / sample_period
        else:                                             # quantisation of a sampled encoder
            r_y, r_z = (resolution_y * settings.quantization_std_counts) ** 2, \
                       (resolution_z * settings.quantization_std_counts) ** 2
        r_leg = (resolution_leg * settings.quantization_std_counts) ** 2
        self.measurement_variances = np.array([r_y, r_z, r_leg])
        self._variances = (r_y, r_z, r_leg)           # the same as floats, for the gate at every sample
        self._noise = (settings.horizontal_process_noise ** 2, settings.vertical_process_noise ** 2,
                       settings.leg_process_noise ** 2)
        self._models: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.kf = _LoopKalmanFilter(dim_x=8, dim_z=3)
        self._H = np.zeros((3, 8))
        for row, column in enumerate(MEASURED):
            self._H[row, column] = 1.0
        self.kf.H = self._H
        self.kf.R = np.diag(self.measurement_variances)
        # The axes are independent (P block-diagonal), so S = H P H' + R is diagonal: invert it as such.
        self.kf.inv = _diagonal_inverse
        self._row_sets = {}   # accepted-axes mask -> (H, R) of those rows
        self.clock = ClockOffset(settings.clock_drift_rate, settings.clock_max_error,
                                 settings.clock_reanchor_after, settings.clock_max_lag)
        self.counters = dict.fromkeys(COUNTER_NAMES, 0)
        self.last_problem = ""
        self.initialised = False
        self._time = 0.0          # mcu time of the state
        self._sequence = 0
        self._streaks = [0, 0, 0]  # consecutive rejections per axis
        self.last_mahalanobis = np.zeros(3)
        self._held: Measurement | None = None   # a sample whose clock mapping the next one tells

    @classmethod
    def from_config(cls, settings: EstimatorSettings, hardware: HardwareConfig) -> "StateEstimator":
        return cls(settings, BoomKinematics.from_config(hardware), hardware.microcontroller.sample_period)

    # ------------------------------------------------------------------ model
    def model(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Block-diagonal Fd and Qd of the three filters for a step of dt seconds (cached per us)."""
        key = round(dt * 1e6)
        cached = self._models.get(key)
        if cached is None:
            step = key * 1e-6
            F, Q = np.zeros((8, 8)), np.zeros((8, 8))
            Fa, Qa = constant_acceleration(step)
            Fl, Ql = constant_velocity(step)
            q_y, q_z, q_leg = self._noise
            F[0:3, 0:3], F[3:6, 3:6], F[6:8, 6:8] = Fa, Fa, Fl
            Q[0:3, 0:3], Q[3:6, 3:6], Q[6:8, 6:8] = Qa * q_y, Qa * q_z, Ql * q_leg
            if len(self._models) > 256:
                self._models.clear()
            cached = self._models[key] = (F, Q)
        return cached

    def _rows(self, accepted: tuple[bool, bool, bool]) -> tuple[np.ndarray, np.ndarray]:
        rows = self._row_sets.get(accepted)
        if rows is None:
            index = [i for i, ok in enumerate(accepted) if ok]
            rows = self._row_sets[accepted] = (self._H[index], np.diag(self.measurement_variances[index]))
        return rows

    # ------------------------------------------------------------------ samples
    def reset(self) -> None:
        """Forget the state: the next measurement initialises the filter."""
        self.initialised = False
        self._held = None

    def initialise(self, m: Measurement) -> Estimate:
        s = self.settings
        r_y, r_z, r_leg = self.measurement_variances
        self.kf.x = np.array([[m.y], [0.0], [0.0], [m.z], [0.0], [0.0], [m.leg_angle], [0.0]])
        self.kf.P = np.diag([r_y, s.initial_velocity_std ** 2, s.initial_acceleration_std ** 2,
                             r_z, s.initial_velocity_std ** 2, s.initial_acceleration_std ** 2,
                             r_leg, s.initial_leg_rate_std ** 2])
        self._time, self._sequence = m.mcu_time, m.sequence
        self._streaks = [0, 0, 0]
        self.initialised = True
        return self._estimate(True, False)

    def update(self, m: Measurement) -> list[Estimate]:
        """Estimates for one measurement: a prediction per missing sample, then the (gated) update.

        A sample that ends a silence late on the clock mapping (`ClockOffset.undecided`: the
        simulated robot stood still, or the host stalled and a burst follows) is held until the next
        one, which tells the mapping its stamp is on: re-anchored by the time the robot stood still,
        or the old one for a burst. Stamped at once on the old mapping, the first state after a stop
        lay the whole stop in the past: a pre-touchdown event detected on it predicted a touchdown
        already over, and the controller cancelled the stance ramp (bench_demo_load: 0.68 cm). The
        cost is one sample period of latency for that one sample."""
        self.counters["measurements"] += 1
        self.clock.update(m.mcu_time, m.receive_time)
        held, self._held = self._held, None
        estimates = self._estimates(held) if held is not None else []
        if (self.clock.undecided and self.initialised
                and 0.0 < m.mcu_time - self._time <= self.settings.max_prediction_gap):
            self._held = m
            return estimates
        return estimates + self._estimates(m)

    def _estimates(self, m: Measurement) -> list[Estimate]:
        if not self.initialised:
            return [self.initialise(m)]
        dt = m.mcu_time - self._time
        if dt < -self.settings.max_prediction_gap:   # the microcontroller clock restarted
            self.counters["reinitialisations"] += 1
            self.last_problem = f"microcontroller clock went back {-dt:.3f} s: filter and clock mapping restarted"
            self.clock.reset()
            self.clock.update(m.mcu_time, m.receive_time)
            return [self.initialise(m)]
        if dt <= 0.0:
            self.counters["stale_measurements"] += 1
            self.last_problem = f"measurement {m.sequence} is not newer than the state (dt {dt * 1e3:.3f} ms)"
            return []
        if dt > self.settings.max_prediction_gap:
            self.counters["reinitialisations"] += 1
            self.last_problem = f"gap of {dt * 1e3:.1f} ms in the samples: filter restarted"
            return [self.initialise(m)]
        estimates = []
        missing = int(round(dt / self.period)) - 1
        for _ in range(missing):
            self._predict(self.period)
            self.counters["predicted_samples"] += 1
            estimates.append(self._estimate(False, False))
        self._predict(m.mcu_time - self._time)
        self._time, self._sequence = m.mcu_time, m.sequence
        estimate = self._correct(m)
        if estimate is None:   # restarted after persistent outliers
            return estimates + [self.initialise(m)]
        estimates.append(estimate)
        return estimates

    def _predict(self, dt: float) -> None:
        F, Q = self.model(dt)
        self.kf.predict(F=F, Q=Q)
        self._time += dt

    def _correct(self, m: Measurement) -> Estimate | None:
        """Gate each axis (Mahalanobis distance of its innovation), Joseph-form update with the rest."""
        kf = self.kf
        values = (m.y, m.z, m.leg_angle)
        gate = self.settings.outlier_gate
        state, diagonal, noise = kf.x.ravel().tolist(), kf.P.diagonal().tolist(), self._variances
        priors = [state[i] for i in MEASURED]
        variances = [diagonal[i] + r for i, r in zip(MEASURED, noise)]   # S = H P H' + R, diagonal
        accepted = []
        for axis in range(3):
            innovation = values[axis] - priors[axis]
            distance = abs(innovation) / math.sqrt(variances[axis])
            self.last_mahalanobis[axis] = distance
            ok = distance <= gate
            accepted.append(ok)
            if ok:
                self._streaks[axis] = 0
            else:
                self._streaks[axis] += 1
                self.counters[f"outliers_{AXES[axis]}"] += 1
                self.last_problem = (f"sample {m.sequence}: {AXES[axis]} innovation {innovation:.3g} is "
                                     f"{distance:.1f} sigma (gate {gate:g})")
        if max(self._streaks) >= self.settings.reinitialise_after:
            self.counters["reinitialisations"] += 1
            self.last_problem = (f"sample {m.sequence}: {self.settings.reinitialise_after} outliers in a row on "
                                 f"{AXES[self._streaks.index(max(self._streaks))]}: filter restarted")
            return None
        accepted = tuple(accepted)
        if any(accepted):
            H, R = self._rows(accepted)
            z = np.array([[v] for v, ok in zip(values, accepted) if ok])
            kf.update(z, R=R, H=H)       # Joseph form, A.1.2 line 11 (filterpy's update)
        return self._estimate(any(accepted), not all(accepted))

    def _estimate(self, measurement_used: bool, outlier_rejected: bool) -> Estimate:
        x = self.kf.x[:, 0].tolist()
        diagonal = self.kf.P.diagonal().tolist()
        return Estimate(
            sequence=self._sequence, mcu_time=self._time, stamp=self._time + self.clock.offset,
            y=x[Y], z=x[Z], y_dot=x[Y_DOT], z_dot=x[Z_DOT], y_ddot=x[Y_DDOT], z_ddot=x[Z_DDOT],
            leg_angle=x[THETA], leg_angle_rate=x[THETA_DOT],
            variances=(diagonal[Y], diagonal[Z], diagonal[Y_DOT], diagonal[Z_DOT], diagonal[Y_DDOT],
                       diagonal[Z_DDOT], diagonal[THETA], diagonal[THETA_DOT]),
            measurement_used=measurement_used, outlier_rejected=outlier_rejected)
