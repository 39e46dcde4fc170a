"""The rclpy side of `hopper bag record`: raw (still serialized) subscriptions written into a
`BagWriter`, as `ros2 bag record` does.

Topics are discovered continuously: those named (or every visible one with `record_all`)
are subscribed as soon as a publisher appears, with the message type the graph reports and a
QoS every publisher can serve (reliable and transient local when all of them are). Messages
are stored with their reception time as log time. A topic whose message definition cannot be
found is reported once and skipped; it never stops the recording.

Nothing is lost silently (issue 17: 81 consecutive /force_plate messages were once missing inside
a bag while another subscriber had them):

- every message carries its publisher's DDS sequence number (rmw message info); a jump in the
  numbers of one publisher is a message the recorder never received. It is counted per topic
  (`dropped`), logged as it happens (at most once a second per topic) and summed up at the end;
- messages are taken in batches by `spin_once` (a wait set over every subscription, then
  everything waiting is taken), not by an rclpy executor, which spends a callback's worth of
  Python on each message: with five 1 kHz topics on a busy machine that executor fell seconds
  behind, and the subscription's history (KEEP_LAST) then silently replaced the oldest
  messages: the cause of the gap (docs/recording.md);
- a thread of its own writes the taken messages into the bag, so compressing a chunk or a slow
  disk never holds up the taking. The queue is bounded (`MAX_QUEUED_BYTES`); what would
  overflow it is dropped and counted too;
- the subscriptions keep `SUBSCRIPTION_DEPTH` messages per topic for a recorder that falls behind.
"""

from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

from hopper_ros.runtime.messages import message_class

from .bag import BagWriter
from .schemas import SchemaError, message_definition

SUBSCRIPTION_DEPTH = 1000      # [messages] per topic kept for a recorder that falls behind
MAX_QUEUED_BYTES = 256 << 20   # [bytes] received, not yet written; beyond it messages are dropped (counted)
DROP_REPORT_PERIOD = 1.0       # [s] at most one line per topic and period about dropped messages
_WRITER_PERIOD = 0.02          # [s] the writer thread writes what is queued this often (not at every message:
                               #   the executor's thread would then wait for the interpreter at every callback)


def qos_to_dict(profile) -> dict:
    """A publisher's QoS as rosbag2 stores it in offered_qos_profiles (metadata version 9)."""
    def duration(value):
        seconds, nanoseconds = divmod(int(value.nanoseconds), 1_000_000_000)
        return {"sec": seconds, "nsec": nanoseconds}

    return {"history": profile.history.name.lower(), "depth": int(profile.depth),
            "reliability": profile.reliability.name.lower(), "durability": profile.durability.name.lower(),
            "deadline": duration(profile.deadline), "lifespan": duration(profile.lifespan),
            "liveliness": profile.liveliness.name.lower(),
            "liveliness_lease_duration": duration(profile.liveliness_lease_duration),
            "avoid_ros_namespace_conventions": bool(profile.avoid_ros_namespace_conventions)}


def subscription_qos(publishers):
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
    latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=SUBSCRIPTION_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


@dataclass
class TopicStats:
    """What the recorder saw of one topic."""

    received: int = 0
    dropped: int = 0                 # gaps in a publisher's sequence numbers: never received
    queue_dropped: int = 0           # received, but the write queue was full
    first_ns: int | None = None      # reception time of the first message [ns since the epoch]
    last_seq: dict = field(default_factory=dict)    # publisher gid -> last sequence number
    reported_at: float = 0.0
    reported_dropped: int = 0


def _gid_key(info) -> bytes | None:
    gid = info.get("publisher_gid") if isinstance(info, dict) else None
    if isinstance(gid, dict):
        data = gid.get("data")
        return bytes(data) if data is not None else None
    return bytes(gid) if gid is not None else None


