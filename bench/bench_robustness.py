"""The issue 17 audit as a bench: watchdog distribution, hub abuse, fuzzing (`make bench BENCH_ARGS="--only robustness"`).

Everything on 127.0.0.1, bounded in count and time.

watchdog: this process runs the socketcand hub, the emulated EPOS2 (a thread) and a bus spy; child
1 is the motor_driver node with its default settings (config/motor_driver.yaml: 10 ms
command_timeout), child 2 publishes MotorCommand (current mode, a new setpoint every command) at
the controller's repeat period (control.yaml stride.keep_alive, 3 ms) in LOSSES bursts of 0.3 s,
each followed by silence: a lost command stream. Per loss, from the last command's publish()
(CLOCK_REALTIME, taken just before it) to frames on the drive's bus (stamped by the virtual bus
with CLOCK_REALTIME when the hub puts them there): the RPDO with the quick stop
(`watchdog_stop_ms`), the RPDO with disable voltage (`watchdog_disable_cmd_ms`) and the drive's
own TPDO1 whose statusword says SWITCH ON DISABLED (`watchdog_disable_ms`: the drive disabled,
as the bus shows it). Median, max and the count over 20 ms; `watchdog_current_after_stop_ma`: the
largest current setpoint in any RPDO at or after a quick stop (0: zeroed at once).

hub: the raw-mode no-read attack (test/hub_attack.py: 200 clients in raw mode that never read,
dropped ones reconnecting at once, for 10 s) while a canopen master in another process
(test/data/socketcand_load_client.py) sends SYNC at 1 kHz and an SDO upload every 20 ms; before,
during and after: SDO answers, failures, p50/max round trip, TPDO1 per SYNC, longest TPDO1 gap;
the hub's counters; a new client after the attack; then sim_robot with its hub under the same
attack, SIGTERM -> exit (`hub_sigterm_stop_s`, the worst of 3 runs).
"""
import json
import os
import signal
import socket
import statistics
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

from _common import Paced, child_env, percentile  # noqa: E402 - bench/ is on sys.path (the script's folder)

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "test"))

LOSSES = 12                 # lost command streams measured
QUICK_LOSSES = 10
BURST_S = 0.3               # commands flow this long before each loss
SILENCE_S = 0.2             # then nothing (the watchdog acts within 20 ms)
MATCH_TIMEOUT_S = 30.0
ATTACK_CLIENTS = 200
ATTACK_S = 10.0
QUICK_ATTACK_S = 4.0
SIGTERM_RUNS = 3


def _hardware():
    from hopper_ros.motor_driver import load_hardware
    return load_hardware()


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


# ---------------------------------------------------------------------------- watchdog

