"""encoder_bridge, state_estimator and event_detector as processes, on real topics, fed by real
UDP packets: from the sim_robot node, and from this test with bad packets mixed in."""

from __future__ import annotations

import bisect
import dataclasses
import math
import random
import signal
import socket
import threading
import time

import numpy as np
import yaml

from conftest import SAFETY_TIMEOUT, free_port, spin_until
from hopper_ros.config import load_yaml
from hopper_ros.hardware.config import load_hardware
from hopper_ros.hardware.encoders import BoomKinematics, to_register
from hopper_ros.physics.params import load_params
from hopper_ros.sensing.config import load_sensing_config
from hopper_ros.harness.sensing_evaluation import (MCU_CLOCK_OFFSET, inject_faults, match_events, receive_times,
                                           record_experiments, toe_heights, true_events)
from hopper_ros.sensing.samples import EventType
from hopper_ros.sim.config import load_sim_config
from hopper_ros.sim.plant import PlantEvent
from hopper_ros.sim.robot import SimRobot

HARDWARE = load_hardware()
PARAMS = load_params()
PRE_TOUCHDOWN = load_sensing_config().detector.pre_touchdown_height
KINDS = {EventType.APEX: "apex", EventType.TOUCHDOWN: "touchdown", EventType.BOTTOM: "bottom",
         EventType.LIFTOFF: "liftoff"}
DEPTH = 2000


def seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def queue_settings(tmp_path) -> str:
    """config/sensing.yaml with a 10 s queue: on a starved machine the nodes fall behind but never
    drop a sample, so these tests check detection, not how it degrades under overload (the
    estimator's predictions across dropped samples are tested on the modules)."""
    settings = load_yaml("sensing.yaml")
    settings["sensing"]["queue_depth"] = 10000
    path = tmp_path / "sensing.yaml"
    path.write_text(yaml.safe_dump(settings))
    return str(path)


def start_sensing(hopper_cli, port: int, sensing_file: str, *extra: str):
    """The three nodes, started together; returns them once each has logged its start."""
    common = ["-p", "diagnostics_period:=0.5", "-p", f"sensing_file:={sensing_file}", *extra]
    nodes = [hopper_cli("run", "encoder_bridge", "--ros-args", "-p", f"port:={port}", *common),
             hopper_cli("run", "state_estimator", "--ros-args", *common),
             hopper_cli("run", "event_detector", "--ros-args", *common)]
    for node in nodes:
        node.wait_for_line(r"started: pid")
    return nodes


def stop(nodes) -> None:
    for node in nodes:
        node.signal(signal.SIGINT)
    for node in nodes:
        assert node.wait() == 0, node.stderr


