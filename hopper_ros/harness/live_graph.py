"""The demo graph as processes, followed from this one: start it with `hopper launch`, throw the robot,
count its strides and falls, kill a node and see what happens (issue 29: bench_demo_respawn.py, the
node tests). Uses rclpy in this process (a monitor node) and a spy on the simulated robot's CAN hub.

    with LiveGraph("demo.launch.yaml", out_dir) as graph:
        graph.wait_up(); graph.throw(); graph.wait_apexes(4)
        kill = graph.kill("sensing")          # SIGKILL, then: drive off, respawn, up again
        graph.throw(); graph.wait_apexes(4)

Times are CLOCK_REALTIME seconds, the clock of the nodes' log lines and of the spy's frames.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

STARTED = re.compile(r"^\[launch\] started (\S+): pid (\d+)")
RESPAWNING = re.compile(r"^\[launch\] (\S+) ended by itself \((.*)\); respawning")
ENDED = re.compile(r"^\[launch\] (\S+) ended by itself \((.*)\); stopping the others")
LOG_TIME = re.compile(r"^\[(\S+)\] \[(\w+)\] \[(\d+\.\d+)\] \[[^\]]*\]: (.*)$")
NO_COMMAND = re.compile(r"no motor command for ([\d.]+) ms")
DISABLED = re.compile(r"drive state \S+ -> (SWITCH_ON_DISABLED|FAULT)")
EMCY_BASE, RPDO1_BASE, RPDO2_BASE = 0x080, 0x200, 0x300      # 0x080 itself: SYNC
MASTER_HEARTBEAT = 0x700 + 127                               # motor_driver.yaml master_node_id
THROW_RETRY = 3.0   # [s] without an apex after a throw, throw again


@dataclass
class Kill:
    """What one SIGKILL of a node did."""

    label: str
    killed_at: float
    respawned_at: float = float("nan")         # the launcher started it again
    up_again_at: float = float("nan")          # it does its work again (per node: see LiveGraph.kill)
    last_command: float = float("nan")         # the last motor command the drive had (see drive_off_ms)
    drive_off: float = float("nan")            # the drive reported itself disabled (or faulted)
    others_ended: list[str] = field(default_factory=list)   # other nodes that ended meanwhile

    @property
    def drive_off_ms(self) -> float:
        return 1e3 * (self.drive_off - self.last_command)

    @property
    def respawn_s(self) -> float:
        return self.up_again_at - self.killed_at


class LiveGraph:
    def __init__(self, launch_file: str, out_dir: Path, arguments: tuple[str, ...] = (), env: dict | None = None):
        """`arguments` of the launch file; its simulated robot gets free ports unless they say others."""
        from hopper_ros.runtime.environment import robot_port_arguments

        given = {argument.split(":=", 1)[0] for argument in arguments}
        ports = tuple(a for a in robot_port_arguments() if a.split(":=", 1)[0] not in given)
        self.launch_file, self.out_dir, self.arguments = launch_file, Path(out_dir), tuple(arguments) + ports
        self.can_port = int(dict(a.split(":=", 1) for a in self.arguments)["can_port"])   # its robot's CAN hub
        self.env = dict(os.environ if env is None else env)
        self.lines: list[tuple[float, str]] = []          # (receive time, line) of the launcher's output
        self.pids: dict[str, int] = {}
        self._lock = threading.Lock()
        self.frames: list[tuple[float, int, bytes]] = []   # the spy's (time, COB-ID, data) since `spy_from`
        self.spy_from = float("inf")
        self._spy_port = 0
        self.seen = {"state": 0, "enabled": False, "status": 0, "falls": 0, "apexes": 0, "setpoint": None}
        self.health: dict[str, dict] = {}                   # each node's last /diagnostics values

    # ------------------------------------------------------------------ lifetime
    def __enter__(self) -> "LiveGraph":
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        from diagnostic_msgs.msg import DiagnosticArray

        from hopper_ros.msg import ApexState, BodyState, MotorStatus
        from hopper_ros.nodes.diagnostics import DIAGNOSTICS_TOPIC, split_node_name, status_values

        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._log = open(self.out_dir / "launch.log", "w", encoding="utf-8")
        self.process = subprocess.Popen([sys.executable, "-m", "hopper_ros.cli", "launch", self.launch_file,
                                         *self.arguments], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                        stdin=subprocess.DEVNULL, env=self.env, start_new_session=True, text=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        from rclpy.signals import SignalHandlerOptions

        self.context = rclpy.Context()           # its own: this process may have rclpy initialised already
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("live_graph_monitor", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        seen = self.seen

        reported = {"falls": 0, "base": 0}

        def on_diagnostics(msg):
            for status in msg.status:
                namespace, name = split_node_name(status.name)
                if namespace == "/":
                    self.health[name] = status_values(status)
                if (namespace, name) == ("/", "sim_robot"):
                    falls = status_values(status).get("falls", reported["falls"])
                    if falls < reported["falls"]:          # a new robot (respawned): its count starts again
                        reported["base"] += reported["falls"]
                    reported["falls"] = falls
                    seen["falls"] = reported["base"] + falls

        def on_apex(msg):
            seen["apexes"] += 1

        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.node.create_subscription(BodyState, "body_state", lambda m: seen.__setitem__("state", seen["state"] + 1),
                                      best_effort)
        def on_status(msg):
            seen["status"] += 1
            seen["enabled"] = msg.state == MotorStatus.STATE_OPERATION_ENABLED

        self.node.create_subscription(MotorStatus, "motor_status", on_status, best_effort)
        self.node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, on_diagnostics, 100)
        self.node.create_subscription(ApexState, "apex", on_apex, 100)
        self.node.create_subscription(ApexState, "apex_setpoint", lambda m: seen.__setitem__("setpoint", m), latched)
        self._throw = self.node.create_publisher(ApexState, "sim/throw", 10)
        return self

    def __exit__(self, *exc_info) -> None:
        self.stop_spy()
        try:
            if self.process.poll() is None:
                os.killpg(self.process.pid, signal.SIGINT)
            self.process.wait(30)
        except subprocess.TimeoutExpired:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait()
        finally:
            self._reader.join(5)
            self._log.close()
            import rclpy

            self.executor.shutdown()
            self.node.destroy_node()
            rclpy.try_shutdown(context=self.context)

    def _read(self) -> None:
        for line in self.process.stdout:
            now = time.time()
            line = line.rstrip("\n")
            self._log.write(line + "\n")
            with self._lock:
                self.lines.append((now, line))
                match = STARTED.match(line)
                if match:
                    self.pids[match.group(1)] = int(match.group(2))

    # ------------------------------------------------------------------ following
    def spin_until(self, condition, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > end or self.process.poll() is not None:
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def wait_up(self, timeout: float = 60.0, enabled: bool = True) -> bool:
        """Estimates flow, the drive is enabled (or only reports), the controller has its setpoint and
        hears apexes."""
        seen = self.seen
        return self.spin_until(lambda: seen["state"] > 100 and (seen["enabled"] or not enabled and seen["status"])
                               and seen["setpoint"] is not None
                               and self.node.count_subscribers("apex") >= 2 and self._throw.get_subscription_count(),
                               timeout)

    def throw(self) -> None:
        from hopper_ros.control.deadbeat import DeadbeatController
        from hopper_ros.msg import ApexState
        from hopper_ros.physics.params import load_params

        setpoint = self.seen["setpoint"]
        angle = DeadbeatController(load_params()).neutral_angle(setpoint.forward_speed)
        self._throw.publish(ApexState(apex_height=setpoint.apex_height, forward_speed=setpoint.forward_speed,
                                      leg_angle=angle))

    def hop(self, strides: int, timeout: float = 30.0, throw: bool = False) -> bool:
        """`strides` more apexes without a fall; with `throw`, the robot thrown first (again every
        THROW_RETRY without an apex: a respawned robot hears the throw once discovery matched it)."""
        falls, apexes = self.seen["falls"], self.seen["apexes"]
        end = time.monotonic() + timeout
        while throw and self.seen["apexes"] == apexes and time.monotonic() < end:
            self.throw()
            self.spin_until(lambda: self.seen["apexes"] > apexes, THROW_RETRY)
            falls = self.seen["falls"]
        target = apexes + strides
        return self.spin_until(lambda: self.seen["apexes"] >= target or self.seen["falls"] > falls,
                               max(0.0, end - time.monotonic())) and self.seen["falls"] == falls

    def log_lines(self, since: float) -> list[tuple[float, str]]:
        with self._lock:
            return [(t, line) for t, line in self.lines if t >= since]

    # ------------------------------------------------------------------ the CAN spy
    def start_spy(self, port: int) -> None:
        """Every frame on the simulated robot's hub from now on, stamped on arrival here."""
        import can

        self.spy_from, self._spy_port = time.time(), port
        self._spy_stop = threading.Event()
        self._spy_bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="can0")

        def spy():
            while not self._spy_stop.is_set():
                try:
                    frame = self._spy_bus.recv(timeout=0.05)
                except Exception:  # noqa: BLE001 - the hub went away (the robot was killed)
                    return
                if frame is not None:
                    self.frames.append((time.time(), frame.arbitration_id, bytes(frame.data)))

        self._spy = threading.Thread(target=spy, daemon=True)
        self._spy.start()

    def stop_spy(self) -> None:
        if getattr(self, "_spy_bus", None) is not None:
            self._spy_stop.set()
            self._spy.join(2)
            self._spy_bus.shutdown()
            self._spy_bus = None

    # ------------------------------------------------------------------ faults
    def kill(self, label: str, up_timeout: float = 30.0) -> Kill:
        """SIGKILL the process of `label` (a launch label: sim_robot, motor_driver, sensing, ...) and follow
        what happens: the drive switched off (the driver's log: its watchdog's gap and the drive's
        report; a killed driver: the spy's last RPDO and the drive's EMCY, its heartbeat consumer),
        the launcher's respawn, the node doing its work again (the sensing container: estimates and
        a controller hearing apexes; the driver: its drive's status again; the scheduler: its latched
        setpoint again; the robot: estimates again)."""
        seen = self.seen
        if label == "sim_robot":
            self.stop_spy()                       # its hub goes with it
        result = Kill(label, time.time())
        os.kill(self.pids[label], signal.SIGKILL)
        old_pid = self.pids[label]
        seen["state"], seen["enabled"], seen["status"] = 0, False, 0
        if label == "setpoint_scheduler":
            seen["setpoint"] = None

        def respawned():
            return self.pids.get(label) != old_pid

        if self.spin_until(respawned, up_timeout):
            result.respawned_at = next(t for t, line in self.log_lines(result.killed_at)
                                       if STARTED.match(line) and STARTED.match(line).group(1) == label)
        up = {"sensing": lambda: seen["state"] > 100 and self.node.count_subscribers("apex") >= 2,
              "motor_driver": lambda: seen["status"] > 10,
              "setpoint_scheduler": lambda: seen["setpoint"] is not None,
              "sim_robot": lambda: seen["state"] > 100}.get(label, lambda: True)
        if self.spin_until(lambda: respawned() and up(), up_timeout):
            result.up_again_at = time.time()
        if label == "sim_robot" and self._spy_port:
            self.start_spy(self._spy_port)
        self.spin_until(lambda: False, 0.3)                    # the log lines of the drive going off
        lines = self.log_lines(result.killed_at)
        result.others_ended = [m.group(1) for _, line in lines for m in [ENDED.match(line) or RESPAWNING.match(line)]
                               if m and m.group(1) != label]
        self._drive_off(result, lines)
        return result

    def _drive_off(self, result: Kill, lines) -> None:
        if result.label == "motor_driver":        # the drive on its own: its consumer of our heartbeat
            # the dead driver's last frame (SYNC, RPDO, its heartbeat) to the drive's EMCY of the fault
            driver_frames = [t for t, cob, _ in self.frames if result.killed_at - 0.1 <= t
                             and (cob == EMCY_BASE or cob & 0x780 in (RPDO1_BASE, RPDO2_BASE) or cob == MASTER_HEARTBEAT)]
            emcy = [t for t, cob, _ in self.frames if t >= result.killed_at and cob & 0x780 == EMCY_BASE and cob != EMCY_BASE]
            if driver_frames and emcy:
                result.last_command = max(t for t in driver_frames if t <= emcy[0])
                result.drive_off = emcy[0]
            return
        trip = None
        for _, line in lines:
            match = LOG_TIME.match(line)
            if not match or match.group(1) != "motor_driver":
                continue
            stamp, text = float(match.group(3)), match.group(4)
            gap = NO_COMMAND.search(text)
            if gap and trip is None:
                trip = stamp
                result.last_command = stamp - float(gap.group(1)) * 1e-3
            elif trip is not None and DISABLED.search(text):
                result.drive_off = stamp
                return
