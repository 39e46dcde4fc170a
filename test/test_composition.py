"""Composition (issue 19): launch files' node_container entries, and the sensing chain composed in
one process on one executor with the in-process hand-over (hopper_ros/nodes/intra_process.py),
on real nodes fed by real UDP packets of the simulated robot."""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest
import yaml

from conftest import SAFETY_TIMEOUT, free_port, spin_until
from hopper_ros.config import load_yaml
from hopper_ros.harness.sensing_evaluation import record_experiments
from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.config import load_hardware
from hopper_ros.launch import LaunchFileError, load_launch, parse_launch
from hopper_ros.sim.config import load_sim_config
from hopper_ros.sim.robot import SimRobot


def container(*composable, **attributes) -> dict:
    return {"node_container": {"pkg": "hopper_ros", "exec": "component_container", "name": "sensing",
                               "namespace": "/hopper", "composable_node": list(composable), **attributes}}


def component(plugin: str, name: str, **attributes) -> dict:
    return {"pkg": "hopper_ros", "plugin": plugin, "name": name, **attributes}


def components_of(child) -> list[dict]:
    assert child.argv[3:5] == ["run", "component_container"] and child.argv[-2] == "--components"
    return json.loads(child.argv[-1])


# ------------------------------------------------------------------------------------ launch format


def test_a_container_entry_becomes_one_process_with_its_composable_nodes():
    data = {"launch": [
        {"arg": {"name": "ns", "default": "/robot"}},
        container(
            component("hopper_ros::EncoderBridge", "bridge", namespace="$(var ns)", param=[{"name": "port", "value": 15811}],
                      extra_arg=[{"name": "use_intra_process_comms", "value": "true"}]),
            component("hopper_ros::StateEstimator", "estimator", namespace="$(var ns)",
                      remap=[{"from": "body_measurement", "to": "/shared/measurements"}]),
            component("hopper_ros::EventDetector", "detector", **{"if": "false"}),
            env=[{"name": "HOPPER_REALTIME_PRIORITY", "value": "50"}], sigterm_timeout=3),
        {"node": {"pkg": "hopper_ros", "exec": "stride_predictor"}},
    ]}
    description = parse_launch(data, source="test.launch.yaml")
    sensing, predictor = description.children
    assert sensing.label == "hopper/sensing" and predictor.label == "stride_predictor"
    assert sensing.argv[5:10] == ["--ros-args", "-r", "__node:=sensing", "-r", "__ns:=/hopper"]
    assert sensing.env["HOPPER_REALTIME_PRIORITY"] == "50" and description.sigint_timeout == 3
    assert components_of(sensing) == [
        {"plugin": "hopper_ros::EncoderBridge", "intra_process": True,
         "args": ["-r", "__node:=bridge", "-r", "__ns:=/robot", "-p", "port:=15811"]},
        {"plugin": "hopper_ros::StateEstimator", "intra_process": False,
         "args": ["-r", "__node:=estimator", "-r", "__ns:=/robot", "-r", "body_measurement:=/shared/measurements"]},
    ]   # the detector's `if` is false: not loaded


def test_the_demo_composes_the_sensing_chain_with_the_in_process_hand_over():
    description = load_launch("demo.launch.yaml")
    containers = [c for c in description.children if c.argv[4] == "component_container"]
    assert len(containers) == 1
    loaded = components_of(containers[0])
    plugins = [c["plugin"] for c in loaded]
    assert plugins[:3] == ["hopper_ros::EncoderBridge", "hopper_ros::StateEstimator", "hopper_ros::EventDetector"]
    assert all(c["intra_process"] for c in loaded)
    separate = {c.argv[4] for c in description.children} - {"component_container"}
    assert not separate & {"encoder_bridge", "state_estimator", "event_detector"}


BRIDGE = component("hopper_ros::EncoderBridge", "bridge")