class Listener:
    """Subscriptions of the test: everything the sensing nodes (and the sim) publish."""

    def __init__(self, rclpy_session, name: str, keys: tuple[str, ...]):
        from rclpy.experimental import EventsExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

        from diagnostic_msgs.msg import DiagnosticArray

        from hopper_ros.msg import ApexState, BodyMeasurement, BodyState, EncoderSample, GaitEvent

        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        self.node = rclpy_session.create_node(name)
        # rclpy's EventsExecutor costs a third of the SingleThreadedExecutor's CPU per message: this
        # process listens to 2 kHz while sharing two cores with the graph under test
        self.executor = EventsExecutor()
        self.executor.add_node(self.node)
        self.keys = keys
        self.got = {key: [] for key in ("truth", "sim_events", "states", "events", "apex", "samples",
                                        "measurements", "diagnostics")}
        topics = [("truth", BodyState, "sim/truth"), ("sim_events", GaitEvent, "sim/events"),
                  ("states", BodyState, "body_state"), ("events", GaitEvent, "gait_event"),
                  ("apex", ApexState, "apex"), ("samples", EncoderSample, "encoder_sample"),
                  ("measurements", BodyMeasurement, "body_measurement"),
                  ("diagnostics", DiagnosticArray, "/diagnostics")]
        for key, kind, topic in topics:
            if key in keys:       # only what the test needs: this process shares the 2 cores with the graph
                store = self.got[key].append if key != "diagnostics" else (lambda m: self.got["diagnostics"].extend(m.status))
                self.node.create_subscription(kind, topic, store, qos)

    def wait_connected(self) -> None:
        """Until the three nodes' topics are all matched with this listener and with each other: the
        bridge's and the estimator's publishers report their matched subscriptions (the listener
        seeing a subscription does not mean the publisher has matched it yet: a run once lost its
        first 150 samples that way)."""
        node = self.node
        assert spin_until(self.executor, lambda: node.count_publishers("body_measurement") and
                          node.count_subscribers("body_measurement") >= 1 and node.count_publishers("body_state")
                          and node.count_subscribers("body_state") >= 1 and node.count_publishers("gait_event"))
        wanted = {"/encoder_bridge": ("measurement_subscribers", 1 + ("measurements" in self.keys)),
                  "/state_estimator": ("state_subscribers", 1 + ("states" in self.keys))}

        def matched():
            reports = {name: self.diagnostics(name) for name in wanted}
            return all(r is not None and values_of(r)[value] >= count
                       for (value, count), r in zip(wanted.values(), reports.values()))

        if "diagnostics" in self.keys:
            assert spin_until(self.executor, matched)
        else:
            end = time.monotonic() + 1.0     # no diagnostics to tell: let the nodes' own matches settle
            spin_until(self.executor, lambda: time.monotonic() > end)

    def spin_for(self, duration: float) -> None:
        end = time.monotonic() + duration
        spin_until(self.executor, lambda: time.monotonic() > end)

    def diagnostics(self, node_name: str):
        reports = [d for d in self.got["diagnostics"] if d.name == node_name]
        return reports[-1] if reports else None

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


def got_reports(listener) -> list:
    return [r for r in (listener.diagnostics(name) for name in ("/encoder_bridge", "/state_estimator",
                                                                  "/event_detector")) if r is not None]


def counters_of(report) -> dict[str, int]:
    """The counters (integer values) of a node's DiagnosticStatus."""
    from hopper_ros.nodes.diagnostics import status_values

    return {key: value for key, value in status_values(report).items() if isinstance(value, int)}


def values_of(report) -> dict[str, float]:
    """Every value of a node's DiagnosticStatus (counters as int, measurements as float)."""
    from hopper_ros.nodes.diagnostics import status_values

    return status_values(report)


def run_with_sim_robot(rclpy_session, hopper_cli, tmp_path, mode: str, duration: float, keys: tuple[str, ...]):
    """The three nodes fed by the sim_robot node (section 4.1's experiments, thrown again after each);
    returns what the listener got once every packet went through the bridge and the estimator."""
    port = free_port(socket.SOCK_DGRAM)
    packets = round(duration * 1000)
    nodes = start_sensing(hopper_cli, port, queue_settings(tmp_path))
    listener = Listener(rclpy_session, f"sensing_nodes_{mode}_test", keys)
    try:
        listener.wait_connected()
        sim = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", "experiments:=true",
                         "-p", f"mode:={mode}", "-p", f"udp_port:={port}", "-p", f"duration:={duration}")
        sim.wait_for_line(rf"{mode} at 1000 Hz")
        assert spin_until(listener.executor, lambda: sim.process.poll() is not None, timeout=SAFETY_TIMEOUT)
        assert sim.wait() == 0
        listener.freezes = int(sim.wait_for_line(r"done, real-time factor [0-9.]+, (\d+) freezes").group(1))

        def all_reported():          # every packet through the bridge, the estimator and the detector (diagnostics;
            bridge, estimator = listener.diagnostics("/encoder_bridge"), listener.diagnostics("/state_estimator")
            detector = listener.diagnostics("/event_detector")  # without the detector's, its last report once
            return (bridge is not None and counters_of(bridge)["packets_received"] == packets  # had 7999 of 8000
                    and estimator is not None and counters_of(estimator)["measurements"] == packets
                    and detector is not None and counters_of(detector)["samples"] >= packets)

        assert spin_until(listener.executor, all_reported), [
            (d.name, counters_of(d)) for d in got_reports(listener)]
        listener.spin_for(0.5)                       # the tail of the topics
    finally:
        stop(nodes)
        listener.close()
    return listener


