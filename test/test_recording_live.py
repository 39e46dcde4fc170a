"""`hopper bag record` on a live graph: real nodes, real topics, the bag read back by `rosbags`.
SIGINT closes the bag; SIGKILL loses at most the chunk being filled."""

from __future__ import annotations

import signal
import socket
import threading
import time

import numpy as np

from conftest import SAFETY_TIMEOUT
from hopper_ros.recording.bag import BagReader, bag_info


def rosbags_messages(path):
    """(topic, log time, decoded message) of a bag, types registered from its own definitions."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    out = []
    with Reader(path) as reader:
        types = {}
        for connection in reader.connections:
            types.update(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        store.register(types)
        for connection, timestamp, raw in reader.messages():
            out.append((connection.topic, timestamp, store.deserialize_cdr(raw, connection.msgtype)))
        assert reader.message_count == len(out)
    return out


def test_sigint_closes_a_bag_recorded_from_the_simulated_robot(hopper_cli, tmp_path):
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))          # the simulated robot's encoder packets land here, unread
    robot = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", f"udp_port:={udp.getsockname()[1]}")
    recorder = hopper_cli("bag", "record", "force_plate", "sim/truth", "diagnostics", "-o", str(tmp_path / "bag"))
    try:
        robot.wait_for_line(r"realtime at 1000 Hz")
        for topic, type_name in (("/force_plate", "hopper_ros/msg/GroundReactionForce"),
                                 ("/sim/truth", "hopper_ros/msg/BodyState"),
                                 ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")):
            recorder.wait_for_line(rf"subscribed to {topic} \[{type_name}\]")
        time.sleep(3.0)         # a subscription is matched some time after it is made: on a loaded machine, 1-2 s
        recorder.signal(signal.SIGINT)
        assert recorder.wait() == 0
        assert "closed" in recorder.stderr
    finally:
        robot.signal(signal.SIGINT)
        robot.wait()
        udp.close()
    messages = rosbags_messages(tmp_path / "bag")
    by_topic = {}
    for topic, stamp, msg in messages:
        by_topic.setdefault(topic, []).append((stamp, msg))
    assert set(by_topic) == {"/force_plate", "/sim/truth", "/diagnostics"}
    plate = by_topic["/force_plate"]
    assert len(plate) > 1000                                 # 1 kHz for more than a second
    assert all(msg.header.frame_id == "force_plate" for _, msg in plate)
    log_times = np.array([stamp for stamp, _ in plate])
    assert np.all(np.diff(log_times) >= 0)
    stamps = np.array([msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 for _, msg in by_topic["/sim/truth"]])
    assert abs(np.median(np.diff(stamps)) - 1e-3) < 1e-6     # the robot's 1 kHz clock, every sample kept
    assert np.sum(np.diff(stamps) > 1.5e-3) < 0.01 * len(stamps)
    assert [status.name for status in by_topic["/diagnostics"][-1][1].status] == ["/sim_robot"]
    info = bag_info(tmp_path / "bag")
    assert info.complete and info.message_count == len(messages)


def test_sigkill_loses_at_most_the_last_chunk(rclpy_session, hopper_cli, tmp_path):
    from rclpy.executors import SingleThreadedExecutor

    from hopper_ros.msg import BodyMeasurement

    rate, interval = 500.0, 0.2
    node = rclpy_session.create_node("bag_kill_test_publisher")
    publisher = node.create_publisher(BodyMeasurement, "body_measurement", 100)
    published, publishing = [0], [True]

    def publish():
        if not publishing[0]:
            return
        msg = BodyMeasurement(sequence=published[0], y=0.001 * published[0])
        msg.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(msg)
        published[0] += 1

    node.create_timer(1.0 / rate, publish)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    stop = threading.Event()
    spinner = threading.Thread(target=lambda: [executor.spin_once(timeout_sec=0.01) for _ in iter(stop.is_set, True)],
                               daemon=True)
    spinner.start()
    recorder = hopper_cli("bag", "record", "body_measurement", "-o", str(tmp_path / "bag"),
                          "--chunk-interval", str(interval))
    try:
        recorder.wait_for_line(r"subscribed to /body_measurement")
        # the subscription created is not yet matched: on a loaded machine (CI) discovery took long enough that only
        # the last 28 of the messages counted from the line reached the recorder; count from the match
        deadline = time.monotonic() + SAFETY_TIMEOUT
        while not publisher.get_subscription_count() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert publisher.get_subscription_count(), "the recorder's subscription never matched the publisher"
        # and until the recorder has its first message: matched on the publisher's side, the first 640 messages after
        # it never reached the recorder once under make test's load (98 in the bag, the check below failed)
        recorder.wait_for_line(r"recording from .*first message")
        # two seconds' worth of messages after that (a loaded machine publishes late: count, not time)
        start, deadline = published[0], time.monotonic() + SAFETY_TIMEOUT
        while published[0] - start < 2 * rate and time.monotonic() < deadline:
            time.sleep(0.05)
        publishing[0] = False
        at_kill = published[0]
        # what a SIGKILL may lose is the chunk in the recorder's memory, not what is still on its way to it: under
        # make test's load 0.6 s of messages were in DDS or the recorder's queue at the kill (counted lost: 293 and
        # 323 for 170). Once it has them, everything older than a chunk is on disk (a hang guard: a recorder that
        # held more in memory never gets there)
        bound, deadline = rate * interval * 1.5 + 20, time.monotonic() + SAFETY_TIMEOUT
        while time.monotonic() < deadline and at_kill - 1 - _last_sequence_on_disk(tmp_path / "bag") > bound:
            time.sleep(0.1)
        recorder.process.send_signal(signal.SIGKILL)          # the recorder's own pid: no chance to clean up
        assert recorder.wait() == -signal.SIGKILL
    finally:
        stop.set()
        spinner.join(5.0)
        executor.shutdown()
        node.destroy_node()
    assert not (tmp_path / "bag" / "metadata.yaml").exists()
    info = bag_info(tmp_path / "bag")
    assert not info.complete and "interrupted" in " ".join(info.problems)
    sequences = [msg.sequence for _, _, msg in BagReader(tmp_path / "bag").messages()]
    # more than a second survived (once, in CI, only the match's first message did: what the recorder said is shown)
    assert len(sequences) > rate, (f"{len(sequences)} message(s) in the bag {sequences[:5]}, {at_kill - start} "
                                   f"published after its first message; the recorder's log: {recorder.stderr[-1500:]!r}")
    assert np.all(np.diff(sequences) == 1)                               # nothing lost inside the bag
    lost = at_kill - 1 - sequences[-1]
    assert lost <= bound, f"{lost} messages lost, a chunk holds about {rate * interval:.0f}"
    shown = hopper_cli("bag", "info", str(tmp_path / "bag"))
    assert shown.wait() == 0 and "UNFINISHED" in shown.stdout and "hopper bag recover" in shown.stdout
    repaired = hopper_cli("bag", "recover", str(tmp_path / "bag"))
    assert repaired.wait() == 0 and f"recovered {len(sequences)} messages" in repaired.stdout
    recovered = rosbags_messages(tmp_path / "bag")
    assert [msg.sequence for _, _, msg in recovered] == sequences


def _last_sequence_on_disk(folder) -> int:
    """The newest message's sequence in a bag being written (-1: none readable yet)."""
    try:
        return max((msg.sequence for _, _, msg in BagReader(folder).messages()), default=-1)
    except Exception:  # noqa: BLE001 - a bag caught mid-write is read again at the next look
        return -1


