"""Launch files and the process supervisor behind `hopper launch`. No ROS import.

Launch files are ros2 launch's YAML front end (launch_yaml with launch_ros's `node` and
`node_container`), so a file of nodes runs with `ros2 launch hopper_ros FILE` on a machine with
ROS 2 and with `hopper launch FILE` here (containers: hopper launch only, see below). The files live in `launch/` (installed by CMake to
`share/hopper_ros/launch/`). What `hopper launch` supports of the format:

    launch:
      - arg:                          # a launch argument: `hopper launch FILE rate:=500`
          name: rate
          default: "1000"             # without a default the argument is required
          description: samples per second
      - let: {name: ns, value: /hopper}          # a launch configuration
      - node:                         # one process per node, started in file order
          pkg: hopper_ros             # required: this package
          exec: sim_robot             # required: a node of hopper_ros/nodes/registry.py
          name: sim_robot             # ROS node name   (-r __node:=...)
          namespace: $(var ns)        # ROS namespace   (-r __ns:=...)
          param:                      # parameters     (-p name:=value; rcl reads the value as YAML)
            - {name: mode, value: realtime}
            - {name: gains, param: [{name: kp, value: 1.5}]}   # nested: gains.kp
            - {from: params.yaml}     # a ROS parameter file (--params-file): absolute, next to the
                                      #   launch file, or in config/
          remap:                      # remappings     (-r from:=to)
            - {from: apex, to: /events/apex}
          env:                        # environment of the node's process
            - {name: HOPPER_REALTIME_PRIORITY, value: "50"}   # SCHED_FIFO priority (hopper_ros.environment)
          args: "--extra 1"           # arguments after --ros-args ... --
          ros_args: "--log-level debug"   # more ROS arguments
          output: screen              # accepted; hopper launch always relays the output
          on_exit: shutdown           # accepted; hopper launch stops all when a node ends (but see respawn)
          respawn: true               # started again when it ends by itself (launch_ros's Node), after
          respawn_delay: 1.0          #   this many seconds (default 0); the others run on. Not with on_exit
          sigterm_timeout: 5          # s from SIGINT to SIGTERM when stopping (ros2 launch's meaning)
          sigkill_timeout: 5          # s from SIGTERM to SIGKILL
          if: $(var with_sim)         # conditions (also on arg and let): true/false/1/0
          unless: ...
      - node_container:               # several nodes in ONE process on ONE executor (launch_ros's
          pkg: hopper_ros             #   ComposableNodeContainer); the keys of `node` but `args`
          exec: component_container   # required: our container (see below)
          name: sensing               # required, as in launch_ros (the container is a node too)
          namespace: ""               # required, as in launch_ros ("" = none)
          env: [...]                  # the process's: HOPPER_REALTIME_PRIORITY holds for every node in it
          composable_node:            # loaded in this order (launch_ros's ComposableNode.parse)
            - pkg: hopper_ros         # required: this package
              plugin: hopper_ros::EncoderBridge   # required: COMPONENTS of hopper_ros/nodes/registry.py
              name: encoder_bridge    # required
              namespace: $(var ns)    # optional: the node's own; the container's is not inherited
              param: [...]            # as for `node` (a `from` file too)
              remap: [...]            # as for `node`, applied to this node only
              extra_arg:              # only this one: the node's subscriptions take the container's
                - {name: use_intra_process_comms, value: "true"}   # messages in-process (rclcpp's meaning)
              if: ...                 # conditions, as for `node`

A container runs `python -m hopper_ros.cli run component_container --ros-args ... -- --components
JSON` (hopper_ros/nodes/component_container.py): each composable node built from its own class
with its own arguments, all on run_node's executor, the hand-over between them in-process where
use_intra_process_comms says so (hopper_ros/nodes/intra_process.py); each node stays runnable
alone (`hopper run NODE`). What differs from ros2 launch, and why: in ROS the container is
rclcpp_components' `component_container` and launch_ros loads the nodes into it through the
container's `_container/load_node` service (composition_interfaces). An rclcpp container loads
C++ classes only and composition_interfaces is not among the PyPI wheels, so `pkg:
rclcpp_components` (and `component_container_mt`, `_isolated`: one executor here) is refused, the
container is hopper_ros's own executable (also `ros2 run hopper_ros component_container`), and it
takes its nodes on its command line, not by service: `ros2 launch` on a ROS 2 machine would start
it without nodes and wait for the service, so files with a node_container run with `hopper
launch` (demo_500hz.launch.yaml, all separate processes, runs under both). `load_composable_node`
(loading into a running container) is not supported. A plugin is named like a C++ component's
registered class (`hopper_ros::EncoderBridge`) and maps to a Python class in the registry.

Substitutions: `$(var NAME)`, `$(env NAME [DEFAULT])`, `$(optenv NAME [DEFAULT])`,
`$(find-pkg-share PKG)` (hopper_ros: the folder holding config/ and launch/), `$(dirname)`.
Anything else of the format (groups, includes, other actions, other node attributes) is
refused with the file, the entry and the key named, rather than silently ignored.

There is no extension key for our extras: ros2 launch rejects any key of a `node` it does not
know (launch/frontend/expose.py checks that every key was parsed), so the real-time priority is
the standard `env` entry HOPPER_REALTIME_PRIORITY, which ros2 launch passes to the node as well,
and the stop timeouts are launch's own `sigterm_timeout` / `sigkill_timeout`.

Each node runs as `python -m hopper_ros.cli run EXEC --ros-args ... -- ARGS` in its own session
(process group), with the default SIGINT/SIGTERM dispositions whatever ours were. Its
stdout/stderr lines are copied to ours, prefixed with `[label] ` ([namespace/]name).

Respawn: a node (or container) with `respawn: true` that ends by itself while the launch runs is
started again after its `respawn_delay`, the others running on (launch's ExecuteProcess: any exit,
clean or not; with `on_exit: shutdown` as well ros2 launch would shut down instead, so the pair is
refused). Its end does not count in the exit status.

Stopping: on SIGINT/SIGTERM (a second one skips ahead), or as soon as a process without respawn
ends by itself, every process group gets SIGINT, then SIGTERM after the largest `sigterm_timeout`, then SIGKILL
after the largest `sigkill_timeout`; signals go to the whole group, so grandchildren stop too.
Exit status: 0 when the stop was requested and every node exited 0; otherwise non-zero (the
status of the node that ended by itself: its exit code, 128 + signal, or 1 when it exited 0; 1
when a node needed SIGTERM/SIGKILL or failed while stopping). Should the launcher itself be
killed, Linux sends each node SIGTERM (PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import errno
import json
import math
import os
import re
import selectors
import shlex
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, TextIO

import yaml

from hopper_ros.config import config_path, launch_dir, package_share_dir
from hopper_ros.environment import REALTIME_PRIORITY_VAR, RosEnvironmentError, apply_ros_environment, realtime_priority

PACKAGE = "hopper_ros"
DEFAULT_SIGINT_TIMEOUT = 5.0       # launch's default sigterm_timeout: SIGINT -> SIGTERM
DEFAULT_SIGTERM_TIMEOUT = 5.0      # launch's default sigkill_timeout: SIGTERM -> SIGKILL
_ENTITIES = ("arg", "let", "node", "node_container")
CONTAINER = "component_container"   # our container executable (hopper_ros/nodes/component_container.py)
_NODE_KEYS = {"pkg", "exec", "name", "namespace", "param", "remap", "env", "args", "ros_args", "output", "on_exit",
              "sigterm_timeout", "sigkill_timeout", "if", "unless", "respawn", "respawn_delay"}
_CONTAINER_KEYS = (_NODE_KEYS - {"args"}) | {"composable_node"}
_COMPOSABLE_KEYS = {"pkg", "plugin", "name", "namespace", "param", "remap", "extra_arg", "if", "unless"}
_ARG_KEYS = {"name", "default", "description", "if", "unless"}
_LET_KEYS = {"name", "value", "if", "unless"}
_OUTPUTS = {"screen", "log", "both", "own_log"}
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
    respawn: bool = False          # started again when it ends by itself (launch's `respawn`)
    respawn_delay: float = 0.0     # [s] after it ended


@dataclass
class LaunchDescription:
    children: list[ChildSpec]
    sigint_timeout: float = DEFAULT_SIGINT_TIMEOUT
    sigterm_timeout: float = DEFAULT_SIGTERM_TIMEOUT
    arguments: dict[str, str] = field(default_factory=dict)   # the launch arguments in force


# --------------------------------------------------------------------------- launch files


def _param_value(value: Any) -> str:
    """A parameter value as `-p name:=VALUE` text. Strings go as they are: rcl reads the text as
    YAML, as ros2 launch reads a string value (so "0.5" is a double there as here)."""
    if isinstance(value, str):
        return value
    text = yaml.safe_dump(value, default_flow_style=True, width=sys.maxsize, allow_unicode=True)
    if text.endswith("\n...\n"):
        text = text[: -len("\n...\n")]
    return text.strip()


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


_SUBSTITUTION = re.compile(r"\$\(([^()]*)\)")


class _Context:
    """Launch configurations and the substitutions over them, for one launch file."""

    def __init__(self, source: str, base_dir: Path | None, arguments: Mapping[str, str]):
        self.source = source
        self.base_dir = base_dir
        self.given = dict(arguments)
        self.configurations: dict[str, str] = {}
        self.declared: list[str] = []

    def substitute(self, value: Any, where: str) -> Any:
        if not isinstance(value, str):
            return value
        if isinstance(value, str) and "$(" not in value:
            return value

        def replace(match: re.Match) -> str:
            parts = match.group(1).split()
            if not parts:
                raise LaunchFileError(f"{where}: empty substitution '$()'")
            kind, args = parts[0], parts[1:]
            if kind == "var" and len(args) == 1:
                if args[0] not in self.configurations:
                    raise LaunchFileError(f"{where}: $(var {args[0]}): no launch argument or 'let' of that name "
                                          f"before this entry (known: {', '.join(sorted(self.configurations)) or 'none'})")
                return self.configurations[args[0]]
            if kind in ("env", "optenv") and 1 <= len(args) <= 2:
                if args[0] in os.environ:
                    return os.environ[args[0]]
                if len(args) == 2 or kind == "optenv":
                    return args[1] if len(args) == 2 else ""
                raise LaunchFileError(f"{where}: $(env {args[0]}): environment variable not set (give a default: "
                                      f"$(env {args[0]} DEFAULT))")
            if kind == "find-pkg-share" and len(args) == 1:
                return str(find_package_share(args[0], where))
            if kind == "dirname" and not args:
                return str(self.base_dir) if self.base_dir is not None else "."
            raise LaunchFileError(f"{where}: substitution '$({match.group(1)})' is not supported by hopper launch "
                                  f"(supported: var, env, optenv, find-pkg-share, dirname)")

        text = _SUBSTITUTION.sub(replace, value)
        if "$(" in text:
            raise LaunchFileError(f"{where}: cannot read the substitution in {value!r} (nested or unclosed)")
        return text

    def condition(self, entity: dict, where: str) -> bool:
        """False when the entity's `if` is false or its `unless` true."""
        for key, wanted in (("if", True), ("unless", False)):
            if key not in entity:
                continue
            raw = entity[key]
            text = str(self.substitute(raw, where)).strip().lower() if not isinstance(raw, bool) else str(raw).lower()
            if text not in ("true", "false", "1", "0"):
                raise LaunchFileError(f"{where}: '{key}' must be true, false, 1 or 0, got {raw!r}")
            if (text in ("true", "1")) != wanted:
                return False
        return True


