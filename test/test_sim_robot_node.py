"""sim_robot as a process: UDP encoder packets, force plate and ground truth on real topics."""

from __future__ import annotations

import dataclasses
import signal
import socket
import time

import numpy as np
import pytest

from conftest import REPO, SAFETY_TIMEOUT, free_port, spin_until
from hopper_ros.hardware import packet as packet_format
from hopper_ros.sim.plant import PlantEvent
from hopper_ros.sim.stance import LATE_AFTER, SAID_AFTER

ATTACK_GUARD = 40.0   # [s] hang guard of the wait for every attacking hub client to be dropped once


def receive_packets(sock: socket.socket, count: int, timeout: float = SAFETY_TIMEOUT) -> list[bytes]:
    sock.settimeout(1.0)
    packets = []
    end = time.monotonic() + timeout
    while len(packets) < count and time.monotonic() < end:
        try:
            packets.append(sock.recv(2048))
        except socket.timeout:
            continue
    return packets


def latest_packets(sock: socket.socket, count: int) -> list:
    """Drop what queued up in the socket, then decode the next `count` packets."""
    sock.setblocking(False)
    try:
        while True:
            sock.recv(2048)
    except BlockingIOError:
        pass
    sock.setblocking(True)
    return [packet_format.decode(data) for data in receive_packets(sock, count)]


def stance_seen(forces) -> bool:
    """A whole stance on the plate: contact, then none."""
    first = next((i for i, f in enumerate(forces) if f.contact), None)
    return first is not None and any(not f.contact for f in forces[first:])


def test_node_streams_packets_force_plate_and_true_events(rclpy_session, hopper_cli):
    from rclpy.executors import SingleThreadedExecutor

    from diagnostic_msgs.msg import DiagnosticArray

    from hopper_ros.msg import ApexState, BodyState, GaitEvent, GroundReactionForce
    from hopper_ros.nodes.diagnostics import OK, WARN, level_of, status_values

    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    node = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", f"udp_port:={udp.getsockname()[1]}")
    node.wait_for_line(r"realtime at 1000 Hz, packets to 127.0.0.1")
    test_node = rclpy_session.create_node("sim_robot_test")
    executor = SingleThreadedExecutor()
    executor.add_node(test_node)
    got = {"force": [], "truth": [], "events": [], "diagnostics": []}
    test_node.create_subscription(GroundReactionForce, "force_plate", got["force"].append, 1000)
    test_node.create_subscription(BodyState, "sim/truth", got["truth"].append, 1000)
    test_node.create_subscription(GaitEvent, "sim/events", got["events"].append, 100)
    test_node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: got["diagnostics"].extend(m.status), 10)
    try:
        packets = [packet_format.decode(data) for data in receive_packets(udp, 1500)]
        assert len(packets) == 1500                 # pacing (real-time factor 1): bench sim_realtime_mode_factor
        sequences = np.array([p.sequence for p in packets])
        assert (np.diff(sequences) == 1).mean() > 0.999   # loopback UDP loses nothing in practice
        clock = np.array([p.mcu_time_us for p in packets])
        assert set(np.diff(clock) / np.diff(sequences)) == {1000.0}
        # once connected, throw the robot again (with the motor off its first stride is its last)
        throw = test_node.create_publisher(ApexState, "sim/throw", 10)
        assert spin_until(executor, lambda: test_node.count_publishers("sim/events") and throw.get_subscription_count())
        got["events"].clear()
        throw.publish(ApexState(apex_height=0.38, forward_speed=1.5, leg_angle=0.25))
        kinds = {GaitEvent.TOUCHDOWN, GaitEvent.LIFTOFF, GaitEvent.APEX}
        assert spin_until(executor, lambda: kinds <= {e.type for e in got["events"]} and got["diagnostics"]
                          and stance_seen(got["force"]) and len(got["truth"]) > 500)
        stance_force = max(f.force_vertical for f in got["force"])
        assert stance_force > 50.0                  # the robot landed on the plate
        report = got["diagnostics"][-1]
        assert report.name == "/sim_robot" and report.hardware_id == "simulated robot"
        values = status_values(report)
        assert isinstance(values["periods"], int) and values["periods"] > 0
        # with the motor off the robot falls after its stride: a warning, said in words
        assert (level_of(report), report.message) == ((WARN, "the robot fell") if values["falls"] else (OK, "OK"))
        assert 0.5 < values["realtime_factor"] < 1.5
    finally:
        node.signal(signal.SIGINT)
        assert node.wait() == 0
        executor.shutdown()
        test_node.destroy_node()
        udp.close()


def test_lockstep_ends_after_its_duration_with_every_period_sent(hopper_cli):
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    udp.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    node = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", "mode:=lockstep",
                      "-p", "duration:=3.0", "-p", f"udp_port:={udp.getsockname()[1]}")
    node.wait_for_line(r"lockstep at 1000 Hz")
    node.wait_for_line(r"simulated 3\.000 s: done")    # how fast: bench sim_realtime_factor
    assert node.wait() == 0                         # ends by itself
    packets = receive_packets(udp, 3000, timeout=5.0)
    assert len(packets) >= 2500                     # the socket buffer may drop a few at full speed
    udp.close()