class Recorder:
    """Subscribes `node` to the wanted topics and writes what arrives into `bag` (from a thread of
    its own: call `close()` before closing the bag)."""

    def __init__(self, node, bag: BagWriter, topics: list[str] | None = None, *, include_hidden: bool = False,
                 log: Callable[[str], None] = print) -> None:
        self.node = node
        self.bag = bag
        self.record_all = topics is None
        self.wanted = None if topics is None else {node.resolve_topic_name(t) for t in topics}
        self.include_hidden = include_hidden
        self.log = log
        self.subscriptions: dict[str, object] = {}
        self.skipped: set[str] = set()
        self.stats: dict[str, TopicStats] = {}
        self.started_ns = time.time_ns()
        self.first_ns: int | None = None       # the bag's first message [ns since the epoch]
        self.write_error: str | None = None
        self._queue: collections.deque = collections.deque()
        self._queued_bytes = 0
        self._lock = threading.Lock()
        self._bag_lock = threading.Lock()      # the writer thread and add_topic share the bag
        self._wake = threading.Event()
        self._closing = False
        self._wait_set = None
        self._wait_size = 0
        self._writer = threading.Thread(target=self._write_loop, name="bag-writer", daemon=True)
        self._writer.start()

    # ------------------------------------------------------------------ subscribing
    def discover(self) -> list[str]:
        """Subscribe to wanted topics that have publishers now; returns the new ones."""
        from rclpy.topic_or_service_is_hidden import topic_or_service_is_hidden

        added = []
        for name, types in self.node.get_topic_names_and_types():
            if name in self.subscriptions or name in self.skipped:
                continue
            if self.wanted is not None and name not in self.wanted:
                continue
            if self.record_all and topic_or_service_is_hidden(name) and not self.include_hidden:
                continue
            publishers = self.node.get_publishers_info_by_topic(name)
            if not publishers:
                continue
            if len(set(types)) != 1:
                self._skip(name, f"published with several types {sorted(set(types))}")
                continue
            type_name = types[0]
            try:
                cls = message_class(type_name)
                message_definition(type_name)
            except (LookupError, SchemaError, ValueError) as exc:
                self._skip(name, str(exc))
                continue
            with self._bag_lock:
                self.bag.add_topic(name, type_name, [qos_to_dict(p.qos_profile) for p in publishers])
            self.stats[name] = TopicStats()
            # taken by spin_once(), not by an executor: no callback
            self.subscriptions[name] = self.node.create_subscription(
                cls, name, _never_called, subscription_qos(publishers), raw=True)
            self.log(f"subscribed to {name} [{type_name}]")
            added.append(name)
        return added

    def _skip(self, name: str, reason: str) -> None:
        self.skipped.add(name)
        self.log(f"not recording {name}: {reason}")

    def spin_once(self, timeout: float) -> int:
        """Wait up to `timeout` [s] for messages, then take every message waiting on every
        subscription (a batch per wake-up, no executor: rclpy's executors cost a callback's worth
        of Python per message, and the events executor cannot hand over message info). Returns
        how many were taken."""
        from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy

        subscriptions = list(self.subscriptions.items())
        if not subscriptions:
            time.sleep(max(0.0, timeout))
            return 0
        if self._wait_set is None or self._wait_size != len(subscriptions):
            self._wait_set = _rclpy.WaitSet(len(subscriptions), 0, 0, 0, 0, 0, self.node.context.handle)
            self._wait_size = len(subscriptions)
        wait_set = self._wait_set
        wait_set.clear_entities()
        for _, subscription in subscriptions:
            wait_set.add_subscription(subscription.handle)
        wait_set.wait(max(0, int(timeout * 1e9)))
        taken = 0
        for name, subscription in subscriptions:
            stats = self.stats[name]
            while True:
                with subscription.handle:
                    message = subscription.handle.take_message(subscription.msg_type, True)
                if message is None:
                    break
                self._received(name, stats, message[0], message[1])
                taken += 1
        return taken

    def _received(self, name: str, stats: TopicStats, data: bytes, info) -> None:
        now = time.time_ns()
        stats.received += 1
        gid = _gid_key(info)
        sequence = info.get("publication_sequence_number") if isinstance(info, dict) else None
        if gid is not None and sequence:
            last = stats.last_seq.get(gid)
            if last is not None and sequence > last + 1:
                stats.dropped += sequence - last - 1
            if last is None or sequence > last:
                stats.last_seq[gid] = sequence
        size = len(data)
        with self._lock:
            if self._queued_bytes + size > MAX_QUEUED_BYTES:
                stats.queue_dropped += 1
                return
            self._queued_bytes += size
            self._queue.append((name, data, now))
        if stats.first_ns is None:
            stats.first_ns = now
            self._first_message(name, now)

    def _first_message(self, name: str, now_ns: int) -> None:
        if self.first_ns is None:
            self.first_ns = now_ns
            self.log(f"recording from {_clock(now_ns)} ({(now_ns - self.started_ns) / 1e9:.2f} s after the start): "
                     f"first message, on {name}")
        else:
            self.log(f"recording {name} from {_clock(now_ns)} ({(now_ns - self.started_ns) / 1e9:.2f} s after the start)")

    # ------------------------------------------------------------------ writing
    def _write_loop(self) -> None:
        while True:
            self._wake.wait(_WRITER_PERIOD)
            self._wake.clear()
            while True:
                with self._lock:
                    if not self._queue:
                        break
                    name, data, stamp = self._queue.popleft()
                    self._queued_bytes -= len(data)
                if self.write_error is None:
                    try:
                        with self._bag_lock:
                            self.bag.write(name, data, stamp)
                    except Exception as exc:  # noqa: BLE001 - reported; the rest is still counted
                        self.write_error = f"{type(exc).__name__}: {exc}"
                        self.log(f"hopper bag record: error writing {self.bag.path}: {self.write_error}")
            if self._closing:
                return

    def report_drops(self) -> None:
        """Log topics that lost messages since the last report (at most once a period per topic)."""
        now = time.monotonic()
        for name, stats in self.stats.items():
            lost = stats.dropped + stats.queue_dropped
            if lost > stats.reported_dropped and now - stats.reported_at >= DROP_REPORT_PERIOD:
                self.log(f"DROPPED {lost - stats.reported_dropped} message(s) of {name}: never received by the "
                         f"recorder ({lost} in all, {stats.received} received)")
                stats.reported_dropped, stats.reported_at = lost, now

    def close(self) -> None:
        """Write everything queued (the bag stays open: the caller closes it)."""
        self._closing = True
        self._wake.set()
        self._writer.join()

    @property
    def received(self) -> int:
        return sum(s.received for s in self.stats.values())

    @property
    def dropped(self) -> dict[str, int]:
        """Messages per topic that never reached the bag (sequence gaps, a full queue)."""
        return {name: s.dropped + s.queue_dropped for name, s in self.stats.items()}

    def summary(self) -> list[str]:
        """One line per topic: received, dropped (and why)."""
        lines = []
        for name, s in sorted(self.stats.items()):
            first = f"from {_clock(s.first_ns)}" if s.first_ns is not None else "no message"
            lines.append(f"  {name}: {s.received} messages {first}, dropped {s.dropped + s.queue_dropped}"
                         f" (sequence gaps {s.dropped}, queue full {s.queue_dropped})")
        return lines

    @property
    def missing(self) -> list[str]:
        """Named topics without a publisher so far."""
        if self.wanted is None:
            return []
        return sorted(self.wanted - set(self.subscriptions) - self.skipped)


def _never_called(_message) -> None:   # pragma: no cover - the recorder takes messages itself
    raise AssertionError("recorder subscriptions are taken by Recorder.spin_once")


def _clock(ns: int) -> str:
    seconds, nanoseconds = divmod(ns, 1_000_000_000)
    return time.strftime("%H:%M:%S", time.localtime(seconds)) + f".{nanoseconds // 1_000_000:03d}"
