"""motor_driver node in its own process on real topics, reaching the emulated EPOS2 of this test
process through the loopback socketcand hub (python-can's socketcand client in the node)."""

from __future__ import annotations

import math
import queue
import signal
import threading
import time

import numpy as np
import pytest

from conftest import SAFETY_TIMEOUT, spin_until
from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_emulator import Epos2Emulator
from hopper_ros.canbus.epos2_objects import Command, NmtState, State
from hopper_ros.canbus.socketcand_server import SocketcandServer
from hopper_ros.hardware.config import load_hardware

HW = load_hardware()
K_T, GEAR = HW.motor.torque_constant, HW.motor.gear_ratio
RPDO_COB_IDS = {eo.rpdo_cob_id(n, int(HW.drive.node_id)) for n in (1, 2)}


class DriveThread:
    """The emulated EPOS2 on the hub's in-process side, served every 0.5 ms by a thread."""

    def __init__(self, hub: SocketcandServer):
        self.bus = hub.local_bus()
        self.spy = hub.local_bus()                      # every RPDO on the bus (the drive may take two in one poll)
        self.drive = Epos2Emulator(self.bus, HW)
        self.actions: queue.Queue = queue.Queue()       # run in the drive's thread (it is single-threaded)
        self.controlwords: list[int] = []
        self._stop = threading.Event()
        self.longest_stall = 0.0                        # [s] the longest gap between two turns of its loop
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        drive = self.drive
        last = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            self.longest_stall, last = max(self.longest_stall, now - last), now
            while not self.actions.empty():
                self.actions.get()(now)
            drive.poll(now)
            drive.control(now, 0, 0.0, drive.demand)
            while (frame := self.spy.recv(timeout=0)) is not None:
                if frame.arbitration_id in RPDO_COB_IDS and len(frame.data) >= 2:
                    controlword = int.from_bytes(frame.data[:2], "little")
                    if not self.controlwords or self.controlwords[-1] != controlword:
                        self.controlwords.append(controlword)
            time.sleep(0.0005)

    def describe(self) -> str:
        """The drive's state and error code and how long its thread stalled at most (for a failed check)."""
        return (f"drive: {self.drive.state}, NMT {self.drive.nmt_state}, error 0x{self.drive.value(eo.ERROR_CODE, 0):04X}, "
                f"its thread stalled up to {self.longest_stall * 1e3:.0f} ms")

    def wait_for(self, condition, timeout: float = SAFETY_TIMEOUT) -> None:
        end = time.monotonic() + timeout        # a hang guard
        while not condition():
            assert time.monotonic() < end, self.describe()
            time.sleep(0.005)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)


@pytest.fixture
def drive():
    hub = SocketcandServer("127.0.0.1", 0, "can0").start()
    served = DriveThread(hub)
    served.hub = hub
    yield served
    served.stop()
    hub.close()


DRIVE_CONSUMER_TIME = 1.0    # [s] the emulated drive's consumer of the master's heartbeat (`driver_config`)


@pytest.fixture(scope="module")
def driver_config(tmp_path_factory):
    """config/motor_driver.yaml with the drive's consumer of the master's heartbeat at DRIVE_CONSUMER_TIME instead
    of 15 ms: the emulated drive runs in this test's process beside the hub's threads and the test's executor, where
    its thread and the hub's reader stopped 12-46 ms at times (measured); the drive then faulted (0x8130) before the
    test had commanded anything. At 100 ms, on CI's loaded machine (`make test`'s diagnosis sessions beside it), the
    SIGINT test once waited 60 s for a drive that never enabled, as a faulted drive waits for its fault reset; at
    300 ms the SIGTERM test once waited 60 s after its fault reset for a drive that never enabled (2026-11-27, the
    diagnosis sessions heavier; not traced: that wait said nothing, it now says the drive's state): now 1 s. The
    15 ms of the real-time graph is for a drive that never stops; what the driver does on that fault is tested in
    test_motor_driver.py."""
    path = tmp_path_factory.mktemp("motor_driver") / "motor_driver.yaml"
    path.write_text(f"base: motor_driver.yaml\nmotor_driver:\n  drive_consumer_time: {DRIVE_CONSUMER_TIME}\n")
    return path


def _start_node(hopper_cli, hub, config):
    process = hopper_cli("run", "motor_driver", "--ros-args", "-p", "interface:=socketcand",
                         "-p", "host:=127.0.0.1", "-p", f"port:={hub.port}", "-p", f"config_file:={config}")
    process.wait_for_line(r"drive 1 configured and started")
    return process


