"""The sensing half of the 1 kHz loop: per-sample cost of each stage, and packet-to-event latency
through the three nodes composed in one process and in separate processes.

Per-sample cost (plain modules, this process, no ROS): SimRobot's packets of section 4.1's
single-stride experiments (thrown anew after each) through EncoderBridge.process
(`bridge_sample_us`), StateEstimator.update (`estimator_sample_us`) and EventDetector.update
(`detector_sample_us`): mean over every sample.

Latency (five processes on loopback, their own namespace): encoder_bridge, state_estimator and
event_detector (`hopper run ...`); a source that replays SimRobot's packet stream over UDP at 1 kHz
on the wall clock and notes the clocks just before each sendto, by sequence number; a sink
(rclpy) that listens to `gait_event` and the detector's `diagnostics`. An event is matched to the
packet that revealed it by GaitEvent.state.sequence. The first second is warm-up, not measured.

rclpy_two_hop_floor_p50_us / _p99_us: the same path with no work and no UDP (a 1 kHz publisher, a
relay, an end noting publication time; 20 s, quick 5 s, same scheduling as the main run): what
two hops of rclpy cost on this machine, the part of packet_to_event no node can remove.

The main run puts every process on SCHED_FIFO (priority 50, as the demo's loop runs; normal
scheduling where that is not permitted: `sensing_realtime_priority` 0).

Figures: packet_to_event_p50_us / _p99_us / _max_us (packet sent -> its event published by the
detector, from the event's stamp + detection_delay, both host wall clock, against the source's
wall clock at sendto; target p99 < 1000 us), packet_to_event_received_p50_us / _p99_us (the same
to the sink's callback: one more hop), deadline_miss_pct (the event detector's late_samples over
its samples: states that reached it more than sensing.yaml's sample_deadline (0: the sample period, 1 ms) after their
sample's instant, i.e. the packet's earliest arrival; from its diagnostics, so that no 1 kHz
listener loads the machine), events_measured,
sensing_source_rate_hz. 40 s of packets (quick: 5 s). The same (20 s) with normal scheduling:
*_normal_scheduling. And (20 s) with the nodes on
rclpy's SingleThreadedExecutor (HOPPER_EXECUTOR=single) instead of run_node's default events
executor: packet_to_event_p50_us_single_executor, _p99_us_single_executor,
deadline_miss_pct_single_executor.

Composed (issue 19): the three nodes in one component_container (hopper_ros/nodes/component_container.py,
what a launch file's node_container starts), the hand-over in-process (use_intra_process_comms:
hopper_ros/nodes/intra_process.py; every message still on DDS for the sink): packet_to_event_p50_us_composed,
_p99_us_composed (target < 1000 us), _max_us_composed, deadline_miss_pct_composed (target < 0.5 %),
events_measured_composed, 40 s (quick 5 s) on SCHED_FIFO as the main run; the same 20 s with normal
scheduling (*_composed_normal_scheduling); and composed with the hand-over through DDS (20 s, SCHED_FIFO:
*_composed_dds), what one process saves without the in-process path.

The hand-over alone (15 s, quick 5 s, SCHED_FIFO as the main run): two nodes composed in one process,
a thread publishing BodyMeasurement at 1 kHz as the bridge's receiving thread does, the other node's
callback noting now - stamp: composed_handover_p50_us / _p99_us and the process's CPU per message
composed_handover_cpu_us (in-process), the same through DDS inside the process (*_dds).
"""
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from _common import Paced, available_realtime_priority, child_env, percentile  # noqa: E402 - bench/ is on sys.path (the script's folder)

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

DURATION_S = 40.0
QUICK_DURATION_S = 5.0
VARIANT_DURATION_S = 20.0
COST_DURATION_S = 20.0
HANDOVER_S = 15.0
HANDOVER_QUICK_S = 5.0
QUICK_COST_DURATION_S = 6.0
WARMUP_S = 1.0
PERIOD_S = 1e-3
START_TIMEOUT_S = 60.0
NODES = ("encoder_bridge", "state_estimator", "event_detector")
COMPONENTS = ("hopper_ros::EncoderBridge", "hopper_ros::StateEstimator", "hopper_ros::EventDetector")