def test_bad_parameters_stop_the_node_with_a_clear_error(hopper_cli):
    node = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", "udp_host:=192.0.2.1")
    assert node.wait() == 3                         # bad input
    assert "only sends on loopback" in node.stderr
    node = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", "enable_effects:=[levitation]")
    assert node.wait() == 3
    assert "unknown effect 'levitation'" in node.stderr


def test_canopen_master_in_another_process_drives_the_simulated_epos2(hopper_cli):
    """Issue 4's acceptance: sim_robot in its process, the `canopen` library as master in this one."""
    import canopen
    from canopen.sdo.exceptions import SdoAbortedError

    from hopper_ros.hardware.encoders import CounterUnwrapper

    hub_port = free_port()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    node = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=hub", "-p", f"can_port:={hub_port}",
                      "-p", f"udp_port:={udp.getsockname()[1]}", "-p", "hold:=true")   # held: the leg swings free
    node.wait_for_line(rf"CAN hub on 127.0.0.1:{hub_port}")
    network = canopen.Network()
    network.connect(interface="socketcand", host="127.0.0.1", port=hub_port, channel="can0")
    try:
        drive = canopen.RemoteNode(1, str(REPO / "test" / "data" / "epos2.eds"))
        network.add_node(drive)
        drive.nmt.wait_for_heartbeat(SAFETY_TIMEOUT)
        drive.nmt.state = "OPERATIONAL"
        assert drive.nmt.wait_for_heartbeat(SAFETY_TIMEOUT) == "OPERATIONAL"
        assert drive.sdo[0x1000].raw == 0x00020192                   # device type: CiA 402 servo drive
        with pytest.raises(SdoAbortedError) as abort:
            drive.sdo.upload(0x2345, 0)
        assert abort.value.code == 0x06020000                        # object does not exist
        network.send_message(0x200 + 1, b"\x0f")                     # RPDO1 one byte short: malformed

        drive.sdo["Controlword"].raw = 0x00
        drive.sdo["Controlword"].raw = 0x80                          # clear the PDO length fault
        drive.sdo["Modes of operation"].raw = -3                     # current mode
        for command, state in ((0x06, 0x21), (0x07, 0x23), (0x0F, 0x27)):  # CiA 402 states
            drive.sdo["Controlword"].raw = command
            assert drive.sdo["Statusword"].raw & 0x6F == state
        drive.rpdo.read()
        unwrap = CounterUnwrapper()
        before = unwrap.update(latest_packets(udp, 1)[0].motor_counts)
        drive.rpdo[1]["Controlword"].raw = 0x0F
        drive.rpdo[1]["Current mode setting value"].raw = 1000       # [mA]
        drive.rpdo[1].transmit()
        time.sleep(0.3)
        packets = latest_packets(udp, 5)
        moved = unwrap.update(packets[-1].motor_counts) - before
        assert moved > 500                                           # the motor turned (1 A for 0.3 s)
        assert packets[-1].motor_current_ma == pytest.approx(1000, abs=5)

        # a fault: the master's heartbeat, which the drive consumes, stops
        drive.sdo[0x1016][1].raw = (0x7F << 16) | 50                 # consume node 0x7F, 50 ms
        heartbeat = network.send_periodic(0x700 + 0x7F, [0x05], 0.01)
        time.sleep(0.2)
        heartbeat.stop()
        end = time.monotonic() + SAFETY_TIMEOUT
        while not any(e.code == 0x8130 for e in drive.emcy.log) and time.monotonic() < end:
            time.sleep(0.01)
        assert [e.code for e in drive.emcy.log if e.code] == [0x8210, 0x8130]
        assert drive.sdo["Statusword"].raw & 0x4F == 0x08            # FAULT
        time.sleep(0.05)
        idle = latest_packets(udp, 5)
        assert idle[-1].motor_current_ma == 0                         # a fault disables the motor
        drive.sdo[0x1016][1].raw = 0
        drive.sdo["Controlword"].raw = 0x80                          # fault reset
        assert drive.sdo["Statusword"].raw & 0x4F == 0x40            # switch on disabled
    finally:
        network.disconnect()
        node.signal(signal.SIGINT)
        assert node.wait() == 0
        udp.close()