def _watchdog(quick):
    from hopper_ros.canbus.epos2_emulator import Epos2Emulator
    from hopper_ros.canbus.epos2_objects import Command, State, decode_statusword, rpdo_cob_id, tpdo_cob_id
    from hopper_ros.canbus.socketcand_server import SocketcandServer
    from hopper_ros.config import load_yaml

    hardware = _hardware()
    node_id = hardware["drive"]["node_id"]
    repeat = float(load_yaml("control.yaml")["stride"]["keep_alive"])
    timeout = float(load_yaml("motor_driver.yaml")["motor_driver"]["command_timeout"])
    losses = QUICK_LOSSES if quick else LOSSES
    namespace = f"/hopper_bench_watchdog_{os.getpid()}"
    rpdo1, tpdo1 = rpdo_cob_id(1, node_id), tpdo_cob_id(1, node_id)
    frames = []                                      # (realtime ns, "rpdo"/"tpdo", controlword or state, mA)
    stop = threading.Event()
    hub = SocketcandServer("127.0.0.1", 0, "can0").start()
    drive_bus, spy_bus = hub.local_bus(), hub.local_bus()
    drive = Epos2Emulator(drive_bus, hardware)

    def serve_drive():
        while not stop.is_set():
            now = time.monotonic()
            drive.poll(now)
            drive.control(now, 0, 0.0, drive.demand)
            time.sleep(0.0005)

    def spy():
        while not stop.is_set():
            frame = spy_bus.recv(timeout=0.05)
            if frame is None:
                continue
            stamp = round(frame.timestamp * 1e9)
            if frame.arbitration_id == rpdo1 and len(frame.data) == 5:
                controlword, _, milliamps = struct.unpack("<Hbh", frame.data)
                frames.append((stamp, "rpdo", controlword, milliamps))
            elif frame.arbitration_id == tpdo1 and len(frame.data) >= 2:
                frames.append((stamp, "tpdo", decode_statusword(struct.unpack("<H", frame.data[:2])[0]), 0))

    threads = [threading.Thread(target=serve_drive, daemon=True), threading.Thread(target=spy, daemon=True)]
    for thread in threads:
        thread.start()
    node = subprocess.Popen(
        [sys.executable, "-m", "hopper_ros.cli", "run", "motor_driver", "--ros-args",
         "-r", f"__ns:={namespace}", "-p", "interface:=socketcand", "-p", "host:=127.0.0.1",
         "-p", f"port:={hub.port}"],
        cwd=REPO, env=child_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        publisher = subprocess.run(
            [sys.executable, os.path.abspath(__file__), "bursts", f"{namespace}/motor_command", str(losses),
             str(repeat)],
            stdout=subprocess.PIPE, text=True, env=child_env(), cwd=REPO,
            timeout=MATCH_TIMEOUT_S + losses * (BURST_S + SILENCE_S) + 30.0, check=True)
        time.sleep(0.2)
    finally:
        node.send_signal(signal.SIGINT)
        try:
            _, node_log = node.communicate(timeout=30.0)
        except subprocess.TimeoutExpired:
            node.kill()
            _, node_log = node.communicate()
        stop.set()
        for thread in threads:
            thread.join(5.0)
        hub.close()
    lasts = json.loads(publisher.stdout.strip().splitlines()[-1])["last_ns"]
    frames.sort()
    stops, disable_cmds, disables, late_current = [], [], [], 0
    for last in lasts:
        after = [f for f in frames if last < f[0] < last + SILENCE_S * 1e9]
        stop_frame = next((f for f in after if f[1] == "rpdo" and f[2] == Command.QUICK_STOP), None)
        disable_cmd = next((f for f in after if f[1] == "rpdo" and f[2] == Command.DISABLE_VOLTAGE), None)
        disabled = next((f for f in after if f[1] == "tpdo" and f[2] is State.SWITCH_ON_DISABLED), None)
        if stop_frame is None or disable_cmd is None or disabled is None:
            raise RuntimeError(f"loss at {last}: no stop/disable on the bus; node log:\n{node_log[-3000:]}")
        stops.append((stop_frame[0] - last) / 1e6)
        disable_cmds.append((disable_cmd[0] - last) / 1e6)
        disables.append((disabled[0] - last) / 1e6)
        late_current = max([late_current] + [abs(f[3]) for f in after if f[1] == "rpdo" and f[0] >= stop_frame[0]])
    figures = [
        {"name": "watchdog_losses", "value": len(lasts), "unit": "losses"},
        {"name": "watchdog_command_repeat_ms", "value": round(repeat * 1e3, 2), "unit": "ms"},
        {"name": "watchdog_command_timeout_ms", "value": round(timeout * 1e3, 2), "unit": "ms"},
    ]
    for name, values in (("watchdog_stop", stops), ("watchdog_disable_cmd", disable_cmds),
                         ("watchdog_disable", disables)):
        figures += [
            {"name": f"{name}_ms", "value": round(statistics.median(values), 2), "unit": "ms"},
            {"name": f"{name}_min_ms", "value": round(min(values), 2), "unit": "ms"},
            {"name": f"{name}_p90_ms", "value": round(percentile(values, 0.9), 2), "unit": "ms"},
            {"name": f"{name}_max_ms", "value": round(max(values), 2), "unit": "ms"},
        ]
    figures += [
        {"name": "watchdog_disable_over_20ms", "value": sum(1 for v in disables if v > 20.0), "unit": "losses"},
        {"name": "watchdog_current_after_stop_ma", "value": late_current, "unit": "mA"},
    ]
    return figures


def _bursts(topic, losses, repeat):
    """Child: `losses` bursts of commands every `repeat` s, each followed by silence; prints the last stamps."""
    import rclpy
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

    from hopper_ros.msg import MotorCommand

    rclpy.init()
    node = rclpy.create_node("hopper_bench_watchdog_commands")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    publisher = node.create_publisher(MotorCommand, topic, qos)
    deadline = time.monotonic() + MATCH_TIMEOUT_S
    while publisher.get_subscription_count() < 1:
        if time.monotonic() > deadline:
            raise SystemExit("publisher: the motor driver did not subscribe")
        time.sleep(0.01)
    time.sleep(1.0)                                   # the driver configures the drive meanwhile
    msg = MotorCommand(mode=MotorCommand.MODE_CURRENT)
    lasts = []
    per_burst = int(BURST_S / repeat)
    sequence = 0
    for _ in range(losses):
        last = 0
        for _ in Paced(per_burst, repeat):
            sequence += 1
            msg.setpoint = 0.5 + 0.001 * (sequence % 500)         # a new current every command
            msg.header.stamp = node.get_clock().now().to_msg()
            last = time.time_ns()
            publisher.publish(msg)
        lasts.append(last)
        time.sleep(SILENCE_S)
    print(json.dumps({"last_ns": lasts}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


# ---------------------------------------------------------------------------- hub abuse

def _hub(quick):
    from hub_attack import RawModeAttack, handshake
    from test_canbus_epos2 import EDS, HARDWARE, NODE, DriveLoop

    from hopper_ros.canbus.socketcand_server import SocketcandServer

    attack_s = QUICK_ATTACK_S if quick else ATTACK_S
    script = REPO / "test" / "data" / "socketcand_load_client.py"
    figures = []
    with SocketcandServer("127.0.0.1", 0, HARDWARE["can"]["channel"]) as hub, DriveLoop(hub.local_bus()):
        load = subprocess.Popen([sys.executable, str(script), str(hub.port), str(EDS), str(NODE)],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1,
                                env=child_env(), cwd=REPO)
        try:
            if load.stdout.readline().strip() != "ready":
                raise RuntimeError("load client did not start")

            def phase(name, seconds):
                load.stdin.write(f"phase {name} {seconds}\n")
                load.stdin.flush()
                words = load.stdout.readline().split()
                return {k: float(v) for k, v in (w.split("=") for w in words[1:])}

            before = phase("before", 3.0)
            started = time.monotonic()
            with RawModeAttack(hub.port, clients=ATTACK_CLIENTS) as attack:
                while attack.connected < ATTACK_CLIENTS and time.monotonic() - started < 30.0:
                    time.sleep(0.05)
                during = phase("attack", attack_s)
            after = phase("after", 3.0)
            try:
                handshake(hub.port).close()
                fresh = 1
            except OSError:
                fresh = 0
            load.stdin.write("quit\n")
            load.stdin.flush()
            load.wait(30.0)
        finally:
            if load.poll() is None:
                load.kill()
                load.wait()
        counters = hub.counters
    figures += [
        {"name": "hub_attack_clients", "value": ATTACK_CLIENTS, "unit": "clients"},
        {"name": "hub_attack_s", "value": attack_s, "unit": "s"},
        {"name": "hub_attack_reconnects", "value": attack.reopened, "unit": "clients"},
        {"name": "hub_attack_handshake_failures", "value": attack.failures, "unit": "clients"},
        {"name": "hub_slow_clients_dropped", "value": counters.slow_clients_dropped, "unit": "clients"},
        {"name": "hub_new_client_after_attack_ok", "value": fresh, "unit": "bool"},
    ]
    for label, figs in (("before", before), ("attack", during), ("after", after)):
        sent = figs["sdo_ok"] + figs["sdo_failed"]
        figures += [
            {"name": f"hub_{label}_sdo_answered_pct", "value": round(100.0 * figs["sdo_ok"] / max(sent, 1), 2), "unit": "%"},
            {"name": f"hub_{label}_sdo_round_trips", "value": int(sent), "unit": "SDO"},
            {"name": f"hub_{label}_sdo_p50_ms", "value": figs["sdo_p50_ms"], "unit": "ms"},
            {"name": f"hub_{label}_sdo_max_ms", "value": figs["sdo_max_ms"], "unit": "ms"},
            {"name": f"hub_{label}_sync_rate_hz", "value": round(figs["syncs"] / (3.0 if label != "attack" else attack_s), 1), "unit": "Hz"},
            {"name": f"hub_{label}_tpdo_per_sync_pct", "value": round(100.0 * figs["tpdo1"] / max(figs["syncs"], 1), 2), "unit": "%"},
            {"name": f"hub_{label}_tpdo_gap_max_ms", "value": figs["tpdo_gap_max_ms"], "unit": "ms"},
        ]
    figures.append({"name": "hub_sigterm_stop_s", "value": round(max(_sigterm_under_attack() for _ in range(SIGTERM_RUNS)), 3), "unit": "s"})
    return figures


def _sigterm_under_attack():
    """sim_robot (hub on) under the attack with SYNC at 1 kHz; seconds from SIGTERM to its exit."""
    from hub_attack import RawModeAttack
    from test_canbus_epos2 import EDS, NODE

    port = _free_port()
    node = subprocess.Popen([sys.executable, "-m", "hopper_ros.cli", "run", "sim_robot", "--ros-args",
                             "-p", "can:=hub", "-p", f"can_port:={port}", "-p", "hold:=true", "-p", "udp_port:=9"],
                            cwd=REPO, env=child_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    load = None
    try:
        deadline = time.monotonic() + 30.0
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
                break
            except OSError:
                if time.monotonic() > deadline or node.poll() is not None:
                    raise RuntimeError("sim_robot's hub did not come up")
                time.sleep(0.1)
        load = subprocess.Popen([sys.executable, str(REPO / "test" / "data" / "socketcand_load_client.py"),
                                 str(port), str(EDS), str(NODE)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                text=True, bufsize=1, env=child_env(), cwd=REPO)
        if load.stdout.readline().strip() != "ready":
            raise RuntimeError("load client did not start")
        load.stdin.write("phase attack 6\n")
        load.stdin.flush()
        with RawModeAttack(port, clients=ATTACK_CLIENTS) as attack:
            end = time.monotonic() + 5.0
            while attack.reopened < ATTACK_CLIENTS and time.monotonic() < end:
                time.sleep(0.05)
            started = time.monotonic()
            node.send_signal(signal.SIGTERM)
            node.wait(30.0)
            return time.monotonic() - started
    finally:
        for child in (load, node):
            if child is not None and child.poll() is None:
                child.kill()
                child.wait()


def run(quick=False):
    return _watchdog(quick) + _hub(quick)


if __name__ == "__main__":
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if sys.argv[1] == "bursts":
        _bursts(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]))
    else:
        raise SystemExit(f"unknown role {sys.argv[1]}")