def _packets(duration, seed=3):
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.harness.sensing_evaluation import record_experiments
    from hopper_ros.sim.config import load_sim_config
    from hopper_ros.sim.robot import SimRobot

    hardware = load_hardware()
    return hardware, record_experiments(SimRobot(load_sim_config(), hardware), duration, seed=seed).packets


# ---------------------------------------------------------------------------- per-sample cost

def stage_costs(duration):
    from hopper_ros.hardware import packet as packet_format
    from hopper_ros.physics.params import load_params
    from hopper_ros.sensing.bridge import EncoderBridge
    from hopper_ros.sensing.config import load_sensing_config
    from hopper_ros.sensing.estimator import StateEstimator
    from hopper_ros.sensing.events import EventDetector

    hardware, packets = _packets(duration)
    config = load_sensing_config()
    datagrams = [packet_format.encode(p) for p in packets]
    bridge = EncoderBridge.from_config(hardware, config.bridge)
    clock = time.perf_counter
    started = clock()
    samples = [bridge.process(d, p.mcu_time_us * 1e-6) for d, p in zip(datagrams, packets)]
    bridge_s = clock() - started
    measurements = [s.measurement() for s in samples]
    estimator = StateEstimator.from_config(config.estimator, hardware)
    started = clock()
    estimates = [e for m in measurements for e in estimator.update(m)]
    estimator_s = clock() - started
    detector = EventDetector(load_params(config.model_file), config.detector)
    started = clock()
    events = [ev for e in estimates for ev in detector.update(e)]
    detector_s = clock() - started
    n = len(packets)
    return {"bridge_sample_us": 1e6 * bridge_s / n, "estimator_sample_us": 1e6 * estimator_s / n,
            "detector_sample_us": 1e6 * detector_s / n, "events": len(events)}


# ---------------------------------------------------------------------------- latency

def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _container_command(namespace, port, intra_process):
    """The three nodes composed in one component_container, as a launch file's node_container."""
    components = [{"plugin": plugin, "intra_process": intra_process,
                   "args": ["-r", f"__node:={name}", "-r", f"__ns:={namespace}"]
                   + (["-p", f"port:={port}"] if name == "encoder_bridge" else [])}
                  for name, plugin in zip(NODES, COMPONENTS)]
    return [sys.executable, "-m", "hopper_ros.cli", "run", "component_container", "--ros-args",
            "-r", "__node:=sensing", "-r", f"__ns:={namespace}", "--", "--components", json.dumps(components)]