def find_package_share(package: str, where: str = "") -> Path:
    """`$(find-pkg-share PKG)`: hopper_ros's own folder of config/ and launch/, else the ament index's."""
    if package == PACKAGE:
        return package_share_dir()
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:
        raise LaunchFileError(f"{where}: $(find-pkg-share {package}): no ament index here") from None
    try:
        return Path(get_package_share_directory(package))
    except PackageNotFoundError:
        raise LaunchFileError(f"{where}: $(find-pkg-share {package}): package not found") from None


def _string(context: _Context, entity: dict, key: str, where: str, required: bool = False) -> str | None:
    if key not in entity:
        if required:
            raise LaunchFileError(f"{where}: missing '{key}'")
        return None
    value = entity[key]
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise LaunchFileError(f"{where}: '{key}' must be a string, got {value!r}")
    text = str(context.substitute(str(value), where))
    if required and not text:
        raise LaunchFileError(f"{where}: '{key}' is empty")
    return text


def _entity_list(value: Any, key: str, where: str) -> list[dict]:
    """A `param`/`remap`/`env` attribute: a list of mappings, as launch_yaml wants it."""
    if not isinstance(value, list) or not value or not all(isinstance(item, dict) for item in value):
        raise LaunchFileError(f"{where}: '{key}' must be a list of mappings, e.g. [{{name: x, value: 1}}]")
    return value