@pytest.mark.parametrize("entry, message", [
    (container(BRIDGE, pkg="rclcpp_components"), "entry 1 (node_container): pkg 'rclcpp_components' exec "
     "'component_container': a container of Python nodes is pkg: hopper_ros, exec: component_container"),
    (container(BRIDGE, exec="component_container_mt"), "exec 'component_container_mt': a container of Python nodes"),
    ({"node_container": {"pkg": "hopper_ros", "exec": "component_container", "name": "c", "composable_node": [BRIDGE]}},
     "entry 1 (node_container) (component_container): missing 'namespace' (launch_ros requires it of a container"),
    (container(), "'composable_node' must be a non-empty list of composable nodes"),
    (container(BRIDGE, args="--x"), "unknown key(s) 'args' of 'node_container'"),
    (container(component("hopper_ros::Nope", "n")), "entry 1 (node_container) (component_container), composable_node 1: "
     "unknown plugin 'hopper_ros::Nope'; hopper_ros's: hopper_ros::DeadbeatController"),
    (container(component("composition::Talker", "t", pkg="composition")),
     "composable_node 1: pkg 'composition': the container loads hopper_ros's nodes only"),
    (container(BRIDGE, {"pkg": "hopper_ros", "plugin": "hopper_ros::StateEstimator"}),
     "composable_node 2 (hopper_ros::StateEstimator): missing 'name' (launch_ros requires it of a composable_node)"),
    (container(component("hopper_ros::EncoderBridge", "b", exec="x")), "composable_node 1: unknown key(s) 'exec' of "
     "'composable_node' (hopper launch supports: extra_arg, if, name, namespace, param, pkg, plugin, remap, unless)"),
    (container(component("hopper_ros::EncoderBridge", "b", extra_arg=[{"name": "use_intra_process_comms", "value": "yes"}])),
     "extra_arg 'use_intra_process_comms': 'yes': hopper launch supports only use_intra_process_comms, 'true' or 'false'"),
    (container(component("hopper_ros::EncoderBridge", "b", extra_arg=[{"name": "other", "value": "true"}])),
     "extra_arg 'other': 'true': hopper launch supports only use_intra_process_comms"),
    (container(BRIDGE, component("hopper_ros::StateEstimator", "bridge")),
     "a node 'bridge' is already started by entry 1"),
    ({"node": {"pkg": "hopper_ros", "exec": "component_container"}},
     "unknown exec 'component_container'; hopper_ros's nodes: deadbeat_controller"),
])
def test_bad_container_entries_are_refused_with_one_line(entry, message):
    with pytest.raises(LaunchFileError) as error:
        parse_launch({"launch": [entry]}, source="bad.launch.yaml")
    text = str(error.value)
    assert "\n" not in text and text.startswith("bad.launch.yaml: entry 1") and message in text


def test_hopper_launch_says_what_is_wrong_with_a_container_in_one_line(hopper_cli, tmp_path):
    path = tmp_path / "bad.launch.yaml"
    path.write_text(yaml.safe_dump({"launch": [container(BRIDGE, pkg="rclcpp_components")]}))
    process = hopper_cli("launch", str(path))
    assert process.wait() == 3
    assert process.stderr.strip().count("\n") == 0
    assert f"hopper launch: error: {path}: entry 1 (node_container): pkg 'rclcpp_components'" in process.stderr


# ------------------------------------------------------------------------------------ composed chain


