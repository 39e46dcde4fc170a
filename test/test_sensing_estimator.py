"""The state estimator as a plain module: appendix A's filters on the simulated robot's packets."""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np
import pytest
from scipy.linalg import expm

from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.config import load_hardware
from hopper_ros.hardware.encoders import BoomKinematics
from hopper_ros.sensing.bridge import EncoderBridge
from hopper_ros.harness.sensing_evaluation import flight_velocity_errors, record_experiments, replay
from hopper_ros.physics.params import load_params
from hopper_ros.sensing.config import load_sensing_config
from hopper_ros.sensing.estimator import StateEstimator, constant_acceleration
from hopper_ros.sensing.pipeline import SensingPipeline
from hopper_ros.sensing.samples import Measurement
from hopper_ros.sim.config import load_sim_config
from hopper_ros.sim.robot import SimRobot
from hopper_ros.sim.runner import RESYNC_AFTER

HARDWARE = load_hardware()
CONFIG = load_sensing_config()
KINEMATICS = BoomKinematics.from_config(HARDWARE)
PERIOD = 1e-3


@lru_cache(maxsize=None)
def recording(seconds: float = 8.0, seed: int = 11):
    return record_experiments(SimRobot(load_sim_config(), HARDWARE), seconds, seed=seed)


def run(settings=CONFIG.estimator, seconds: float = 8.0):
    rec = recording(seconds)
    config = dataclasses.replace(CONFIG, estimator=settings)
    result = replay(SensingPipeline(config, HARDWARE, load_params()),
                    (packet_format.encode(p) for p in rec.packets), (p.mcu_time_us * 1e-6 for p in rec.packets))
    return rec, result


def rms(values) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def estimator(**changes) -> StateEstimator:
    return StateEstimator(dataclasses.replace(CONFIG.estimator, **changes), KINEMATICS, PERIOD)


def measurement(sequence: int, z: float, y: float = 0.0, leg: float = 0.1, received: float | None = None):
    t = 1.0 + sequence * PERIOD
    return Measurement(sequence, t, received if received is not None else t + 2e-4, y, z, leg)


