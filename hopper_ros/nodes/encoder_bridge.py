"""encoder_bridge: the microcontroller's UDP encoder packets onto ROS topics.

A receiving thread of its own takes each datagram as it arrives and hands it, with the kernel's
stamp of its arrival (SO_TIMESTAMPNS; the thread's clock where the kernel gives none), to
`hopper_ros.sensing.bridge.EncoderBridge` (checks: size, magic, version, CRC, sequence, clock;
32-bit counters unwrapped; appendix A conversions; hip torque from the current). Every accepted
packet is published at once (1 kHz) on
  `encoder_sample` (EncoderSample): the raw sample as decoded, stamped with its receive time
    (only while something subscribes: the recorder, `hopper topic echo`),
  `body_measurement` (BodyMeasurement): boom angles, y, z, leg angle, motor current, hip torque;
a rejected packet is counted and dropped, never published. `/diagnostics` (diagnostic_msgs/
DiagnosticArray, every `diagnostics_period`; hopper_ros.nodes.diagnostics): counters (packets_received, samples_accepted, packets_lost, malformed_*,
duplicates, reordered, sequence_jump, clock_backwards, clock_inconsistent, stream_resyncs,
counter_wraps) and values (sample_rate_hz, loss_ratio over the period, process_time_max_s,
socket_wait_max_s: the longest a packet waited in the socket for this node, measurement_subscribers:
the subscriptions body_measurement is matched with).

Parameters (read only):
  sensing_file (string): sensing settings, default `sensing.yaml` (config/sensing.yaml)
  hardware_file (string): boom, encoders, motor, microcontroller ("" = sensing_file's hardware_file)
  host (string), port (int): where to listen ("" / 0 = hardware.yaml `microcontroller.host/port`)
  diagnostics_period (double) [s]: 0 = sensing_file's

The logic lives in hopper_ros.sensing.bridge; this node only connects it to a socket and ROS.
"""

from __future__ import annotations

import socket
import struct
import sys
import threading
import time

from rclpy.node import Node

from hopper_ros.hardware.config import load_hardware
from hopper_ros.msg import BodyMeasurement, EncoderSample
from hopper_ros.nodes.common import run_node, sensing_parameters
from hopper_ros.nodes.diagnostics import DiagnosticsReporter
from hopper_ros.sensing.bridge import MALFORMED, ORDER, EncoderBridge
from hopper_ros.nodes.sensing_messages import (CounterDeltas, any_of, fill_body_measurement,
                                         fill_encoder_sample, sample_qos)

RECEIVE_TIMEOUT = 0.2     # [s] the receiving thread checks for shutdown this often
DATAGRAM_BUFFER = 2048    # [bytes] larger than any packet, so an oversized one shows its real size
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)   # Linux (asm-generic): the kernel stamps each datagram
_TIMESPEC = struct.Struct("@qq")


def kernel_timestamps(sock: socket.socket) -> bool:
    """Ask the kernel to stamp every datagram on arrival (CLOCK_REALTIME); False where it cannot."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def arrival_time(ancillary) -> float | None:
    """The kernel's arrival stamp of a datagram from recvmsg's ancillary data [s], None without one."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= _TIMESPEC.size:
            seconds, nanoseconds = _TIMESPEC.unpack_from(data)
            return seconds + nanoseconds * 1e-9
    return None