def latency(duration, executor="events", realtime_priority=0, composed=None):
    """The three nodes as `hopper run` starts them (hopper_ros.nodes.common.run_node), on rclpy's
    events executor (its default) or, with executor="single", HOPPER_EXECUTOR=single; with a
    realtime_priority every process of the run (nodes, source, sink) on SCHED_FIFO at it.
    composed: None (three processes), "intra_process" or "dds" (one container, the hand-over
    in-process or through DDS)."""
    namespace = f"/bench_sensing_{os.getpid()}_{executor}_{realtime_priority}_{composed or 'separate'}"
    port = _free_port()
    env = child_env(unbuffered=True)
    env["HOPPER_EXECUTOR"] = executor
    env["HOPPER_REALTIME_PRIORITY"] = str(realtime_priority)
    me = os.path.abspath(__file__)
    nodes = []
    sink = None
    try:
        commands = [_container_command(namespace, port, composed == "intra_process")] if composed else []
        for name in NODES if not composed else ():
            args = [sys.executable, "-m", "hopper_ros.cli", "run", name, "--ros-args", "-r", f"__ns:={namespace}"]
            if name == "encoder_bridge":
                args += ["-p", f"port:={port}"]
            commands.append(args)
        for args in commands:
            nodes.append(subprocess.Popen(args, cwd=REPO, env=env, stdin=subprocess.DEVNULL,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        sink = subprocess.Popen([sys.executable, me, "sink", namespace, str(duration)], cwd=REPO, env=env,
                                stdout=subprocess.PIPE, text=True)
        if sink.stdout.readline().strip() != "ready":
            raise RuntimeError("sink did not see the sensing nodes")
        source = subprocess.run([sys.executable, me, "source", str(port), str(duration)], cwd=REPO, env=env,
                                stdout=subprocess.PIPE, text=True, check=True, timeout=duration * 3 + 120)
        received = json.loads(sink.communicate(timeout=60)[0].strip().splitlines()[-1])
    finally:
        for process in nodes + ([sink] if sink else []):
            if process.poll() is None:
                process.terminate()
        for process in nodes + ([sink] if sink else []):
            try:
                process.wait(10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
    sent = json.loads(source.stdout.strip().splitlines()[-1])
    send_ns = {int(k): v for k, v in sent["send_ns"].items()}
    first_measured = min(send_ns) + int(WARMUP_S / PERIOD_S)
    # deadline misses: the detector's late_samples over the measured span (its reports after the warm-up)
    start_ns = min(send_ns.values()) + int(WARMUP_S * 1e9)
    reports = [r for r in received["reports"] if r[0] >= start_ns]
    if len(reports) < 2:
        raise RuntimeError("too few diagnostics reports of the event detector")
    samples, late = reports[-1][1] - reports[0][1], reports[-1][2] - reports[0][2]
    send_wall_ns = {int(k): v for k, v in sent["send_wall_ns"].items()}
    events = [(s, t, p) for s, t, p in received["events"] if s in send_ns and s >= first_measured]
    event_latency = sorted((p - send_wall_ns[s]) / 1e3 for s, _, p in events)
    event_received_latency = sorted((t - send_ns[s]) / 1e3 for s, t, _ in events)
    return {"event_latency": event_latency, "event_received_latency": event_received_latency,
            "deadline_miss_pct": 100.0 * late / samples, "rate_hz": sent["rate_hz"]}


def _source(port, duration):
    """Replay SimRobot's packets at 1 kHz on the wall clock; print the send times by sequence."""
    from hopper_ros.hardware import packet as packet_format

    _, packets = _packets(duration + WARMUP_S)
    datagrams = [(p.sequence, packet_format.encode(p)) for p in packets]
    send_ns, send_wall_ns = {}, {}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        address = ("127.0.0.1", port)
        pace = Paced(len(datagrams), PERIOD_S, start_delay_s=0.2)
        for index in pace:
            sequence, data = datagrams[index]
            send_ns[sequence] = time.monotonic_ns()
            send_wall_ns[sequence] = time.time_ns()
            sock.sendto(data, address)
    time.sleep(1.0)
    print(json.dumps({"send_ns": send_ns, "send_wall_ns": send_wall_ns, "rate_hz": pace.rate_hz}),
          flush=True)


def _sink(namespace, duration):
    """Receive times of gait_event, and the event detector's diagnostics (its late_samples). Nothing
    at 1 kHz: a listener of body_state would itself take a third of a core from the nodes."""
    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from diagnostic_msgs.msg import DiagnosticArray

    from hopper_ros.msg import GaitEvent
    from hopper_ros.nodes.diagnostics import DIAGNOSTICS_TOPIC, status_of, status_values

    rclpy.init()
    node = rclpy.create_node("bench_sensing_sink", namespace=namespace, start_parameter_services=False)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    events, reports = [], []
    last = [time.monotonic()]

    def on_event(msg):
        published_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec + round(msg.detection_delay * 1e9)
        events.append((msg.state.sequence, time.monotonic_ns(), published_ns))
        last[0] = time.monotonic()

    def on_diagnostics(msg):          # every node of every namespace reports on /diagnostics: ours only
        status = status_of(msg, f"{namespace}/event_detector")
        if status is not None:
            counters = status_values(status)
            reports.append((time.monotonic_ns(), counters["samples"], counters["late_samples"]))

    node.create_subscription(GaitEvent, "gait_event", on_event, qos)
    node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, on_diagnostics, qos)
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + START_TIMEOUT_S
    while not (node.count_publishers("body_state") and node.count_publishers("gait_event")
               and node.count_subscribers("body_measurement") and node.count_publishers("body_measurement")):
        if time.monotonic() > deadline:
            raise SystemExit("sink: the sensing nodes did not show up")
        executor.spin_once(timeout_sec=0.05)
    end = time.monotonic() + 1.5
    while time.monotonic() < end:               # let the nodes' own matches settle
        executor.spin_once(timeout_sec=0.05)
    print("ready", flush=True)
    deadline = time.monotonic() + duration + WARMUP_S + START_TIMEOUT_S
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if events and time.monotonic() - last[0] > 3.0:
            break                                # the source is done and nothing came for a while
    print(json.dumps({"events": events, "reports": reports}), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


# ---------------------------------------------------------------------------- rclpy floor

def floor_latency(duration, realtime_priority=0):
    """What two rclpy hops cost here with no work at all: a publisher at 1 kHz (in the bridge's
    place), a relay (the estimator's), an end (the detector's) noting publication time minus the
    stamp set just before the first publish. The same message type (BodyMeasurement), QoS, executor
    and scheduling as the nodes; the sensing chain adds the UDP hop and its own work to this."""
    namespace = f"/bench_sensing_floor_{os.getpid()}"
    env = child_env(unbuffered=True)
    env["HOPPER_REALTIME_PRIORITY"] = str(realtime_priority)
    me = os.path.abspath(__file__)
    roles = [("floor_relay", "in", "mid"), ("floor_end", "mid", ""), ("floor_source", "", "in")]
    processes = []
    try:
        for role, source, target in roles:
            processes.append(subprocess.Popen([sys.executable, me, role, namespace, source, target, str(duration)],
                                              cwd=REPO, env=env, stdout=subprocess.PIPE, text=True))
        outputs = [process.communicate(timeout=duration + START_TIMEOUT_S + 30)[0] for process in processes]
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.wait()
    return sorted(json.loads(outputs[1].strip().splitlines()[-1])["latency_us"])


def _floor(role, namespace, source, target, duration):
    import rclpy
    from rclpy.experimental import EventsExecutor

    from hopper_ros.msg import BodyMeasurement
    from hopper_ros.nodes.sensing_messages import sample_qos

    rclpy.init()
    node = rclpy.create_node(f"bench_{role}", namespace=namespace, start_parameter_services=False)
    qos = sample_qos(100)
    executor = EventsExecutor()
    executor.add_node(node)
    publisher = node.create_publisher(BodyMeasurement, target, qos) if target else None
    latency = []
    seen = [0]                            # messages received (relayed or measured)

    def on_message(msg):
        seen[0] += 1
        if publisher is not None:
            publisher.publish(msg)
        else:
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            latency.append((time.time_ns() - stamp) / 1e3)

    if source:
        node.create_subscription(BodyMeasurement, source, on_message, qos)
    deadline = time.monotonic() + START_TIMEOUT_S
    if role == "floor_source":            # wait for the chain, then publish at 1 kHz
        while not (publisher.get_subscription_count() and node.count_subscribers("mid")):
            if time.monotonic() > deadline:
                raise SystemExit("floor: the relay did not show up")
            executor.spin_once(timeout_sec=0.05)
        time.sleep(1.0)
        msg = BodyMeasurement()
        for index in Paced(int(duration / PERIOD_S), PERIOD_S):
            msg.sequence = index
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
            publisher.publish(msg)
        time.sleep(1.0)
    else:
        end = deadline + duration + 5.0
        last = time.monotonic()
        while time.monotonic() < end:       # until the stream has stopped for 2 s
            count = seen[0]
            executor.spin_once(timeout_sec=0.05)
            if seen[0] != count:
                last = time.monotonic()
            if seen[0] and time.monotonic() - last > 2.0:
                break
    print(json.dumps({"latency_us": latency[int(WARMUP_S / PERIOD_S):]}), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


# ---------------------------------------------------------------------------- the hand-over alone

def handover_latency(duration, intra_process, realtime_priority=0):
    """One hop between two nodes composed in one process (hopper_ros.nodes.intra_process), in-process
    or through DDS: (latency publish -> callback in us, sorted; CPU of the process per message in us)."""
    env = child_env(unbuffered=True)
    env["HOPPER_REALTIME_PRIORITY"] = str(realtime_priority)
    output = subprocess.run([sys.executable, os.path.abspath(__file__), "handover", str(duration), str(int(intra_process))],
                            cwd=REPO, env=env, stdout=subprocess.PIPE, text=True, check=True,
                            timeout=duration + START_TIMEOUT_S).stdout
    result = json.loads(output.strip().splitlines()[-1])
    return sorted(result["latency_us"]), result["cpu_us_per_message"]


def _handover(duration, intra_process):
    """A sender thread publishing BodyMeasurement at 1 kHz (as the bridge's receiving thread does) and
    a receiver noting now - stamp, both nodes of one container's bus, on the events executor."""
    import threading

    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node

    from hopper_ros.msg import BodyMeasurement
    from hopper_ros.nodes.intra_process import IntraProcessBus, composable
    from hopper_ros.nodes.sensing_messages import sample_qos

    class Sender(Node):
        def __init__(self, **kwargs):
            super().__init__("handover_sender", **kwargs)
            self.publisher = self.create_publisher(BodyMeasurement, "handover", sample_qos(100))

    class Receiver(Node):
        def __init__(self, **kwargs):
            super().__init__("handover_receiver", **kwargs)
            self.latency = []
            self.create_subscription(BodyMeasurement, "handover", self._on_message, sample_qos(100))

        def _on_message(self, msg):
            self.latency.append((time.time_ns() - msg.header.stamp.sec * 1_000_000_000 - msg.header.stamp.nanosec) / 1e3)

    rclpy.init()
    bus = IntraProcessBus(rclpy.logging.get_logger("handover"))
    namespace = f"/bench_handover_{os.getpid()}"
    sender = composable(Sender, bus, intra_process)(namespace=namespace, start_parameter_services=False)
    receiver = composable(Receiver, bus, intra_process)(namespace=namespace, start_parameter_services=False)
    executor = EventsExecutor()
    executor.add_node(sender)
    executor.add_node(receiver)
    deadline = time.monotonic() + START_TIMEOUT_S
    while not sender.publisher.get_subscription_count() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    count = int(duration / PERIOD_S)
    cpu = []

    def send():
        msg = BodyMeasurement()
        time.sleep(0.5)
        cpu.append(time.process_time())
        for index in Paced(count, PERIOD_S):
            msg.sequence = index
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(time.time_ns(), 1_000_000_000)
            sender.publisher.publish(msg)
        time.sleep(0.2)

    thread = threading.Thread(target=send)
    thread.start()
    while thread.is_alive() or len(receiver.latency) < count and time.monotonic() < deadline + duration + 5:
        executor.spin_once(timeout_sec=0.05)
    cpu_s = time.process_time() - cpu[0]
    print(json.dumps({"latency_us": receiver.latency[int(WARMUP_S / PERIOD_S):],
                      "cpu_us_per_message": 1e6 * cpu_s / max(1, len(receiver.latency))}), flush=True)
    executor.shutdown()
    receiver.destroy_node()
    sender.destroy_node()
    rclpy.shutdown()


def run(quick=False):
    costs = stage_costs(QUICK_COST_DURATION_S if quick else COST_DURATION_S)
    priority = available_realtime_priority()     # SCHED_FIFO of every process of the main run, as in the demo
    result = latency(QUICK_DURATION_S if quick else DURATION_S, realtime_priority=priority)
    events = result["event_latency"]
    if not events:
        raise RuntimeError("no gait event came through")
    normal = latency(QUICK_DURATION_S if quick else VARIANT_DURATION_S)
    floor = floor_latency(QUICK_DURATION_S if quick else VARIANT_DURATION_S, realtime_priority=priority)
    variant = latency(QUICK_DURATION_S if quick else VARIANT_DURATION_S, executor="single")
    composed = latency(QUICK_DURATION_S if quick else DURATION_S, realtime_priority=priority, composed="intra_process")
    composed_normal = latency(QUICK_DURATION_S if quick else VARIANT_DURATION_S, composed="intra_process")
    composed_dds = latency(QUICK_DURATION_S if quick else VARIANT_DURATION_S, realtime_priority=priority,
                           composed="dds")
    handover = {mode: handover_latency(HANDOVER_QUICK_S if quick else HANDOVER_S, mode == "intra_process", priority)
                for mode in ("intra_process", "dds")}

    def chain(suffix, measured):
        return [{"name": f"packet_to_event_p50_us_{suffix}",
                 "value": round(percentile(measured["event_latency"], 0.50), 1), "unit": "us"},
                {"name": f"packet_to_event_p99_us_{suffix}",
                 "value": round(percentile(measured["event_latency"], 0.99), 1), "unit": "us"},
                {"name": f"deadline_miss_pct_{suffix}", "value": round(measured["deadline_miss_pct"], 3), "unit": "%"}]

    return chain("composed", composed) + chain("composed_normal_scheduling", composed_normal) + [
        {"name": "packet_to_event_max_us_composed", "value": round(composed["event_latency"][-1], 1), "unit": "us"},
        {"name": "events_measured_composed", "value": len(composed["event_latency"]), "unit": "events"},
    ] + chain("composed_dds", composed_dds) + [
        {"name": f"composed_handover_{figure}_us{'' if mode == 'intra_process' else '_dds'}", "unit": "us",
         "value": round(percentile(handover[mode][0], q) if q else handover[mode][1], 1)}
        for mode in ("intra_process", "dds") for figure, q in (("p50", 0.50), ("p99", 0.99), ("cpu", None))
    ] + [
        {"name": "bridge_sample_us", "value": round(costs["bridge_sample_us"], 1), "unit": "us"},
        {"name": "estimator_sample_us", "value": round(costs["estimator_sample_us"], 1), "unit": "us"},
        {"name": "detector_sample_us", "value": round(costs["detector_sample_us"], 1), "unit": "us"},
        {"name": "packet_to_event_p50_us", "value": round(percentile(events, 0.50), 1), "unit": "us"},
        {"name": "packet_to_event_p99_us", "value": round(percentile(events, 0.99), 1), "unit": "us"},
        {"name": "packet_to_event_max_us", "value": round(events[-1], 1), "unit": "us"},
        {"name": "packet_to_event_received_p50_us",
         "value": round(percentile(result["event_received_latency"], 0.50), 1), "unit": "us"},
        {"name": "packet_to_event_received_p99_us",
         "value": round(percentile(result["event_received_latency"], 0.99), 1), "unit": "us"},
        {"name": "deadline_miss_pct", "value": round(result["deadline_miss_pct"], 3), "unit": "%"},
        {"name": "events_measured", "value": len(events), "unit": "events"},
        {"name": "sensing_realtime_priority", "value": priority, "unit": "SCHED_FIFO"},
        # two rclpy hops without any work, same scheduling: the part of the latency that is rclpy's
        {"name": "rclpy_two_hop_floor_p50_us", "value": round(percentile(floor, 0.50), 1), "unit": "us"},
        {"name": "rclpy_two_hop_floor_p99_us", "value": round(percentile(floor, 0.99), 1), "unit": "us"},
        # the same with normal scheduling (SCHED_OTHER)
        {"name": "packet_to_event_p50_us_normal_scheduling",
         "value": round(percentile(normal["event_latency"], 0.50), 1), "unit": "us"},
        {"name": "packet_to_event_p99_us_normal_scheduling",
         "value": round(percentile(normal["event_latency"], 0.99), 1), "unit": "us"},
        {"name": "deadline_miss_pct_normal_scheduling", "value": round(normal["deadline_miss_pct"], 3), "unit": "%"},
        {"name": "sensing_source_rate_hz", "value": round(result["rate_hz"], 1), "unit": "Hz"},
        # the same with HOPPER_EXECUTOR=single (rclpy's SingleThreadedExecutor in run_node)
        {"name": "packet_to_event_p50_us_single_executor",
         "value": round(percentile(variant["event_latency"], 0.50), 1), "unit": "us"},
        {"name": "packet_to_event_p99_us_single_executor",
         "value": round(percentile(variant["event_latency"], 0.99), 1), "unit": "us"},
        {"name": "deadline_miss_pct_single_executor", "value": round(variant["deadline_miss_pct"], 3), "unit": "%"},
    ]


if __name__ == "__main__":
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    role = sys.argv[1] if len(sys.argv) > 1 else "run"
    if role in ("source", "sink", "floor_source", "floor_relay", "floor_end", "handover"):
        from hopper_ros.runtime.environment import apply_realtime_priority

        apply_realtime_priority()            # HOPPER_REALTIME_PRIORITY of the run, as the nodes
    if role == "source":
        _source(int(sys.argv[2]), float(sys.argv[3]))
    elif role == "sink":
        _sink(sys.argv[2], float(sys.argv[3]))
    elif role == "handover":
        _handover(float(sys.argv[2]), sys.argv[3] == "1")
    elif role.startswith("floor_"):
        _floor(role, sys.argv[2], sys.argv[3], sys.argv[4], float(sys.argv[5]))
    else:
        for figure in run(quick="--quick" in sys.argv):
            print(figure)