def _check_keys(entity: dict, known: set[str], kind: str, where: str) -> None:
    unknown = sorted(set(entity) - known)
    if unknown:
        raise LaunchFileError(f"{where}: unknown key(s) {', '.join(map(repr, unknown))} of '{kind}' "
                              f"(hopper launch supports: {', '.join(sorted(known))})")


def _params(context: _Context, items: list[dict], prefix: str, where: str, out: list[str]) -> None:
    for item in items:
        if "from" in item:
            _check_keys(item, {"from", "allow_substs"} if not prefix else {"from"}, "param", where)
            if prefix:
                raise LaunchFileError(f"{where}: a parameter file ('from') cannot be nested")
            path = _resolve_file(context.substitute(item["from"], where), context.base_dir, where)
            out += ["--params-file", str(path)]
            continue
        _check_keys(item, {"name", "value", "param"}, "param", where)
        name = _string(context, item, "name", where, required=True)
        full = f"{prefix}.{name}" if prefix else name
        if ("value" in item) == ("param" in item):
            raise LaunchFileError(f"{where}: parameter {full!r} needs either 'value' or nested 'param' (not both)")
        if "param" in item:
            _params(context, _entity_list(item["param"], "param", f"{where}, parameter {full!r}"), full, where, out)
            continue
        value = item["value"]
        if value is None or isinstance(value, dict):
            raise LaunchFileError(f"{where}: parameter {full!r} has no usable value ({value!r}); nest mappings "
                                  f"with 'param'")
        if isinstance(value, list):
            value = [context.substitute(v, where) for v in value]
        else:
            value = context.substitute(value, where)
        out += ["-p", f"{full}:={_param_value(value)}"]