def _publish_and_record(rclpy_session, tmp_path, name, count, take_every, depth=None, monkeypatch=None):
    """Publish `count` BodyMeasurement (sequence 0..count-1) on a reliable KEEP_LAST 100 topic
    while a Recorder takes what arrives, calling spin_once only every `take_every` messages."""
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from hopper_ros.msg import BodyMeasurement
    from hopper_ros.recording import recorder as recorder_module
    from hopper_ros.recording.bag import BagWriter

    if depth is not None:
        monkeypatch.setattr(recorder_module, "SUBSCRIPTION_DEPTH", depth)
    node = rclpy_session.create_node(f"recorder_test_{name}")
    publisher = node.create_publisher(BodyMeasurement, f"recorder_test_{name}", QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE))
    lines = []
    bag = BagWriter(tmp_path / name)
    recorder = recorder_module.Recorder(node, bag, [f"recorder_test_{name}"], log=lines.append)
    try:
        end = time.monotonic() + 30.0
        while not recorder.subscriptions or publisher.get_subscription_count() < 1:
            assert time.monotonic() < end, "the recorder did not subscribe"
            recorder.discover()
            time.sleep(0.02)
        msg = BodyMeasurement()
        for sequence in range(count):
            msg.sequence = sequence
            publisher.publish(msg)
            if (sequence + 1) % take_every == 0:
                recorder.spin_once(0.0)
            time.sleep(0.0002)
        end = time.monotonic() + 5.0
        while recorder.received + sum(recorder.dropped.values()) < count and time.monotonic() < end:
            recorder.spin_once(0.05)
    finally:
        recorder.close()
        bag.close()
        node.destroy_node()
    sequences = [m.sequence for _, _, m in BagReader(tmp_path / name).messages()]
    return recorder, sequences, lines


