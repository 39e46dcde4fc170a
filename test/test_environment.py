"""Loopback-only DDS: apply_ros_environment, and proof by behaviour that a node started through
our entry point joins no multicast group and binds no socket to the SPDP multicast port."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from hopper_ros.runtime.environment import (
    DISCOVERY_RANGE_VAR,
    LOOPBACK_PROFILE,
    LOOPBACK_VAR,
    PROFILES_FILE_VAR,
    RosEnvironmentError,
    apply_ros_environment,
    discovery_range,
    loopback_installed,
)

STARTED = r"\bstarted: pid (\d+), ROS_DOMAIN_ID (\d+), discovery range (\S+)"
SPDP_GROUP_HEX = "0100FFEF"  # 239.255.0.1 as /proc/net/igmp stores it (little-endian hex)


@pytest.mark.parametrize("before", [None, "", "LOCALHOST"])
def test_unset_empty_or_localhost_installs_the_loopback_profile(before):
    env = {} if before is None else {DISCOVERY_RANGE_VAR: before}
    assert apply_ros_environment(env) == {DISCOVERY_RANGE_VAR: "SYSTEM_DEFAULT", LOOPBACK_VAR: "1",
                                          PROFILES_FILE_VAR: str(LOOPBACK_PROFILE)}
    assert discovery_range(env) == "LOCALHOST" and loopback_installed(env)
    assert apply_ros_environment(env) == {}  # idempotent (a child started with this environment)
    assert LOOPBACK_PROFILE.is_file()


@pytest.mark.parametrize("chosen", ["OFF", "SUBNET", "SYSTEM_DEFAULT"])
def test_a_wider_range_the_user_chose_is_kept_without_the_profile(chosen):
    env = {DISCOVERY_RANGE_VAR: chosen}
    assert apply_ros_environment(env) == {}
    assert env == {DISCOVERY_RANGE_VAR: chosen} and discovery_range(env) == chosen
    # chosen in an environment we had prepared (e.g. a launch file's env): the profile goes
    prepared = {}
    apply_ros_environment(prepared)
    prepared[DISCOVERY_RANGE_VAR] = chosen if chosen != "SYSTEM_DEFAULT" else "SUBNET"
    apply_ros_environment(prepared)
    assert LOOPBACK_VAR not in prepared and PROFILES_FILE_VAR not in prepared


def test_a_users_own_fast_dds_profile_is_respected():
    env = {PROFILES_FILE_VAR: "/home/me/my_profile.xml"}
    assert apply_ros_environment(env) == {DISCOVERY_RANGE_VAR: "LOCALHOST"}
    assert env[PROFILES_FILE_VAR] == "/home/me/my_profile.xml" and not loopback_installed(env)


def test_an_invalid_range_is_refused():
    env = {DISCOVERY_RANGE_VAR: "localhost "}
    with pytest.raises(RosEnvironmentError, match="not a discovery range"):
        apply_ros_environment(env)
    assert apply_ros_environment(env, strict=False) == {}  # import-time call: left for run_node to report


def _udp_ports_by_inode() -> dict[int, int]:
    ports = {}
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            ports[int(fields[9])] = int(fields[1].rsplit(":", 1)[1], 16)
    return ports


def _socket_inodes(pid: int) -> set[int]:
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(int(target[len("socket:[") : -1]))
    return inodes


def _spdp_memberships() -> int:
    """Users of the 239.255.0.1 group summed over all interfaces (/proc/net/igmp)."""
    users = 0
    for line in Path("/proc/net/igmp").read_text().splitlines():
        fields = line.split()
        if fields and fields[0].upper() == SPDP_GROUP_HEX:
            users += int(fields[1])
    return users


def test_entry_point_keeps_dds_on_loopback(hopper_cli):
    from conftest import domain_id

    memberships_before = _spdp_memberships()
    # No range in the environment: our entry point must choose LOCALHOST.
    default = hopper_cli("run", "setpoint_scheduler", unset=(DISCOVERY_RANGE_VAR,))
    # Empty counts as unset (rcl would take it as its default, SUBNET).
    empty = hopper_cli("run", "setpoint_scheduler", "--ros-args", "-r", "__node:=empty", env={DISCOVERY_RANGE_VAR: ""})
    # A range the user chose is kept (OFF: no discovery at all, safe here).
    off = hopper_cli("run", "setpoint_scheduler", "--ros-args", "-r", "__node:=off", env={DISCOVERY_RANGE_VAR: "OFF"})

    started = default.wait_for_line(STARTED)
    assert int(started.group(1)) == default.pid  # the bootstrapper's re-exec keeps the pid
    assert int(started.group(2)) == domain_id()
    assert started.group(3) == "LOCALHOST"
    assert empty.wait_for_line(STARTED).group(3) == "LOCALHOST"
    assert off.wait_for_line(STARTED).group(3) == "OFF"

    # Behaviour, not only the log line: the running participant has UDP sockets, none of them on
    # the domain's SPDP multicast port, and no membership of the SPDP group 239.255.0.1 exists.
    spdp_port = 7400 + 250 * domain_id()
    ports = _udp_ports_by_inode()
    node_ports = sorted(ports[inode] for inode in _socket_inodes(default.pid) if inode in ports)
    assert node_ports, "the node has no UDP socket at all: the check below would prove nothing"
    assert spdp_port not in node_ports, f"socket on the SPDP multicast port {spdp_port}: {node_ports}"
    assert _spdp_memberships() <= memberships_before == 0, "someone joined 239.255.0.1"

    # Clean stop on both signals.
    default.signal(signal.SIGINT)
    off.signal(signal.SIGTERM)
    empty.signal(signal.SIGINT)
    assert default.wait() == 0
    assert off.wait() == 0
    assert empty.wait() == 0
    assert "stopping on SIGINT" in default.stderr
    assert "stopping on SIGTERM" in off.stderr


def test_invalid_range_stops_the_entry_point(hopper_cli):
    process = hopper_cli("topic", "list", env={DISCOVERY_RANGE_VAR: "EVERYWHERE"})
    assert process.wait() == 2
    assert "is not a discovery range" in process.stderr


def _policies(pid: int) -> set[int]:
    """The scheduling policy of every thread of a process (/proc/PID/task/TID/stat field 41)."""
    policies = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        stat = Path(f"/proc/{pid}/task/{tid}/stat").read_text()
        policies.add(int(stat[stat.rfind(")") + 2:].split()[38]))
    return policies


@pytest.mark.parametrize("value", ["0", "100", "high"])
def test_a_bad_realtime_priority_is_refused(value):
    from hopper_ros.runtime.environment import REALTIME_PRIORITY_VAR, apply_realtime_priority

    env = {REALTIME_PRIORITY_VAR: value}
    if value == "0":
        assert apply_realtime_priority(env) == "normal scheduling"
    else:
        with pytest.raises(RosEnvironmentError, match="SCHED_FIFO priority 1-99"):
            apply_realtime_priority(env)


@pytest.mark.parametrize("value", ["-1", "first", "1.5"])
def test_a_bad_cpu_index_is_refused(value):
    from hopper_ros.runtime.environment import CPU_VAR, apply_cpu_affinity

    with pytest.raises(RosEnvironmentError, match="must be a CPU index >= 0"):
        apply_cpu_affinity({CPU_VAR: value})
    assert apply_cpu_affinity({}) == "any CPU"


def test_a_node_asked_for_realtime_priority_runs_every_thread_on_sched_fifo(hopper_cli):
    """... and pinned, every thread, to the CPU HOPPER_CPU names (the index among the allowed CPUs)."""
    import socket

    from conftest import free_port
    from hopper_ros.runtime.environment import CPU_VAR, REALTIME_PRIORITY_VAR

    allowed = sorted(os.sched_getaffinity(0))
    rt = hopper_cli("run", "encoder_bridge", "--ros-args", "-p", f"port:={free_port(socket.SOCK_DGRAM)}",
                    env={REALTIME_PRIORITY_VAR: "7", CPU_VAR: "1"})
    normal = hopper_cli("run", "encoder_bridge", "--ros-args", "-p", f"port:={free_port(socket.SOCK_DGRAM)}",
                        unset=(REALTIME_PRIORITY_VAR, CPU_VAR))
    line = rt.wait_for_line(r"scheduling: (.*)").group(1)
    normal.wait_for_line(r"scheduling: normal scheduling, any CPU")
    if "refused" in line:
        pytest.skip(f"this machine gives no SCHED_FIFO: {line}")
    assert "SCHED_FIFO priority 7" in line
    rt_pid = int(rt.wait_for_line(STARTED).group(1))
    normal_pid = int(normal.wait_for_line(STARTED).group(1))
    assert _policies(rt_pid) == {os.SCHED_FIFO}          # the DDS threads and the UDP thread too
    assert os.sched_getparam(rt_pid).sched_priority == 7
    assert _policies(normal_pid) == {os.SCHED_OTHER}
    if len(allowed) > 1:
        assert line.endswith(f"CPU {allowed[1]}")
        assert {frozenset(os.sched_getaffinity(int(tid))) for tid in os.listdir(f"/proc/{rt_pid}/task")} == \
            {frozenset({allowed[1]})}
        assert os.sched_getaffinity(normal_pid) == set(allowed)
    rt.signal(signal.SIGINT)
    normal.signal(signal.SIGINT)
    assert rt.wait() == 0 and normal.wait() == 0


def test_a_test_session_started_in_the_background_still_stops_what_it_starts():
    """`bash -c 'make test & wait $!'` (a script, a CI runner) starts pytest with SIGINT and SIGQUIT
    ignored; every process a test starts would inherit that and never stop on SIGINT. The session
    restores the defaults (conftest.py): a test that stops a `hopper topic echo` with SIGINT passes."""
    import subprocess
    import sys

    from conftest import REPO

    test = f"{REPO}/test/test_cli.py::test_topic_echo_gives_up_or_stops_on_request"
    result = subprocess.run(["bash", "-c", f"'{sys.executable}' -m pytest -p no:cacheprovider '{test}' & wait $!"],
                            cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "restored default SIGINT, SIGQUIT: started with them ignored" in result.stdout
    assert "1 passed" in result.stdout


# --------------------------------------------------------------------------- every socket on loopback (issue 17)

_LOOPBACK_V6 = {"00000000000000000000000001000000",           # ::1
                "0000000000000000FFFF00000100007F"}           # ::ffff:127.0.0.1


def _sockets_by_inode() -> dict[int, tuple[str, str]]:
    """inode -> (protocol, local address as in /proc/net) for every IP socket of this machine."""
    found = {}
    for protocol in ("udp", "udp6", "tcp", "tcp6", "raw", "raw6"):
        for line in Path(f"/proc/net/{protocol}").read_text().splitlines()[1:]:
            fields = line.split()
            found[int(fields[9])] = (protocol, fields[1])
    return found


def _on_loopback(local: str) -> bool:
    address = local.rsplit(":", 1)[0].upper()
    if len(address) == 8:                                      # IPv4, little-endian hex: 127.x.x.x
        return address.endswith("7F")
    return address in _LOOPBACK_V6


def _node_sockets(pid: int) -> list[tuple[str, str]]:
    table = _sockets_by_inode()
    return [table[inode] for inode in _socket_inodes(pid) if inode in table]


def test_the_check_sees_a_socket_off_loopback():
    import socket

    wide = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    wide.bind(("0.0.0.0", 0))                                  # bound, never used
    narrow = socket.socket(socket.AF_INET6, socket.SOCK_DGRAM)
    narrow.bind(("::1", 0))
    try:
        verdicts = {local: _on_loopback(local) for _, local in _node_sockets(os.getpid())}
        port = lambda sock: f"{sock.getsockname()[1]:04X}"     # noqa: E731
        assert [ok for local, ok in verdicts.items() if local.endswith(":" + port(wide))] == [False]
        assert [ok for local, ok in verdicts.items() if local.endswith(":" + port(narrow))] == [True]
    finally:
        wide.close()
        narrow.close()


def test_every_socket_of_running_nodes_is_on_loopback(hopper_cli):
    """DDS (every node), the CAN hub and its client, the UDP encoder stream: sim_robot, motor_driver,
    encoder_bridge and setpoint_scheduler started as users start them; every IP socket they hold is
    on 127.0.0.1 or ::1 (Fast DDS used to bind 0.0.0.0 and eth0's address as well)."""
    import socket
    import time

    from conftest import free_port

    hub_port, udp_port = free_port(), free_port(socket.SOCK_DGRAM)
    sim = hopper_cli("run", "sim_robot", "--ros-args", "-p", "can:=hub", "-p", f"can_port:={hub_port}",
                     "-p", f"udp_port:={udp_port}", "-p", "hold:=true")
    sim.wait_for_line(rf"CAN hub on 127.0.0.1:{hub_port}")
    nodes = {
        "sim_robot": sim,
        "encoder_bridge": hopper_cli("run", "encoder_bridge", "--ros-args", "-p", f"port:={udp_port}"),
        "motor_driver": hopper_cli("run", "motor_driver", "--ros-args", "-p", f"port:={hub_port}"),
        "setpoint_scheduler": hopper_cli("run", "setpoint_scheduler"),
    }
    pids = {name: int(node.wait_for_line(STARTED).group(1)) for name, node in nodes.items()}
    for node in nodes.values():
        node.wait_for_line(r"discovery range LOCALHOST \(every DDS socket on 127\.0\.0\.1: .*fastdds_loopback\.xml\)")
    nodes["motor_driver"].wait_for_line(r"drive 1 configured and started")
    time.sleep(1.0)                                            # discovery has run: all transports up
    held = {name: _node_sockets(pid) for name, pid in pids.items()}
    for name, sockets in held.items():
        assert any(protocol.startswith("udp") for protocol, _ in sockets), f"{name}: no UDP socket: {sockets}"
        off = [(protocol, local) for protocol, local in sockets if not _on_loopback(local)]
        assert not off, f"{name} holds sockets off loopback: {off}"
    assert any(p.startswith("tcp") for p, _ in held["sim_robot"]) and any(p.startswith("tcp") for p, _ in held["motor_driver"])
    for name, node in nodes.items():
        node.signal(signal.SIGINT)
    for name, node in nodes.items():
        assert node.wait() == 0, f"{name}: {node.stderr[-2000:]}"