def _test_node(rclpy_session, name):
    from rclpy.executors import SingleThreadedExecutor

    from diagnostic_msgs.msg import DiagnosticArray

    from hopper_ros.msg import MotorCommand, MotorStatus

    node = rclpy_session.create_node(name)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    got = {"status": [], "diagnostics": []}
    node.create_subscription(MotorStatus, "motor_status", got["status"].append, 100)
    node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: got["diagnostics"].extend(m.status), 10)
    publisher = node.create_publisher(MotorCommand, "motor_command", 10)
    assert spin_until(executor, lambda: publisher.get_subscription_count() and got["status"])

    def command(mode: int, setpoint: float, seconds: float, until=lambda: True, seen=lambda: "") -> None:
        """Publish the command every ~2 ms for `seconds`, then on until `until()` holds (`seen()`: what to say
        if it never does)."""
        msg = MotorCommand(mode=mode, setpoint=setpoint)
        start = time.monotonic()
        while time.monotonic() - start < seconds or not until():
            assert time.monotonic() - start < SAFETY_TIMEOUT, f"condition not reached while commanding; {seen()}"
            msg.header.stamp = node.get_clock().now().to_msg()
            publisher.publish(msg)
            executor.spin_once(timeout_sec=0.002)

    return node, executor, got, command


def _seen(drive, got, process) -> str:
    """The drive's side, the node's reports and its log: what a failed wait says."""
    last = got["status"][-1] if got["status"] else None
    return (f"drive {drive.drive.state}, NMT {drive.drive.nmt_state}, demand {drive.drive.demand:.4f} A, "
            f"controlwords {[hex(c) for c in drive.controlwords[-6:]]}; {len(got['status'])} motor_status, last "
            f"state {getattr(last, 'state', None)} current {getattr(last, 'current', None)}; node log: "
            f"{process.stderr[-1500:]!r}")


def test_node_drives_the_epos2_reports_and_stops_safely_on_sigterm(rclpy_session, hopper_cli, drive, driver_config):
    from hopper_ros.msg import MotorCommand, MotorStatus
    from hopper_ros.nodes.diagnostics import WARN, level_of, status_values

    process = _start_node(hopper_cli, drive.hub, driver_config)
    node, executor, got, command = _test_node(rclpy_session, "motor_driver_test")
    try:
        expected = 1.0 / (K_T * GEAR)
        enabled = lambda msg: msg.state == MotorStatus.STATE_OPERATION_ENABLED and abs(msg.current - expected) < 1e-3  # noqa: E731
        # until the drive is enabled as the node last saw it (a gap in this loaded test's own stream stops the drive,
        # and the node enables it again: a stop while it is enabling is a disable, not the quick stop tested below)
        command(MotorCommand.MODE_CURRENT, 1.0, 0.3,
                until=lambda: (abs(drive.drive.demand - expected) < 1e-3 and drive.drive.state is State.OPERATION_ENABLED
                               and enabled(got["status"][-1])),
                seen=lambda: _seen(drive, got, process))
        status = next(msg for msg in reversed(got["status"]) if enabled(msg))
        assert status.state == MotorStatus.STATE_OPERATION_ENABLED and status.state_name == "OPERATION ENABLED"
        assert status.commanded_mode == MotorCommand.MODE_CURRENT and status.operation_mode == -3
        assert status.current == pytest.approx(1.595, abs=1e-3) and status.torque == pytest.approx(1.0, abs=1e-3)
        assert status.heartbeat_ok and status.fault_code == 0
        # per SYNC (~1 kHz), not per status_period (0.1 s): by the node's own stamps, as counting what a loaded test
        # process took in 0.2 s once found 6 (make test, its diagnosis sessions beside it)
        count = len(got["status"])
        assert spin_until(executor, lambda: len(got["status"]) - count > 20), _seen(drive, got, process)
        spacing = np.diff([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in got["status"][count:]])
        assert np.median(spacing) < 0.01, spacing

        # the stream stops: quick stop, then disabled, and said so
        got["diagnostics"].clear()
        drive.wait_for(lambda: drive.drive.state is State.SWITCH_ON_DISABLED, 1.0)
        assert Command.QUICK_STOP in drive.controlwords[-3:]
        assert spin_until(executor, lambda: got["status"][-1].state == MotorStatus.STATE_SWITCH_ON_DISABLED)
        assert spin_until(executor, lambda: any(d.message == "command timeout: drive stopped"
                                                for d in got["diagnostics"]))
        report = next(d for d in got["diagnostics"] if d.message == "command timeout: drive stopped")
        assert level_of(report) == WARN and report.name == "/motor_driver" and report.hardware_id.startswith("EPOS2 node")
        assert status_values(report)["watchdog_stops"] >= 1   # more if we stalled
        process.wait_for_line(r"no motor command for \d+\.\d ms: current zeroed, quick stop")

        # a drive fault: EMCY decoded into the EPOS2's words
        command(MotorCommand.MODE_CURRENT, 1.0, 0.1, until=lambda: drive.drive.state is State.OPERATION_ENABLED,
                seen=lambda: _seen(drive, got, process))
        drive.actions.put(lambda now: drive.drive.inject_fault(eo.ERROR_OVER_CURRENT, now))
        assert spin_until(executor, lambda: got["status"][-1].state == MotorStatus.STATE_FAULT, 5.0)
        assert (got["status"][-1].fault_code, got["status"][-1].fault_text) == (0x2310, "Over current error")
        process.wait_for_line(r"drive EMCY 0x2310: Over current error")
        command(MotorCommand.MODE_DISABLED, 0.0, 0.1,                  # acknowledge: fault reset
                until=lambda: drive.drive.state is State.SWITCH_ON_DISABLED, seen=lambda: _seen(drive, got, process))
        command(MotorCommand.MODE_CURRENT, -0.5, 0.1,
                until=lambda: drive.drive.state is State.OPERATION_ENABLED and drive.drive.demand < 0,
                seen=lambda: _seen(drive, got, process))

        # SIGTERM while the drive is enabled and commanded: disabled before the node goes
        process.signal(signal.SIGTERM)
        command(MotorCommand.MODE_CURRENT, -0.5, 0.2)
        assert process.wait(SAFETY_TIMEOUT) == 0
        assert drive.drive.state is State.SWITCH_ON_DISABLED and drive.drive.demand == 0.0, (
            # a fault here has been seen once under make test's load: say which (0x8130: the master's heartbeat
            # missed for the consumer's 1 s) and how long the drive's thread stalled
            drive.describe() + "; the node said: " + " | ".join(line for line in process.stderr.splitlines() if "EMCY" in line or "heartbeat" in line))
        drive.wait_for(lambda: drive.drive.nmt_state == NmtState.PRE_OPERATIONAL, 2.0)
        assert drive.drive.value(eo.CONSUMER_HEARTBEAT_TIME, 1) == 0
        assert "drive disabled (confirmed by the drive)" in process.stderr
        time.sleep(DRIVE_CONSUMER_TIME + 0.3)                           # past the drive's heartbeat consumer time
        assert drive.drive.state is State.SWITCH_ON_DISABLED            # no fault: the consumer was switched off
    finally:
        executor.shutdown()
        node.destroy_node()


