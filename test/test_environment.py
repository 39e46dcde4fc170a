"""Loopback-only DDS: apply_ros_environment, and proof by behaviour that a node started through
our entry point joins no multicast group and binds no socket to the SPDP multicast port."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from hopper_ros.environment import (
    DISCOVERY_RANGE_VAR,
    RosEnvironmentError,
    apply_ros_environment,
    discovery_range,
)

STARTED = r"\bstarted: pid (\d+), ROS_DOMAIN_ID (\d+), discovery range (\S+)"
SPDP_GROUP_HEX = "0100FFEF"  # 239.255.0.1 as /proc/net/igmp stores it (little-endian hex)


@pytest.mark.parametrize("before", [None, ""])
def test_unset_or_empty_range_becomes_localhost(before):
    env = {} if before is None else {DISCOVERY_RANGE_VAR: before}
    assert apply_ros_environment(env) == {DISCOVERY_RANGE_VAR: "LOCALHOST"}
    assert env[DISCOVERY_RANGE_VAR] == "LOCALHOST" and discovery_range(env) == "LOCALHOST"
    assert apply_ros_environment(env) == {}  # idempotent


@pytest.mark.parametrize("chosen", ["OFF", "LOCALHOST", "SUBNET", "SYSTEM_DEFAULT"])
def test_a_range_the_user_chose_is_kept(chosen):
    env = {DISCOVERY_RANGE_VAR: chosen}
    assert apply_ros_environment(env) == {}
    assert env[DISCOVERY_RANGE_VAR] == chosen


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
    from hopper_ros.environment import REALTIME_PRIORITY_VAR, apply_realtime_priority

    env = {REALTIME_PRIORITY_VAR: value}
    if value == "0":
        assert apply_realtime_priority(env) == "normal scheduling"
    else:
        with pytest.raises(RosEnvironmentError, match="SCHED_FIFO priority 1-99"):
            apply_realtime_priority(env)


def test_a_node_asked_for_realtime_priority_runs_every_thread_on_sched_fifo(hopper_cli):
    import socket

    from conftest import free_port
    from hopper_ros.environment import REALTIME_PRIORITY_VAR

    rt = hopper_cli("run", "encoder_bridge", "--ros-args", "-p", f"port:={free_port(socket.SOCK_DGRAM)}",
                    env={REALTIME_PRIORITY_VAR: "7"})
    normal = hopper_cli("run", "encoder_bridge", "--ros-args", "-p", f"port:={free_port(socket.SOCK_DGRAM)}",
                        unset=(REALTIME_PRIORITY_VAR,))
    line = rt.wait_for_line(r"scheduling: (.*)").group(1)
    normal.wait_for_line(r"scheduling: normal scheduling")
    if "refused" in line:
        pytest.skip(f"this machine gives no SCHED_FIFO: {line}")
    assert "SCHED_FIFO priority 7" in line
    rt_pid = int(rt.wait_for_line(STARTED).group(1))
    normal_pid = int(normal.wait_for_line(STARTED).group(1))
    assert _policies(rt_pid) == {os.SCHED_FIFO}          # the DDS threads and the UDP thread too
    assert os.sched_getparam(rt_pid).sched_priority == 7
    assert _policies(normal_pid) == {os.SCHED_OTHER}
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
