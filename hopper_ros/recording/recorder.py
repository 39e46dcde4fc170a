"""The rclpy side of `hopper bag record`: raw (still serialized) subscriptions written into a
`BagWriter`, as `ros2 bag record` does.

Topics are discovered continuously: those named (or every visible one with `record_all`)
are subscribed as soon as a publisher appears, with the message type the graph reports and a
QoS every publisher can serve (reliable and transient local when all of them are). Messages
are stored with their reception time as log time. A topic whose message definition cannot be
found is reported once and skipped; it never stops the recording.
"""

from __future__ import annotations

import time
from typing import Callable

from hopper_ros.messages import message_class

from .bag import BagWriter
from .schemas import SchemaError, message_definition

SUBSCRIPTION_DEPTH = 1000   # deep enough for 1 kHz topics while a chunk is compressed


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


class Recorder:
    """Subscribes `node` to the wanted topics and writes what arrives into `bag`."""

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
        self.received = 0

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
            self.bag.add_topic(name, type_name, [qos_to_dict(p.qos_profile) for p in publishers])
            self.subscriptions[name] = self.node.create_subscription(
                cls, name, self._writer_for(name), subscription_qos(publishers), raw=True)
            self.log(f"recording {name} [{type_name}]")
            added.append(name)
        return added

    def _skip(self, name: str, reason: str) -> None:
        self.skipped.add(name)
        self.log(f"not recording {name}: {reason}")

    def _writer_for(self, name: str):
        write = self.bag.write

        def on_message(data: bytes) -> None:
            write(name, data, time.time_ns())
            self.received += 1

        return on_message

    @property
    def missing(self) -> list[str]:
        """Named topics without a publisher so far."""
        if self.wanted is None:
            return []
        return sorted(self.wanted - set(self.subscriptions) - self.skipped)