def _timeout(entity: dict, key: str, where: str) -> float | None:
    if key not in entity:
        return None
    value = entity[key]
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < math.inf:
        raise LaunchFileError(f"{where}: '{key}' must be a number of seconds >= 0, got {entity[key]!r}")
    return float(value)


def _flag(context: _Context, entity: dict, key: str, where: str) -> bool:
    """A true/false attribute (YAML boolean or the text of a substitution), False when absent."""
    if key not in entity:
        return False
    raw = entity[key]
    text = str(raw).lower() if isinstance(raw, bool) else str(context.substitute(str(raw), where)).strip().lower()
    if text not in ("true", "false", "1", "0"):
        raise LaunchFileError(f"{where}: '{key}' must be true or false, got {raw!r}")
    return text in ("true", "1")


def _names(context: _Context, entity: dict, where: str, ros_args: list[str],
           required: bool = False) -> tuple[str | None, str | None]:
    """`name` and `namespace` as `-r __node:=` / `-r __ns:=` (namespace made absolute)."""
    name = _string(context, entity, "name", where, required=required)
    if required and "namespace" not in entity:
        raise LaunchFileError(f"{where}: missing 'namespace' (launch_ros requires it of a container; '' for none)")
    namespace = _string(context, entity, "namespace", where)
    if name:
        ros_args += ["-r", f"__node:={name}"]
    if namespace:
        namespace = namespace if namespace.startswith("/") else "/" + namespace
        if namespace != "/":
            ros_args += ["-r", f"__ns:={namespace}"]
    return name, namespace


