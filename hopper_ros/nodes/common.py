"""Scaffolding shared by every node: environment, init, spin, clean shutdown.

A node module defines its `rclpy.node.Node` subclass (a thin adapter over a plain module) and

    def main(args=None):
        return run_node(MyNode, args)

`run_node` applies the ROS environment (loopback-only discovery unless the user chose a range),
initialises rclpy with `args` (None: `sys.argv`, so `--ros-args ...` work as with `ros2 run`),
builds the node (with normal scheduling: a respawned node's start-up must not starve the running
loop), puts every thread of the process on SCHED_FIFO when HOPPER_REALTIME_PRIORITY asks
(hopper_ros.runtime.environment), logs its startup (pid, domain id, discovery range; scheduling), freezes the start-up's
objects for the garbage collector (gc.freeze: a full collection walked all of them, a 50 ms pause of
every thread; a pause over GC_PAUSE_WARNING is logged) and spins it on rclpy's
EventsExecutor (HOPPER_EXECUTOR=single: the SingleThreadedExecutor). The events executor costs a
fraction of the CPU per message: measured on the demo graph at 1 kHz, 150 % of a core in all
instead of 190 %, the event detector and the controller at 13 % instead of 30 %. It has no guard
conditions, so a stop signal is seen within `_EVENTS_SPIN_PERIOD`. SIGINT and SIGTERM both end the spin
(unless the parent process had set them to be ignored), and so does a node setting its attribute `finished`
(its work is done; seen at the next wake-up of the executor; with `failed` set too, the status is 1); the node
is destroyed, rclpy shut down (a teardown that hangs is cut short after nodes/shutdown_guard.SHUTDOWN_GRACE)
and 0 returned. A node that cannot start (bad configuration) makes it return 3, one whose callback raises 1
(cli/exit_codes.py).
"""

from __future__ import annotations

import gc
import os
import signal
import sys
import time
import traceback
from typing import Any, Callable, Sequence

from hopper_ros.runtime.environment import (RosEnvironmentError, apply_cpu_affinity, apply_realtime_priority,
                                    apply_ros_environment, cpu_index, dds_network, realtime_priority)
from hopper_ros.nodes.shutdown_guard import ShutdownGuard
from hopper_ros.nodes.signals import StopSignals

_SPIN_PERIOD = 1.0  # [s] the executor wakes at least this often (belt and braces, see StopSignals)
_EVENTS_SPIN_PERIOD = 0.1  # [s] with the events executor (no guard conditions): stop latency


_ACTIVE_STOP: StopSignals | None = None
GC_PAUSE_WARNING = 0.005  # [s] a garbage collection longer than this is logged (it holds every thread of the node)


class GcPauses:
    """The garbage collector's pauses (gc.callbacks): the longest since `take()`. Python's full
    collection walks every object of the process, ~50 ms in a node (rclpy, numpy, scipy, the
    model), more in a container: it stops every thread, the 1 kHz loop and the command stream with
    it. run_node freezes the objects of the start-up (gc.freeze) so that it walks only the few made
    since (issue 29: such pauses made the motor command stream's 20 ms gaps)."""

    def __init__(self) -> None:
        self.longest, self.generation = 0.0, -1
        self._started = 0.0

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._started = time.perf_counter()
        else:
            pause = time.perf_counter() - self._started
            if pause > self.longest:
                self.longest, self.generation = pause, info.get("generation", -1)

    def take(self) -> tuple[float, int]:
        """(the longest pause [s], its generation) since the last call."""
        taken = self.longest, self.generation
        self.longest, self.generation = 0.0, -1
        return taken


def read_only_parameters(node) -> Callable[[str, Any, str], Any]:
    """`param(name, default, description)`: declares a read-only parameter of `node`, returns its value."""
    from rcl_interfaces.msg import ParameterDescriptor

    return lambda name, default, text: node.declare_parameter(
        name, default, ParameterDescriptor(description=text, read_only=True)).value


def log_event(logger, level: str, text: str) -> None:
    """Log `text` at `level` ("info", "warning", "error"). One call site per level: rclpy ties each
    call site to the severity of its first call and raises ValueError on another ("Logger severity
    cannot be changed between calls"): `getattr(logger, level)(text)` on one line crashed the
    controller the first time a warning followed an error (issue 29: the robot fell)."""
    if level == "error":
        logger.error(text)
    elif level == "warning":
        logger.warning(text)
    else:
        logger.info(text)


def sensing_parameters(node):
    """The sensing nodes' shared parameters: (`param` as `read_only_parameters`, the sensing config of
    `sensing_file`, the diagnostics period: `diagnostics_period`, or the sensing file's when 0)."""
    from hopper_ros.sensing.config import load_sensing_config

    param = read_only_parameters(node)
    config = load_sensing_config(param("sensing_file", "sensing.yaml", "sensing settings (YAML)"))
    period = param("diagnostics_period", 0.0, "[s] diagnostics period (0 = sensing file)") or config.diagnostics_period
    return param, config, period


def stop_requested() -> bool:
    """True once SIGINT/SIGTERM arrived: for a node whose start-up waits (e.g. for a server)."""
    return _ACTIVE_STOP is not None and _ACTIVE_STOP.received is not None