def test_qd_of_a11_is_the_exact_discretisation_of_white_jerk():
    """Lines 32-34: Qd = int_0^dt e^{Fc s} Qc e^{Fc' s} ds (Van Loan), for any dt the mcu clock gives."""
    Fc = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])       # line 24
    Qc = np.diag([0.0, 0.0, 1.0])                                              # line 27 / sigma_w^2
    for dt in (1e-3, 3e-3):
        block = np.block([[-Fc, Qc], [np.zeros((3, 3)), Fc.T]]) * dt
        van_loan = expm(block)
        F = van_loan[3:, 3:].T
        Q = F @ van_loan[:3, 3:]
        Fd, Qd = constant_acceleration(dt)
        np.testing.assert_allclose(Fd, F, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(Qd, Q, rtol=1e-9, atol=1e-24)


def test_measurement_noise_quantisation_and_the_thesis_rd():
    """Rd = count^2/12 (default) and A.1.1 line 35's sigma_v^2/dt: 12000 times more at 1 kHz."""
    resolution_y, resolution_z = KINEMATICS.position_resolution(0.3)
    ours = estimator().measurement_variances
    thesis = estimator(measurement_noise="thesis").measurement_variances
    assert ours[1] == pytest.approx((resolution_z * 0.2887) ** 2)
    assert thesis[1] == pytest.approx(resolution_z ** 2 / PERIOD)
    assert thesis[0] / ours[0] == pytest.approx(12000.0, rel=1e-3)


def test_the_update_is_a12s_joseph_form():
    """A.1.2 lines 3-11 by hand against the filter's predict and update."""
    est = estimator()
    est.update(measurement(0, 0.35))
    x, P = est.kf.x.copy(), est.kf.P.copy()
    F, Q = est.model(PERIOD)
    H, R = est.kf.H, np.diag(est.measurement_variances)
    z = np.array([[0.0004], [0.3499], [0.1002]])
    est.update(measurement(1, 0.3499, y=0.0004, leg=0.1002))
    x_prior = F @ x                                                   # line 3
    P_prior = F @ P @ F.T + Q                                         # line 5
    K = P_prior @ H.T @ np.linalg.inv(H @ P_prior @ H.T + R)         # line 7
    x_post = x_prior + K @ (z - H @ x_prior)                          # line 9
    I_KH = np.eye(8) - K @ H
    P_post = I_KH @ P_prior @ I_KH.T + K @ R @ K.T                    # line 11
    np.testing.assert_allclose(est.kf.x, x_post, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(est.kf.P, P_post, rtol=1e-9, atol=1e-18)
    assert np.allclose(est.kf.P, est.kf.P.T)


def test_flight_velocity_error_is_below_5_cm_per_s_and_the_thesis_rd_lags():
    rec, ours = run()
    _, thesis = run(dataclasses.replace(CONFIG.estimator, measurement_noise="thesis"))
    sequences = [p.sequence for p in rec.packets]
    error = rms(flight_velocity_errors(ours.estimates, rec.truth, sequences, rec.throws))
    error_thesis = rms(flight_velocity_errors(thesis.estimates, rec.truth, sequences, rec.throws))
    print(f"flight z' RMS error: {error:.4f} m/s (A.1.1's Rd: {error_thesis:.4f} m/s)")
    assert error < 0.05                                   # the bound
    assert error_thesis > 1.5 * error                     # 1000x the variance: the filter trusts the model
    # in stance (accelerations up to 10 g) the lag shows in the position too
    stance = [(ours.estimates[s].z - t.z, thesis.estimates[s].z - t.z)
              for s, t in zip(sequences, rec.truth) if t.in_contact and s in ours.estimates and s in thesis.estimates]
    ours_z, thesis_z = rms([a for a, _ in stance]), rms([b for _, b in stance])
    assert ours_z < 0.3e-3 < thesis_z


def test_dropped_samples_are_predicted_on_the_microcontroller_clock():
    est_full, est_gap = estimator(), estimator()
    t = np.arange(40) * PERIOD
    z = 0.35 + 1.2 * t - 0.5 * 11.42 * t ** 2        # a ballistic flight
    full = [est_full.update(measurement(i, z[i]))[-1] for i in range(40)]
    gap = []
    for i in range(40):
        if 25 <= i < 30:
            continue                                   # five packets lost
        # host receive times jitter by up to 3 ms: dt must come from the microcontroller clock
        gap.extend(est_gap.update(measurement(i, z[i], received=1.0002 + i * PERIOD + 0.003 * (i % 3))))
    predicted = [e for e in gap if not e.measurement_used]
    assert len(predicted) == 5 and est_gap.counters["predicted_samples"] == 5
    assert [round(e.mcu_time, 6) for e in predicted] == [round(1.0 + i * PERIOD, 6) for i in range(25, 30)]
    assert all(e.sequence == 24 for e in predicted)                 # the last sample used
    assert all(a.variances[1] < b.variances[1] for a, b in zip(predicted, predicted[1:]))  # uncertainty grows
    after = gap[-1]
    assert after.measurement_used and after.sequence == 39
    assert abs(after.z_dot - full[-1].z_dot) < 0.02 and abs(after.z - full[-1].z) < 1e-4
    assert gap[-1].stamp == pytest.approx(gap[-1].mcu_time + 2e-4, abs=2e-6)   # host stamp: least-delayed packet


def test_an_outlier_is_gated_and_a_jump_restarts_the_filter():
    est = estimator()
    t = np.arange(60) * PERIOD
    z = 0.35 + 0.8 * t - 0.5 * 11.42 * t ** 2
    for i in range(30):
        est.update(measurement(i, z[i]))
    spike = est.update(measurement(30, z[30] + 0.005))[-1]          # one 5 mm glitch
    assert spike.outlier_rejected and spike.measurement_used        # y and leg angle were still used
    assert est.counters["outliers_z"] == 1 and abs(spike.z - z[30]) < 2e-4
    assert "z innovation" in est.last_problem
    for i in range(31, 40):
        assert not est.update(measurement(i, z[i]))[-1].outlier_rejected
    results = [est.update(measurement(i, z[i] + 0.05))[-1] for i in range(40, 45)]    # moved 5 cm by hand
    assert [r.outlier_rejected for r in results[:3]] == [True, True, True]
    assert est.counters["reinitialisations"] == 1 and "restarted" in est.last_problem
    restarted = results[3]
    assert restarted.z == pytest.approx(z[43] + 0.05) and restarted.variances[3] == pytest.approx(3.0 ** 2)
    assert est.update(measurement(200, 0.3))[-1].variances[3] == pytest.approx(9.0)   # 155 ms gap: restart
    assert est.counters["reinitialisations"] == 2
    assert est.update(measurement(199, 0.3)) == [] and est.counters["stale_measurements"] == 1


def test_stamps_follow_the_host_clock_with_the_microcontrollers_spacing():
    rng = np.random.default_rng(2)
    est = estimator()
    stamps = []
    for i in range(3000):                       # 0.3 to 1.3 ms delays, the first one 1.3 ms
        delay = 1.3e-3 if i == 0 else 0.3e-3 + rng.exponential(0.2e-3)
        stamps.append(est.update(measurement(i, 0.3, received=1.0 + i * PERIOD + delay))[-1].stamp)
    spacing = np.diff(stamps)
    # the first packet's 1.3 ms is 1 ms above the least delay (more than clock_max_lag): one step down
    # to it after clock_reanchor_after; otherwise the microcontroller's spacing within clock_drift_rate
    off = np.abs(spacing - PERIOD) > 0.5e-3 * PERIOD + 1e-12
    assert off.sum() == 1 and est.clock.anchors == 2 and spacing[off][0] == pytest.approx(PERIOD - 1e-3, abs=0.2e-3)
    assert est.clock.offset == pytest.approx(0.3e-3, abs=0.05e-3)          # converged to the least delay
    # faster than real time (lockstep): the stamps keep the spacing and run ahead of the host clock
    lockstep = estimator()
    stamps = [lockstep.update(measurement(i, 0.3, received=1.0 + i * PERIOD / 5))[-1].stamp for i in range(500)]
    assert np.allclose(np.diff(stamps), PERIOD, rtol=1e-3) and lockstep.clock.anchors == 1
    # the host stalled 0.15 s (the bridge descheduled) and then read the queued packets in a burst:
    # the packets are late, the stamps keep their spacing
    realtime = estimator()
    resume = 1.0 + 650 * PERIOD + 3e-4
    stamps = stamps_of(realtime, [measurement(i, 0.3, received=1.0 + i * PERIOD + 3e-4) for i in range(500)] +
                       [measurement(i, 0.3, received=resume + (i - 500) * 1e-6) for i in range(500, 650)])
    assert np.allclose(np.diff(stamps), PERIOD, rtol=1e-3) and realtime.clock.anchors == 1
    # the host clock stepped 0.2 s forward for good (no packet for 0.2 s, then late ones at their pace):
    # re-anchored, to the least delay, by the second packet; the first waited for it
    step = stamps_of(realtime, [measurement(i, 0.3, received=1.2 + i * PERIOD + 3e-4) for i in range(650, 660)])
    assert realtime.clock.anchors == 2
    assert step == pytest.approx([1.2 + i * PERIOD + 3e-4 for i in range(650, 660)])
    # late packets without a silence before them (a standing queue): less than clock_max_error late, the robot
    # runs late and catches up (its drive feels each setting at the instant it was meant for: the stamps stay);
    # more, they re-anchor the mapping once clock_reanchor_after showed it
    settings = CONFIG.estimator
    span = int(round(settings.clock_reanchor_after / PERIOD))
    behind = 1.2 + 0.5 * settings.clock_max_error
    running_late = stamps_of(realtime, [measurement(i, 0.3, received=behind + i * PERIOD + 3e-4)
                                        for i in range(660, 660 + 3 * span)])
    assert realtime.clock.anchors == 2
    assert running_late == pytest.approx([1.2 + i * PERIOD + 3e-4 for i in range(660, 660 + 3 * span)], abs=1e-4)
    late, first = 1.2 + 1.2 * settings.clock_max_error, 660 + 3 * span   # a step under clock_reanchor_after: no silence
    queued = stamps_of(realtime, [measurement(i, 0.3, received=late + i * PERIOD + 3e-4)
                                  for i in range(first, first + span + 2)])
    assert realtime.clock.anchors == 3
    assert queued[span - 2] == pytest.approx(1.2 + (first + span - 2) * PERIOD + 3e-4, abs=1e-3)
    assert queued[-1] == pytest.approx(late + (first + span + 1) * PERIOD + 3e-4)
    # the microcontroller restarted (its clock back to the start): filter and mapping restart
    restarted = lockstep.update(Measurement(1, 0.001, 2.0, 0.0, 0.31, 0.1))
    assert len(restarted) == 1 and restarted[0].stamp == pytest.approx(2.0)
    assert lockstep.counters["reinitialisations"] == 1 and "clock went back" in lockstep.last_problem


def stamps_of(est, measurements):
    """The stamp of each measurement's own estimate, in order (a sample held until the next one tells its
    clock mapping comes out with that one; the last, if held, is nan)."""
    stamps = {}
    for m in measurements:
        for e in est.update(m):
            stamps.setdefault(e.sequence, e.stamp)      # predictions after a gap carry the last sequence used
    return [stamps.get(m.sequence, float("nan")) for m in measurements]


def _stamp_errors(est, packets):
    """(receive time, stamp - the sample's true host instant) of each packet (sequence, mcu time,
    true host instant of sampling, receive time), in order."""
    stamps = stamps_of(est, [Measurement(sequence, mcu, received, 0.0, 0.3, 0.1)
                             for sequence, mcu, sampled, received in packets])
    return [(received, stamp - sampled) for (_, _, sampled, received), stamp in zip(packets, stamps)]


def test_stamps_follow_a_simulated_robot_that_skipped_time():
    """Issue 29: the simulated robot, stalled beyond sim/runner.py's RESYNC_AFTER, drops the time
    it missed: its microcontroller clock then runs 80 ms behind the host clock for good, and every
    packet arrives 80 ms after its instant on the old mapping. The stamps must follow within
    clock_max_error (a few ms) once clock_reanchor_after of packets showed it, not drift 0.5 ms/s."""
    s = CONFIG.estimator
    est = estimator()
    skip = 0.08
    packets = [(i, 1.0 + i * PERIOD, 5.0 + i * PERIOD, 5.0 + i * PERIOD + 3e-4) for i in range(1000)]
    packets += [(i, 1.0 + i * PERIOD, 5.0 + skip + i * PERIOD, 5.0 + skip + i * PERIOD + 3e-4) for i in range(1000, 2000)]
    errors = _stamp_errors(est, packets)
    resumed = 5.0 + skip + 1.0
    assert max(abs(e) for _, e in errors[100:1000]) < 1e-3
    settled = [e for received, e in errors if received >= resumed + 0.1]
    assert max(abs(e) for e in settled) <= 0.005                      # "a few ms" within 0.1 s
    # no packet for 80 ms, then late ones at their pace: right from the first on (it waits for the second,
    # which says the stream goes on at its pace; stamped at once, it lay the whole 80 ms in the past and a
    # pre-touchdown event detected on it predicted a touchdown already over)
    assert max(abs(e) for _, e in errors[1000:]) <= s.clock_max_error
    assert s.clock_max_error < RESYNC_AFTER and s.clock_reanchor_after <= 0.1   # every stand-still re-anchors
    settled = [e for received, e in errors if received >= resumed + s.clock_reanchor_after + 2 * PERIOD]
    assert len(settled) > 900 and max(abs(e) for e in settled) <= s.clock_max_error
    assert est.clock.anchors == 2
    # the stamps keep the microcontroller's spacing but for the one step of the re-anchor
    stamps = np.array([e for _, e in errors]) + np.array([p[2] for p in packets])
    assert np.sum(np.abs(np.diff(stamps) - PERIOD) > 1e-6) == 1


def test_stamps_do_not_stay_ahead_when_the_first_packets_came_late():
    """Issue 29: the first packets of a run arrive 40 ms late (a burst at start-up), the rest on time.
    Anchored on the first, the stamps ran 40 ms ahead for 80 s (the offset may only fall 0.5 ms/s):
    the driver then held every stance ramp. A packet earlier than the mapping allows proves it
    wrong: within clock_reanchor_after the stamps must be within clock_max_error."""
    s = CONFIG.estimator
    est = estimator()
    late = [(i, 1.0 + i * PERIOD, 5.0 + i * PERIOD, 5.04 + i * 1e-5) for i in range(40)]
    on_time = [(i, 1.0 + i * PERIOD, 5.0 + i * PERIOD, 5.0 + i * PERIOD + 3e-4) for i in range(40, 2000)]
    errors = _stamp_errors(est, late + on_time)
    assert errors[0][1] == pytest.approx(0.04, abs=1e-3)            # nothing better was known then
    assert max(abs(e) for received, e in errors if received >= 5.14) <= 0.005    # within 0.1 s
    settled = [e for received, e in errors if received >= 5.04 + s.clock_reanchor_after + 2 * PERIOD]
    assert len(settled) > 1800 and max(abs(e) for e in settled) <= s.clock_max_error


def test_stamps_come_down_at_once_when_a_stand_still_was_anchored_on_late_packets():
    """Issue 29: after the simulated robot stood still 80 ms, the host reading its packets was starved: the first
    ones after the stand-still came 6 ms late, at their pace, and the mapping was anchored on them. Waiting
    clock_reanchor_after for the on-time packets that proved it wrong left the stamps 6 ms late over a touchdown
    (bench_demo_load at 1 kHz: the ramp's torque on the leg 6.3 ms after it, the apex 1.09 cm high). From the
    second on-time packet on the stamps are within clock_max_lag; a burst and a lockstep stream (the test below)
    still keep the mapping."""
    s = CONFIG.estimator
    est = estimator()
    skip, late = 0.08, 0.006
    packets = [(i, 1.0 + i * PERIOD, 5.0 + i * PERIOD, 5.0 + i * PERIOD + 3e-4) for i in range(1000)]
    packets += [(i, 1.0 + i * PERIOD, 5.0 + skip + i * PERIOD, 5.0 + skip + i * PERIOD + late + 3e-4)
                for i in range(1000, 1004)]                 # read late, at their pace
    packets += [(i, 1.0 + i * PERIOD, 5.0 + skip + i * PERIOD, 5.0 + skip + i * PERIOD + 3e-4) for i in range(1004, 1300)]
    errors = _stamp_errors(est, packets)
    assert late - 1e-3 < max(e for _, e in errors[1000:1004]) <= late + 1e-3      # anchored on the late ones
    assert max(abs(e) for _, e in errors[1005:]) <= s.clock_max_lag + 3e-4
    assert s.clock_reanchor_after > 2 * PERIOD                                    # sooner than it would have


def test_a_lockstep_stream_and_a_host_stall_keep_the_mapping():
    """What must not re-anchor: a stream faster than real time (sim_robot in lockstep: the stamps run
    ahead, spaced as the microcontroller's) and a burst of packets queued while the host stalled
    longer than clock_reanchor_after (late, but read in a few ms: the next ones are on time)."""
    s = CONFIG.estimator
    lockstep = estimator()
    stamps = [lockstep.update(measurement(i, 0.3, received=1.0 + i * PERIOD / 5))[-1].stamp for i in range(3000)]
    assert np.allclose(np.diff(stamps), PERIOD, rtol=1e-3) and lockstep.clock.anchors == 1
    stall = 3 * s.clock_reanchor_after + 0.05
    burst = int(stall / PERIOD)
    packets = [(i, 1.0 + i * PERIOD, 5.0 + i * PERIOD, 5.0 + i * PERIOD + 3e-4) for i in range(500)]
    packets += [(i, 1.0 + i * PERIOD, 5.0 + i * PERIOD, 5.0 + 500 * PERIOD + stall + (i - 500) * 1e-5)
                for i in range(500, 500 + burst)]
    packets += [(i, 1.0 + i * PERIOD, 5.0 + i * PERIOD, 5.0 + i * PERIOD + 3e-4) for i in range(500 + burst, 1500)]
    realtime = estimator()
    errors = _stamp_errors(realtime, packets)
    assert realtime.clock.anchors == 1 and max(abs(e) for _, e in errors[100:]) < 1e-3


def test_the_loops_filter_gives_filterpys_numbers_bit_for_bit():
    """The estimator's filter skips filterpy's bookkeeping copies (`_LoopKalmanFilter`): the same estimates as filterpy's
    own KalmanFilter, to the last bit, over the simulated robot's samples with a gap, outliers and a restart."""
    from filterpy.kalman import KalmanFilter

    rec = recording()
    ours, filterpys = estimator(), estimator()
    lean = ours.kf
    filterpys.kf = KalmanFilter(dim_x=8, dim_z=3)
    filterpys.kf.H, filterpys.kf.R, filterpys.kf.inv = lean.H, lean.R, lean.inv
    assert type(lean) is not KalmanFilter
    compared = 0
    bridge = EncoderBridge.from_config(HARDWARE, CONFIG.bridge)
    for index, packet in enumerate(rec.packets[:4000]):
        sample = bridge.process(packet_format.encode(packet), packet.mcu_time_us * 1e-6 + 2e-4)
        if 1000 <= index < 1004 or sample is None:
            continue                                           # a gap: four predictions
        m = sample.measurement()
        if index in (2000, 2001):
            m = dataclasses.replace(m, z=m.z + 0.3)            # outliers, gated
        if 3000 <= index < 3010:
            m = dataclasses.replace(m, y=m.y + 1.0)            # a jump: the filter restarts
        a, b = ours.update(m), filterpys.update(m)
        assert a == b, index
        compared += len(a)
    assert compared > 3900 and ours.counters == filterpys.counters
    assert ours.counters["reinitialisations"] >= 1 and ours.counters["outliers_z"] >= 2