def test_sigterm_stops_sim_robot_whatever_its_hub_clients_do(hopper_cli):
    """Issue 17: 200 hub clients in raw mode that never read (dropped ones reconnect) and a master
    sending SYNC at 1 kHz: the simulated robot keeps stepping, the master keeps its SDO round trips,
    and SIGTERM ends the node promptly (it used to hang in a blocking write to the hub; the bench
    measures how promptly: hub_sigterm_stop_s)."""
    from hub_attack import RawModeAttack
    from test_canbus_socketcand import LoadClient

    hub_port = free_port()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    node = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=hub", "-p", f"can_port:={hub_port}",
                      "-p", f"udp_port:={udp.getsockname()[1]}", "-p", "hold:=true")
    try:
        node.wait_for_line(rf"CAN hub on 127.0.0.1:{hub_port}")
        load = LoadClient(hub_port)
        try:
            with RawModeAttack(hub_port, clients=200) as attack:
                # SYNC at 1 kHz (traffic) for longer than the wait's hang guard, so that it is still on at
                # the SIGTERM however slowly this machine fills the attackers' buffers
                load.start_phase("attack", ATTACK_GUARD + 5.0)
                end = time.monotonic() + ATTACK_GUARD
                while attack.reopened < 200 and time.monotonic() < end:   # every client dropped once
                    time.sleep(0.1)
                reopened = attack.reopened
                before = latest_packets(udp, 1)[0].sequence
                time.sleep(0.2)
                assert latest_packets(udp, 1)[0].sequence > before + 50   # the robot keeps stepping
                started = time.monotonic()
                node.signal(signal.SIGTERM)                              # attack and SYNC still on
                status = node.wait(10.0)
                stopped_after = time.monotonic() - started
        finally:
            load.abort()                                                 # its figures are not this test's
    finally:
        udp.close()
    assert status == 0, node.stderr
    assert stopped_after < 10.0
    assert reopened >= 200
    assert "stopping on SIGTERM" in node.stderr


# ------------------------------------------------------------------ in-process: the stepping thread's callbacks
# Issue 29: under load a stance whose ramp torque reached the leg late (said as a warning) followed one said at
# info from the same call site; rclpy raised "Logger severity cannot be changed between calls", the stepping
# thread died, the robot stood still while its node lived on, and the demo never hopped again.


@pytest.fixture
def sim_node(rclpy_session):
    from rclpy.parameter import Parameter

    from hopper_ros.nodes.sim_robot import SimRobotNode

    node = SimRobotNode(parameter_overrides=[Parameter("can", value="none"), Parameter("hold", value=True)])
    node.runner.close()             # the test steps the robot itself, from one thread
    yield node
    node.destroy_node()


def stance(node, onset: float) -> None:
    """One stance through the node's own callback: touchdown, the ramp torque at `onset`, lift-off."""
    sample = node.robot.step(False)
    truth = sample.truth
    motion = {name: getattr(truth, name) for name in ("t", "y", "z", "ydot", "zdot", "leg_angle")}
    emit = node._emit
    emit(dataclasses.replace(sample, events=[PlantEvent(**motion, kind="touchdown")]))
    at_onset = dataclasses.replace(truth, t=truth.t + onset, hip_torque=5.0)
    emit(dataclasses.replace(sample, truth=at_onset, events=[]))
    ended = dataclasses.replace(truth, t=truth.t + 0.1)
    emit(dataclasses.replace(sample, truth=ended, events=[PlantEvent(**(motion | {"t": ended.t}), kind="liftoff")]))


def test_a_late_stance_after_one_in_time_is_said_without_killing_the_stepping_thread(sim_node):
    said_in_time = (SAID_AFTER + LATE_AFTER) / 2       # said at info
    late = 2 * LATE_AFTER                               # said as a warning
    for onset in (said_in_time, late, said_in_time):
        stance(sim_node, onset)
    assert (sim_node.stances.stances, sim_node.stances.late) == (3, 1)


def test_a_ramp_on_the_leg_before_its_touchdown_is_measured_and_said(sim_node):
    """A stance ramp whose torque reached the leg in the flight (a setting the simulated robot took a period before
    it was sent: bench_demo_load at 500 Hz) shows no late onset; its lead before the touchdown is measured, said at
    info or as a warning by its size, one after the other from one call site."""
    for early in ((SAID_AFTER + LATE_AFTER) / 2, 2 * LATE_AFTER, 0.0):
        sample = sim_node.robot.step(False)
        truth = sample.truth
        motion = {name: getattr(truth, name) for name in ("t", "y", "z", "ydot", "zdot", "leg_angle")}
        flight = dataclasses.replace(truth, hip_torque=5.0 if early else 0.0)
        sim_node._emit(dataclasses.replace(sample, truth=flight, events=[]))
        touchdown = dataclasses.replace(truth, t=truth.t + early, hip_torque=5.0)
        sim_node._emit(dataclasses.replace(sample, truth=touchdown,
                                           events=[PlantEvent(**(motion | {"t": touchdown.t}), kind="touchdown")]))
        assert sim_node.stances.early == pytest.approx(early)
        ended = dataclasses.replace(truth, t=truth.t + 0.1)
        sim_node._emit(dataclasses.replace(sample, truth=ended, events=[PlantEvent(**(motion | {"t": ended.t}),
                                                                                    kind="liftoff")]))
    assert sim_node.stances.early_max == pytest.approx(2 * LATE_AFTER) and sim_node.stances.late == 0


def test_a_stepping_thread_that_raises_ends_the_node_with_a_failure(sim_node):
    assert not sim_node.finished
    sim_node.runner._on_failure(RuntimeError("a step raised"))
    assert sim_node.finished and sim_node.failed