def _params_and_remaps(context: _Context, entity: dict, where: str, ros_args: list[str]) -> None:
    if "param" in entity:
        _params(context, _entity_list(entity["param"], "param", where), "", where, ros_args)
    for item in _entity_list(entity["remap"], "remap", where) if "remap" in entity else []:
        _check_keys(item, {"from", "to"}, "remap", where)
        ros_args += ["-r", f"{_string(context, item, 'from', where, True)}:={_string(context, item, 'to', where, True)}"]


def _label(name: str | None, namespace: str | None, default: str) -> str:
    return (namespace.strip("/") + "/" if namespace and namespace != "/" else "") + (name or default)


def _composable_node(context: _Context, entity: Any, where: str) -> tuple[dict, str] | None:
    """One `composable_node` of a container: (its --components entry, its label), None if its condition is false."""
    from hopper_ros.nodes.registry import COMPONENTS

    if not isinstance(entity, dict):
        raise LaunchFileError(f"{where}: a composable_node is a mapping of its attributes")
    _check_keys(entity, _COMPOSABLE_KEYS, "composable_node", where)
    if not context.condition(entity, where):
        return None
    package = _string(context, entity, "pkg", where, required=True)
    if package != PACKAGE:
        raise LaunchFileError(f"{where}: pkg {package!r}: the container loads {PACKAGE}'s nodes only")
    plugin = _string(context, entity, "plugin", where, required=True)
    if plugin not in COMPONENTS:
        raise LaunchFileError(f"{where}: unknown plugin {plugin!r}; {PACKAGE}'s: {', '.join(sorted(COMPONENTS))}")
    where = f"{where} ({plugin})"
    args: list[str] = []
    name, namespace = _names(context, entity, where, args)
    if not name:
        raise LaunchFileError(f"{where}: missing 'name' (launch_ros requires it of a composable_node)")
    _params_and_remaps(context, entity, where, args)
    intra_process = False
    for item in _entity_list(entity["extra_arg"], "extra_arg", where) if "extra_arg" in entity else []:
        _check_keys(item, {"name", "value"}, "extra_arg", where)
        key, value = _string(context, item, "name", where, True), str(item.get("value", "")).strip().lower()
        if key != "use_intra_process_comms" or value not in ("true", "false"):
            raise LaunchFileError(f"{where}: extra_arg {key!r}: {value!r}: hopper launch supports only "
                                  f"use_intra_process_comms, 'true' or 'false'")
        intra_process = value == "true"
    return {"plugin": plugin, "args": args, "intra_process": intra_process}, _label(name, namespace, name)


