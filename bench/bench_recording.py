"""Bag recording and reading (hopper_ros/recording).

- bag_write_msgs_per_s: BagWriter.write_message of BodyMeasurement messages (rclpy CDR
  serialisation, zstd chunks, indexes) into a bag on disk, closed at the end
- bag_write_raw_msgs_per_s: BagWriter.write of already serialized messages, what the recorder's
  raw subscriptions do
- bag_read_samples_per_s: load_bag of a collected bag (three 1 kHz topics, commands, events),
  samples per second of wall time
- bag_record_loss_pct: `hopper bag record` of five 1 kHz topics (force_plate, sim/truth,
  encoder_sample, body_measurement, body_state) of the live sensing graph for 60 s (10 s with
  --quick): the share of published messages the recorder never got (its own count from the
  publishers' sequence numbers, stored in the bag); bag_record_dropped_msgs, bag_record_msgs;
  bag_record_truth_holes: samples missing from the ground truth's 1 ms grid inside the bag (an
  independent check); bag_record_start_s: from the command to the bag's first message
"""
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from hopper_ros.runtime.environment import free_domain_id  # noqa: E402
from hopper_ros.hardware.config import load_hardware  # noqa: E402
from hopper_ros.harness.collect import CollectionSettings, collect  # noqa: E402
from hopper_ros.msg import BodyMeasurement  # noqa: E402
from hopper_ros.recording.bag import BagReader, BagWriter  # noqa: E402
from hopper_ros.recording.recordings import load_bag  # noqa: E402
from hopper_ros.sim.config import load_sim_config  # noqa: E402


def write_rate(folder: Path, count: int, raw: bool) -> float:
    from rclpy.serialization import serialize_message

    msg = BodyMeasurement()
    msg.header.frame_id = "ground"
    payload = serialize_message(msg)
    started = time.perf_counter()
    bag = BagWriter(folder, chunk_interval=0.0)
    bag.add_topic("/body_measurement", "hopper_ros/msg/BodyMeasurement")
    for k in range(count):
        if raw:
            bag.write("/body_measurement", payload, 10**18 + k * 10**6)
        else:
            msg.sequence, msg.y = k, k * 1e-3
            bag.write_message("/body_measurement", msg, 10**18 + k * 10**6)
    bag.close()
    return count / (time.perf_counter() - started)


LIVE_TOPICS = ("force_plate", "sim/truth", "encoder_sample", "body_measurement", "body_state")   # 1 kHz each


def live_recording(seconds: float) -> list[dict]:
    """`hopper bag record` of five 1 kHz topics of the live sensing graph (sim_robot, encoder_bridge,
    state_estimator) for `seconds`: what the recorder dropped (publisher sequence gaps, counted by
    the recorder itself and stored in the bag's metadata), the ground truth's own 1 ms grid checked
    for holes, and when the bag started after the command."""
    import json

    from hopper_ros.recording.bag import bag_info

    env = dict(os.environ, PYTHONUNBUFFERED="1", ROS_DOMAIN_ID=str(free_domain_id()))
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    cli = [sys.executable, "-m", "hopper_ros.cli"]
    quiet = {"cwd": REPO, "env": env, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    with tempfile.TemporaryDirectory() as folder, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
        probe.close()
        nodes = [subprocess.Popen(cli + ["run", "encoder_bridge", "--ros-args", "-p", f"port:={port}"], **quiet),
                 subprocess.Popen(cli + ["run", "state_estimator"], **quiet),
                 subprocess.Popen(cli + ["run", "sim_robot", "--ros-args", "-p", "can:=none",
                                         "-p", f"udp_port:={port}"], **quiet)]
        try:
            time.sleep(3.0)                                  # the graph is up
            command_ns = time.time_ns()
            recorder = subprocess.run(cli + ["bag", "record", *LIVE_TOPICS, "-o", f"{folder}/bag", "-d", str(seconds)],
                                      cwd=REPO, env=env, capture_output=True, text=True, timeout=seconds + 120)
        finally:
            for node in nodes:
                node.send_signal(signal.SIGINT)
            for node in nodes:
                try:
                    node.wait(30)
                except subprocess.TimeoutExpired:
                    node.kill()
        if recorder.returncode != 0:
            raise RuntimeError(f"hopper bag record failed:\n{recorder.stderr[-2000:]}")
        custom = yaml.safe_load((Path(folder) / "bag" / "metadata.yaml").read_text())[
            "rosbag2_bagfile_information"]["custom_data"]
        dropped = json.loads(custom["hopper_recorder_dropped"])
        first_ns = int(custom["hopper_recorder_first_message_ns"])
        info = bag_info(f"{folder}/bag")
        kept = info.message_count
        truth = sorted(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
                       for topic, _, msg in BagReader(f"{folder}/bag").messages() if topic == "/sim/truth")
    holes = sum(max(0, round((b - a) / 1e6) - 1) for a, b in zip(truth, truth[1:]))
    return [
        {"name": "bag_record_loss_pct", "value": round(100.0 * sum(dropped.values()) / max(1, kept + sum(dropped.values())), 4), "unit": "%"},
        {"name": "bag_record_dropped_msgs", "value": sum(dropped.values()), "unit": "msgs"},
        {"name": "bag_record_msgs", "value": kept, "unit": "msgs"},
        {"name": "bag_record_topics", "value": len(LIVE_TOPICS), "unit": "topics"},
        {"name": "bag_record_s", "value": seconds, "unit": "s"},
        {"name": "bag_record_truth_holes", "value": holes, "unit": "samples"},
        {"name": "bag_record_start_s", "value": round((first_ns - command_ns) / 1e9, 3), "unit": "s"},
    ]


def run(quick=False):
    count = 20_000 if quick else 100_000
    with tempfile.TemporaryDirectory() as folder:
        written = write_rate(Path(folder) / "objects", count, raw=False)
        raw = write_rate(Path(folder) / "raw", count, raw=True)
        collect(Path(folder) / "collected", load_sim_config(), load_hardware(),
                CollectionSettings(strides=10 if quick else 40, seed=1))
        started = time.perf_counter()
        recording = load_bag(Path(folder) / "collected")
        read = len(recording) / (time.perf_counter() - started)
    figures = [
        {"name": "bag_write_msgs_per_s", "value": round(written), "unit": "msgs/s"},
        {"name": "bag_write_raw_msgs_per_s", "value": round(raw), "unit": "msgs/s"},
        {"name": "bag_read_samples_per_s", "value": round(read), "unit": "samples/s"},
    ]
    figures += live_recording(10.0 if quick else 60.0)
    return figures


if __name__ == "__main__":
    for figure in run(quick="--quick" in sys.argv):
        print(figure)
