"""`hopper run NODE [ARGS...]`: run one registered node in this process (as `ros2 run hopper_ros NODE`)."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

HELP = "run a registered node in this process (like `ros2 run hopper_ros NODE`)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("node", help="registered node name (see hopper_ros/nodes/registry.py)")
    parser.add_argument(
        "node_args",
        nargs=argparse.REMAINDER,
        metavar="ARGS",
        help="arguments for the node, e.g. --ros-args -r __node:=name -p param:=value",
    )


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