def _node(context: _Context, entity: dict, where: str, env: dict[str, str],
          kind: str = "node") -> tuple[ChildSpec, float | None, float | None, list[str]]:
    """A `node` or `node_container`: (the process, its sigterm/sigkill timeouts, the labels of its nodes)."""
    from hopper_ros.nodes.registry import NODES

    if "realtime_priority" in entity:   # the key of our former launch format
        raise LaunchFileError(f"{where}: 'realtime_priority' is not a key of ros2 launch's node: give the SCHED_FIFO "
                              f"priority as env [{{name: {REALTIME_PRIORITY_VAR}, value: \"N\"}}]")
    container = kind == "node_container"
    _check_keys(entity, _CONTAINER_KEYS if container else _NODE_KEYS, kind, where)
    package = _string(context, entity, "pkg", where, required=True)
    executable = _string(context, entity, "exec", where, required=True)
    if container and (package, executable) != (PACKAGE, CONTAINER):
        raise LaunchFileError(f"{where}: pkg {package!r} exec {executable!r}: a container of Python nodes is "
                              f"pkg: {PACKAGE}, exec: {CONTAINER} (rclcpp_components' containers load C++ nodes only)")
    if package != PACKAGE:
        raise LaunchFileError(f"{where}: pkg {package!r}: hopper launch starts the nodes of {PACKAGE} only")
    if executable not in NODES or (executable == CONTAINER and not container):
        known = ", ".join(sorted(set(NODES) - {CONTAINER}))
        raise LaunchFileError(f"{where}: unknown exec {executable!r}; {PACKAGE}'s nodes: {known}"
                              + (f" ({CONTAINER}: a node_container entry)" if executable == CONTAINER else ""))
    where = f"{where} ({executable})"
    ros_args: list[str] = []
    name, namespace = _names(context, entity, where, ros_args, required=container)
    _params_and_remaps(context, entity, where, ros_args)
    if "ros_args" in entity:
        ros_args += shlex.split(_string(context, entity, "ros_args", where) or "")
    extra = shlex.split(_string(context, entity, "args", where) or "") if "args" in entity else []
    labels = [_label(name, namespace, executable)]
    if container:
        components = []
        items = entity.get("composable_node")
        if not isinstance(items, list) or not items:
            raise LaunchFileError(f"{where}: 'composable_node' must be a non-empty list of composable nodes")
        for number, item in enumerate(items, start=1):
            loaded = _composable_node(context, item, f"{where}, composable_node {number}")
            if loaded is not None:
                components.append(loaded[0])
                labels.append(loaded[1])
        if not components:
            raise LaunchFileError(f"{where}: no composable_node to load")
        extra = ["--components", json.dumps(components)]
    output = _string(context, entity, "output", where)
    if output is not None and output not in _OUTPUTS:
        raise LaunchFileError(f"{where}: 'output' must be one of {', '.join(sorted(_OUTPUTS))}, got {output!r}")
    on_exit = _string(context, entity, "on_exit", where)
    if on_exit is not None and on_exit != "shutdown":
        raise LaunchFileError(f"{where}: 'on_exit' can only be 'shutdown' (as in ros2 launch), got {on_exit!r}")
    respawn = _flag(context, entity, "respawn", where)
    respawn_delay = _timeout(entity, "respawn_delay", where)
    if respawn and on_exit is not None:
        raise LaunchFileError(f"{where}: 'respawn: true' with 'on_exit: shutdown': ros2 launch shuts everything "
                              f"down when the node ends, so it is never respawned; give one of the two")
    child_env = env
    if "env" in entity:
        child_env = dict(env)
        for item in _entity_list(entity["env"], "env", where):
            _check_keys(item, {"name", "value"}, "env", where)
            child_env[_string(context, item, "name", where, True)] = _string(context, item, "value", where) or ""
        try:
            realtime_priority(child_env)
        except RosEnvironmentError as exc:
            raise LaunchFileError(f"{where}: {exc}") from None
    spec = ChildSpec(labels[0], node_command(executable, ros_args, extra), child_env, respawn=respawn,
                     respawn_delay=respawn_delay or 0.0)
    return spec, _timeout(entity, "sigterm_timeout", where), _timeout(entity, "sigkill_timeout", where), labels


