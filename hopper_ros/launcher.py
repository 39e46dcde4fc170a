"""Launch files and the process supervisor behind `hopper launch`. No ROS import.

Launch file format (YAML; example: config/launch/example.yaml):

    nodes:                          # started in this order, each as its own process
      - node: setpoint_scheduler    # required: a registered node (hopper_ros/nodes/registry.py)
        name: setpoints             # optional: ROS node name        (-r __node:=setpoints)
        namespace: /hopper          # optional: ROS namespace        (-r __ns:=/hopper)
        parameters:                 # optional: parameter values     (-p name:=value, YAML-encoded;
          schedule_file: setpoints/fig5_5.yaml   #  nested mappings become dotted names)
        params_file: params.yaml    # optional: a ROS parameter file (--params-file), or a list of
                                    #   them; relative to the launch file's folder, else config/
        remappings:                 # optional: topic/service remaps (-r from:=to)
          apex: /events/apex
        args: []                    # optional: more arguments for the node, after the above
        label: setpoints            # optional: the log prefix (default: [namespace/]name or node)
        realtime_priority: 60       # optional: SCHED_FIFO priority 1-99 of the node's process
                                    #   (HOPPER_REALTIME_PRIORITY; hopper_ros/environment.py)
    sigint_timeout: 5.0             # optional: seconds from SIGINT to SIGTERM when stopping (5)
    sigterm_timeout: 3.0            # optional: seconds from SIGTERM to SIGKILL (3)

Each entry runs as `python -m hopper_ros.cli run NODE --ros-args ... -- ARGS` in its own session
(process group). Its stdout/stderr lines are copied to ours, prefixed with `[label] `.

Stopping: on SIGINT/SIGTERM (a second one skips ahead), or as soon as one process ends by itself,
every process group gets SIGINT, then SIGTERM after `sigint_timeout`, then SIGKILL after
`sigterm_timeout`; signals go to the whole group, so grandchildren stop too. Exit status: 0 when
the stop was requested and every node exited 0; otherwise non-zero (the status of the node that
ended by itself: its exit code, 128 + signal, or 1 when it exited 0; 1 when a node needed
SIGTERM/SIGKILL or failed while stopping). Should the launcher itself be killed, Linux sends
each node SIGTERM (PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import errno
import math
import os
import selectors
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import yaml

from hopper_ros.config import config_path
from hopper_ros.environment import REALTIME_PRIORITY_VAR, apply_ros_environment

DEFAULT_SIGINT_TIMEOUT = 5.0
DEFAULT_SIGTERM_TIMEOUT = 3.0
_ENTRY_KEYS = {"node", "name", "namespace", "parameters", "params_file", "remappings", "args", "label",
               "realtime_priority"}
_TOP_KEYS = {"nodes", "sigint_timeout", "sigterm_timeout"}
_READ_SIZE = 65536
_MAX_LINE = 65536  # a longer line without newline is passed on in pieces
_KILL_GRACE = 2.0  # [s] after SIGKILL before we give up on a process (unkillable: not ours)


class LaunchFileError(ValueError):
    """A launch file that cannot be used, with the file and entry named."""


@dataclass
class ChildSpec:
    label: str
    argv: list[str]
    env: dict[str, str] | None = None
    cwd: str | None = None


@dataclass
class LaunchDescription:
    children: list[ChildSpec]
    sigint_timeout: float = DEFAULT_SIGINT_TIMEOUT
    sigterm_timeout: float = DEFAULT_SIGTERM_TIMEOUT


# --------------------------------------------------------------------------- launch files


def _param_value(value: Any) -> str:
    text = yaml.safe_dump(value, default_flow_style=True, width=sys.maxsize, allow_unicode=True)
    if text.endswith("\n...\n"):
        text = text[: -len("\n...\n")]
    return text.strip()


def _flatten(prefix: str, value: Any, out: list[tuple[str, Any]]) -> None:
    if isinstance(value, dict):
        for key, sub in value.items():
            _flatten(f"{prefix}.{key}" if prefix else str(key), sub, out)
    else:
        out.append((prefix, value))


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    apply_ros_environment(env)
    env["PYTHONUNBUFFERED"] = "1"
    # Make the child import the same hopper_ros as we do (a checkout need not be installed).
    package_root = str(Path(__file__).resolve().parent.parent)
    paths = [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p]
    if package_root not in paths:
        env["PYTHONPATH"] = os.pathsep.join([package_root, *paths])
    return env


def node_command(node: str, ros_args: list[str] = (), extra_args: list[str] = ()) -> list[str]:
    """The command that runs one registered node in a fresh interpreter of this environment."""
    argv = [sys.executable, "-m", "hopper_ros.cli", "run", node]
    if ros_args:
        argv += ["--ros-args", *ros_args, "--"]
    return argv + list(extra_args)


def parse_launch(data: Any, source: str = "<launch>", base_dir: Path | None = None) -> LaunchDescription:
    """Validate a parsed launch file and build the commands to run."""
    from hopper_ros.nodes.registry import NODES

    if not isinstance(data, dict) or not isinstance(data.get("nodes"), list) or not data["nodes"]:
        raise LaunchFileError(f"{source}: expected a mapping with a non-empty 'nodes' list")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise LaunchFileError(f"{source}: unknown key(s) {', '.join(map(repr, unknown))} (known: {', '.join(sorted(_TOP_KEYS))})")
    timeouts = {}
    for key, default in (("sigint_timeout", DEFAULT_SIGINT_TIMEOUT), ("sigterm_timeout", DEFAULT_SIGTERM_TIMEOUT)):
        value = data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < math.inf:
            raise LaunchFileError(f"{source}: {key!r} must be a number of seconds >= 0, got {value!r}")
        timeouts[key] = float(value)

    env = _child_env()
    children: list[ChildSpec] = []
    labels: dict[str, int] = {}
    for index, entry in enumerate(data["nodes"], start=1):
        where = f"{source}: entry {index}"
        if not isinstance(entry, dict):
            raise LaunchFileError(f"{where}: expected a mapping, got {entry!r}")
        if "node" in entry:
            where += f" ({entry['node']})"
        unknown = sorted(set(entry) - _ENTRY_KEYS)
        if unknown:
            raise LaunchFileError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))} (known: {', '.join(sorted(_ENTRY_KEYS))})")
        node = entry.get("node")
        if node not in NODES:
            problem = "missing 'node'" if node is None else f"unknown node {node!r}"
            raise LaunchFileError(f"{where}: {problem}; registered nodes: {', '.join(sorted(NODES))}")
        for key in ("name", "namespace", "label"):
            if key in entry and (not isinstance(entry[key], str) or not entry[key]):
                raise LaunchFileError(f"{where}: {key!r} must be a non-empty string, got {entry[key]!r}")

        ros_args: list[str] = []
        name, namespace = entry.get("name"), entry.get("namespace")
        if name:
            ros_args += ["-r", f"__node:={name}"]
        if namespace:
            namespace = namespace if namespace.startswith("/") else "/" + namespace
            ros_args += ["-r", f"__ns:={namespace}"]

        parameters = entry.get("parameters", {})
        if not isinstance(parameters, dict):
            raise LaunchFileError(f"{where}: 'parameters' must be a mapping of name: value")
        flat: list[tuple[str, Any]] = []
        _flatten("", parameters, flat)
        for pname, value in flat:
            if value is None:
                raise LaunchFileError(f"{where}: parameter {pname!r} has no value")
            ros_args += ["-p", f"{pname}:={_param_value(value)}"]

        params_files = entry.get("params_file", [])
        for pfile in [params_files] if isinstance(params_files, str) else params_files:
            ros_args += ["--params-file", str(_resolve_file(pfile, base_dir, where))]

        remappings = entry.get("remappings", {})
        if not isinstance(remappings, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in remappings.items()):
            raise LaunchFileError(f"{where}: 'remappings' must be a mapping of from: to (strings)")
        for source_name, target in remappings.items():
            ros_args += ["-r", f"{source_name}:={target}"]

        extra = entry.get("args", [])
        if not isinstance(extra, list):
            raise LaunchFileError(f"{where}: 'args' must be a list")

        label = entry.get("label") or ((namespace.strip("/") + "/" if namespace and namespace != "/" else "") + (name or node))
        if label in labels:
            raise LaunchFileError(
                f"{where}: label {label!r} is already used by entry {labels[label]}; give the entries distinct names or labels"
            )
        labels[label] = index
        child_env = env
        if "realtime_priority" in entry:
            priority = entry["realtime_priority"]
            if isinstance(priority, bool) or not isinstance(priority, int) or not 1 <= priority <= 99:
                raise LaunchFileError(f"{where}: 'realtime_priority' must be a SCHED_FIFO priority 1-99, got {priority!r}")
            child_env = {**env, REALTIME_PRIORITY_VAR: str(priority)}
        children.append(ChildSpec(label, node_command(node, ros_args, [str(a) for a in extra]), child_env))
    return LaunchDescription(children, timeouts["sigint_timeout"], timeouts["sigterm_timeout"])


def _resolve_file(value: Any, base_dir: Path | None, where: str) -> Path:
    if not isinstance(value, str) or not value:
        raise LaunchFileError(f"{where}: 'params_file' must be a path or a list of paths, got {value!r}")
    path = Path(value)
    if path.is_absolute() and path.exists():
        return path
    if base_dir is not None and (base_dir / path).exists():
        return (base_dir / path).resolve()
    try:
        return config_path(path).resolve()
    except FileNotFoundError as exc:
        raise LaunchFileError(f"{where}: params_file {value!r} not found") from exc


def load_launch(name: str | os.PathLike) -> LaunchDescription:
    """Read a launch file: a path, or relative to the config directory (e.g. launch/example.yaml)."""
    path = config_path(name)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise LaunchFileError(f"{path}: not valid YAML: {exc}") from exc
    return parse_launch(data, source=str(name), base_dir=path.resolve().parent)


# --------------------------------------------------------------------------- supervisor


def _group_alive(pgid: int) -> bool:
    """Whether any live (non-zombie) process is left in process group `pgid`."""
    try:
        entries = os.listdir("/proc")
    except OSError:
        entries = None
    if entries is None:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as handle:
                stat = handle.read()
        except OSError:
            continue
        fields = stat[stat.rfind(b")") + 2 :].split()
        if len(fields) > 2 and int(fields[2]) == pgid and fields[0] not in (b"Z", b"X"):
            return True
    return False


def _die_with_parent(parent_pid: int):
    """A preexec_fn asking Linux to send SIGTERM to the child if the launcher itself dies
    (SIGKILL included), so not even a killed launcher leaves its nodes running."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None

    def preexec() -> None:
        prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        if os.getppid() != parent_pid:  # the launcher died before that: stop right away
            os.kill(os.getpid(), signal.SIGTERM)

    return preexec


