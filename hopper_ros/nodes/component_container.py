"""component_container: several hopper_ros nodes in one process, on one executor.

What `hopper launch` runs for a launch file's `node_container` entry (launch_ros's composable
nodes; hopper_ros/launch/__init__.py says what of the format is supported):

    hopper run component_container --ros-args -r __node:=sensing -- --components JSON

JSON is a list of {"plugin": "hopper_ros::EncoderBridge", "args": [ROS arguments of that node],
"intra_process": bool}, one per composable node, built in that order. Each node is its own class
(hopper_ros/nodes/registry.py COMPONENTS), built as when it runs alone, with its own arguments only
(`-r __node:=NAME -r __ns:=NS -p ... -r FROM:=TO --params-file F`; the container's `--ros-args` are
not applied to it, as rclcpp's component manager sets use_global_arguments false). The container is
a node too (its launch entry's name and namespace), holding nothing but the others. All of them spin
on the one executor of `run_node` (the events executor, SCHED_FIFO by HOPPER_REALTIME_PRIORITY as
for any node). `intra_process` (extra_arg use_intra_process_comms): the node's subscriptions take the
container's messages in-process (hopper_ros/nodes/intra_process.py), not through DDS.

A node that cannot be built (bad configuration) stops the container with exit status 1, its error
prefixed with the node's name; the nodes already built are destroyed.
"""

from __future__ import annotations

import argparse
import importlib
import json

from rclpy.node import Node

from hopper_ros.nodes.common import run_node
from hopper_ros.nodes.intra_process import IntraProcessBus, composable
from hopper_ros.nodes.registry import COMPONENTS


def component_class(plugin: str):
    """The node class of a registered plugin name."""
    if plugin not in COMPONENTS:
        raise ValueError(f"unknown plugin {plugin!r} (hopper_ros's: {', '.join(sorted(COMPONENTS))})")
    module, _, name = COMPONENTS[plugin].partition(":")
    return getattr(importlib.import_module(module), name)


def parse_components(text: str) -> list[dict]:
    """The `--components` JSON, checked."""
    try:
        items = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"--components: not JSON: {exc}") from None
    if not isinstance(items, list) or not items:
        raise ValueError("--components: a non-empty list of composable nodes")
    for item in items:
        if (not isinstance(item, dict) or not isinstance(item.get("plugin"), str)
                or not all(isinstance(a, str) for a in item.get("args", []))
                or not isinstance(item.get("intra_process", False), bool)
                or set(item) - {"plugin", "args", "intra_process"}):
            raise ValueError(f"--components: bad entry {item!r} (plugin, args, intra_process)")
        component_class(item["plugin"])
    return items


class Composition(list):
    """The container node first, then the composed nodes; `spinning()` flushes early messages and
    tells each node that its executor runs (as run_node does for a node alone)."""

    def __init__(self, components: list[dict], context=None):
        super().__init__()
        container = Node("component_container", start_parameter_services=False, context=context)
        self.append(container)
        self.bus = IntraProcessBus(container.get_logger())
        try:
            for item in components:
                node_class = composable(component_class(item["plugin"]), self.bus, item.get("intra_process", False))
                try:
                    node = node_class(cli_args=["--ros-args", *item.get("args", [])], use_global_arguments=False,
                                      context=context)
                except (ValueError, OSError) as exc:
                    raise type(exc)(f"{item['plugin']}: {exc}") from exc
                self.append(node)
                container.get_logger().info(f"loaded {node.get_fully_qualified_name()} ({item['plugin']}"
                                            f"{', intra-process' if item.get('intra_process') else ''})")
        except BaseException:
            for node in reversed(self):
                node.destroy_node()
            raise

    def spinning(self) -> None:
        self.bus.flush()
        for node in self[1:]:
            getattr(node, "spinning", lambda: None)()


def main(args=None) -> int:
    import sys

    from rclpy.utilities import remove_ros_args

    argv = list(args) if args is not None else sys.argv
    parser = argparse.ArgumentParser(prog="component_container", description=__doc__.splitlines()[0])
    parser.add_argument("--components", required=True, help="the composable nodes (JSON, see the module)")
    options = parser.parse_args(remove_ros_args(argv)[1:])
    try:
        components = parse_components(options.components)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return run_node(lambda: Composition(components), argv)


if __name__ == "__main__":
    raise SystemExit(main())