def test_sigint_disables_the_drive_first(rclpy_session, hopper_cli, drive, driver_config):
    from hopper_ros.msg import MotorCommand

    process = _start_node(hopper_cli, drive.hub, driver_config)
    node, executor, got, command = _test_node(rclpy_session, "motor_driver_sigint_test")
    try:
        command(MotorCommand.MODE_POSITION, 0.05, 0.1,
                until=lambda: drive.drive.state is State.OPERATION_ENABLED and drive.drive.operation_mode == -1,
                seen=lambda: _seen(drive, got, process))
        assert drive.drive.value(eo.POSITION_MODE_SETTING_VALUE) == round(0.05 * 52000 / (2 * math.pi))
        process.signal(signal.SIGINT)
        command(MotorCommand.MODE_POSITION, 0.05, 0.2)
        assert process.wait(SAFETY_TIMEOUT) == 0
        assert drive.drive.state is State.SWITCH_ON_DISABLED
        assert drive.controlwords[-1] == Command.DISABLE_VOLTAGE
        assert "stopping on SIGINT" in process.stderr and "drive disabled (confirmed by the drive)" in process.stderr
    finally:
        executor.shutdown()
        node.destroy_node()


def test_a_ros_teardown_that_hangs_after_the_drive_is_disabled_does_not_keep_the_node_running(
        rclpy_session, hopper_cli, drive, driver_config, tmp_path):
    """CI once saw the motor driver, its drive confirmed disabled, still inside rclpy's native node teardown 60 s after
    its SIGINT. Here every rclpy node's teardown is made to hang (a sitecustomize in the child): the node disables the
    drive, waits the shutdown's grace, says so with every thread's stack and exits with its status."""
    (tmp_path / "sitecustomize.py").write_text(
        "import time\n"
        "import rclpy.node\n"
        "import hopper_ros.nodes.shutdown_guard as guard\n"
        "guard.SHUTDOWN_GRACE = 1.0\n"
        "_destroy = rclpy.node.Node.destroy_node\n"
        "def _hangs(self):\n"
        "    _destroy(self)\n"
        "    time.sleep(3600)\n"
        "rclpy.node.Node.destroy_node = _hangs\n")
    process = hopper_cli("run", "motor_driver", "--ros-args", "-p", "interface:=socketcand", "-p", "host:=127.0.0.1",
                         "-p", f"port:={drive.hub.port}", "-p", f"config_file:={driver_config}",
                         env={"PYTHONPATH": str(tmp_path)})
    process.wait_for_line(r"drive 1 configured and started")
    drive.wait_for(lambda: drive.drive.state is State.SWITCH_ON_DISABLED)
    process.signal(signal.SIGINT)
    assert process.wait(SAFETY_TIMEOUT) == 0, process.stderr    # before the guard: still waiting at this timeout
    assert "drive disabled (confirmed by the drive)" in process.stderr
    assert "motor_driver: the ROS shutdown has not ended in 1 s" in process.stderr, process.stderr
    assert "Current thread" in process.stderr                   # faulthandler's stacks: where it hung
    assert drive.drive.state is State.SWITCH_ON_DISABLED
