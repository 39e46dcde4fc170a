"""Motor driver latency and watchdog, three processes on loopback.

This process: the socketcand hub (loopback), the emulated EPOS2 served by a thread, and a bus
spy. A frame is "on the bus" when the hub puts it on its in-process python-can bus (the drive's
bus); the virtual bus stamps it then with CLOCK_REALTIME, so the spy thread's own scheduling does
not count. Child 1: the motor_driver node (`hopper run motor_driver`, socketcand client, own
namespace). Child 2: a publisher of MotorCommand at 1 kHz (current mode), taking CLOCK_REALTIME
just before each publish(); every command's torque maps to a distinct current setting, so the
RPDO of each command is known.

Every process of the main run (node, publisher, this one's threads) on SCHED_FIFO at priority 50,
as the demo's loop runs (normal scheduling where that is not permitted: `motor_realtime_priority`
0); the same with normal scheduling: *_normal_scheduling.

Figures: motor_cmd_to_frame_p50_us / _p99_us / _max_us (publish -> the RPDO carrying that
command on the bus; target p99 < 1000 us), motor_cmd_superseded (commands whose RPDO never showed), motor_cmd_publish_rate_hz. The
watchdog's figures (watchdog_stop_ms, watchdog_disable_ms over a dozen lost streams) are
bench_robustness's. A command counts as superseded when a newer one reached the driver
first (the driver keeps only the latest: stale setpoints are not sent).
"""
import json
import os
import struct
import subprocess
import sys
import time
from pathlib import Path

# bench/ is on sys.path (the script's folder)
from _common import (DriverOnEmulatedDrive, Paced, available_realtime_priority, child_env,  # noqa: E402
                     child_role, motor_command_publisher, percentile, realtime)

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

COUNT = 3000            # measured commands
QUICK_COUNT = 800
WARMUP = 500            # sent first, not measured (discovery, enabling the drive)
RATE_HZ = 1000.0
MATCH_TIMEOUT_S = 30.0
BASE_MA = 1000          # command k asks for BASE_MA + k % SPAN_MA milliamps
SPAN_MA = 8000






def _torque_for(sequence, hardware):
    milliamps = BASE_MA + sequence % SPAN_MA
    return milliamps / 1000.0 * hardware.motor.torque_constant * hardware.motor.gear_ratio


def _measure(count, priority):
    """Publish -> RPDO latencies [us] of `count` commands (after WARMUP), every process of the run (the node, the
    publisher, this one's hub, drive and spy) on SCHED_FIFO at `priority` (0: normal scheduling); and the number
    superseded, the publisher's rate."""
    from hopper_ros.canbus.epos2_objects import rpdo_cob_id
    from hopper_ros.hardware.config import load_hardware

    hardware = load_hardware()
    total = WARMUP + count
    namespace = f"/hopper_bench_motor_{os.getpid()}_{priority}"
    rpdo1 = rpdo_cob_id(1, hardware.drive.node_id)
    frames = []                                      # (realtime ns on the bus, controlword, mA) of every RPDO1

    def on_frame(frame):
        if frame.arbitration_id == rpdo1 and len(frame.data) == 5:
            controlword, _, milliamps = struct.unpack("<Hbh", frame.data)
            frames.append((round(frame.timestamp * 1e9), controlword, milliamps))

    with realtime(priority), DriverOnEmulatedDrive(hardware, namespace, on_frame, realtime_priority=priority) as rig:
        publisher = subprocess.run(
            [sys.executable, os.path.abspath(__file__), "publish", f"{namespace}/motor_command", str(total),
             str(RATE_HZ)],
            stdout=subprocess.PIPE, text=True, env=dict(child_env(), HOPPER_REALTIME_PRIORITY=str(priority)),
            cwd=REPO, timeout=MATCH_TIMEOUT_S + total / RATE_HZ + 30.0, check=True)
    node_log = rig.node_log
    sent = json.loads(publisher.stdout.strip().splitlines()[-1])
    stamps = sent["stamps_ns"]

    latencies_us, lost = [], 0
    index = 0
    for sequence in range(WARMUP, total):
        milliamps = BASE_MA + sequence % SPAN_MA
        while index < len(frames) and frames[index][0] < stamps[sequence]:
            index += 1
        match = next((f for f in frames[index:index + 200] if f[2] == milliamps), None)
        if match is None:
            lost += 1
            continue
        latencies_us.append((match[0] - stamps[sequence]) / 1000.0)
    latencies_us.sort()
    if not latencies_us:
        raise RuntimeError(f"no command reached the bus; node log:\n{node_log[-3000:]}")
    return latencies_us, lost, sent["rate_hz"]


def run(quick=False):
    priority = available_realtime_priority()
    latencies_us, lost, rate_hz = _measure(QUICK_COUNT if quick else COUNT, priority)
    normal_us, _, _ = _measure(QUICK_COUNT if quick else COUNT, 0)
    return [
        {"name": "motor_cmd_to_frame_p50_us", "value": round(percentile(latencies_us, 0.50), 1), "unit": "us"},
        {"name": "motor_cmd_to_frame_p99_us", "value": round(percentile(latencies_us, 0.99), 1), "unit": "us"},
        {"name": "motor_cmd_to_frame_max_us", "value": round(latencies_us[-1], 1), "unit": "us"},
        {"name": "motor_cmd_superseded", "value": lost, "unit": "msgs"},
        {"name": "motor_cmd_publish_rate_hz", "value": round(rate_hz, 1), "unit": "Hz"},
        {"name": "motor_realtime_priority", "value": priority, "unit": "SCHED_FIFO"},
        {"name": "motor_cmd_to_frame_p50_us_normal_scheduling", "value": round(percentile(normal_us, 0.50), 1),
         "unit": "us"},
        {"name": "motor_cmd_to_frame_p99_us_normal_scheduling", "value": round(percentile(normal_us, 0.99), 1),
         "unit": "us"},
    ]


# ---------------------------------------------------------------------------- publisher process

def _publish(topic, total, rate_hz):
    from hopper_ros.runtime.environment import apply_realtime_priority
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.msg import MotorCommand

    apply_realtime_priority()                        # HOPPER_REALTIME_PRIORITY, as the run asks
    hardware = load_hardware()
    with motor_command_publisher("hopper_bench_motor_command", topic, MATCH_TIMEOUT_S) as (node, publisher):
        msg = MotorCommand(mode=MotorCommand.MODE_CURRENT)
        stamps = []
        pace = Paced(total, 1.0 / rate_hz)
        for sequence in pace:
            msg.setpoint = _torque_for(sequence, hardware)
            msg.header.stamp = node.get_clock().now().to_msg()
            now = time.time_ns()
            publisher.publish(msg)
            stamps.append(now)
        print(json.dumps({"rate_hz": pace.rate_hz, "stamps_ns": stamps}), flush=True)


if __name__ == "__main__":
    child_role({"publish": lambda topic, total, rate_hz: _publish(topic, int(total), float(rate_hz))})