def compare_with_sim(got, anchors: int, freezes: int):
    """Our events on the simulator's clock against its true events: (report, truth, stamps). `anchors`: how
    often the estimator's clock mapping re-anchored (its diagnostics' clock_anchors): where the simulated robot,
    further behind the wall clock than it catches up, froze its world (`freezes`; its clock then steps against
    the host's) and wherever its packets came more than clock_max_error late for clock_reanchor_after (a
    process starved under load)."""
    # every clock onto the simulator's stamps: our stamp minus (ours - sim's) of the nearest sample
    truth_stamp = {m.sequence: seconds(m.header.stamp) for m in got["truth"]}
    our_stamp = {}
    for m in got["states"]:
        our_stamp.setdefault(m.sequence, seconds(m.header.stamp))
    offsets = {s: our_stamp[s] - truth_stamp[s] for s in our_stamp.keys() & truth_stamp.keys()}
    # (the first truth messages are sent before this test's subscription is matched: discovery; and
    # this process, sharing two cores with five others, may miss some of what it listens to)
    assert len(offsets) > 0.5 * len(our_stamp)
    known = sorted(offsets)
    # our stamps keep the microcontroller's spacing (the flight fit relies on it) while following the
    # host clock: from one sample to the next the mapping moves by tens of microseconds at most, but where
    # it re-anchored (one step each; measured on 2026-11-28, alone: 15 and 18 steps for 16 and 19 anchors,
    # 1 freeze; beside two busy processes: 43 and 67 for 44 and 68, 15-17 freezes). The bound was the freezes
    # alone, from before the mapping re-anchored on late packets too (issue 29): under make test's load it
    # failed with 118-202 steps for 17-50 freezes.
    steps = np.abs(np.diff([offsets[s] for s in known])) / np.maximum(1, np.diff(known))
    jumps = int(np.sum(steps >= 50e-6))
    print(f"\nstamp mapping: {jumps} steps of 50 us or more over {len(steps)} samples, {anchors} re-anchors, "
          f"the robot froze {freezes} times")
    assert jumps <= anchors + 0.01 * len(steps), (jumps, anchors, freezes)

    def offset(sequence: int) -> float:
        index = min(bisect.bisect_left(known, sequence), len(known) - 1)
        return offsets[known[index]]

    first_apex = min(seconds(m.header.stamp) for m in got["sim_events"] if m.type == EventType.APEX)
    plant_events = [PlantEvent(seconds(m.header.stamp), m.state.y, m.state.z, m.state.y_dot, m.state.z_dot,
                               m.state.leg_angle, kind=KINDS[EventType(m.type)])
                    for m in got["sim_events"] if seconds(m.header.stamp) >= first_apex]
    toes = sorted((truth_stamp[m.sequence], m.z - PARAMS.rest_length * math.cos(m.leg_angle)) for m in got["truth"])
    truth = true_events(plant_events, toes, PARAMS.rest_length, PRE_TOUCHDOWN)
    detected = []
    for m in got["events"]:
        t = seconds(m.header.stamp) - offset(m.state.sequence)
        if t > first_apex + 2e-3:
            detected.append((EventType(m.type), t))
    return match_events(truth, detected), truth, truth_stamp, first_apex


