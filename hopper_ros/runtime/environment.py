"""The process environment every hopper_ros entry point sets up before rclpy is imported.

DDS stays on this machine, and on loopback, unless a user explicitly asks for more. Every entry
point (the `hopper` CLI, each node's `main`, the launcher for its children, the venv's start-up
hook tools/hopper_ros_env.pth) calls `apply_ros_environment()` first. When the discovery range
is unset, empty or LOCALHOST it installs the loopback profile (issue 17):

- `FASTDDS_DEFAULT_PROFILES_FILE` = hopper_ros/dds/fastdds_loopback.xml: no built-in transports,
  UDPv4 with the interface allowlist 127.0.0.1, shared memory, no multicast, discovery by the
  initial peer 127.0.0.1. Every socket of a participant is on 127.0.0.1;
- `ROS_AUTOMATIC_DISCOVERY_RANGE=SYSTEM_DEFAULT` for rcl, because rmw_fastrtps, given LOCALHOST,
  adds a UDPv4 transport of its own that binds 0.0.0.0 and every interface's address (seen with
  `ss -lnup`: Fast DDS then sends nothing off the machine but anyone on the network can send in);
- `HOPPER_DDS_LOOPBACK=1`, so that children and `discovery_range()` know that SYSTEM_DEFAULT here
  means our LOCALHOST.

A range the user chose (OFF, SUBNET, SYSTEM_DEFAULT without our marker) is kept and no profile
is installed: a wider range only when asked for. A user's own FASTDDS_DEFAULT_PROFILES_FILE is
respected (LOCALHOST then stays rmw_fastrtps's). A misspelt range is rejected instead of being
handed to rcl. No ROS import here.

Real-time priority: `HOPPER_REALTIME_PRIORITY=N` (1-99; a launch entry's `realtime_priority`)
makes `run_node` put every thread of the node's process (rclpy's, DDS's, the node's own; threads
started later inherit it) on SCHED_FIFO at priority N once the node is built, its start-up having
run with normal scheduling (`apply_realtime_priority`). That is how the
nodes of the 1 kHz loop run on the robot's real-time PC: a sample is handled as soon as it comes
instead of waiting behind a busy process. Linux's RT throttling (95 % of each second by default)
keeps a runaway node from locking the machine. Without the privilege (CAP_SYS_NICE or an
rtprio limit) the node runs as usual and says so.

CPU: `HOPPER_CPU=N` pins every thread of the node's process to one CPU, the Nth (modulo their
count) of those the process may use, once the node is built (`apply_cpu_affinity`): the usual
practice on a real-time PC with CPUs set apart for the loop. The demo leaves it unset by default
(launch/demo.launch.yaml says what pinning did on a 2-core machine). An index that is not an
integer >= 0 is refused; with one CPU allowed it is left as it is, and said.

Stop signals: a command started with `&` from a script (`bash -c 'make test & wait $!'`, a CI
runner) starts with SIGINT and SIGQUIT ignored, and its children inherit that; a node that
inherits an ignored SIGINT does not stop on SIGINT (run_node keeps a disposition its parent chose).
Whatever starts processes it will stop with signals (the launcher, the test session) therefore
gives them the default dispositions: `restore_default_stop_signals()`.
"""

from __future__ import annotations

import os
import signal
import socket
from pathlib import Path
from typing import MutableMapping

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGQUIT)
DISCOVERY_RANGE_VAR = "ROS_AUTOMATIC_DISCOVERY_RANGE"
REALTIME_PRIORITY_VAR = "HOPPER_REALTIME_PRIORITY"
CPU_VAR = "HOPPER_CPU"
PROFILES_FILE_VAR = "FASTDDS_DEFAULT_PROFILES_FILE"
LOOPBACK_VAR = "HOPPER_DDS_LOOPBACK"
DEFAULT_DISCOVERY_RANGE = "LOCALHOST"
# The values rcl accepts (rcl/discovery_options.h); compared exactly, as rcl does.
VALID_DISCOVERY_RANGES = ("OFF", "LOCALHOST", "SUBNET", "SYSTEM_DEFAULT")
#: the Fast DDS profile that keeps every socket on 127.0.0.1
LOOPBACK_PROFILE = Path(__file__).resolve().parents[1] / "dds" / "fastdds_loopback.xml"
_RCL_RANGE_WITH_PROFILE = "SYSTEM_DEFAULT"   # rmw_fastrtps leaves the transports to the profile


class RosEnvironmentError(ValueError):
    """The environment asks for something the stack refuses to run with."""