def _executor():
    """(executor, spin period): the events executor unless HOPPER_EXECUTOR=single or unavailable."""
    from rclpy.executors import SingleThreadedExecutor

    if os.environ.get("HOPPER_EXECUTOR", "events") != "single":
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:  # pragma: no cover - older rclpy
            pass
        else:
            return EventsExecutor(), _EVENTS_SPIN_PERIOD
    return SingleThreadedExecutor(), _SPIN_PERIOD


def _half_built(exc: BaseException) -> list:
    """The nodes whose constructor raised `exc` after rclpy had built them (e.g. a bad config file read
    from a parameter): destroyed explicitly before rclpy shuts down, never left to the collector at exit,
    where rcl handles outliving their context can crash the process (seen once as SIGSEGV under load)."""
    from rclpy.node import Node

    found, frame = [], exc.__traceback__
    while frame is not None:
        candidate = frame.tb_frame.f_locals.get("self")
        if isinstance(candidate, Node) and all(candidate is not each for each in found):
            found.append(candidate)
        frame = frame.tb_next
    return found


def run_node(node_factory: Callable[[], "rclpy.node.Node"], args: Sequence[str] | None = None) -> int:  # noqa: F821
    """Run one node until SIGINT/SIGTERM; returns the process exit status (0: clean stop). A factory
    may return a list of nodes (a container: all on the one executor, the first one logs; its
    `spinning()`, if any, is called once they are added)."""
    try:
        apply_ros_environment()
        realtime_priority()          # checked now; applied once the node is built (below)
        cpu_index()
    except RosEnvironmentError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    global _ACTIVE_STOP
    stop = _ACTIVE_STOP = StopSignals().install()  # before rclpy: a signal during start-up is not lost either

    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    node = None
    nodes, half_built = [], []
    executor = None
    status = 0
    pauses = GcPauses()
    try:
        rclpy.init(args=list(args) if args is not None else None, signal_handler_options=SignalHandlerOptions.NO)
        if stop.received is None:
            built = node_factory()
            nodes = list(built) if isinstance(built, (list, tuple)) else [built]
            node = nodes[0]
            executor, spin_period = _executor()
            if spin_period == _SPIN_PERIOD:
                stop.attach(node)
            node.get_logger().info(
                f"started: pid {os.getpid()}, ROS_DOMAIN_ID {node.context.get_domain_id()}, "
                f"discovery range {dds_network()}"
            )
            for each in nodes:
                executor.add_node(each)
            gc.collect()
            gc.freeze()              # the start-up's objects are never walked again (GcPauses)
            gc.callbacks.append(pauses)
            # SCHED_FIFO only now, for every thread there (rclpy's, DDS's, the node's; later ones inherit it):
            # the imports and construction (a second of CPU) ran with normal scheduling. A node respawned
            # at FIFO priority starved the running loop of the same or lower priority while it started
            node.get_logger().info(f"scheduling: {apply_realtime_priority()}, {apply_cpu_affinity()}")
            getattr(built, "spinning", lambda: None)()
            logger = node.get_logger()
            while (stop.received is None and node.context.ok()
                   and not any(getattr(each, "finished", False) for each in nodes)):
                executor.spin_once(timeout_sec=spin_period)
                if pauses.longest > GC_PAUSE_WARNING:
                    pause, generation = pauses.take()
                    logger.warning(f"garbage collection (generation {generation}) held the node {pause * 1e3:.1f} ms")
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as exc:  # noqa: BLE001 - a node's failure is reported, then we clean up
        if node is None:
            half_built = _half_built(exc)
        if stop.received is None:  # otherwise: the shutdown interrupted start-up, not an error
            status = 1
            if isinstance(exc, (ValueError, OSError)) and node is None:
                status = 3                                # bad input (cli/exit_codes.py)
                print(f"error: {exc}", file=sys.stderr)  # configuration: the message says it all
            else:
                traceback.print_exc()
    finally:
        if status == 3:
            # bad input before any node ran: nothing to clean up that matters, and tearing a half-built
            # node down still crashed the interpreter now and then (exit -11 in CI, its error line printed)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(status)
        if stop.received is not None and node is not None:
            node.get_logger().info(f"stopping on {signal.Signals(stop.received).name}")
        if stop.received is None and any(getattr(each, "failed", False) for each in nodes):
            status = 1               # ended by itself, but not because its work was done (nor asked to stop)
        stop.detach()
        if pauses in gc.callbacks:
            gc.callbacks.remove(pauses)
        name = node.get_name() if node is not None else "node"
        with ShutdownGuard(name, "the node has stopped", status):   # a hung DDS teardown cannot keep it running
            if executor is not None:
                executor.shutdown(timeout_sec=1.0)
            for each in reversed(nodes):
                each.destroy_node()
            for each in half_built:   # rclpy's own destroy: the subclass's may need what its constructor never set
                Node.destroy_node(each)
            gc.collect()    # a node whose constructor failed (bad config) is freed while its context lives: left to the
            rclpy.try_shutdown()   # interpreter's exit, rcl handles outlive their context and the process may crash
        stop.uninstall()
    return status