def test_recorder_keeps_every_message_and_says_from_when(rclpy_session, tmp_path):
    recorder, sequences, lines = _publish_and_record(rclpy_session, tmp_path, "all", 3000, take_every=10)
    assert sequences == list(range(3000))                          # nothing missing inside the bag
    assert recorder.dropped == {"/recorder_test_all": 0}
    assert any(line.startswith("recording from ") and "first message, on /recorder_test_all" in line
               for line in lines), lines


def test_recorder_counts_every_message_it_could_not_keep(rclpy_session, tmp_path, monkeypatch):
    """A recorder that falls behind a subscription of depth 20 (taking only every 500 messages):
    the history replaces the oldest, and each message never taken is counted as dropped, from the
    publisher's sequence numbers: what is in the bag plus what is counted is all that was published."""
    recorder, sequences, lines = _publish_and_record(rclpy_session, tmp_path, "behind", 3000, take_every=500,
                                                     depth=20, monkeypatch=monkeypatch)
    dropped = recorder.dropped["/recorder_test_behind"]
    assert dropped > 0 and len(sequences) + dropped == 3000 - sequences[0]
    assert sequences == sorted(sequences) and len(set(sequences)) == len(sequences)
    recorder.report_drops()
    assert any(line.startswith(f"DROPPED {dropped} message(s) of /recorder_test_behind") for line in lines), lines
    assert "dropped " + str(dropped) in "\n".join(recorder.summary())


def test_a_ros_shutdown_that_hangs_does_not_keep_the_recorder_from_ending(tmp_path):
    """`hopper bag record` with rclpy's shutdown made to hang (a DDS teardown that never returns): once its bag is
    closed the recorder waits its grace and exits with its status, saying why and where each thread stood; the bag
    is complete."""
    import subprocess
    import sys

    from conftest import REPO

    script = (
        "import time, rclpy\n"
        "import hopper_ros.nodes.shutdown_guard\n"
        "hopper_ros.nodes.shutdown_guard.SHUTDOWN_GRACE = 1.0\n"
        "rclpy.try_shutdown = lambda *a, **k: time.sleep(3600)\n"
        "from hopper_ros.cli import main\n"
        f"raise SystemExit(main(['bag', 'record', '-a', '-o', {str(tmp_path / 'bag')!r}, '-d', '0.5']))\n")
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True,
                          timeout=SAFETY_TIMEOUT)      # before the grace: the recorder waited here for an hour
    assert done.returncode == 0, done.stderr
    assert "closed:" in done.stderr and "has not ended in 1 s (the bag is closed)" in done.stderr, done.stderr
    assert "Thread" in done.stderr, done.stderr                  # faulthandler's stacks
    info = bag_info(tmp_path / "bag")
    assert info.complete, info.problems
    assert len(rosbags_messages(tmp_path / "bag")) == info.message_count      # an independent reader opens it


def test_a_ros_shutdown_that_holds_the_interpreter_still_ends_the_recorder(tmp_path):
    """The same with a teardown that never lets the interpreter's lock go (rclpy's native `Publisher.destroy` did, in
    an event detector: the grace's timer, a Python thread, could not run): faulthandler's watchdog ends the recorder
    `BACKSTOP` seconds after the grace, with status 1 and the stacks; the bag is complete. (Before, it ran on.)"""
    import subprocess
    import sys

    from conftest import REPO

    script = (
        "import re, rclpy\n"
        "import hopper_ros.nodes.shutdown_guard\n"
        "hopper_ros.nodes.shutdown_guard.SHUTDOWN_GRACE = 1.0\n"
        # a regular expression's backtracking runs in C and keeps the interpreter's lock for hours
        "rclpy.try_shutdown = lambda *a, **k: re.match(r'(a+)+$', 'a' * 48 + 'b')\n"
        "from hopper_ros.cli import main\n"
        f"raise SystemExit(main(['bag', 'record', '-a', '-o', {str(tmp_path / 'bag')!r}, '-d', '0.5']))\n")
    done = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True,
                          timeout=SAFETY_TIMEOUT)
    assert done.returncode == 1, done.stderr
    assert "closed:" in done.stderr and "Timeout" in done.stderr and "Thread" in done.stderr, done.stderr
    info = bag_info(tmp_path / "bag")
    assert info.complete, info.problems
    assert len(rosbags_messages(tmp_path / "bag")) == info.message_count
