"""`hopper topic hz` and `hopper topic pub` (like `ros2 topic hz|pub`); registered by cli/topic.py.

  hopper topic hz TOPIC [TYPE] [-w WINDOW] [--duration S] [--timeout S]
  hopper topic pub TOPIC TYPE [VALUES] [-r RATE | -1 | -t TIMES] [--wait-matching-subscriptions N] [--timeout S]

`hz` prints the rate of arrival once a second over the last WINDOW messages (average, min, max and
std dev of the periods), as `ros2 topic hz` does; messages are counted, not decoded. `pub` publishes
VALUES (YAML, e.g. "{apex_height: 0.42, forward_speed: 2.0}"; fields not given keep their defaults)
at RATE Hz until Ctrl-C, or once (-1) / TIMES times after a subscriber has matched; e.g. to throw the
simulated robot: `hopper topic pub -1 /sim/throw hopper_ros/msg/ApexState "{apex_height: 0.4, forward_speed: 2.0}"`.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from hopper_ros.cli.exit_codes import BAD_INPUT

_POLL = 0.05          # [s]
DEFAULT_WINDOW = 10000
DEFAULT_RATE = 1.0    # [Hz] ros2 topic pub's
DEFAULT_TIMEOUT = 30.0  # [s] pub's wait for a matching subscription (with -1 / -t)
_LINGER = 0.5         # [s] pub -1 / -t stays this long after the last message (reliable delivery)


def add_arguments(verbs) -> None:
    hz = verbs.add_parser("hz", help="print the rate at which a topic's messages arrive",
                          formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    hz.add_argument("topic", help="topic name")
    hz.add_argument("type", nargs="?", help="message type (default: taken from the graph)")
    hz.add_argument("-w", "--window", type=int, default=DEFAULT_WINDOW, help="periods the statistics run over")
    hz.add_argument("--duration", type=float, metavar="S", help="stop after S seconds (default: at Ctrl-C)")
    hz.add_argument("--timeout", type=float, metavar="S", help="fail (exit 1) if no message arrived within S seconds")
    hz.set_defaults(_verb=_hz)

    pub = verbs.add_parser("pub", help="publish a message (YAML values) at a rate, or once",
                           formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    pub.add_argument("topic", help="topic name, e.g. /sim/throw")
    pub.add_argument("type", help="message type, e.g. hopper_ros/msg/ApexState")
    pub.add_argument("values", nargs="?", default="{}", help="field values as YAML, e.g. \"{apex_height: 0.4}\"")
    pub.add_argument("-r", "--rate", type=float, default=DEFAULT_RATE, help="publishing rate [Hz]")
    how = pub.add_mutually_exclusive_group()
    how.add_argument("-1", "--once", action="store_const", const=1, dest="times", help="publish one message, then exit")
    how.add_argument("-t", "--times", type=int, help="publish this many messages at --rate, then exit")
    pub.add_argument("--wait-matching-subscriptions", type=int, metavar="N",
                     help="wait for N subscriptions first (default: 1 with -1/-t, else 0)")
    pub.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT, metavar="S",
                     help="give up (exit 1) if the subscriptions have not matched within S seconds")
    pub.add_argument("--transient-local", action="store_true", help="latched: late subscribers get the last message")
    pub.set_defaults(_verb=_pub)


def _wait_for_publisher(node, topic: str, timeout, stop, tool: str):
    from hopper_ros.cli.topic import _sleep_or_stop

    start = time.monotonic()
    while True:
        publishers = node.get_publishers_info_by_topic(topic)
        if publishers:
            return publishers
        if timeout is not None and time.monotonic() - start > timeout:
            print(f"hopper topic {tool}: error: no publisher on {topic} within {timeout:g} s", file=sys.stderr)
            return None
        if not _sleep_or_stop(_POLL, stop):
            return []


def hz_line(periods) -> str:
    """ros2 topic hz's report of the periods [s] in the window."""
    import numpy as np

    p = np.asarray(periods, dtype=float)
    mean = float(p.mean())
    return (f"average rate: {1.0 / mean:.3f}\n\tmin: {p.min():.6f}s max: {p.max():.6f}s "
            f"std dev: {p.std():.6f}s window: {len(p) + 1}")


