"""In-process hand-over between nodes composed in one process (rclpy has no intra-process path).

`composable(NodeClass, bus, intra_process)` makes a subclass whose `create_publisher` /
`create_subscription` also register with the container's `IntraProcessBus`; the node's own code
does not know it is composed. What the bus keeps of rclcpp's intra-process semantics:
- a publish goes to DDS where a subscription other than this container's in-process ones is matched (another
  process: a recorder, `hopper topic echo`), or its durability is transient-local (late joiners get its
  history), as rclcpp's intra-process manager does (`Publisher::publish`: inter-process only with
  inter-process subscriptions). Handing every 1 kHz state to DDS with nobody listening cost the demo's
  real-time container a tenth of a core (issue 29);
- a subscription of a node with intra-process on (extra_arg use_intra_process_comms) gets this
  container's messages in-process: a copy (publishers reuse their message objects) is queued and
  the callback runs on the subscriber's executor, never in the publishing thread; same full topic
  name (rcl's `topic_name`: remaps, namespaces), same type, QoS that DDS would match (reliable
  hears no best-effort), KEEP_LAST depth as a bounded queue (oldest dropped), publication order;
- no double delivery: such a subscription ignores local publications on DDS (rmw's option
  `ignore_local_publications`, set on its rmw handle as rclpy does not expose it; a per-message
  check of the publisher's gid needs message info, which rclpy's events executor cannot give), so
  it hears other processes by DDS and its own context (one DDS participant) only in-process: every
  publisher of that context must be a composed one, as the container makes them. /rosout and
  /parameter_events (rcl's own), transient-local subscriptions, callbacks taking message info and
  subscriptions whose rmw option cannot be set (logged) stay on DDS.
"""

from __future__ import annotations

import copy
import ctypes
import threading
from collections import deque

from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
from rclpy.serialization import deserialize_message

DDS_ONLY_TOPICS = ("/rosout", "/parameter_events")   # rcl publishes these itself, unseen by the bus
_IMMUTABLE = {float, int, bool, str, bytes, type(None)}


def copy_message(msg):
    """A deep copy of a ROS message, ~4x faster than copy.deepcopy (slots, numpy arrays, lists)."""
    cls = type(msg)
    new = cls.__new__(cls)
    for slot in cls.__slots__:
        value = getattr(msg, slot)
        if type(value) not in _IMMUTABLE:
            if hasattr(value, "get_fields_and_field_types"):
                value = copy_message(value)
            elif hasattr(value, "__copy__"):         # numpy arrays, array.array
                value = copy.copy(value)
            elif isinstance(value, list):
                value = [copy_message(v) if hasattr(v, "get_fields_and_field_types") else v for v in value]
        setattr(new, slot, value)
    return new


class _RmwSubscriptionOptions(ctypes.Structure):   # rmw/types.h: the head of rmw_subscription_options_t,
    _fields_ = [("rmw_specific_subscription_payload", ctypes.c_void_p), ("ignore_local_publications", ctypes.c_bool)]


class _RmwSubscription(ctypes.Structure):          # and of rmw_subscription_t
    _fields_ = [("implementation_identifier", ctypes.c_char_p), ("data", ctypes.c_void_p),
                ("topic_name", ctypes.c_char_p), ("options", _RmwSubscriptionOptions)]


def ignore_local_publications(subscription) -> str:
    """Set the rmw option on a live subscription (rmw_fastrtps reads it at each take); '' or why not."""
    try:
        get_rmw_handle = ctypes.CDLL("librcl.so").rcl_subscription_get_rmw_handle
        get_rmw_handle.restype, get_rmw_handle.argtypes = ctypes.c_void_p, [ctypes.c_void_p]
        with subscription.handle:
            address = get_rmw_handle(subscription.handle.pointer)
            rmw = _RmwSubscription.from_address(address) if address else None
            if rmw is None or (rmw.topic_name or b"").decode() != subscription.topic_name:
                return "rmw subscription layout not recognised"
            if not (rmw.implementation_identifier or b"").startswith(b"rmw_fastrtps"):
                return f"not verified with {rmw.implementation_identifier!r}"
            rmw.options.ignore_local_publications = True
    except (OSError, AttributeError) as exc:
        return f"rcl not reachable ({exc})"
    return ""