@dataclass
class _Child:
    spec: ChildSpec
    process: subprocess.Popen
    pidfd: int | None = None
    status: int | None = None  # returncode once reaped (negative: killed by that signal)
    group_gone: bool = False
    buffers: dict[int, bytearray] = field(default_factory=dict)

    @property
    def pgid(self) -> int:
        return self.process.pid

    def done(self) -> bool:
        if self.status is None:
            return False
        if not self.group_gone:
            self.group_gone = not _group_alive(self.pgid)
        return self.group_gone


class Launcher:
    """Start processes in their own sessions, relay their output, stop them all together."""

    def __init__(
        self,
        children: list[ChildSpec],
        *,
        sigint_timeout: float = DEFAULT_SIGINT_TIMEOUT,
        sigterm_timeout: float = DEFAULT_SIGTERM_TIMEOUT,
        out: TextIO | None = None,
        err: TextIO | None = None,
    ):
        self.specs = children
        self.sigint_timeout = sigint_timeout
        self.sigterm_timeout = sigterm_timeout
        self.out = out or sys.stdout
        self.err = err or sys.stderr
        self._children: list[_Child] = []
        self._selector = selectors.DefaultSelector()
        self._stop_requests = 0
        self._stage = 0  # 0 running, 1 SIGINT sent, 2 SIGTERM sent, 3 SIGKILL sent
        self._stage_deadline = math.inf
        self._failure: tuple[_Child | None, int] | None = None
        self._gave_up = False

    # -- output
    def _say(self, text: str) -> None:
        self.out.write(f"[launch] {text}\n")
        self.out.flush()

    def _emit(self, child: _Child, fd: int, data: bytes) -> None:
        stream = self.out if fd == child.process.stdout.fileno() else self.err
        stream.write(f"[{child.spec.label}] {data.decode('utf-8', 'replace')}\n")
        stream.flush()

    def _read(self, child: _Child, fd: int) -> None:
        try:
            chunk = os.read(fd, _READ_SIZE)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EINTR):
                return
            chunk = b""
        buffer = child.buffers.setdefault(fd, bytearray())
        if not chunk:  # EOF: flush the last partial line
            if buffer:
                self._emit(child, fd, bytes(buffer))
                buffer.clear()
            self._selector.unregister(fd)
            return
        buffer += chunk
        while True:
            newline = buffer.find(b"\n")
            if newline < 0:
                if len(buffer) >= _MAX_LINE:
                    self._emit(child, fd, bytes(buffer))
                    buffer.clear()
                break
            self._emit(child, fd, bytes(buffer[:newline]).rstrip(b"\r"))
            del buffer[: newline + 1]

    # -- signals
    def _on_signal(self, signum, _frame) -> None:
        self._stop_requests += 1

    def _signal_groups(self, signum: int) -> None:
        for child in self._children:
            if not child.done():
                try:
                    os.killpg(child.pgid, signum)
                except (ProcessLookupError, PermissionError):
                    pass

    def _escalate(self, now: float) -> None:
        self._stage += 1
        if self._stage == 1:
            self._signal_groups(signal.SIGINT)
            self._stage_deadline = now + self.sigint_timeout
        elif self._stage == 2:
            alive = [c.spec.label for c in self._children if not c.done()]
            self._say(f"sending SIGTERM to {', '.join(alive)}")
            self._signal_groups(signal.SIGTERM)
            self._stage_deadline = now + self.sigterm_timeout
        elif self._stage == 3:
            alive = [c.spec.label for c in self._children if not c.done()]
            self._say(f"sending SIGKILL to {', '.join(alive)}")
            self._signal_groups(signal.SIGKILL)
            self._stage_deadline = now + _KILL_GRACE

    # -- children
    def _start(self, spec: ChildSpec) -> None:
        process = subprocess.Popen(
            spec.argv,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=spec.env,
            cwd=spec.cwd,
            start_new_session=True,  # own session and process group: no terminal signals, group kill
            preexec_fn=_die_with_parent(os.getpid()),
        )
        child = _Child(spec, process)
        self._children.append(child)
        for stream in (process.stdout, process.stderr):
            os.set_blocking(stream.fileno(), False)
            self._selector.register(stream.fileno(), selectors.EVENT_READ, ("io", child))
        if hasattr(os, "pidfd_open"):
            try:
                child.pidfd = os.pidfd_open(process.pid)
                self._selector.register(child.pidfd, selectors.EVENT_READ, ("exit", child))
            except OSError:
                child.pidfd = None
        self._say(f"started {spec.label}: pid {process.pid}")

    def _reap(self, child: _Child) -> None:
        if child.status is not None or child.process.poll() is None:
            return
        child.status = child.process.returncode
        if child.pidfd is not None:
            self._selector.unregister(child.pidfd)
            os.close(child.pidfd)
            child.pidfd = None
        how = f"exit status {child.status}" if child.status >= 0 else f"signal {signal.Signals(-child.status).name}"
        if self._stage == 0:
            self._say(f"{child.spec.label} ended by itself ({how}); stopping the others")
            code = child.status if child.status > 0 else (128 - child.status if child.status < 0 else 1)
            self._failure = (child, code)
        else:
            self._say(f"{child.spec.label} stopped ({how})")

    # -- main loop
    def run(self) -> int:
        """Start every child and supervise until all are gone; returns the exit status."""
        previous = {}
        wakeup_r, wakeup_w = os.pipe()
        os.set_blocking(wakeup_r, False)
        os.set_blocking(wakeup_w, False)
        old_wakeup = None
        try:
            # Signals first, so a Ctrl-C during start-up is not lost; the wake-up pipe makes
            # select() return on a signal.
            old_wakeup = signal.set_wakeup_fd(wakeup_w, warn_on_full_buffer=False)
            self._selector.register(wakeup_r, selectors.EVENT_READ, ("signal", None))
            for signum in (signal.SIGINT, signal.SIGTERM):
                previous[signum] = signal.signal(signum, self._on_signal)
            for spec in self.specs:
                if self._stop_requests:
                    break
                try:
                    self._start(spec)
                except OSError as exc:
                    self._say(f"cannot start {spec.label}: {exc}; stopping the others")
                    self._failure = (None, 1)
                    break
            self._loop()
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)
            if old_wakeup is not None:
                signal.set_wakeup_fd(old_wakeup)
            self._selector.close()
            os.close(wakeup_r)
            os.close(wakeup_w)
            for child in self._children:
                for stream in (child.process.stdout, child.process.stderr):
                    stream.close()
                if child.pidfd is not None:
                    os.close(child.pidfd)

        if self._failure is not None:
            return self._failure[1]
        if self._gave_up or any(c.status != 0 for c in self._children) or self._stage >= 2:
            return 1
        return 0

    def _loop(self) -> None:
        handled_requests = 0
        while True:
            now = time.monotonic()
            for child in self._children:
                self._reap(child)
            if self._stage == 0 and (self._failure is not None or self._stop_requests):
                if self._stop_requests and self._failure is None:
                    self._say("stopping (signal received)")
                handled_requests = self._stop_requests
                self._escalate(now)
            elif self._stage > 0 and self._stop_requests > handled_requests and self._stage < 3:
                handled_requests = self._stop_requests  # asked again: skip ahead
                self._escalate(now)
            if self._stage > 0:
                if all(c.done() for c in self._children):
                    self._drain()
                    return
                if now >= self._stage_deadline:
                    if self._stage >= 3:
                        alive = [c.spec.label for c in self._children if not c.done()]
                        self._say(f"giving up on {', '.join(alive)}: still running after SIGKILL")
                        self._gave_up = True
                        return
                    self._escalate(now)
            # Without pidfds we look at the children now and then; while stopping, grandchildren
            # (no event for them) are checked for every 0.1 s.
            timeout = None
            if self._stage > 0:
                timeout = max(0.0, min(0.1, self._stage_deadline - now))
            elif any(c.pidfd is None for c in self._children):
                timeout = 0.2
            for key, _events in self._selector.select(timeout):
                self._handle(key)

    def _handle(self, key: selectors.SelectorKey) -> None:
        kind, child = key.data
        if kind == "io":
            self._read(child, key.fd)
        elif kind == "signal":  # the handler has counted it; just empty the wake-up pipe
            try:
                while os.read(key.fd, 512):
                    pass
            except BlockingIOError:
                pass
        # "exit": the child is reaped at the top of the loop

    def _drain(self) -> None:
        """Pass on what the stopped processes wrote last (bounded: a leaked pipe must not hang us)."""
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            io_keys = [k for k in self._selector.get_map().values() if k.data[0] == "io"]
            if not io_keys:
                return
            for key, _events in self._selector.select(max(0.0, end - time.monotonic())):
                self._handle(key)