def loopback_installed(environ: MutableMapping[str, str] | None = None) -> bool:
    """True when the loopback profile is in force (installed by us, range not changed since)."""
    env = os.environ if environ is None else environ
    return (env.get(LOOPBACK_VAR) == "1" and env.get(DISCOVERY_RANGE_VAR) == _RCL_RANGE_WITH_PROFILE
            and bool(env.get(PROFILES_FILE_VAR)))


def discovery_range(environ: MutableMapping[str, str] | None = None) -> str | None:
    """The discovery range in force (LOCALHOST with our loopback profile), or None when none is set."""
    env = os.environ if environ is None else environ
    if loopback_installed(env):
        return DEFAULT_DISCOVERY_RANGE
    value = env.get(DISCOVERY_RANGE_VAR, "")
    return value or None


def dds_network(environ: MutableMapping[str, str] | None = None) -> str:
    """Where DDS may bind and send, in words (for the nodes' start-up log line)."""
    env = os.environ if environ is None else environ
    if loopback_installed(env):
        return f"LOCALHOST (every DDS socket on 127.0.0.1: {env[PROFILES_FILE_VAR]})"
    return str(discovery_range(env) or "unset (rcl default)")


def apply_ros_environment(environ: MutableMapping[str, str] | None = None, *, strict: bool = True) -> dict[str, str]:
    """Prepare `environ` (default: `os.environ`) for rclpy; returns the variables it set.

    Must run before rclpy is imported (and, in any case, before `rclpy.init`). Idempotent.
    With `strict`, an unknown discovery range raises `RosEnvironmentError`; without it, the
    value is left for a later strict call to report (used at import time, where raising would
    only give a traceback).
    """
    env = os.environ if environ is None else environ
    changed: dict[str, str] = {}
    if loopback_installed(env):
        return changed
    ours = env.get(LOOPBACK_VAR) == "1"
    current = env.get(DISCOVERY_RANGE_VAR, "") or None
    if current is None or current == DEFAULT_DISCOVERY_RANGE:
        if env.get(PROFILES_FILE_VAR) and not ours:
            # the user's own Fast DDS profile: theirs to decide; rcl gets LOCALHOST
            if current is None:
                env[DISCOVERY_RANGE_VAR] = changed[DISCOVERY_RANGE_VAR] = DEFAULT_DISCOVERY_RANGE
            return changed
        wanted = {DISCOVERY_RANGE_VAR: _RCL_RANGE_WITH_PROFILE, LOOPBACK_VAR: "1"}
        if not env.get(PROFILES_FILE_VAR):
            wanted[PROFILES_FILE_VAR] = str(LOOPBACK_PROFILE)
        for name, value in wanted.items():
            if env.get(name) != value:
                env[name] = changed[name] = value
        return changed
    if strict and current not in VALID_DISCOVERY_RANGES:
        raise RosEnvironmentError(
            f"{DISCOVERY_RANGE_VAR}={current!r} is not a discovery range; "
            f"use one of {', '.join(VALID_DISCOVERY_RANGES)} (unset means {DEFAULT_DISCOVERY_RANGE}: loopback only)"
        )
    if ours:               # the user widened the range in an environment we had prepared: no profile
        env.pop(LOOPBACK_VAR, None)
        if env.get(PROFILES_FILE_VAR, "").endswith("/hopper_ros/dds/fastdds_loopback.xml"):
            env.pop(PROFILES_FILE_VAR, None)      # ours (or the venv's copy of it, tools/hopper_ros_env.pth)
    return changed


def realtime_priority(environ: MutableMapping[str, str] | None = None) -> int | None:
    """The SCHED_FIFO priority asked for by HOPPER_REALTIME_PRIORITY (None: unset or 0)."""
    env = os.environ if environ is None else environ
    value = env.get(REALTIME_PRIORITY_VAR, "").strip()
    if not value:
        return None
    try:
        priority = int(value)
    except ValueError:
        priority = -1
    if not 0 <= priority <= 99:
        raise RosEnvironmentError(f"{REALTIME_PRIORITY_VAR}={value!r} must be a SCHED_FIFO priority 1-99 (0 or unset: none)")
    return priority or None


