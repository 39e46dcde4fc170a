"""`hopper bag record|info|recover`: rosbag2 bags (MCAP) of live topics (like `ros2 bag`).

  hopper bag record (-a | TOPIC ...) -o DIR [--duration S] [--chunk-size B] [--chunk-interval S]
  hopper bag info DIR
  hopper bag recover DIR

`record` runs until Ctrl-C (SIGINT) or SIGTERM, then finishes the MCAP and writes
metadata.yaml (exit 0). Killed harder, the bag keeps every closed chunk; `info` reads it and
says it is unfinished, `recover` makes it complete. Format: hopper_ros/recording/bag/.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

HELP = "record topics into a rosbag2 bag (MCAP), show a bag, recover an interrupted one (like `ros2 bag`)"

_POLL_PERIOD = 0.25   # [s] between looks at the graph for new topics
_FAST_POLL_PERIOD = 0.02   # [s] ... while named topics are still missing (the bag starts sooner)
_FAST_POLL_FOR = 10.0      # [s] ... during the first seconds only
_STOP_LATENCY = 0.05       # [s] the recorder's wait for messages: how soon Ctrl-C is seen


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from hopper_ros.recording.bag import DEFAULT_CHUNK_INTERVAL, DEFAULT_CHUNK_SIZE

    verbs = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    record = verbs.add_parser("record", help="record topics of the running graph into a new bag folder")
    record.add_argument("topics", nargs="*", metavar="TOPIC", help="topics to record")
    record.add_argument("-a", "--all", action="store_true", help="record every topic (hidden ones with --include-hidden-topics)")
    record.add_argument("--include-hidden-topics", action="store_true")
    record.add_argument("-o", "--output", required=True, metavar="DIR", help="new bag folder (must not exist or be empty)")
    record.add_argument("-d", "--duration", type=float, metavar="S", help="stop after S seconds")
    record.add_argument("--chunk-size", type=int, default=DEFAULT_CHUNK_SIZE, metavar="BYTES",
                        help=f"uncompressed chunk size (default {DEFAULT_CHUNK_SIZE})")
    record.add_argument("--chunk-interval", type=float, default=DEFAULT_CHUNK_INTERVAL, metavar="S",
                        help=f"close a chunk at least every S seconds: at most this much is lost if the "
                             f"recorder is killed (default {DEFAULT_CHUNK_INTERVAL:g})")
    record.add_argument("--compression", choices=("zstd", "none"), default="zstd", help="chunk compression")
    record.set_defaults(_verb=_record)
    info = verbs.add_parser("info", help="topics, counts, duration and state of a bag (also an unfinished one)")
    info.add_argument("bag", help="bag folder or .mcap file")
    info.add_argument("--json", action="store_true", help="print the summary as JSON (times in ns and ISO 8601, UTC)")
    info.set_defaults(_verb=_info)
    recover = verbs.add_parser("recover", help="complete a bag whose recorder was killed (keeps the original file)")
    recover.add_argument("bag", help="bag folder")
    recover.set_defaults(_verb=_recover)
    from hopper_ros.cli import bag_play

    bag_play.add_arguments(verbs)


def main(args: argparse.Namespace) -> int:
    return args._verb(args)


def _info(args) -> int:
    from hopper_ros.cli.errors import run_tool

    return run_tool("bag info", [args.bag], lambda: _info_main(args))


def _recover(args) -> int:
    from hopper_ros.cli.errors import run_tool

    return run_tool("bag recover", [args.bag], lambda: _recover_main(args))


def _info_main(args) -> int:
    from hopper_ros.recording.bag import BagError, bag_info
    from hopper_ros.recording.bag_report import info_json, info_text

    try:
        info = bag_info(args.bag)
        print(info_json(info) if args.json else info_text(info))
    except (BagError, OSError) as exc:
        print(f"hopper bag info: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)
    return 0


def _recover_main(args) -> int:
    from hopper_ros.recording.bag import BagError, recover_bag

    try:
        result = recover_bag(args.bag)
    except (BagError, OSError) as exc:
        print(f"hopper bag recover: error: {exc}", file=sys.stderr)
        return 3
    if result.already_complete:
        print(f"{result.path}: complete already ({result.messages} messages), nothing to do")
    else:
        kept = f"; the unfinished file is kept as {result.kept_original}" if result.kept_original else ""
        print(f"{result.path}: recovered {result.messages} messages ({result.dropped_bytes} bytes of an "
              f"unfinished chunk dropped: {result.problem}){kept}")
    return 0


def _record(args) -> int:
    from hopper_ros.nodes.shutdown_guard import ShutdownGuard
    from hopper_ros.nodes.signals import StopSignals
    from hopper_ros.recording.bag import BagError, BagWriter

    if bool(args.all) == bool(args.topics):
        print("hopper bag record: error: give either -a or one or more topics", file=sys.stderr)
        return 2
    try:
        bag = BagWriter(args.output, chunk_size=args.chunk_size, chunk_interval=args.chunk_interval,
                        compression=args.compression)
    except (BagError, OSError) as exc:
        print(f"hopper bag record: error: {exc}", file=sys.stderr)
        return 3
    stop = StopSignals().install()
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from hopper_ros.recording.recorder import Recorder

    def log(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    node = None
    recorder = None
    status = 0
    try:
        rclpy.init(args=["hopper"], signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node(f"_hopper_bag_record_{os.getpid()}", start_parameter_services=False)
        recorder = Recorder(node, bag, None if args.all else args.topics,
                            include_hidden=args.include_hidden_topics, log=log)
        started = time.monotonic()
        log(f"recording to {bag.path} ({'all topics' if args.all else ', '.join(sorted(recorder.wanted))}); "
            f"Ctrl-C stops")
        end = None if args.duration is None else time.monotonic() + args.duration
        next_look = 0.0
        while stop.received is None and (end is None or time.monotonic() < end):
            now = time.monotonic()
            if now >= next_look:
                recorder.discover()
                recorder.report_drops()
                fast = (recorder.missing or not recorder.subscriptions) and now - started < _FAST_POLL_FOR
                next_look = now + (_FAST_POLL_PERIOD if fast else _POLL_PERIOD)
            recorder.spin_once(max(0.0, min(next_look - time.monotonic(), _STOP_LATENCY)))
    except Exception as exc:  # noqa: BLE001 - close the bag whatever happened, then report
        log(f"hopper bag record: error: {exc}")
        status = 1
    finally:
        stop.detach()
        try:
            if recorder is not None:
                recorder.close()                   # everything received is in the bag
                dropped = recorder.dropped
                bag.custom_data["hopper_recorder_dropped"] = json.dumps(dropped, sort_keys=True)
                if recorder.first_ns is not None:
                    bag.custom_data["hopper_recorder_first_message_ns"] = str(recorder.first_ns)
                for line in recorder.summary():
                    log(line)
                if any(dropped.values()):
                    log(f"hopper bag record: DROPPED {sum(dropped.values())} message(s) that never reached the bag "
                        f"(per topic above)")
                if recorder.write_error is not None:
                    status = 1
            bag.close()
            log(f"bag {bag.path} closed: {bag.message_count} messages on {len(bag.topics)} topic(s)")
        except Exception as exc:  # noqa: BLE001
            log(f"hopper bag record: error closing {bag.path}: {exc} (run `hopper bag recover {bag.path}`)")
            status = 1
        with ShutdownGuard("hopper bag record", "the bag is closed", status):   # a hung DDS teardown
            if node is not None:                                                 # cannot keep it running
                node.destroy_node()
            rclpy.try_shutdown()
        stop.uninstall()
    return status