class ComposedChain:
    """encoder_bridge, state_estimator and event_detector composed as the container composes them,
    in a context (DDS participant) of their own, spun in a thread; a listener in the test's context (`listen`:
    subscribed to the chain's measurements, states and events)."""

    def __init__(self, rclpy_session, tmp_path, remapped: bool, listen: bool = True):
        from rclpy.experimental import EventsExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

        from hopper_ros.msg import BodyMeasurement, BodyState, GaitEvent
        from hopper_ros.nodes.component_container import Composition

        settings = load_yaml("sensing.yaml")
        settings["sensing"]["queue_depth"] = 10000     # a starved machine delays, never drops: exact counts
        (tmp_path / "sensing.yaml").write_text(yaml.safe_dump(settings))
        self.port = free_port(socket.SOCK_DGRAM)
        common = ["-p", f"sensing_file:={tmp_path / 'sensing.yaml'}", "-p", "diagnostics_period:=0.5"]
        # remapped: the bridge in another namespace than its subscriber, both remapped to one topic
        self.measurements = "/shared/measurements" if remapped else "/c/body_measurement"
        remap = ["-r", f"body_measurement:={self.measurements}"] if remapped else []
        components = [
            {"plugin": "hopper_ros::EncoderBridge", "intra_process": True,
             "args": ["-r", "__ns:=/a" if remapped else "__ns:=/c", "-p", f"port:={self.port}", *common, *remap]},
            {"plugin": "hopper_ros::StateEstimator", "intra_process": True, "args": ["-r", "__ns:=/c", *common, *remap]},
            {"plugin": "hopper_ros::EventDetector", "intra_process": True, "args": ["-r", "__ns:=/c", *common]},
        ]
        self.context = rclpy_session.Context()
        rclpy_session.init(context=self.context)
        self.nodes = Composition(components, context=self.context)
        self.executor = EventsExecutor(context=self.context)
        for node in self.nodes:
            self.executor.add_node(node)
        self.nodes.spinning()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

        self.listener = rclpy_session.create_node("composition_test_listener")
        self.listener_executor = EventsExecutor()
        self.listener_executor.add_node(self.listener)
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=20000, reliability=ReliabilityPolicy.RELIABLE)
        self.got = {"measurements": [], "states": [], "events": []}
        topics = (("measurements", BodyMeasurement, self.measurements), ("states", BodyState, "/c/body_state"),
                  ("events", GaitEvent, "/c/gait_event"))
        for key, kind, topic in topics if listen else ():
            self.listener.create_subscription(kind, topic, lambda msg, key=key: self.got[key].append(msg), qos)

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    @property
    def bridge(self):
        return self.nodes[1].bridge

    @property
    def estimator(self):
        return self.nodes[2].estimator

    @property
    def detector(self):
        return self.nodes[3].detector

    def wait_connected(self) -> None:
        """The listener matched with every publisher it listens to (outside observers see them)."""
        def matched():
            return all(self.listener.count_publishers(t) for t in (self.measurements, "/c/body_state", "/c/gait_event"))
        assert spin_until(self.listener_executor, matched)
        spin_until(self.listener_executor, lambda: False, timeout=1.0)

    def send(self, datagrams) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            start = time.monotonic()
            for index, data in enumerate(datagrams):
                delay = start + index * 1e-3 - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                sock.sendto(data, ("127.0.0.1", self.port))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(SAFETY_TIMEOUT)
        self.executor.shutdown()
        for node in reversed(self.nodes):
            node.destroy_node()
        self.context.try_shutdown()
        self.listener_executor.shutdown()
        self.listener.destroy_node()


def experiment_datagrams(duration: float) -> list[bytes]:
    recording = record_experiments(SimRobot(load_sim_config(), load_hardware()), duration, seed=4)
    return [packet_format.encode(p) for p in recording.packets]


