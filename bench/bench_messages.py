"""Message latency between two processes over rclpy: hopper_ros/msg/BodyState at 1 kHz.

A publisher process sends BodyState at 1 kHz (after a warm-up) to a subscriber process on
a topic of its own; each message carries the publisher's CLOCK_MONOTONIC time in
header.stamp, taken just before publish(). The subscriber takes the same clock first thing
in its callback, so a figure is the one-way publish -> callback latency, including the
rclpy executor of the subscriber. DDS discovery is kept on loopback.

Figures: msg_roundtrip_p50_us, msg_roundtrip_p99_us, msg_roundtrip_max_us,
msg_roundtrip_lost, msg_publish_rate_hz.
"""
import json
import os
import subprocess
import sys
import time

from _common import Paced, child_env, child_role, percentile  # noqa: E402 - bench/ is on sys.path (the script's folder)

COUNT = 2000          # measured messages
QUICK_COUNT = 500
WARMUP = 200          # sent first, not measured (discovery settling, first-use costs)
RATE_HZ = 1000.0
MATCH_TIMEOUT_S = 30.0






def run(quick=False):
    count = QUICK_COUNT if quick else COUNT
    topic = f"/hopper_bench/body_state_{os.getpid()}_{time.monotonic_ns()}"
    total = WARMUP + count
    me = os.path.abspath(__file__)
    subscriber = subprocess.Popen(
        [sys.executable, me, "subscribe", topic, str(total), str(WARMUP)],
        stdout=subprocess.PIPE, text=True, env=child_env())
    try:
        if subscriber.stdout.readline().strip() != "ready":
            raise RuntimeError("subscriber did not start")
        publisher = subprocess.run(
            [sys.executable, me, "publish", topic, str(total), str(RATE_HZ)],
            stdout=subprocess.PIPE, text=True, env=child_env(),
            timeout=MATCH_TIMEOUT_S + total / RATE_HZ + 30.0, check=True)
        out, _ = subscriber.communicate(timeout=30.0)
    finally:
        if subscriber.poll() is None:
            subscriber.kill()
            subscriber.wait()
    if subscriber.returncode != 0:
        raise RuntimeError(f"subscriber exited with {subscriber.returncode}")
    result = json.loads(out.strip().splitlines()[-1])
    sent = json.loads(publisher.stdout.strip().splitlines()[-1])
    latencies_us = sorted(ns / 1000.0 for ns in result["latencies_ns"])
    if not latencies_us:
        raise RuntimeError("no message received")
    return [
        {"name": "msg_roundtrip_p50_us", "value": round(percentile(latencies_us, 0.50), 1),
         "unit": "us"},
        {"name": "msg_roundtrip_p99_us", "value": round(percentile(latencies_us, 0.99), 1),
         "unit": "us"},
        {"name": "msg_roundtrip_max_us", "value": round(latencies_us[-1], 1), "unit": "us"},
        {"name": "msg_roundtrip_lost", "value": count - len(latencies_us), "unit": "msgs"},
        {"name": "msg_publish_rate_hz", "value": round(sent["rate_hz"], 1), "unit": "Hz"},
    ]


# ---------------------------------------------------------------------------- processes

def _qos():
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=200,
                      reliability=ReliabilityPolicy.RELIABLE)


def _subscribe(topic, total, warmup):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from hopper_ros.msg import BodyState

    rclpy.init()
    node = rclpy.create_node("hopper_bench_messages_sub")
    latencies = []
    state = {"last": None, "count": 0}

    def callback(msg):
        now = time.monotonic_ns()
        sent = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        state["count"] += 1
        state["last"] = time.monotonic()
        if msg.sequence >= warmup:
            latencies.append(now - sent)

    node.create_subscription(BodyState, topic, callback, _qos())
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    print("ready", flush=True)
    deadline = time.monotonic() + MATCH_TIMEOUT_S + total / RATE_HZ + 20.0
    while time.monotonic() < deadline and state["count"] < total:
        executor.spin_once(timeout_sec=0.05)
        # the publisher is done and nothing came for a while: the rest is lost
        if state["last"] is not None and time.monotonic() - state["last"] > 3.0:
            break
    print(json.dumps({"received": state["count"], "latencies_ns": latencies}), flush=True)
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown()


def _publish(topic, total, rate_hz):
    import rclpy

    from hopper_ros.msg import BodyState

    rclpy.init()
    node = rclpy.create_node("hopper_bench_messages_pub")
    publisher = node.create_publisher(BodyState, topic, _qos())
    deadline = time.monotonic() + MATCH_TIMEOUT_S
    while publisher.get_subscription_count() < 1:
        if time.monotonic() > deadline:
            raise SystemExit("publisher: no subscriber matched")
        time.sleep(0.01)
    time.sleep(0.5)  # let the subscriber's side of the match settle too
    msg = BodyState()
    msg.header.frame_id = "ground"
    pace = Paced(total, 1.0 / rate_hz)
    for sequence in pace:
        msg.sequence = sequence
        msg.y = sequence * 1e-3
        now = time.monotonic_ns()
        msg.header.stamp.sec = now // 1_000_000_000
        msg.header.stamp.nanosec = now % 1_000_000_000
        publisher.publish(msg)
    time.sleep(1.0)  # reliable delivery of the tail before the writer goes away
    print(json.dumps({"sent": total, "rate_hz": pace.rate_hz}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    child_role({"subscribe": lambda topic, total, warmup: _subscribe(topic, int(total), int(warmup)),
                "publish": lambda topic, total, rate_hz: _publish(topic, int(total), float(rate_hz))})