def test_nodes_find_every_event_of_the_simulated_robot_within_2_ms(rclpy_session, hopper_cli, tmp_path):
    listener = run_with_sim_robot(rclpy_session, hopper_cli, tmp_path, "realtime", 8.0,
                                  ("truth", "sim_events", "states", "events", "apex", "diagnostics"))
    got = listener.got
    anchors = counters_of(listener.diagnostics("/state_estimator"))["clock_anchors"]
    report, truth, truth_stamp, first_apex = compare_with_sim(got, anchors, listener.freezes)
    print(f"\n{len(truth.clean_spans)} clean strides: {report.summary()}")
    assert len(truth.clean_spans) >= 8
    assert not report.missed, report.missed
    assert not report.extra, report.extra
    assert report.max_error() <= 2e-3

    # flight vertical velocity against the truth, leaving out 30 ms after every apex (the sim throws there)
    boundaries = sorted((seconds(m.header.stamp), m.type, m.state.z_dot) for m in got["sim_events"])
    boundary_times = [b[0] for b in boundaries]
    apex_times = [b[0] for b in boundaries if b[1] == EventType.APEX]
    states = {m.sequence: m for m in got["states"] if m.measurement_used}
    errors = []
    for m in got["truth"]:
        t = truth_stamp[m.sequence]
        last = bisect.bisect_right(boundary_times, t) - 1
        if last < 0 or t < first_apex or m.sequence not in states:
            continue
        _, kind, z_dot = boundaries[last]
        flying = kind == EventType.APEX or (kind == EventType.LIFTOFF and z_dot > 0.0)
        since_apex = t - apex_times[bisect.bisect_right(apex_times, t) - 1]
        if flying and since_apex >= 0.03:
            errors.append(states[m.sequence].z_dot - m.z_dot)
    rms = float(np.sqrt(np.mean(np.square(errors))))
    print(f"flight z' RMS error {rms:.4f} m/s over {len(errors)} samples")
    assert len(errors) > 2000 and rms < 0.05

    # apex topic: one ApexState per apex event, same time, stride and height
    apex_events = {(m.stride_index, m.header.stamp.sec, m.header.stamp.nanosec): m
                   for m in got["events"] if m.type == EventType.APEX}
    assert len(got["apex"]) == len(apex_events) > 8
    for apex in got["apex"]:
        event = apex_events[(apex.stride_index, apex.header.stamp.sec, apex.header.stamp.nanosec)]
        assert apex.apex_height == event.state.z and apex.forward_speed == event.state.y_dot

    bridge = listener.diagnostics("/encoder_bridge")
    counters = counters_of(bridge)
    assert counters["samples_accepted"] == 8000 and counters["packets_lost"] == 0
    assert sum(v for k, v in counters.items() if k.startswith("malformed")) == 0
    report = listener.diagnostics("/event_detector")
    detector = counters_of(report)
    assert detector["apex"] == len(apex_events)
    # every state's age was checked against the 1 ms deadline (how many were late depends on the load)
    assert 0 <= detector["late_samples"] <= detector["samples"] >= 8000
    assert "sample_age_max_s" in values_of(report)
    estimator = counters_of(listener.diagnostics("/state_estimator"))
    assert estimator["measurements"] == 8000


