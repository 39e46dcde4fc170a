"""Bag recording and reading (hopper_ros/recording).

- bag_write_msgs_per_s: BagWriter.write_message of BodyMeasurement messages (rclpy CDR
  serialisation, zstd chunks, indexes) into a bag on disk, closed at the end
- bag_write_raw_msgs_per_s: BagWriter.write of already serialized messages, what the recorder's
  raw subscriptions do
- bag_read_samples_per_s: load_bag of a collected bag (three 1 kHz topics, commands, events),
  samples per second of wall time
- bag_record_loss_pct: `hopper bag record` on the live graph, the sim_robot node at 1 kHz for 5 s:
  share of the robot's ground-truth samples missing from the bag (skipped with --quick)
"""
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from hopper_ros.config import load_yaml  # noqa: E402
from hopper_ros.identification.recordings import load_bag  # noqa: E402
from hopper_ros.msg import BodyMeasurement  # noqa: E402
from hopper_ros.recording.bag import BagReader, BagWriter  # noqa: E402
from hopper_ros.recording.collect import CollectionSettings, collect  # noqa: E402
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


def live_loss(seconds: float) -> float:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    cli = [sys.executable, "-m", "hopper_ros.cli"]
    with tempfile.TemporaryDirectory() as folder, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        robot = subprocess.Popen(cli + ["run", "sim_robot", "--ros-args", "-p", "can:=none",
                                        "-p", f"udp_port:={sink.getsockname()[1]}"],
                                 cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            recorder = subprocess.run(cli + ["bag", "record", "sim/truth", "-o", f"{folder}/bag", "-d", str(seconds)],
                                      cwd=REPO, env=env, capture_output=True, text=True, timeout=seconds + 60)
        finally:
            robot.send_signal(signal.SIGINT)
            robot.wait(30)
        if recorder.returncode != 0:
            raise RuntimeError(f"hopper bag record failed:\n{recorder.stderr[-2000:]}")
        sequences = [msg.sequence for _, _, msg in BagReader(f"{folder}/bag").messages()]
    expected = sequences[-1] - sequences[0] + 1
    return 100.0 * (1.0 - len(sequences) / expected)


def run(quick=False):
    count = 20_000 if quick else 100_000
    with tempfile.TemporaryDirectory() as folder:
        written = write_rate(Path(folder) / "objects", count, raw=False)
        raw = write_rate(Path(folder) / "raw", count, raw=True)
        collect(Path(folder) / "collected", load_sim_config(), load_yaml("hardware.yaml"),
                CollectionSettings(strides=10 if quick else 40, seed=1))
        started = time.perf_counter()
        recording = load_bag(Path(folder) / "collected")
        read = len(recording) / (time.perf_counter() - started)
    figures = [
        {"name": "bag_write_msgs_per_s", "value": round(written), "unit": "msgs/s"},
        {"name": "bag_write_raw_msgs_per_s", "value": round(raw), "unit": "msgs/s"},
        {"name": "bag_read_samples_per_s", "value": round(read), "unit": "samples/s"},
    ]
    if not quick:
        figures.append({"name": "bag_record_loss_pct", "value": round(live_loss(5.0), 3), "unit": "%"})
    return figures


if __name__ == "__main__":
    for figure in run(quick="--quick" in sys.argv):
        print(figure)
