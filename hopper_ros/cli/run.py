"""`hopper run NODE [ARGS...]`: run one registered node in this process (as `ros2 run hopper_ros NODE`)."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

HELP = "run a registered node in this process (like `ros2 run hopper_ros NODE`)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = node_list() + "\n\nevery node is also a console script of its own name (e.g. .venv/bin/sim_robot)"
    parser.add_argument("node", help="registered node name (listed below; hopper_ros/nodes/registry.py)")
    parser.add_argument(
        "node_args",
        nargs=argparse.REMAINDER,
        metavar="ARGS",
        help="arguments for the node, e.g. --ros-args -r __node:=name -p param:=value",
    )


def node_list() -> str:
    """The registered nodes with the first line of each module's docstring (read without importing it)."""
    import ast
    import importlib.util

    from hopper_ros.nodes.registry import NODES

    lines = ["nodes:"]
    width = max(map(len, NODES))
    for name, target in NODES.items():
        spec = importlib.util.find_spec(target.partition(":")[0])
        doc = ""
        if spec is not None and spec.origin:
            with open(spec.origin, encoding="utf-8") as handle:
                doc = (ast.get_docstring(ast.parse(handle.read())) or "").strip().splitlines()[0:1]
            doc = doc[0] if doc else ""
            doc = doc[len(name) + 2:] if doc.startswith(f"{name}: ") else doc
        lines.append(f"  {name:<{width}}  {doc}")
    return "\n".join(lines)


def resolve_entry_point(node: str):
    """The `main` callable of a registered node; LookupError naming the known ones otherwise."""
    from hopper_ros.nodes.registry import NODES

    if node not in NODES:
        raise LookupError(f"unknown node {node!r}; registered nodes: {', '.join(sorted(NODES))}")
    module_name, _, function = NODES[node].partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name == module_name:
            raise LookupError(f"node {node!r} is registered but {module_name} does not exist yet") from exc
        raise LookupError(f"node {node!r}: cannot import {module_name}: {exc}") from exc
    return getattr(module, function)


def main(args: argparse.Namespace) -> int:
    try:
        entry = resolve_entry_point(args.node)
    except LookupError as exc:
        print(f"hopper run: error: {exc}", file=sys.stderr)
        return 2
    status = entry([args.node, *args.node_args])
    status = 0 if status is None else int(status)
    if status:
        # a node that failed to start has said why; the interpreter's teardown of what rclpy left behind can
        # only turn that exit status into a crash
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    return status