def _hz(args, node, stop) -> int:
    from collections import deque

    from rclpy.executors import SingleThreadedExecutor

    from hopper_ros.cli.topic import _subscription_qos
    from hopper_ros.runtime.messages import message_class

    topic = node.resolve_topic_name(args.topic)
    started = time.monotonic()
    publishers = _wait_for_publisher(node, topic, args.timeout, stop, "hz")
    if publishers is None:
        return 1
    if not publishers:
        return 0
    types = sorted({p.topic_type for p in publishers})
    type_name = args.type or types[0]
    try:
        cls = message_class(type_name)
    except (LookupError, ValueError) as exc:
        print(f"hopper topic hz: error: {exc}", file=sys.stderr)
        return BAD_INPUT
    arrivals: deque = deque(maxlen=max(args.window, 2) + 1)
    node.create_subscription(cls, topic, lambda _: arrivals.append(time.monotonic()), _subscription_qos(publishers),
                             raw=True)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    end = None if args.duration is None else time.monotonic() + args.duration
    next_report = time.monotonic() + 1.0
    printed = False
    try:
        while stop.received is None and (end is None or time.monotonic() < end):
            executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            if not arrivals and args.timeout is not None and now - started > args.timeout:
                print(f"hopper topic hz: error: no message on {topic} within {args.timeout:g} s", file=sys.stderr)
                return 1
            if now >= next_report:
                next_report = now + 1.0
                if len(arrivals) > 1:
                    stamps = list(arrivals)
                    print(hz_line([b - a for a, b in zip(stamps[:-1], stamps[1:])]), flush=True)
                    printed = True
                else:
                    print("no new messages", flush=True)
    finally:
        executor.shutdown(timeout_sec=1.0)
    if not printed and len(arrivals) > 1:
        stamps = list(arrivals)
        print(hz_line([b - a for a, b in zip(stamps[:-1], stamps[1:])]), flush=True)
    return 0


def set_fields(msg, values, where: str = "") -> None:
    """Set a message's fields from a mapping (nested messages from nested mappings); ValueError naming the field."""
    from hopper_ros.runtime.messages import is_message

    if not isinstance(values, dict):
        raise ValueError(f"{where or 'VALUES'}: expected a mapping of field names, got {values!r}")
    types = msg.get_fields_and_field_types()
    for name, value in values.items():
        here = f"{where}.{name}" if where else name
        if name not in types:
            raise ValueError(f"{here}: {type(msg).__name__} has no such field (fields: {', '.join(types)})")
        current = getattr(msg, name)
        kind = types[name]
        if is_message(current):
            set_fields(current, value, here)
            continue
        try:
            if kind in ("float", "double"):
                value = float(value)
            elif kind in ("boolean",):
                if not isinstance(value, bool):
                    raise TypeError
            elif kind.startswith(("int", "uint", "octet", "byte")) and "[" not in kind and "sequence" not in kind:
                if isinstance(value, bool) or float(value) != int(value):
                    raise TypeError
                value = int(value)
            elif kind.startswith("sequence<double") or kind.startswith("sequence<float") or kind.startswith(("double[", "float[")):
                value = [float(v) for v in value]
            setattr(msg, name, value)
        except (TypeError, ValueError, AssertionError, AttributeError):
            raise ValueError(f"{here}: {value!r} does not fit the field's type {kind}") from None


def _pub(args, node, stop) -> int:
    import yaml
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from hopper_ros.cli.topic import _sleep_or_stop
    from hopper_ros.runtime.messages import message_class, message_to_yaml

    try:
        cls = message_class(args.type)
        values = yaml.safe_load(args.values)
        msg = cls()
        set_fields(msg, values if values is not None else {})
    except yaml.YAMLError as exc:
        print(f"hopper topic pub: error: VALUES is not YAML: {' '.join(str(exc).split())}", file=sys.stderr)
        return BAD_INPUT
    except (LookupError, ValueError) as exc:
        print(f"hopper topic pub: error: {exc}", file=sys.stderr)
        return BAD_INPUT
    if not args.rate > 0 or (args.times is not None and args.times < 1):
        print("hopper topic pub: error: --rate must be above 0 and --times at least 1", file=sys.stderr)
        return 2
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL if args.transient_local else DurabilityPolicy.VOLATILE)
    topic = node.resolve_topic_name(args.topic)
    publisher = node.create_publisher(cls, topic, qos)
    wanted = args.wait_matching_subscriptions
    if wanted is None:
        wanted = 1 if args.times is not None else 0
    deadline = time.monotonic() + args.timeout
    while publisher.get_subscription_count() < wanted:
        if time.monotonic() > deadline:
            print(f"hopper topic pub: error: {publisher.get_subscription_count()} of {wanted} subscription(s) on "
                  f"{topic} within {args.timeout:g} s; nothing published", file=sys.stderr)
            return 1
        if not _sleep_or_stop(_POLL, stop):
            return 0
    print("publisher: beginning loop", flush=True)
    period = 1.0 / args.rate
    count = 0
    next_time = time.monotonic()
    while stop.received is None:
        publisher.publish(msg)
        count += 1
        print(f"publishing #{count}: {' '.join(message_to_yaml(msg).split())}", flush=True)
        if args.times is not None and count >= args.times:
            _sleep_or_stop(_LINGER, stop)
            break
        next_time += period
        if not _sleep_or_stop(max(0.0, next_time - time.monotonic()), stop):
            break
    return 0 if math.isfinite(period) else 1