class _InProcessSubscription:
    def __init__(self, node, subscription):
        self.node, self.subscription = node, subscription
        qos = subscription.qos_profile
        self.reliable = qos.reliability == ReliabilityPolicy.RELIABLE
        self.queue = deque(maxlen=qos.depth if qos.history != HistoryPolicy.KEEP_ALL else None)
        self.lock = threading.Lock()
        self.scheduled = self.closed = False

    def offer(self, msg=None) -> None:
        """Queue a copy of `msg` (None: nothing new); schedule a drain on the subscriber's executor."""
        with self.lock:
            if msg is not None:
                self.queue.append(copy_message(msg))
            executor = self.node.executor
            if self.scheduled or executor is None or not self.queue:   # not spinning yet: see `flush`
                return
            self.scheduled = True
        executor.create_task(self.drain)

    def drain(self) -> None:
        while True:
            with self.lock:
                if not self.queue or self.closed:
                    self.scheduled = False
                    return
                msg = self.queue.popleft()
            self.subscription.callback(msg)


class IntraProcessBus:
    """The container's table of in-process subscriptions by full topic name."""

    def __init__(self, logger):
        self._topics: dict[str, tuple[_InProcessSubscription, ...]] = {}
        self._lock = threading.Lock()
        self._logger = logger

    def add_subscription(self, node, subscription, intra_process: bool) -> None:
        topic = subscription.topic_name
        message_only = getattr(subscription, "_callback_type", None) == type(subscription).CallbackType.MessageOnly
        if (not intra_process or topic in DDS_ONLY_TOPICS or subscription.raw or not message_only
                or subscription.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL):
            return
        problem = ignore_local_publications(subscription)
        if problem:
            return self._logger.warning(f"{topic}: stays on DDS in-process too: {problem}")
        with self._lock:   # copy on write: publishers read the table without the lock
            self._topics[topic] = self._topics.get(topic, ()) + (_InProcessSubscription(node, subscription),)

    def remove(self, subscription) -> None:
        with self._lock:
            for topic, entries in list(self._topics.items()):
                for entry in entries:
                    entry.closed = entry.closed or entry.subscription is subscription
                self._topics[topic] = tuple(e for e in entries if not e.closed)

    def publisher(self, publisher):
        """Wrap `publisher.publish`: every in-process subscription of its topic, then DDS as before."""
        topic, msg_type, dds_publish = publisher.topic_name, publisher.msg_type, publisher.publish
        best_effort = publisher.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
        keeps_history = publisher.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        matched = publisher.get_subscription_count

        def publish(msg) -> None:
            entries = self._topics.get(topic, ())
            for entry in entries:   # first, as rclcpp: the subscriber may run meanwhile
                if entry.subscription.msg_type is msg_type and not (entry.reliable and best_effort):
                    entry.offer(deserialize_message(msg, msg_type) if isinstance(msg, bytes) else msg)
            # the matched count includes this container's own DDS readers (in-process entries exist only on
            # rmw_fastrtps, `ignore_local_publications`, which filters at take: its readers stay matched); more than
            # those is a subscription outside (a reader that stayed on DDS counts as outside)
            if keeps_history or matched() > len(entries):
                dds_publish(msg)

        publisher.publish = publish
        return publisher

    def flush(self) -> None:
        """Schedule what was queued before the nodes were added to their executor."""
        for entries in list(self._topics.values()):
            for entry in entries:
                entry.offer()


def composable(node_class, bus: IntraProcessBus, intra_process: bool):
    """`node_class` as a node of a container: its endpoints registered with `bus`."""

    class Composed(node_class):
        def create_publisher(self, *args, **kwargs):
            return bus.publisher(super().create_publisher(*args, **kwargs))

        def create_subscription(self, *args, **kwargs):
            subscription = super().create_subscription(*args, **kwargs)
            bus.add_subscription(self, subscription, intra_process)
            return subscription

        def destroy_subscription(self, subscription):
            bus.remove(subscription)
            return super().destroy_subscription(subscription)

    Composed.__name__ = Composed.__qualname__ = node_class.__name__
    return Composed