def apply_realtime_priority(environ: MutableMapping[str, str] | None = None) -> str:
    """Put this process on SCHED_FIFO if HOPPER_REALTIME_PRIORITY asks; returns what happened in words."""
    priority = realtime_priority(environ)
    if priority is None:
        return "normal scheduling"
    try:
        # every thread already there (numpy's BLAS pool, ...); threads started later inherit it
        for thread_id in sorted(int(t) for t in os.listdir("/proc/self/task")):
            try:
                os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))
            except ProcessLookupError:
                pass                     # ended meanwhile
    except PermissionError:
        return f"normal scheduling ({REALTIME_PRIORITY_VAR}={priority} refused: no permission for SCHED_FIFO)"
    return f"SCHED_FIFO priority {priority}"


def cpu_index(environ: MutableMapping[str, str] | None = None) -> int | None:
    """The CPU index asked for by HOPPER_CPU (None: unset)."""
    env = os.environ if environ is None else environ
    value = env.get(CPU_VAR, "").strip()
    if not value:
        return None
    if not value.isdigit():
        raise RosEnvironmentError(f"{CPU_VAR}={value!r} must be a CPU index >= 0 (unset: any CPU)")
    return int(value)


def apply_cpu_affinity(environ: MutableMapping[str, str] | None = None) -> str:
    """Pin every thread of this process to the CPU HOPPER_CPU asks for; returns what happened in words."""
    index = cpu_index(environ)
    allowed = sorted(os.sched_getaffinity(0))
    if index is None or len(allowed) < 2:
        return "any CPU" if index is None else f"any CPU ({CPU_VAR}={index}: only CPU {allowed[0]} is allowed)"
    cpu = allowed[index % len(allowed)]
    for thread_id in sorted(int(t) for t in os.listdir("/proc/self/task")):
        try:
            os.sched_setaffinity(thread_id, {cpu})
        except ProcessLookupError:
            pass                         # ended meanwhile
    return f"CPU {cpu}"


def realtime_scheduling_allowed() -> tuple[bool, str]:
    """(whether this process may use SCHED_FIFO, why not); tried on this thread, then undone."""
    try:
        previous = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, previous[0], previous[1])
    except (PermissionError, OSError, AttributeError) as exc:
        return False, str(exc) or type(exc).__name__
    return True, ""


def restore_default_stop_signals() -> list[str]:
    """Give SIGINT, SIGTERM and SIGQUIT their usual dispositions where they are ignored; returns
    the names of those changed.

    In a process that starts children it will stop with signals (a supervisor, the test session):
    children inherit an ignored signal across exec, but a handled one as its default. SIGINT gets
    Python's own handler (KeyboardInterrupt), the others SIG_DFL. Also usable as (part of) a
    subprocess preexec_fn: the child then execs with the defaults. Main thread only.
    """
    changed = []
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) == signal.SIG_IGN:
            signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL)
            changed.append(signal.Signals(signum).name)
    return changed


def _bound_udp_ports() -> set[int]:
    ports = set()
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            with open(table, encoding="ascii") as handle:
                lines = handle.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            ports.add(int(line.split()[1].rsplit(":", 1)[1], 16))
    return ports


PORT_DRAWS = 20                 # free_port: tries for a port this process has not handed out yet
_HANDED_OUT: set[int] = set()


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A loopback port nobody listens on now (TCP by default, UDP with SOCK_DGRAM): a simulated
    robot's own (demo.launch.yaml's `encoder_port`, `can_port`), so that a second graph on this
    machine (a test beside the demo, a soak) never reaches another one's robot. A test's graph on
    hardware.yaml's ports once took over a soak's drive (NMT pre-operational, two masters)."""
    for _ in range(PORT_DRAWS):
        with socket.socket(socket.AF_INET, kind) as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        if port not in _HANDED_OUT:     # two draws before either node bound could give one port twice
            break                       #   ("Address already in use", a clean clone's test_environment once)
    _HANDED_OUT.add(port)
    return port


def robot_port_arguments() -> tuple[str, str]:
    """demo.launch.yaml's arguments giving its simulated robot free loopback ports (`free_port`)."""
    return f"encoder_port:={free_port(socket.SOCK_DGRAM)}", f"can_port:={free_port()}"


def free_domain_id(seed: int | None = None) -> int:
    """A ROS_DOMAIN_ID no participant on this machine uses (no UDP port of the domain's range
    7400 + 250 id ... + 249 bound), never 0 (the usual robot's): the tests', the benches' own graph."""
    used = _bound_udp_ports()
    candidates = list(range(1, 102))
    start = (os.getpid() if seed is None else seed) % len(candidates)
    for domain in candidates[start:] + candidates[:start]:
        base = 7400 + 250 * domain
        if not any(base <= port < base + 250 for port in used):
            return domain
    raise RuntimeError("no free ROS domain id found on this machine")
