"""ros2 habits (issue 31): `hopper bag play` into a live `hopper topic echo` (every message compared),
`hopper topic hz` on a looping play, `hopper topic pub` to a live echo, `hopper bag info` with dates and
--json. Real processes over DDS on this machine's loopback."""

import json
import signal
import subprocess
import sys
import time

import pytest
import yaml

from hopper_ros.recording.bag import BagReader, BagWriter

COUNT = 200
RATE = 100.0        # [Hz] the recorded schedule
ORIGIN = 1_790_000_000 * 10**9


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    from hopper_ros.msg import ApexState, GaitEvent

    path = tmp_path_factory.mktemp("play") / "bag"
    with BagWriter(path) as writer:
        apex = writer.add_topic("/play_test/apex", "hopper_ros/msg/ApexState")
        events = writer.add_topic("/play_test/events", "hopper_ros/msg/GaitEvent")
        for k in range(COUNT):
            ns = ORIGIN + int(k * 1e9 / RATE)
            msg = ApexState(apex_height=0.3 + 1e-4 * k, forward_speed=2.0 - 1e-3 * k)
            msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9
            msg.header.frame_id = f"f{k}"
            writer.write_message(apex, msg, ns)
            if k % 10 == 0:
                writer.write_message(events, GaitEvent(type=GaitEvent.APEX, stride_index=k), ns + 1000)
    return path


def bag_yaml(path, topic):
    from hopper_ros.runtime.messages import message_to_dict

    return [message_to_dict(msg) for name, _, msg in BagReader(path).messages([topic])]


def echoed(text):
    return [yaml.safe_load(block) for block in text.split("---\n") if block.strip()]


def test_play_into_a_live_echo_every_message(bag, hopper_cli):
    echo = hopper_cli("topic", "echo", "/play_test/apex", "hopper_ros/msg/ApexState", "-n", str(COUNT), "--timeout", "120",
                      "--full-length")
    events = hopper_cli("topic", "echo", "/play_test/events", "hopper_ros/msg/GaitEvent", "-n", str(COUNT // 10),
                        "--timeout", "120")
    play = hopper_cli("bag", "play", str(bag), "--rate", "2", "--delay", "0", "--wait-matching-subscriptions", "1")
    line = play.wait_for_line(r"playing .*")
    started = time.monotonic()
    assert play.wait(120) == 0, play.stderr
    took = time.monotonic() - started
    assert echo.wait(60) == 0, (echo.stderr, len(echoed(echo.stdout)), play.stderr)
    assert events.wait(60) == 0, events.stderr
    assert echoed(echo.stdout) == bag_yaml(bag, "/play_test/apex")
    assert echoed(events.stdout) == bag_yaml(bag, "/play_test/events")
    assert f"played {COUNT + COUNT // 10} messages in 1 loop(s)" in play.stderr, play.stderr
    # the recorded schedule at twice the speed: (COUNT - 1) / RATE / 2 s, plus the wait for the echo's match
    assert took > (COUNT - 1) / RATE / 2 * 0.9, (took, line.group(0))


def test_hz_of_a_looping_play(bag, hopper_cli):
    play = hopper_cli("bag", "play", str(bag), "--loop", "--topics", "/play_test/apex", "--delay", "0")
    hz = hopper_cli("topic", "hz", "/play_test/apex", "--duration", "6", "--timeout", "60")
    assert hz.wait(90) == 0, hz.stderr
    rates = [float(line.split()[-1]) for line in hz.stdout.splitlines() if line.startswith("average rate:")]
    assert rates, hz.stdout
    assert rates[-1] == pytest.approx(RATE, rel=0.1), hz.stdout
    play.signal(signal.SIGINT)
    assert play.wait(30) == 0, play.stderr
    assert "loop(s)" in play.stderr


def test_pub_once_to_a_live_echo(hopper_cli):
    echo = hopper_cli("topic", "echo", "/pub_test/throw", "hopper_ros/msg/ApexState", "--once", "--timeout", "60")
    pub = hopper_cli("topic", "pub", "-1", "/pub_test/throw", "hopper_ros/msg/ApexState",
                     "{apex_height: 0.42, forward_speed: 2, header: {frame_id: thrown}}", "--timeout", "60")
    assert pub.wait(90) == 0, pub.stderr
    assert echo.wait(60) == 0, echo.stderr
    (msg,) = echoed(echo.stdout)
    assert msg["apex_height"] == 0.42 and msg["forward_speed"] == 2.0 and msg["header"]["frame_id"] == "thrown"


def test_pub_bad_values_one_line():
    proc = subprocess.run([sys.executable, "-m", "hopper_ros.cli", "topic", "pub", "-1", "/x", "hopper_ros/msg/ApexState",
                           "{apex_heigth: 0.4}"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 3                     # bad input
    assert proc.stderr.strip().splitlines() == [
        "hopper topic pub: error: apex_heigth: ApexState has no such field (fields: header, stride_index, apex_height, "
        "forward_speed, y, leg_angle)"]


def test_bag_info_dates_and_json(bag):
    proc = subprocess.run([sys.executable, "-m", "hopper_ros.cli", "bag", "info", str(bag)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    end_ns = ORIGIN + int((COUNT - 1) * 1e9 / RATE) + 1000 * ((COUNT - 1) % 10 == 0)
    assert f"({ORIGIN // 10**9}.{ORIGIN % 10**9:09d})" in proc.stdout
    assert "start:     2026-" in proc.stdout and "end:       2026-" in proc.stdout, proc.stdout
    proc = subprocess.run([sys.executable, "-m", "hopper_ros.cli", "bag", "info", str(bag), "--json"],
                          capture_output=True, text=True, timeout=60)
    doc = json.loads(proc.stdout)
    assert doc["start_ns"] == ORIGIN and doc["end_ns"] == end_ns and doc["complete"]
    assert doc["start"] == "2026-09-21T14:13:20.000000+00:00"
    assert {t["name"]: t["message_count"] for t in doc["topics"]} == {"/play_test/apex": COUNT,
                                                                     "/play_test/events": COUNT // 10}