def parse_launch(data: Any, source: str = "<launch>", base_dir: Path | None = None,
                 arguments: Mapping[str, str] | None = None) -> LaunchDescription:
    """Validate a parsed launch file, with the launch arguments given, and build the commands."""
    if not isinstance(data, dict) or list(data) != ["launch"]:
        found = ", ".join(map(repr, data)) if isinstance(data, dict) else type(data).__name__
        raise LaunchFileError(f"{source}: expected one root key 'launch' (ros2 launch's YAML format), found {found}")
    entities = data["launch"]
    if not isinstance(entities, list) or not entities:
        raise LaunchFileError(f"{source}: 'launch' must be a non-empty list of entities ({', '.join(_ENTITIES)})")
    context = _Context(source, base_dir, arguments or {})
    env = _child_env()
    children: list[ChildSpec] = []
    labels: dict[str, int] = {}
    sigterm, sigkill = [], []
    for index, item in enumerate(entities, start=1):
        where = f"{source}: entry {index}"
        if not isinstance(item, dict) or len(item) != 1:
            raise LaunchFileError(f"{where}: an entity is a mapping with one key, its type ({', '.join(_ENTITIES)})")
        (kind, entity), = item.items()
        if kind not in _ENTITIES:
            raise LaunchFileError(f"{where}: entity '{kind}' is not supported by hopper launch "
                                  f"(supported: {', '.join(_ENTITIES)})")
        if not isinstance(entity, dict):
            raise LaunchFileError(f"{where}: '{kind}' must be a mapping of its attributes")
        where = f"{where} ({kind})"
        if kind == "arg":
            _check_keys(entity, _ARG_KEYS, kind, where)
            name = _string(context, entity, "name", where, required=True)
            if not context.condition(entity, where):
                continue
            context.declared.append(name)
            if name in context.given:
                context.configurations[name] = context.given[name]
            elif "default" in entity:
                context.configurations[name] = _string(context, entity, "default", where) or ""
            else:
                raise LaunchFileError(f"{where}: launch argument {name!r} is required: give it as {name}:=VALUE")
        elif kind == "let":
            _check_keys(entity, _LET_KEYS, kind, where)
            name = _string(context, entity, "name", where, required=True)
            if context.condition(entity, where):
                context.configurations[name] = _string(context, entity, "value", where, required=False) or ""
        else:
            if not context.condition(entity, where):
                continue
            spec, term, kill, names = _node(context, entity, where, env, kind)
            for label in names:
                if label in labels:
                    raise LaunchFileError(f"{where}: a node {label!r} is already started by entry {labels[label]}; "
                                          f"give the nodes distinct names or namespaces")
                labels[label] = index
            children.append(spec)
            sigterm += [term] if term is not None else []
            sigkill += [kill] if kill is not None else []
    unknown = sorted(set(context.given) - set(context.declared))
    if unknown:
        raise LaunchFileError(f"{source}: no launch argument {', '.join(map(repr, unknown))} in this file "
                              f"(its arguments: {', '.join(context.declared) or 'none'})")
    if not children:
        raise LaunchFileError(f"{source}: no node to start")
    return LaunchDescription(children, max(sigterm, default=DEFAULT_SIGINT_TIMEOUT),
                             max(sigkill, default=DEFAULT_SIGTERM_TIMEOUT),
                             {name: context.configurations[name] for name in context.declared})


def _resolve_file(value: Any, base_dir: Path | None, where: str) -> Path:
    if not isinstance(value, str) or not value:
        raise LaunchFileError(f"{where}: a parameter file ('from') must be a path, got {value!r}")
    path = Path(value)
    if path.is_absolute() and path.exists():
        return path
    if base_dir is not None and (base_dir / path).exists():
        return (base_dir / path).resolve()
    try:
        return config_path(path).resolve()
    except FileNotFoundError as exc:
        raise LaunchFileError(f"{where}: parameter file {value!r} not found") from exc