def test_bad_packets_are_counted_dropped_and_never_change_an_event(rclpy_session, hopper_cli, tmp_path):
    """Packets from this test (a recorded SimRobot run) with garbage, truncated, bit-flipped, other-version,
    duplicated, swapped, clock-backwards packets and gaps mixed in, counters homed near the 32-bit wrap
    point and the sequence number crossing 2^32."""
    recording = record_experiments(SimRobot(load_sim_config(), HARDWARE), 5.0, seed=2)
    kinematics = BoomKinematics.from_config(HARDWARE)
    first = kinematics.counts(recording.truth[0].y, recording.truth[0].z, recording.truth[0].leg_angle)
    offsets = (2 ** 31 - first[0] - 300, -2 ** 31 - first[1] + 200, 2 ** 31 - first[2] - 100)   # homing
    hardware = load_yaml("hardware.yaml")
    for name, offset in zip(("azimuth", "elevation", "motor"), offsets):
        hardware["encoders"][name]["offset_counts"] = int(offset)
    hardware_file = tmp_path / "hardware.yaml"
    hardware_file.write_text(yaml.safe_dump(hardware))
    shift = 2 ** 32 - 2500                                      # sequences wrap 2.5 s into the run
    packets = [dataclasses.replace(p, sequence=(p.sequence + shift) % 2 ** 32,
                                   azimuth_counts=to_register(p.azimuth_counts + offsets[0]),
                                   elevation_counts=to_register(p.elevation_counts + offsets[1]),
                                   motor_counts=to_register(p.motor_counts + offsets[2]))
               for p in recording.packets]
    datagrams, expected, lost = inject_faults(packets, random.Random(5))
    good = {p.sequence for p in packets}

    port = free_port(socket.SOCK_DGRAM)
    nodes = start_sensing(hopper_cli, port, queue_settings(tmp_path), "-p", f"hardware_file:={hardware_file}")
    listener = Listener(rclpy_session, "sensing_bad_packets_test",
                        ("samples", "measurements", "states", "events", "diagnostics"))
    try:
        listener.wait_connected()
        sender = threading.Thread(target=send_at_1khz, args=(datagrams, port), daemon=True)
        sender.start()
        assert spin_until(listener.executor, lambda: not sender.is_alive())
        accepted = len(recording.packets) - lost

        def bridge_reported_all():
            report = listener.diagnostics("/encoder_bridge")
            return report is not None and counters_of(report)["packets_received"] == len(datagrams)

        assert spin_until(listener.executor, bridge_reported_all)
        listener.spin_for(1.0)
        got = listener.got
    finally:
        stop(nodes)
        listener.close()

    counters = counters_of(listener.diagnostics("/encoder_bridge"))
    for name, count in expected.items():
        assert counters[name] == count, name
    assert counters["packets_lost"] == lost and counters["samples_accepted"] == accepted
    assert counters["counter_wraps"] >= 1 and counters["stream_resyncs"] == 0
    # nothing of a bad packet was published, every good one exactly once
    sequences = [m.sequence for m in got["samples"]]
    assert len(sequences) == len(set(sequences)) == accepted and set(sequences) <= good
    # appendix A with the homing offsets: positions within one count of the truth across the wraps
    truth_by_sequence = {(p.sequence + shift) % 2 ** 32: s for p, s in zip(recording.packets, recording.truth)}
    resolution_y, resolution_z = kinematics.position_resolution(0.3)
    for m in got["measurements"]:
        true = truth_by_sequence[m.sequence]
        assert abs(m.y - true.y) <= 1.01 * resolution_y and abs(m.z - true.z) <= 1.1 * resolution_z
        assert abs(m.leg_angle - true.leg_angle) <= 1.01 * kinematics.motor.resolution
    estimator = counters_of(listener.diagnostics("/state_estimator"))
    assert estimator["predicted_samples"] >= lost and estimator["measurements"] == accepted
    # events: as in the recording, within 2 ms, none extra (host stamps mapped back through the samples)
    mcu = {p.sequence: p.mcu_time_us * 1e-6 for p in packets}
    offsets_host = {}
    for m in got["states"]:
        offsets_host.setdefault(m.sequence, seconds(m.header.stamp) - mcu[m.sequence])
    typical = float(np.median(list(offsets_host.values())))
    detected = [(EventType(m.type), seconds(m.header.stamp) - offsets_host.get(m.state.sequence, typical) - MCU_CLOCK_OFFSET)
                for m in got["events"]]
    truth = true_events(recording.plant_events, toe_heights(recording.truth, PARAMS.rest_length), PARAMS.rest_length,
                        PRE_TOUCHDOWN)
    report = match_events(truth, detected)
    print(f"\nbad input: {report.summary()}")
    assert len(truth.clean_spans) >= 8
    assert not report.missed and not report.extra and report.max_error() <= 2e-3


def send_at_1khz(datagrams, port: int) -> None:
    """Send each datagram at its sample's microcontroller time on the wall clock (1 kHz; a bad one
    with the good one next to it), to 127.0.0.1 only."""
    times = receive_times(datagrams)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        start = time.monotonic() - times[0]
        for when, data in zip(times, datagrams):
            delay = start + when - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            sock.sendto(data, ("127.0.0.1", port))