@pytest.mark.parametrize("remapped", [False, True], ids=["same_namespace", "remapped_across_namespaces"])
def test_composed_chain_delivers_each_message_once_and_outside_subscribers_see_all(rclpy_session, tmp_path, remapped):
    datagrams = experiment_datagrams(3.0)
    chain = ComposedChain(rclpy_session, tmp_path, remapped)
    try:
        chain.wait_connected()
        sender = threading.Thread(target=chain.send, args=(datagrams,), daemon=True)
        sender.start()
        n = len(datagrams)

        def everything_arrived():
            return (not sender.is_alive() and len(chain.got["measurements"]) >= n and len(chain.got["states"]) >= n
                    and chain.detector.counters["samples"] >= n)

        assert spin_until(chain.listener_executor, everything_arrived), (
            len(chain.got["measurements"]), len(chain.got["states"]), chain.detector.counters["samples"])
        spin_until(chain.listener_executor, lambda: False, timeout=1.0)   # anything doubled would come now
        got = chain.got
        bridge, estimator, detector = (dict(chain.bridge.counters), dict(chain.estimator.counters),
                                       dict(chain.detector.counters))
    finally:
        chain.close()
    assert bridge["samples_accepted"] == n
    # each composed subscriber got every message exactly once: the in-process copy, not DDS's as well
    # (a second delivery would count twice, or as a stale measurement)
    assert estimator["measurements"] == n and estimator["stale_measurements"] == 0
    assert estimator["predicted_samples"] == 0 and detector["samples"] == n
    # outside observers (another DDS participant) see every intermediate message, in order
    assert [m.sequence for m in got["measurements"]] == [m.sequence for m in got["states"]]
    assert len(got["measurements"]) == n and len({m.sequence for m in got["measurements"]}) == n
    # the chain's output: packet -> gait_event, apexes and touchdowns of the experiments
    from hopper_ros.msg import GaitEvent
    assert {GaitEvent.APEX, GaitEvent.TOUCHDOWN, GaitEvent.LIFTOFF} <= {e.type for e in got["events"]}


def test_with_nobody_outside_listening_the_in_process_messages_stay_off_dds(rclpy_session, tmp_path, monkeypatch):
    """As rclcpp's intra-process publishing: a message goes to DDS only where a subscription outside the
    container's in-process ones is matched (issue 29: the 1 kHz states handed to DDS for nobody took the real-time
    container a tenth of a core). The chain still runs in-process."""
    from rclpy.publisher import Publisher

    handed = {}
    dds_publish = Publisher.publish

    def counting(self, msg):
        handed[self.topic_name] = handed.get(self.topic_name, 0) + 1
        return dds_publish(self, msg)

    monkeypatch.setattr(Publisher, "publish", counting)     # the real publish, counted per topic
    datagrams = experiment_datagrams(1.0)
    chain = ComposedChain(rclpy_session, tmp_path, remapped=False, listen=False)
    try:
        spin_until(chain.listener_executor, lambda: False, timeout=1.0)    # discovery settles
        chain.send(datagrams)
        n = len(datagrams)
        assert spin_until(chain.listener_executor, lambda: chain.detector.counters["samples"] >= n)
        estimator = dict(chain.estimator.counters)
    finally:
        chain.close()
    assert estimator["measurements"] == n and estimator["predicted_samples"] == 0
    assert handed.get("/c/body_measurement", 0) == 0 and handed.get("/c/body_state", 0) == 0, handed


def test_a_composed_subscriber_still_hears_publishers_of_other_processes(rclpy_session, tmp_path):
    """ignore_local_publications drops only this process's own DDS copies: a publisher elsewhere
    (here another participant) reaches the composed, in-process-enabled estimator by DDS."""
    from hopper_ros.msg import BodyMeasurement

    chain = ComposedChain(rclpy_session, tmp_path, remapped=True)
    try:
        publisher = chain.listener.create_publisher(BodyMeasurement, chain.measurements, 100)
        assert spin_until(chain.listener_executor, lambda: publisher.get_subscription_count() >= 2)
        spin_until(chain.listener_executor, lambda: False, timeout=1.0)
        for sequence in range(5):
            msg = BodyMeasurement(sequence=sequence, mcu_time=sequence * 1e-3)
            msg.header.stamp.sec = int(time.time())
            publisher.publish(msg)
            time.sleep(0.002)
        assert spin_until(chain.listener_executor, lambda: chain.estimator.counters["measurements"] >= 5)
        spin_until(chain.listener_executor, lambda: False, timeout=0.5)
        assert chain.estimator.counters["measurements"] == 5
    finally:
        chain.close()
