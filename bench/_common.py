"""Helpers shared by the bench modules (not a bench itself: bench/run.py runs bench_*.py only)."""
import contextlib
import math
import os
import signal
import subprocess
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def percentile(values, fraction):
    """Nearest-rank percentile (NaN for no values)."""
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    rank = min(max(1, math.ceil(fraction * len(ordered))), len(ordered))
    return ordered[rank - 1]


def child_env(unbuffered=False):
    """Environment for a bench's child processes: loopback DDS, this checkout importable."""
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    if unbuffered:
        env["PYTHONUNBUFFERED"] = "1"
    return env


class Paced:
    """`for index in Paced(count, period_s)`: each index at its slot on CLOCK_MONOTONIC (sleeping
    until it; a late slot comes at once), the first `start_delay_s` from now; afterwards
    `rate_hz` is the rate achieved."""

    def __init__(self, count, period_s, start_delay_s=0.0):
        self.count, self.period_ns, self.start_delay_ns = count, int(round(period_s * 1e9)), int(start_delay_s * 1e9)
        self.elapsed = 0.0

    def __iter__(self):
        start = time.monotonic_ns() + self.start_delay_ns
        for index in range(self.count):
            left = start + index * self.period_ns - time.monotonic_ns()
            if left > 0:
                time.sleep(left / 1e9)
            yield index
        self.elapsed = (time.monotonic_ns() - start) / 1e9

    @property
    def rate_hz(self):
        return (self.count - 1) / self.elapsed if self.elapsed else 0.0


def serve_emulated_drive(drive, stop):
    """Run an emulated EPOS2 (`Epos2Emulator`) every 0.5 ms until `stop` is set: a thread target."""
    import time

    while not stop.is_set():
        now = time.monotonic()
        drive.poll(now)
        drive.control(now, 0, 0.0, drive.demand)
        time.sleep(0.0005)


REALTIME_PRIORITY = 50      # SCHED_FIFO priority of the demo's loop (launch/demo.launch.yaml)


def available_realtime_priority() -> int:
    """REALTIME_PRIORITY where this process may use SCHED_FIFO, else 0 (normal scheduling)."""
    from hopper_ros.runtime.environment import realtime_scheduling_allowed

    return REALTIME_PRIORITY if realtime_scheduling_allowed()[0] else 0


@contextlib.contextmanager
def realtime(priority):
    """`with realtime(priority):` every thread of this process (and those started meanwhile) on SCHED_FIFO at
    `priority` (0: unchanged), as the demo's loop runs; normal scheduling again on leaving."""
    from hopper_ros.runtime.environment import REALTIME_PRIORITY_VAR, apply_realtime_priority

    if priority:
        apply_realtime_priority({REALTIME_PRIORITY_VAR: str(priority)})
    try:
        yield
    finally:
        if priority:
            for thread_id in (int(t) for t in os.listdir("/proc/self/task")):
                try:
                    os.sched_setscheduler(thread_id, os.SCHED_OTHER, os.sched_param(0))
                except ProcessLookupError:
                    pass


class DriverOnEmulatedDrive:
    """`with DriverOnEmulatedDrive(hardware, namespace, on_frame) as rig:` this process serves the
    socketcand hub on loopback with an emulated EPOS2 on it (a thread) and a bus spy calling
    `on_frame(frame)` for every frame; a child process runs the motor_driver node (`hopper run
    motor_driver`, socketcand client, in `namespace`). On leaving, the node is stopped with
    `stop_signal` and its stderr is `rig.node_log`."""

    def __init__(self, hardware, namespace, on_frame, stop_signal=None, realtime_priority=0):
        import signal

        self.hardware, self.namespace, self.on_frame = hardware, namespace, on_frame
        self.realtime_priority = realtime_priority       # the node's SCHED_FIFO priority (0: normal scheduling)
        self.stop_signal = signal.SIGTERM if stop_signal is None else stop_signal
        self.node_log = ""

    def __enter__(self):
        import subprocess
        import sys
        import threading

        from hopper_ros.canbus.epos2_emulator import Epos2Emulator
        from hopper_ros.canbus.socketcand_server import SocketcandServer

        self._stop = threading.Event()
        self._hub = SocketcandServer("127.0.0.1", 0, "can0").start()
        drive_bus, spy_bus = self._hub.local_bus(), self._hub.local_bus()
        drive = Epos2Emulator(drive_bus, self.hardware)

        def spy():
            while not self._stop.is_set():
                frame = spy_bus.recv(timeout=0.05)
                if frame is not None:
                    self.on_frame(frame)

        self._threads = [threading.Thread(target=serve_emulated_drive, args=(drive, self._stop), daemon=True),
                         threading.Thread(target=spy, daemon=True)]
        for thread in self._threads:
            thread.start()
        self._node = subprocess.Popen(
            [sys.executable, "-m", "hopper_ros.cli", "run", "motor_driver", "--ros-args",
             "-r", f"__ns:={self.namespace}", "-p", "interface:=socketcand", "-p", "host:=127.0.0.1",
             "-p", f"port:={self._hub.port}"],
            cwd=REPO, env=dict(child_env(), HOPPER_REALTIME_PRIORITY=str(self.realtime_priority)),
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        return self

    def __exit__(self, *exc_info):
        import subprocess

        self._node.send_signal(self.stop_signal)
        try:
            _, self.node_log = self._node.communicate(timeout=30.0)
        except subprocess.TimeoutExpired:
            self._node.kill()
            _, self.node_log = self._node.communicate()
        self._stop.set()
        for thread in self._threads:
            thread.join(5.0)
        self._hub.close()
        return False


@contextlib.contextmanager
def motor_command_publisher(node_name, topic, match_timeout_s=30.0):
    """In a child process: `with motor_command_publisher(name, topic) as (node, publisher):` an rclpy
    node publishing MotorCommand on `topic` (best effort, depth 1, as the controller), given once
    the motor driver subscribed and had a second to configure the drive."""
    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from hopper_ros.msg import MotorCommand

    rclpy.init()
    node = rclpy.create_node(node_name)
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    publisher = node.create_publisher(MotorCommand, topic, qos)
    deadline = time.monotonic() + match_timeout_s
    while publisher.get_subscription_count() < 1:
        if time.monotonic() > deadline:
            raise SystemExit("publisher: the motor driver did not subscribe")
        time.sleep(0.01)
    time.sleep(1.0)                                   # the driver configures the drive meanwhile
    yield node, publisher
    node.destroy_node()
    rclpy.shutdown()


def child_role(roles):
    """A bench module run as a child process, `python bench_x.py ROLE ARG...`: calls roles[ROLE](*ARGS)
    with DDS on loopback."""
    import sys

    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if sys.argv[1] not in roles:
        raise SystemExit(f"unknown role {sys.argv[1]}")
    roles[sys.argv[1]](*sys.argv[2:])


def stop_recorder(recorder: subprocess.Popen, timeout: float) -> None:
    """Stop a `hopper bag record` started in a session of its own with SIGTERM (it closes the bag as on Ctrl-C),
    killed if it does not end within `timeout` seconds. Not SIGINT: a bench started with `&` from a script passes
    SIGINT on ignored, the recorder keeps it so, and its bag was killed without its footer."""
    if recorder.poll() is not None:
        return
    os.killpg(recorder.pid, signal.SIGTERM)
    try:
        recorder.wait(timeout)
    except subprocess.TimeoutExpired:
        os.killpg(recorder.pid, signal.SIGKILL)
        recorder.wait()
