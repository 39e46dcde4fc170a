"""The sensing half of the 1 kHz loop: per-sample cost of each stage, and packet-to-event latency
through the three nodes in separate processes.

Per-sample cost (plain modules, this process, no ROS): SimRobot's packets of section 4.1's
single-stride experiments (thrown anew after each) through EncoderBridge.process
(`bridge_sample_us`), StateEstimator.update (`estimator_sample_us`) and EventDetector.update
(`detector_sample_us`): mean over every sample.

Latency (five processes on loopback, their own namespace): encoder_bridge, state_estimator and
event_detector (`hopper run ...`); a source that replays SimRobot's packet stream over UDP at 1 kHz
on the wall clock and notes CLOCK_MONOTONIC just before each sendto, by sequence number; a sink
(rclpy) that notes CLOCK_MONOTONIC first thing in its callbacks of `body_state` and `gait_event`.
An event is matched to the packet that revealed it by GaitEvent.state.sequence, a state by
BodyState.sequence. The first second is warm-up, not measured.

The main run puts every process on SCHED_FIFO (priority 50, as the demo's loop runs; normal
scheduling where that is not permitted: `sensing_realtime_priority` 0).

Figures: packet_to_event_p50_us / _p99_us / _max_us (packet sent -> its event published by the
detector, from the event's stamp + detection_delay, both host wall clock, against the source's
wall clock at sendto; target p99 < 1000 us), packet_to_event_received_p50_us / _p99_us (the same
to the sink's callback: one more hop), packet_to_measurement_p50_us / _p99_us (to the sink's
BodyMeasurement callback), packet_to_state_p50_us / _p99_us (packet sent -> its BodyState received),
deadline_miss_pct (share of the packets whose BodyState did not reach the subscriber within one
sample period, 1 ms, of the packet being sent; never counts as a miss), events_measured,
sensing_source_rate_hz. 60 s of packets (quick: 10 s). The same (30 s) with normal scheduling:
*_normal_scheduling. And (30 s) with the nodes on
rclpy's SingleThreadedExecutor (HOPPER_EXECUTOR=single) instead of run_node's default events
executor: packet_to_event_p50_us_single_executor, _p99_us_single_executor,
deadline_miss_pct_single_executor.
"""
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from _common import child_env, percentile  # noqa: E402 - bench/ is on sys.path (the script's folder)

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

DURATION_S = 60.0
QUICK_DURATION_S = 10.0
VARIANT_DURATION_S = 30.0
COST_DURATION_S = 30.0
QUICK_COST_DURATION_S = 6.0
WARMUP_S = 1.0
PERIOD_S = 1e-3
START_TIMEOUT_S = 60.0
NODES = ("encoder_bridge", "state_estimator", "event_detector")
REALTIME_PRIORITY = 50   # SCHED_FIFO of every process of the main run, as in config/launch/demo.yaml






def _packets(duration, seed=3):
    from hopper_ros.config import load_yaml
    from hopper_ros.sensing.evaluation import record_experiments
    from hopper_ros.sim.config import load_sim_config
    from hopper_ros.sim.robot import SimRobot

    hardware = load_yaml("hardware.yaml")
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


def latency(duration, executor="events", realtime_priority=0):
    """The three nodes as `hopper run` starts them (hopper_ros.nodes.common.run_node), on rclpy's
    events executor (its default) or, with executor="single", HOPPER_EXECUTOR=single; with a
    realtime_priority every process of the run (nodes, source, sink) on SCHED_FIFO at it."""
    namespace = f"/bench_sensing_{os.getpid()}_{executor}_{realtime_priority}"
    port = _free_port()
    env = child_env(unbuffered=True)
    env["HOPPER_EXECUTOR"] = executor
    env["HOPPER_REALTIME_PRIORITY"] = str(realtime_priority)
    me = os.path.abspath(__file__)
    nodes = []
    sink = None
    try:
        for name in NODES:
            args = [sys.executable, "-m", "hopper_ros.cli", "run", name, "--ros-args", "-r", f"__ns:={namespace}"]
            if name == "encoder_bridge":
                args += ["-p", f"port:={port}"]
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
    measured = [s for s in send_ns if s >= first_measured]
    states = {int(k): v for k, v in received["states"].items()}
    state_latency = sorted((states[s] - send_ns[s]) / 1e3 for s in measured if s in states)
    measurements = {int(k): v for k, v in received["measurements"].items()}
    measurement_latency = sorted((measurements[s] - send_ns[s]) / 1e3 for s in measured if s in measurements)
    misses = sum(1 for s in measured if s not in states or states[s] - send_ns[s] > PERIOD_S * 1e9)
    send_wall_ns = {int(k): v for k, v in sent["send_wall_ns"].items()}
    events = [(s, t, p) for s, t, p in received["events"] if s in send_ns and s >= first_measured]
    event_latency = sorted((p - send_wall_ns[s]) / 1e3 for s, _, p in events)
    event_received_latency = sorted((t - send_ns[s]) / 1e3 for s, t, _ in events)
    return {"event_latency": event_latency, "event_received_latency": event_received_latency,
            "state_latency": state_latency, "measurement_latency": measurement_latency,
            "deadline_miss_pct": 100.0 * misses / len(measured), "rate_hz": sent["rate_hz"]}


