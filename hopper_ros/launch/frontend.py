"""The launch files of `hopper launch`: ros2 launch's YAML front end (launch_yaml with launch_ros's
`node` and `node_container`) parsed into the processes to start (`LaunchDescription` of `ChildSpec`),
every key checked (the pydantic models of hopper_ros/launch/entities.py), substitutions and conditions applied. What of the format is supported:
hopper_ros/launch/__init__.py. No ROS import.
"""

from __future__ import annotations

import json
import math
import os
import re
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

from hopper_ros.config import config_path, launch_dir, package_share_dir
from hopper_ros.runtime.environment import (REALTIME_PRIORITY_VAR, RosEnvironmentError, apply_ros_environment, cpu_index,
                                            realtime_priority)

from .entities import (ENTITIES, ComposableNode, LaunchFileError, NameValue, NestedParamFile, Param, ParamFile,
                       Remap, check_keys)
from .supervisor import DEFAULT_SIGINT_TIMEOUT, DEFAULT_SIGTERM_TIMEOUT, ChildSpec

PACKAGE = "hopper_ros"
CONTAINER = "component_container"   # our container executable (hopper_ros/nodes/component_container.py)
_OUTPUTS = {"screen", "log", "both", "own_log"}


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
    package_root = str(Path(__file__).resolve().parents[2])
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


def _params(context: _Context, items: list[dict], prefix: str, where: str, out: list[str]) -> None:
    for item in items:
        if "from" in item:
            check_keys(item, NestedParamFile if prefix else ParamFile, "param", where)
            if prefix:
                raise LaunchFileError(f"{where}: a parameter file ('from') cannot be nested")
            path = _resolve_file(context.substitute(item["from"], where), context.base_dir, where)
            out += ["--params-file", str(path)]
            continue
        check_keys(item, Param, "param", where)
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
        check_keys(item, Remap, "remap", where)
        ros_args += ["-r", f"{_string(context, item, 'from', where, True)}:={_string(context, item, 'to', where, True)}"]


def _label(name: str | None, namespace: str | None, default: str) -> str:
    return (namespace.strip("/") + "/" if namespace and namespace != "/" else "") + (name or default)


def _composable_node(context: _Context, entity: Any, where: str) -> tuple[dict, str] | None:
    """One `composable_node` of a container: (its --components entry, its label), None if its condition is false."""
    from hopper_ros.nodes.registry import COMPONENTS

    if not isinstance(entity, dict):
        raise LaunchFileError(f"{where}: a composable_node is a mapping of its attributes")
    check_keys(entity, ComposableNode, "composable_node", where)
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
        check_keys(item, NameValue, "extra_arg", where)
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
    check_keys(entity, ENTITIES[kind], kind, where)
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
            check_keys(item, NameValue, "env", where)
            child_env[_string(context, item, "name", where, True)] = _string(context, item, "value", where) or ""
        try:
            realtime_priority(child_env)
            cpu_index(child_env)
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
        raise LaunchFileError(f"{source}: 'launch' must be a non-empty list of entities ({', '.join(ENTITIES)})")
    context = _Context(source, base_dir, arguments or {})
    env = _child_env()
    children: list[ChildSpec] = []
    labels: dict[str, int] = {}
    sigterm, sigkill = [], []
    for index, item in enumerate(entities, start=1):
        where = f"{source}: entry {index}"
        if not isinstance(item, dict) or len(item) != 1:
            raise LaunchFileError(f"{where}: an entity is a mapping with one key, its type ({', '.join(ENTITIES)})")
        (kind, entity), = item.items()
        if kind not in ENTITIES:
            raise LaunchFileError(f"{where}: entity '{kind}' is not supported by hopper launch "
                                  f"(supported: {', '.join(ENTITIES)})")
        if not isinstance(entity, dict):
            raise LaunchFileError(f"{where}: '{kind}' must be a mapping of its attributes")
        where = f"{where} ({kind})"
        if kind == "arg":
            check_keys(entity, ENTITIES[kind], kind, where)
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
            check_keys(entity, ENTITIES[kind], kind, where)
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


