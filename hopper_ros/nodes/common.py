"""Scaffolding shared by every node: environment, init, spin, clean shutdown.

A node module defines its `rclpy.node.Node` subclass (a thin adapter over a plain module) and

    def main(args=None):
        return run_node(MyNode, args)

`run_node` applies the ROS environment (loopback-only discovery unless the user chose a range),
initialises rclpy with `args` (None: `sys.argv`, so `--ros-args ...` work as with `ros2 run`),
builds the node, logs one startup line (pid, domain id, discovery range) and spins it on a
SingleThreadedExecutor. SIGINT and SIGTERM both end the spin; the node is destroyed, rclpy shut
down and 0 returned. A node that cannot start (bad configuration) or whose callback raises makes
it return 1.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import traceback
from typing import Callable, Sequence

from hopper_ros.environment import RosEnvironmentError, apply_ros_environment, discovery_range

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def run_node(node_factory: Callable[[], "rclpy.node.Node"], args: Sequence[str] | None = None) -> int:  # noqa: F821
    """Run one node until SIGINT/SIGTERM; returns the process exit status (0: clean stop)."""
    try:
        apply_ros_environment()
    except RosEnvironmentError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    # Our handlers go in before rclpy.init: rclpy's own SIGINT/SIGTERM handlers (which shut the
    # context down and wake the executor) chain to them, so we learn which signal stopped us,
    # and a signal arriving before rclpy is up is not lost.
    received: list[int] = []
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for signum in _STOP_SIGNALS:
            previous[signum] = signal.signal(signum, lambda s, _f: received.append(s))

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    node = None
    executor = None
    status = 0
    try:
        rclpy.init(args=list(args) if args is not None else None)
        if not received:
            node = node_factory()
            node.get_logger().info(
                f"started: pid {os.getpid()}, ROS_DOMAIN_ID {node.context.get_domain_id()}, "
                f"discovery range {discovery_range()}"
            )
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            if not received:
                executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as exc:  # noqa: BLE001 - a node's failure is reported, then we clean up
        if not received:  # otherwise: the shutdown interrupted start-up, not an error
            status = 1
            if isinstance(exc, (ValueError, OSError)) and node is None:
                print(f"error: {exc}", file=sys.stderr)  # configuration: the message says it all
            else:
                traceback.print_exc()
    finally:
        if received and node is not None:
            node.get_logger().info(f"stopping on {signal.Signals(received[0]).name}")
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return status