def launch_file_path(name: str | os.PathLike, package: str | None = None) -> Path:
    """A launch file: an existing path, else a file of the package's launch/ folder
    (`demo.launch.yaml`), as `ros2 launch hopper_ros demo.launch.yaml` finds it."""
    if package not in (None, PACKAGE):
        raise FileNotFoundError(f"package {package!r}: hopper launch runs {PACKAGE}'s launch files only")
    path = Path(name)
    if package is None and path.is_file():
        return path
    candidate = launch_dir() / path
    if candidate.is_file():
        return candidate
    available = ", ".join(sorted(p.name for p in launch_dir().glob("*.launch.yaml")))
    raise FileNotFoundError(f"launch file {str(name)!r} not found (a path, or one of {PACKAGE}'s: {available})")


def load_launch(name: str | os.PathLike, arguments: Mapping[str, str] | None = None,
                package: str | None = None) -> LaunchDescription:
    """Read a launch file (a path, or a name in launch/) with the launch arguments given."""
    path = launch_file_path(name, package)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise LaunchFileError(f"{path}: not valid YAML: {exc}") from exc
    return parse_launch(data, source=str(name), base_dir=path.resolve().parent, arguments=arguments)


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


def _child_preexec(parent_pid: int):
    """The preexec_fn of every child: the default SIGINT/SIGTERM/SIGQUIT dispositions (a launcher
    started with `&` from a script inherited SIGINT ignored, and so would its nodes: they would
    never stop on our SIGINT), and on Linux a SIGTERM to the child should the launcher itself die
    (SIGKILL included), so not even a killed launcher leaves its nodes running."""
    prctl = None
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            prctl = ctypes.CDLL(None, use_errno=True).prctl
        except (OSError, AttributeError):
            prctl = None

    def preexec() -> None:
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGQUIT):
            signal.signal(signum, signal.SIG_DFL)
        if prctl is not None:
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
    respawned: bool = False    # ended by itself and started again: its status is not the launch's
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
        self._respawns: list[tuple[float, ChildSpec]] = []   # (when, spec) of nodes to start again
        self.respawn_counts: dict[str, int] = {}

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
            process_group=0,  # own process group (no terminal signals, group kill), in our session: one autogroup
            preexec_fn=_child_preexec(os.getpid()),
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
        if self._stage == 0 and child.spec.respawn:
            child.respawned = True
            count = self.respawn_counts[child.spec.label] = self.respawn_counts.get(child.spec.label, 0) + 1
            self._say(f"{child.spec.label} ended by itself ({how}); respawning it in {child.spec.respawn_delay:g} s "
                      f"(respawn {count})")
            self._respawns.append((time.monotonic() + child.spec.respawn_delay, child.spec))
        elif self._stage == 0:
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
        if self._gave_up or any(c.status != 0 for c in self._children if not c.respawned) or self._stage >= 2:
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
            if self._stage == 0:
                timeout = self._respawn_due(now)
            else:
                self._respawns.clear()
                timeout = None
            # Without pidfds we look at the children now and then; while stopping, grandchildren
            # (no event for them) are checked for every 0.1 s.
            if self._stage > 0:
                timeout = max(0.0, min(0.1, self._stage_deadline - now))
            elif any(c.pidfd is None for c in self._children if c.status is None):
                timeout = 0.2 if timeout is None else min(timeout, 0.2)
            for key, _events in self._selector.select(timeout):
                self._handle(key)

    def _respawn_due(self, now: float) -> float | None:
        """Start the nodes whose respawn delay is over; seconds until the next one (None: none)."""
        due = [entry for entry in self._respawns if entry[0] <= now]
        for entry in due:
            self._respawns.remove(entry)
            try:
                self._start(entry[1])
            except OSError as exc:
                self._say(f"cannot respawn {entry[1].label}: {exc}; stopping the others")
                self._failure = (None, 1)
        return max(0.0, min(when for when, _ in self._respawns) - now) if self._respawns else None

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
