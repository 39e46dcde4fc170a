"""The issue 17 audit as a bench: fuzzing, watchdog distribution, hub abuse (`make bench BENCH_ARGS="--only robustness"`).

Everything on 127.0.0.1, bounded in count and time. With --quick: a fifth of the fuzzing, 10
losses, a 4 s attack.

fuzz_udp_*: 60,000 valid encoder packets and 100,000 fuzzed ones through a real UDP socket into the
encoder bridge (see `_udp_fuzz`): counters differing from an oracle, exceptions, wrong results.
fuzz_can_*: 5 seeds x 25,000 random CAN frames into the motor driver running the emulated EPOS2
(see `_can_fuzz`): exceptions, enable commands or enabled periods after the command stream stopped.

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

# bench/ is on sys.path (the script's folder)
from _common import (DriverOnEmulatedDrive, Paced, child_env, child_role,  # noqa: E402
                     motor_command_publisher, percentile)

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
    from hopper_ros.hardware.config import load_hardware
    return load_hardware()


def _free_port():
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


# ---------------------------------------------------------------------------- watchdog

def _watchdog(quick):
    from hopper_ros.canbus.driver import load_motor_driver
    from hopper_ros.canbus.epos2_objects import Command, State, decode_statusword, rpdo_cob_id, tpdo_cob_id
    from hopper_ros.control.config import load_control

    hardware = _hardware()
    node_id = hardware.drive.node_id
    repeat = load_control().stride.keep_alive
    timeout = load_motor_driver().driver.command_timeout
    losses = QUICK_LOSSES if quick else LOSSES
    namespace = f"/hopper_bench_watchdog_{os.getpid()}"
    rpdo1, tpdo1 = rpdo_cob_id(1, node_id), tpdo_cob_id(1, node_id)
    frames = []                                      # (realtime ns, "rpdo"/"tpdo", controlword or state, mA)

    def on_frame(frame):
        stamp = round(frame.timestamp * 1e9)
        if frame.arbitration_id == rpdo1 and len(frame.data) == 5:
            controlword, _, milliamps = struct.unpack("<Hbh", frame.data)
            frames.append((stamp, "rpdo", controlword, milliamps))
        elif frame.arbitration_id == tpdo1 and len(frame.data) >= 2:
            frames.append((stamp, "tpdo", decode_statusword(struct.unpack("<H", frame.data[:2])[0]), 0))

    with DriverOnEmulatedDrive(hardware, namespace, on_frame, stop_signal=signal.SIGINT) as rig:
        publisher = subprocess.run(
            [sys.executable, os.path.abspath(__file__), "bursts", f"{namespace}/motor_command", str(losses),
             str(repeat)],
            stdout=subprocess.PIPE, text=True, env=child_env(), cwd=REPO,
            timeout=MATCH_TIMEOUT_S + losses * (BURST_S + SILENCE_S) + 30.0, check=True)
        time.sleep(0.2)
    node_log = rig.node_log
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
    from hopper_ros.msg import MotorCommand

    with motor_command_publisher("hopper_bench_watchdog_commands", topic, MATCH_TIMEOUT_S) as (node, publisher):
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


# ---------------------------------------------------------------------------- hub abuse

def _hub(quick):
    from hub_attack import RawModeAttack, handshake
    from test_canbus_epos2 import EDS, HARDWARE, NODE, DriveLoop

    from hopper_ros.canbus.socketcand_server import SocketcandServer

    attack_s = QUICK_ATTACK_S if quick else ATTACK_S
    script = REPO / "test" / "data" / "socketcand_load_client.py"
    figures = []
    with SocketcandServer("127.0.0.1", 0, HARDWARE.can.channel) as hub, DriveLoop(hub.local_bus()):
        load = subprocess.Popen([sys.executable, str(script), str(hub.port), str(EDS), str(NODE)],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                bufsize=1, env=child_env(), cwd=REPO)
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
            garbage_phase = threading.Thread(target=_garbage_clients, args=(hub.port, 3.0), daemon=True)
            garbage_phase.start()
            garbage = phase("garbage", 3.0)
            garbage_phase.join(30.0)
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
    figures.append({"name": "hub_garbage_commands", "value": counters.garbage_commands, "unit": "commands"})
    for label, figs in (("before", before), ("attack", during), ("garbage", garbage), ("after", after)):
        sent = figs["sdo_ok"] + figs["sdo_failed"]
        figures += [
            {"name": f"hub_{label}_sdo_answered_pct", "value": round(100.0 * figs["sdo_ok"] / max(sent, 1), 2), "unit": "%"},
            {"name": f"hub_{label}_sdo_round_trips", "value": int(sent), "unit": "SDO"},
            {"name": f"hub_{label}_sdo_p50_ms", "value": figs["sdo_p50_ms"], "unit": "ms"},
            {"name": f"hub_{label}_sdo_max_ms", "value": figs["sdo_max_ms"], "unit": "ms"},
            {"name": f"hub_{label}_sync_rate_hz", "value": round(figs["syncs"] / (attack_s if label == "attack" else 3.0), 1), "unit": "Hz"},
            {"name": f"hub_{label}_tpdo_per_sync_pct", "value": round(100.0 * figs["tpdo1"] / max(figs["syncs"], 1), 2), "unit": "%"},
            {"name": f"hub_{label}_tpdo_gap_max_ms", "value": figs["tpdo_gap_max_ms"], "unit": "ms"},
        ]
    stops = [_sigterm_under_attack() for _ in range(SIGTERM_RUNS)]
    if stops:
        figures.append({"name": "hub_sigterm_stop_s", "value": round(max(stops), 3), "unit": "s"})
        figures.append({"name": "hub_sigterm_runs", "value": len(stops), "unit": "runs"})
    return figures


def _garbage_clients(port, seconds, clients=ATTACK_CLIENTS):
    """`clients` connections sending random bytes (and half-commands) for `seconds`, reading nothing."""
    import random

    rng = random.Random(5)
    sockets = []
    try:
        for _ in range(clients):
            try:
                sockets.append(socket.create_connection(("127.0.0.1", port), timeout=2.0))
            except OSError:
                pass
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for sock in sockets:
                chunk = rng.choice((rng.randbytes(rng.randrange(1, 200)), b"< send 123 9 ff >", b"<<<>>>",
                                    b"< open can0 >< rawmode >< send " + rng.randbytes(20) + b" >"))
                try:
                    sock.setblocking(False)
                    sock.send(chunk)
                except OSError:
                    pass
            time.sleep(0.02)
    finally:
        for sock in sockets:
            sock.close()


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
                                stderr=subprocess.DEVNULL, text=True, bufsize=1, env=child_env(), cwd=REPO)
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



# ---------------------------------------------------------------------------- UDP fuzz of the encoder bridge

UDP_VALID = 60_000
UDP_FUZZ = 100_000
QUICK_UDP_VALID = 12_000
QUICK_UDP_FUZZ = 20_000


def _udp_fuzz(quick):
    """60,000 valid encoder packets (the 32-bit sequence wrapping in the middle, the azimuth
    register wrapping once) interleaved with 100,000 fuzzed ones, through a real UDP socket on
    127.0.0.1 into the encoder bridge's logic. Every fuzzed packet is built so that its fate is
    known (an oracle): random bytes and truncated/oversized packets (size), a wrong magic, version
    or CRC, duplicates, a valid packet reordered after a gap (the gap is lost, the late copy
    reordered), an old packet from beyond the reorder window (sequence jump), the clock going
    backwards or jumping. Figures: the counters that differ from the oracle (0), exceptions (0),
    accepted samples whose conversion differs from the true counts (0)."""
    import random

    from hopper_ros.hardware import packet as fmt
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.hardware.encoders import to_register
    from hopper_ros.sensing.bridge import EncoderBridge
    from hopper_ros.sensing.config import load_sensing_config

    hardware = load_hardware()
    settings = load_sensing_config().bridge
    bridge = EncoderBridge.from_config(hardware, settings)
    valid_n, fuzz_n = (QUICK_UDP_VALID, QUICK_UDP_FUZZ) if quick else (UDP_VALID, UDP_FUZZ)
    rng = random.Random(17)
    period_us = round(float(hardware.microcontroller.sample_period) * 1e6)
    start_seq = (1 << 32) - valid_n // 2                       # the sequence wraps half way
    az0 = (1 << 31) - 40_000 * (valid_n // 2)                  # the azimuth register wraps half way

    def true_counts(i):
        return az0 + 40_000 * i, -5_000 + 3 * i, 1_000 + (i % 7000)

    def packet(i, **changes):
        az, el, mo = true_counts(i)
        values = dict(sequence=(start_seq + i) % (1 << 32), mcu_time_us=10**9 + i * period_us,
                      azimuth_counts=to_register(az), elevation_counts=el, motor_counts=mo, motor_current_ma=i % 3000)
        values.update(changes)
        return fmt.encode(fmt.EncoderPacket(**values))

    expected = dict.fromkeys(bridge.counters, 0)
    plan = []                                                  # (datagram, valid index or None)
    fuzz_kinds = ("size", "magic", "version", "checksum", "truncated", "oversized", "duplicate", "jump",
                  "backwards", "inconsistent", "gap")
    weights = (1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0.02)           # a gap withholds valid packets: rarely
    fuzz_left = fuzz_n
    withheld = []                                              # valid packets of a gap, sent late
    i = 0
    last_sent = None
    while i < valid_n:
        if withheld and rng.random() < 0.5:                    # the late copies of a gap
            for k in withheld:
                plan.append((packet(k), None))
                expected["reordered"] += 1
                fuzz_left -= 1
            withheld = []
        budget = max(0, round(fuzz_left / max(1, valid_n - i)))
        for _ in range(rng.choice((budget - 1, budget, budget + 1)) if budget else 0):
            kind = rng.choices(fuzz_kinds, weights)[0]
            if kind in ("duplicate", "jump", "backwards", "inconsistent", "gap") and last_sent is None:
                kind = "size"
            if kind == "size":
                length = rng.choice([n for n in range(0, 120) if n != fmt.SIZE])
                plan.append((rng.randbytes(length), None))
                expected["malformed_size"] += 1
            elif kind == "magic":
                data = bytearray(rng.randbytes(fmt.SIZE))
                if data[:2] == b"HP":
                    data[0] ^= 0xFF
                plan.append((bytes(data), None))
                expected["malformed_magic"] += 1
            elif kind == "version":
                plan.append((packet(i, version=rng.choice([0, 2, 7, 255])), None))
                expected["malformed_version"] += 1
            elif kind == "checksum":
                data = bytearray(packet(i))
                data[rng.randrange(3, fmt.SIZE - 4)] ^= 1 << rng.randrange(8)
                plan.append((bytes(data), None))
                expected["malformed_checksum"] += 1
            elif kind == "truncated":
                plan.append((packet(i)[:rng.randrange(0, fmt.SIZE)], None))
                expected["malformed_size"] += 1
            elif kind == "oversized":
                plan.append((packet(i) + rng.randbytes(rng.randrange(1, 64)), None))
                expected["malformed_size"] += 1
            elif kind == "duplicate":
                plan.append((packet(last_sent), None))
                expected["duplicates"] += 1
            elif kind == "jump" and last_sent > settings.reorder_window + 10:
                plan.append((packet(last_sent - settings.reorder_window - 1 - rng.randrange(5000 if last_sent > 6100 else 1)), None))
                expected["sequence_jump"] += 1
            elif kind == "backwards":
                plan.append((packet(last_sent + 1, mcu_time_us=10**9 + last_sent * period_us - rng.randrange(0, 10**6)), None))
                expected["clock_backwards"] += 1
            elif kind == "inconsistent":
                plan.append((packet(last_sent + 1, mcu_time_us=10**9 + (last_sent + 1) * period_us
                                    + rng.choice((-1, 1)) * rng.randrange(600, 900)), None))
                expected["clock_inconsistent"] += 1
            elif kind == "gap" and not withheld and i + 6 < valid_n:
                count = rng.randrange(1, 5)
                withheld = list(range(i, i + count))
                expected["packets_lost"] += count
                i += count                                      # these come later, reordered
                continue
            else:
                continue
            fuzz_left -= 1
        plan.append((packet(i), i))
        last_sent = i
        i += 1
    for k in withheld:
        plan.append((packet(k), None))
        expected["reordered"] += 1
    valid_sent = sum(1 for _, index in plan if index is not None)
    expected["packets_received"] = len(plan)
    expected["samples_accepted"] = valid_sent

    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.bind(("127.0.0.1", 0))
    exceptions = wrong = 0
    accepted_indices = []
    started = time.perf_counter()
    try:
        receiver.settimeout(5.0)
        for datagram, index in plan:
            sender.sendto(datagram, receiver.getsockname())
            data = receiver.recv(2048)
            try:
                sample = bridge.process(data, time.monotonic())
            except Exception:  # noqa: BLE001 - counted: a malformed packet must never raise
                exceptions += 1
                continue
            if sample is not None:
                if index is None:
                    wrong += 1                                  # a fuzzed packet accepted
                    continue
                accepted_indices.append(index)
                if (sample.azimuth_count, sample.elevation_count, sample.motor_count) != true_counts(index):
                    wrong += 1
            elif index is not None:
                wrong += 1                                      # a valid packet rejected
    finally:
        receiver.close()
        sender.close()
    elapsed = time.perf_counter() - started
    expected["counter_wraps"] = sum(1 for a, b in zip(accepted_indices, accepted_indices[1:])
                                    if (true_counts(a)[0] + (1 << 31)) // (1 << 32) != (true_counts(b)[0] + (1 << 31)) // (1 << 32))
    mismatched = [name for name in expected if bridge.counters[name] != expected[name]]
    return [
        {"name": "fuzz_udp_valid_packets", "value": valid_sent, "unit": "packets"},
        {"name": "fuzz_udp_fuzzed_packets", "value": len(plan) - valid_sent, "unit": "packets"},
        {"name": "fuzz_udp_counters", "value": len(expected), "unit": "counters"},
        {"name": "fuzz_udp_counters_mismatched", "value": len(mismatched), "unit": "counters"},
        {"name": "fuzz_udp_exceptions", "value": exceptions, "unit": "packets"},
        {"name": "fuzz_udp_wrong_results", "value": wrong, "unit": "packets"},
        {"name": "fuzz_udp_counter_wraps", "value": bridge.counters["counter_wraps"], "unit": "wraps"},
        {"name": "fuzz_udp_packets_per_s", "value": round(len(plan) / elapsed), "unit": "packets/s"},
    ], mismatched, bridge.counters, expected


# ---------------------------------------------------------------------------- CAN fuzz of the motor driver

CAN_SEEDS = 5
CAN_FRAMES_PER_SEED = 25_000
QUICK_CAN_FRAMES_PER_SEED = 5_000


def _can_fuzz(quick):
    """Five seeds of 25,000 random CAN frames handed to the motor driver (our CANopen master) while
    it runs the emulated EPOS2 in simulated time: half of them with the drive's own COB-IDs (TPDOs,
    SDO answers, EMCY, heartbeat, NMT), any length, random data. The command stream stops after
    the first 500 frames. Figures: exceptions (0), enable commands the driver sent after its
    watchdog stopped the drive (0), periods the drive was enabled after that (0)."""
    import random

    import can

    from hopper_ros.canbus import epos2_objects as eo
    from hopper_ros.canbus.driver import MODE_CURRENT
    from hopper_ros.canbus.epos2_objects import Command, State
    from test_motor_driver import NODE, Rig

    frames_per_seed = QUICK_CAN_FRAMES_PER_SEED if quick else CAN_FRAMES_PER_SEED
    exceptions = enables_after = enabled_after = malformed = 0
    ours = [eo.tpdo_cob_id(1, NODE), eo.tpdo_cob_id(2, NODE), eo.sdo_tx_cob_id(NODE), eo.emcy_cob_id(NODE),
            eo.heartbeat_cob_id(NODE), 0x000, 0x080]
    for seed in range(CAN_SEEDS):
        rng = random.Random(1000 + seed)
        rig = Rig()
        try:
            rig.start()
            rig.enable()
            stopped = False
            settle = rig.driver.settings.command_timeout + rig.driver.settings.quick_stop_time + 0.003
            last_command = None
            for k in range(frames_per_seed):
                if k % 5 == 0:
                    commanding = k < 500
                    rig.step(command=(MODE_CURRENT, 1.0) if commanding else None)
                    if commanding:
                        last_command = rig.clock.t
                    elif not stopped and rig.clock.t - last_command > settle:
                        stopped = True                          # the watchdog has had its time
                        sent_before = len(rig.rpdos)
                    if stopped and rig.drive.state is State.OPERATION_ENABLED:
                        enabled_after += 1
                ident = rng.choice(ours) if rng.random() < 0.5 else rng.randrange(0, 0x800)
                frame = can.Message(arbitration_id=ident, data=rng.randbytes(rng.randrange(0, 9)),
                                    is_extended_id=False, is_error_frame=rng.random() < 0.001)
                try:
                    rig.driver.handle(frame)
                except Exception:  # noqa: BLE001 - counted: a malformed frame must never raise
                    exceptions += 1
            if stopped:
                enables_after += sum(1 for _, _, values in rig.rpdos[sent_before:]
                                     if values[0] in (Command.SWITCH_ON_AND_ENABLE, Command.SHUTDOWN))
            else:
                enables_after += 1                              # the watchdog never stopped it: counts as a failure
            malformed += rig.driver.counters["malformed_frames"]
        finally:
            rig.close()
    return [
        {"name": "fuzz_can_frames", "value": CAN_SEEDS * frames_per_seed, "unit": "frames"},
        {"name": "fuzz_can_seeds", "value": CAN_SEEDS, "unit": "seeds"},
        {"name": "fuzz_can_exceptions", "value": exceptions, "unit": "frames"},
        {"name": "fuzz_can_malformed_counted", "value": malformed, "unit": "frames"},
        {"name": "fuzz_can_enable_commands_after_stop", "value": enables_after, "unit": "frames"},
        {"name": "fuzz_can_enabled_periods_after_stop", "value": enabled_after, "unit": "periods"},
    ]


def run(quick=False):
    udp, *_ = _udp_fuzz(quick)
    return udp + _can_fuzz(quick) + _watchdog(quick) + _hub(quick)


if __name__ == "__main__":
    child_role({"bursts": lambda topic, losses, repeat: _bursts(topic, int(losses), float(repeat))})
