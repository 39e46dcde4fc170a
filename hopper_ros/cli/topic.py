"""`hopper topic list|echo`: inspect topics of any graph running on this machine.

  hopper topic list [-t] [-a] [--spin-time S]
  hopper topic echo TOPIC [TYPE] [--once | -n N] [--timeout S] [--full-length]

`echo` takes the message type from the graph (or TYPE, e.g. std_msgs/msg/String), imports its
class from whatever package provides it, waits for a publisher, subscribes with a QoS matching the
publishers (reliable/transient local when all of them are, so latched topics are received) and
prints each message as YAML followed by `---`, like `ros2 topic echo`.

`--timeout S` bounds the whole run: if no publisher appeared, or fewer messages than asked for
with --once/-n arrived, within S seconds the command fails (exit 1); without --once/-n it just
stops after S seconds (exit 0). Ctrl-C stops it (exit 0).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from hopper_ros.runtime.messages import DEFAULT_TRUNCATE_LENGTH, message_class, message_to_yaml

HELP = "list topics, print a topic's messages as YAML or its rate, publish one (like `ros2 topic`)"

_ECHO_DESCRIPTION = """Print the messages of TOPIC as YAML, each followed by '---'.

The type is taken from the graph unless TYPE is given; the command waits for a publisher.
--timeout S bounds the whole run: if no publisher appeared, or fewer messages than asked for
with --once/-n arrived, within S seconds it fails (exit 1); without --once/-n it stops after
S seconds (exit 0)."""

_POLL_PERIOD = 0.05  # [s] between looks at the graph while waiting for discovery
# Without a daemon, `list` sees what it discovers in this time. Measured here with LOCALHOST
# discovery: a newcomer sees an existing participant's topics after 0.06 to 2.7 s (Fast DDS
# re-announces every 3 s), so the default waits a full period.
DEFAULT_SPIN_TIME = 3.5  # [s]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)

    listing = verbs.add_parser("list", help="list the topics of the graph")
    listing.add_argument("-t", "--show-types", action="store_true", help="show each topic's type(s)")
    listing.add_argument(
        "-a", "--include-hidden-topics", action="store_true", help="include hidden topics (names starting with _)"
    )
    listing.add_argument(
        "--spin-time",
        type=float,
        default=DEFAULT_SPIN_TIME,
        metavar="S",
        help=f"time to wait for discovery [s] (default {DEFAULT_SPIN_TIME:g})",
    )
    listing.set_defaults(_verb=_list)

    echo = verbs.add_parser(
        "echo",
        help="print the messages of a topic as YAML",
        description=_ECHO_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    echo.add_argument("topic", help="topic name, e.g. /apex_setpoint")
    echo.add_argument("type", nargs="?", help="message type (default: taken from the graph)")
    count = echo.add_mutually_exclusive_group()
    count.add_argument("--once", action="store_const", const=1, dest="count", help="print one message, then exit")
    count.add_argument("-n", "--count", type=int, metavar="N", help="print N messages, then exit")
    echo.add_argument("--timeout", type=float, metavar="S", help="give up after S seconds (see above)")
    echo.add_argument(
        "-l",
        "--truncate-length",
        type=int,
        default=DEFAULT_TRUNCATE_LENGTH,
        metavar="L",
        help=f"truncate strings and arrays longer than L (default {DEFAULT_TRUNCATE_LENGTH})",
    )
    echo.add_argument("-f", "--full-length", action="store_true", help="never truncate")
    echo.set_defaults(_verb=_echo)
    from hopper_ros.cli import topic_tools

    topic_tools.add_arguments(verbs)


def main(args: argparse.Namespace) -> int:
    from hopper_ros.nodes.shutdown_guard import ShutdownGuard
    from hopper_ros.nodes.signals import StopSignals

    stop = StopSignals().install()  # Ctrl-C / SIGTERM end the command cleanly (exit 0)
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    node, status = None, 1
    try:
        rclpy.init(args=["hopper"], signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node(f"_hopper_topic_{os.getpid()}", start_parameter_services=False)
        stop.attach(node)
        status = args._verb(args, node, stop)
        return status
    finally:
        stop.detach()
        with ShutdownGuard(f"hopper topic {args.verb}", "its work is done", status or 0):
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        stop.uninstall()


def _sleep_or_stop(seconds: float, stop) -> bool:
    """Sleep; False when a stop signal arrived."""
    time.sleep(seconds)
    return stop.received is None


def _list(args: argparse.Namespace, node, stop) -> int:
    from rclpy.topic_or_service_is_hidden import topic_or_service_is_hidden

    end = time.monotonic() + max(args.spin_time, 0.0)
    while time.monotonic() < end:
        if not _sleep_or_stop(min(_POLL_PERIOD, max(end - time.monotonic(), 0.0)), stop):
            return 0
    for name, types in sorted(node.get_topic_names_and_types()):
        if topic_or_service_is_hidden(name) and not args.include_hidden_topics:
            continue
        print(f"{name} [{', '.join(types)}]" if args.show_types else name)
    return 0


ECHO_DEPTH = 1000   # messages the subscription holds until they are printed: an echo starved by a busy machine
#                    loses none (with 10, one of a bag play's 200 apexes was lost under make test's load)


def _subscription_qos(publishers):
    """QoS compatible with every publisher, keeping reliable/transient local when all offer it."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
    latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=ECHO_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def _echo(args: argparse.Namespace, node, stop) -> int:
    from rclpy.executors import SingleThreadedExecutor

    if args.count is not None and args.count < 1:
        print("hopper topic echo: error: -n must be at least 1", file=sys.stderr)
        return 2
    topic = node.resolve_topic_name(args.topic)
    start = time.monotonic()
    deadline = None if args.timeout is None else start + args.timeout

    def time_left() -> float | None:
        return None if deadline is None else deadline - time.monotonic()

    # Wait for a publisher: it gives the type (unless given) and the QoS to ask for.
    warned = False
    while True:
        publishers = node.get_publishers_info_by_topic(topic)
        if publishers:
            break
        left = time_left()
        if left is not None and left <= 0:
            print(f"hopper topic echo: error: no publisher on {topic} within {args.timeout:g} s", file=sys.stderr)
            return 1
        if not warned and time.monotonic() - start > 1.0:
            print(f"waiting for a publisher on {topic} ...", file=sys.stderr, flush=True)
            warned = True
        if not _sleep_or_stop(_POLL_PERIOD if left is None else min(_POLL_PERIOD, left), stop):
            return 0

    type_name = args.type
    if type_name is None:
        types = sorted({p.topic_type for p in publishers})
        if len(types) > 1:
            print(
                f"hopper topic echo: error: {topic} is published with several types ({', '.join(types)}); give TYPE",
                file=sys.stderr,
            )
            return 2
        type_name = types[0]
    try:
        msg_type = message_class(type_name)
    except (LookupError, ValueError) as exc:
        print(f"hopper topic echo: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)

    truncate = None if args.full_length else args.truncate_length
    received = 0

    def on_message(msg) -> None:
        nonlocal received
        if args.count is not None and received >= args.count:
            return
        received += 1
        sys.stdout.write(message_to_yaml(msg, truncate) + "---\n")
        sys.stdout.flush()

    node.create_subscription(msg_type, topic, on_message, _subscription_qos(publishers))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while args.count is None or received < args.count:
            left = time_left()
            if left is not None and left <= 0:
                if args.count is None:
                    return 0
                print(
                    f"hopper topic echo: error: {received} of {args.count} message(s) on {topic} "
                    f"within {args.timeout:g} s",
                    file=sys.stderr,
                )
                return 1
            executor.spin_once(timeout_sec=1.0 if left is None else min(left, 1.0))
            if stop.received is not None:
                return 0
    finally:
        executor.shutdown(timeout_sec=1.0)
    return 0
