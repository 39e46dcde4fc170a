"""`hopper bag play BAG [--rate R] [--loop] [--topics T ...] [--delay S]`: republish a bag's topics on
their recorded schedule (like `ros2 bag play`).

Every message is published as it was recorded (its serialized bytes, nothing decoded) on its topic,
at its log time relative to the first message divided by --rate; --loop starts again at the end until
Ctrl-C. Publishers are created first and --delay seconds pass before the first message, so that
subscribers started with the player are matched (DDS discovery takes up to a few seconds here). A
topic whose message type is not installed here is skipped with one line. QoS: reliable, and transient
local where the recording offered it (a latched topic stays latched).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

DEFAULT_DELAY = 2.0          # [s] between creating the publishers and the first message
QUEUE_DEPTH = 1000
ACK_TIMEOUT = 5.0            # [s] at the end, wait at most this long for the subscribers' acknowledgements
MATCH_TIMEOUT = 60.0         # [s] --wait-matching-subscriptions gives up after this


def add_arguments(verbs) -> None:
    play = verbs.add_parser("play", help="republish a bag's topics on their recorded schedule (--rate, --loop)",
                            description=__doc__.split("\n\n", 1)[1],
                            formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    play.add_argument("bag", help="bag folder or .mcap file")
    play.add_argument("-r", "--rate", type=float, default=1.0, help="playback speed factor (2 = twice as fast)")
    play.add_argument("-l", "--loop", action="store_true", help="start again at the end, until Ctrl-C")
    play.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics (default: all)")
    play.add_argument("-d", "--delay", type=float, default=DEFAULT_DELAY, metavar="S",
                      help="seconds between creating the publishers and the first message (discovery)")
    play.add_argument("--wait-matching-subscriptions", type=int, default=0, metavar="N",
                      help="before the first message, wait until every played topic has N subscriptions "
                           f"(at most {MATCH_TIMEOUT:g} s)")
    play.set_defaults(_verb=_play)


def _qos(info):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    latched = any(str(p.get("durability", "")).lower() in ("1", "transient_local") for p in (info.qos or [])
                  if isinstance(p, dict))
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=QUEUE_DEPTH, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def _play(args) -> int:
    from hopper_ros.cli.errors import run_tool

    return run_tool("bag play", [args.bag], lambda: _play_main(args))


def _play_main(args) -> int:
    from hopper_ros.runtime.messages import message_class
    from hopper_ros.nodes.shutdown_guard import ShutdownGuard
    from hopper_ros.nodes.signals import StopSignals
    from hopper_ros.recording.bag import BagReader, bag_info
    from hopper_ros.recording.play import PlayStats, Schedule, wait_until

    if not args.rate > 0:
        print(f"hopper bag play: error: --rate must be above 0, got {args.rate:g}", file=sys.stderr)
        return 2
    info = bag_info(args.bag)
    topics = dict(info.topics)
    if args.topics:
        wanted = {t if t.startswith("/") else "/" + t for t in args.topics}
        missing = sorted(wanted - set(topics))
        if missing:
            raise ValueError(f"{args.bag}: no topic(s) {', '.join(missing)} in the bag (topics: {', '.join(sorted(topics))})")
        topics = {name: t for name, t in topics.items() if name in wanted}
    if not info.message_count:
        raise ValueError(f"{args.bag}: the bag holds no messages")
    stop = StopSignals().install()
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    node = None
    stats = PlayStats()
    try:
        rclpy.init(args=["hopper"], signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node(f"_hopper_bag_play_{os.getpid()}", start_parameter_services=False)
        publishers = {}
        for name, topic in sorted(topics.items()):
            try:
                cls = message_class(topic.type)
            except (LookupError, ValueError):
                print(f"hopper bag play: skipping {name}: its type {topic.type} is not installed here", file=sys.stderr)
                continue
            publishers[name] = node.create_publisher(cls, name, _qos(topic))
        if not publishers:
            raise ValueError(f"{args.bag}: none of the topics' message types is installed here")
        reader = BagReader(args.bag)
        print(f"playing {args.bag}: {', '.join(publishers)} ({sum(topics[t].message_count for t in publishers)} "
              f"messages, {info.duration:.3f} s at rate {args.rate:g}{', looping' if args.loop else ''})",
              file=sys.stderr, flush=True)
        if not wait_until(time.monotonic() + max(args.delay, 0.0), stop):
            return 0
        give_up = time.monotonic() + MATCH_TIMEOUT
        while any(p.get_subscription_count() < args.wait_matching_subscriptions for p in publishers.values()):
            if time.monotonic() > give_up:
                short = [t for t, p in publishers.items() if p.get_subscription_count() < args.wait_matching_subscriptions]
                print(f"hopper bag play: error: fewer than {args.wait_matching_subscriptions} subscription(s) on "
                      f"{', '.join(short)} within {MATCH_TIMEOUT:g} s; nothing played", file=sys.stderr)
                return 1
            if not wait_until(time.monotonic() + 0.05, stop):
                return 0
        schedule = Schedule(info.start_ns, info.end_ns, args.rate)
        counts = [topics[t].message_count for t in publishers]
        period_ns = int((info.end_ns - info.start_ns) / max(max(counts) - 1, 1))
        schedule.loop_gap_ns = period_ns
        loop = 0
        while True:
            for raw in reader.raw_messages(list(publishers)):
                due = schedule.due(raw.log_time, loop)
                if not wait_until(due, stop):
                    return 0
                publishers[raw.topic].publish(raw.data)
                stats.record(time.monotonic() - due)
            stats.loops += 1
            if not args.loop or stop.received is not None:
                break
            loop += 1
        from rclpy.duration import Duration

        for publisher in publishers.values():        # reliable delivery of the last messages before we leave
            publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT))
        return 0
    finally:
        late = f", {stats.late} more than 5 ms late (max {stats.max_late * 1e3:.1f} ms)" if stats.late else ""
        print(f"played {stats.published} messages in {stats.loops} loop(s){late}", file=sys.stderr, flush=True)
        with ShutdownGuard("hopper bag play", "its messages are sent", 1 if sys.exc_info()[0] else 0):
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        stop.uninstall()