def _source(port, duration):
    """Replay SimRobot's packets at 1 kHz on the wall clock; print the send times by sequence."""
    from hopper_ros.hardware import packet as packet_format

    _, packets = _packets(duration + WARMUP_S)
    datagrams = [(p.sequence, packet_format.encode(p)) for p in packets]
    send_ns, send_wall_ns = {}, {}
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        address = ("127.0.0.1", port)
        start = time.monotonic_ns() + 200_000_000
        for index, (sequence, data) in enumerate(datagrams):
            left = start + index * 1_000_000 - time.monotonic_ns()
            if left > 0:
                time.sleep(left / 1e9)
            send_ns[sequence] = time.monotonic_ns()
            send_wall_ns[sequence] = time.time_ns()
            sock.sendto(data, address)
        elapsed = (time.monotonic_ns() - start) / 1e9
    time.sleep(1.0)
    print(json.dumps({"send_ns": send_ns, "send_wall_ns": send_wall_ns, "rate_hz": (len(datagrams) - 1) / elapsed}),
          flush=True)


def _sink(namespace, duration):
    """Receive times of body_state and gait_event (rclpy's EventsExecutor: the cheapest to listen)."""
    import rclpy
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from hopper_ros.msg import BodyMeasurement, BodyState, GaitEvent

    rclpy.init()
    node = rclpy.create_node("bench_sensing_sink", namespace=namespace, start_parameter_services=False)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    states, measurements, events = {}, {}, []
    last = [time.monotonic()]

    def on_state(msg):
        now = time.monotonic_ns()
        if msg.measurement_used or msg.outlier_rejected:
            states.setdefault(msg.sequence, now)
        last[0] = time.monotonic()

    def on_measurement(msg):
        measurements.setdefault(msg.sequence, time.monotonic_ns())

    def on_event(msg):
        published_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec + round(msg.detection_delay * 1e9)
        events.append((msg.state.sequence, time.monotonic_ns(), published_ns))

    node.create_subscription(BodyState, "body_state", on_state, qos)
    node.create_subscription(GaitEvent, "gait_event", on_event, qos)
    node.create_subscription(BodyMeasurement, "body_measurement", on_measurement, qos)
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
    started = False
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        started = started or bool(states)
        if started and time.monotonic() - last[0] > 3.0:
            break                                # the source is done and nothing came for a while
    print(json.dumps({"states": states, "measurements": measurements, "events": events}), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


def run(quick=False):
    from hopper_ros.environment import realtime_scheduling_allowed

    costs = stage_costs(QUICK_COST_DURATION_S if quick else COST_DURATION_S)
    priority = REALTIME_PRIORITY if realtime_scheduling_allowed()[0] else 0
    result = latency(QUICK_DURATION_S if quick else DURATION_S, realtime_priority=priority)
    events, states = result["event_latency"], result["state_latency"]
    if not events:
        raise RuntimeError("no gait event came through")
    normal = latency(QUICK_DURATION_S if quick else VARIANT_DURATION_S)
    variant = latency(QUICK_DURATION_S if quick else VARIANT_DURATION_S, executor="single")
    return [
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
        {"name": "packet_to_state_p50_us", "value": round(percentile(states, 0.50), 1), "unit": "us"},
        {"name": "packet_to_state_p99_us", "value": round(percentile(states, 0.99), 1), "unit": "us"},
        {"name": "packet_to_measurement_p50_us",
         "value": round(percentile(result["measurement_latency"], 0.50), 1), "unit": "us"},
        {"name": "packet_to_measurement_p99_us",
         "value": round(percentile(result["measurement_latency"], 0.99), 1), "unit": "us"},
        {"name": "deadline_miss_pct", "value": round(result["deadline_miss_pct"], 3), "unit": "%"},
        {"name": "events_measured", "value": len(events), "unit": "events"},
        {"name": "sensing_realtime_priority", "value": priority, "unit": "SCHED_FIFO"},
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
    if role in ("source", "sink"):
        from hopper_ros.environment import apply_realtime_priority

        apply_realtime_priority()            # HOPPER_REALTIME_PRIORITY of the run, as the nodes
    if role == "source":
        _source(int(sys.argv[2]), float(sys.argv[3]))
    elif role == "sink":
        _sink(sys.argv[2], float(sys.argv[3]))
    else:
        for figure in run(quick="--quick" in sys.argv):
            print(figure)