class EncoderBridgeNode(Node):
    def __init__(self, **node_kwargs):
        node_kwargs.setdefault("start_parameter_services", False)   # read-only parameters, fewer entities
        super().__init__("encoder_bridge", **node_kwargs)
        param, config, period = sensing_parameters(self)
        hardware = load_hardware(param("hardware_file", "", "hardware (YAML), '' = the sensing file's") or
                             config.hardware_file)
        microcontroller = hardware.microcontroller
        host = param("host", "", "address to listen on ('' = hardware.yaml)") or microcontroller.host
        port = param("port", 0, "UDP port ('' = hardware.yaml)") or microcontroller.port
        self.bridge = EncoderBridge.from_config(hardware, config.bridge)

        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, config.bridge.receive_buffer_bytes)
        self._socket.bind((host, int(port)))
        self._socket.settimeout(RECEIVE_TIMEOUT)
        self._kernel_stamps = kernel_timestamps(self._socket)
        self._socket_wait_max = 0.0
        self._address = self._socket.getsockname()
        self._sample_msg, self._measurement_msg = EncoderSample(), BodyMeasurement()
        qos = sample_qos(config.queue_depth)
        self._samples = self.create_publisher(EncoderSample, "encoder_sample", qos)
        self._measurements = self.create_publisher(BodyMeasurement, "body_measurement", qos)
        self._diagnostics = DiagnosticsReporter(self, f"microcontroller udp {host}:{port}")
        self.create_timer(period, self._report)
        self._deltas = CounterDeltas()
        self._reported_problem = ""
        self._process_time_max = 0.0
        self._lock = threading.Lock()
        # the receiving thread must get the interpreter within a fraction of a sample period
        sys.setswitchinterval(min(sys.getswitchinterval(), 2.5e-4))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._receive, name="encoder-udp", daemon=True)
        self._thread.start()
        receive_buffer = self._socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        self.get_logger().info(f"listening on udp {self._address[0]}:{self._address[1]} "
                               f"(receive buffer {receive_buffer} bytes), diagnostics every {period:g} s")

    # ------------------------------------------------------------------ receiving thread
    def _receive(self) -> None:
        sock, bridge = self._socket, self.bridge
        ancillary_size = socket.CMSG_SPACE(_TIMESPEC.size)
        while not self._stop.is_set():
            try:
                datagram, ancillary, _, _ = sock.recvmsg(DATAGRAM_BUFFER, ancillary_size)
            except socket.timeout:
                continue
            except OSError:
                if self._stop.is_set():
                    return
                raise
            # the packet's arrival, not when this thread got to it: a bridge descheduled under load
            # must not make its samples look late (their stamps come from it)
            now = time.time()
            received = arrival_time(ancillary) or now
            if now - received > self._socket_wait_max:
                self._socket_wait_max = now - received
            started = time.perf_counter()
            with self._lock:
                sample = bridge.process(datagram, received)
            if sample is None:
                continue
            # the loop's path first: the estimator waits for body_measurement, encoder_sample is for the record
            self._measurements.publish(fill_body_measurement(self._measurement_msg, sample))
            if self._samples.get_subscription_count():      # a publish costs ~0.1 ms of CPU here: only if heard
                self._samples.publish(fill_encoder_sample(self._sample_msg, sample))
            elapsed = time.perf_counter() - started
            if elapsed > self._process_time_max:
                self._process_time_max = elapsed

    # ------------------------------------------------------------------ diagnostics
    def _report(self) -> None:
        now = time.time()
        with self._lock:
            counters = dict(self.bridge.counters)
            problem = self.bridge.last_problem
        deltas, elapsed = self._deltas.update(counters, now)
        accepted, lost = deltas["samples_accepted"], deltas["packets_lost"]
        values = {
            "sample_rate_hz": accepted / elapsed if elapsed > 0 else float("nan"),
            "loss_ratio": lost / (accepted + lost) if accepted + lost else 0.0,
            "process_time_max_s": self._process_time_max,
            "socket_wait_max_s": self._socket_wait_max,
            "measurement_subscribers": float(self._measurements.get_subscription_count()),
        }
        self._process_time_max = self._socket_wait_max = 0.0
        new_problem = any_of(deltas, ("packets_lost", *MALFORMED, *ORDER))
        if new_problem and problem != self._reported_problem:
            self.get_logger().warning(problem)
            self._reported_problem = problem
        self._diagnostics.report(counters, values, problem if new_problem else "", stamp=now)

    def destroy_node(self):
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self._socket.close()
        return super().destroy_node()


def main(args=None) -> int:
    return run_node(EncoderBridgeNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
