"""Node health as the standard `diagnostic_msgs/DiagnosticArray` on `/diagnostics`.

Every node reports itself periodically (and at once on a new problem) with one
`DiagnosticStatus` in one `DiagnosticArray`, built here and nowhere else:

- topic `/diagnostics`, absolute: nodes run under namespaces, and rqt_robot_monitor,
  diagnostic_aggregator and Foxglove's diagnostics panel listen on `/diagnostics`;
- `name`: the node's fully qualified name (e.g. `/hopper/encoder_bridge`);
- `level`: OK, WARN or ERROR, decided by the node from its counters (new lost packets,
  a fall, a drive fault, ...); `message`: the problem in words, "OK" when there is none;
- `hardware_id`: what the node talks to, when it talks to hardware ("" otherwise);
- `values`: key-value pairs, the counters first (integers, counts since the node started),
  then the measured values (SI units, the unit in the key: `sample_rate_hz`, `loss_ratio`);
  values are strings as the message wants them, floats written so that they read back exactly
  (`nan` for a value not known yet).

`status_of` and `status_values` read them back (the demo's monitor, the controller watching the
motor driver, the tests); `hopper topic echo /diagnostics` shows them as any ROS tool does.
"""

from __future__ import annotations

import math
import re
from typing import Any, Iterable, Mapping

DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_DEPTH = 10
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}
_INTEGER = re.compile(r"[-+]?\d+")


def format_value(value: Any) -> str:
    """A counter or measured value as a DiagnosticStatus value string."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if value is None:
        return "nan"
    if isinstance(value, float) or hasattr(value, "__float__"):
        number = float(value)
        if math.isnan(number):
            return "nan"
        return repr(number)
    return str(value)


def diagnostic_status(name: str, counters: Mapping[str, int], values: Mapping[str, Any], message: str = "",
                      level: int | None = None, hardware_id: str = ""):
    """One node's DiagnosticStatus; `level` defaults to WARN with a message and OK without."""
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

    if level is None:
        level = WARN if message else OK
    if level not in (OK, WARN, ERROR, STALE):
        raise ValueError(f"diagnostic level {level!r} is not OK, WARN, ERROR or STALE")
    status = DiagnosticStatus()
    status.level = bytes([level])
    status.name = name
    status.message = message or ("OK" if level == OK else LEVEL_NAMES[level])
    status.hardware_id = hardware_id
    status.values = ([KeyValue(key=key, value=str(int(count))) for key, count in counters.items()]
                     + [KeyValue(key=key, value=format_value(value)) for key, value in values.items()])
    return status


def diagnostic_array(stamp, statuses: Iterable) -> Any:
    """A DiagnosticArray stamped `stamp` (builtin_interfaces/Time, or seconds since the epoch)."""
    from diagnostic_msgs.msg import DiagnosticArray

    from hopper_ros.nodes.stamps import to_stamp

    array = DiagnosticArray()
    array.header.stamp = to_stamp(stamp) if isinstance(stamp, (int, float)) else stamp
    array.status = list(statuses)
    return array


class DiagnosticsReporter:
    """A node's `/diagnostics` publisher: `report(counters, values, message, level)`."""

    def __init__(self, node, hardware_id: str = "") -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        self.node = node
        self.hardware_id = hardware_id
        self.publisher = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_DEPTH)

    def report(self, counters: Mapping[str, int], values: Mapping[str, Any], message: str = "",
               level: int | None = None, stamp=None) -> Any:
        status = diagnostic_status(self.node.get_fully_qualified_name(), counters, values, message, level,
                                   self.hardware_id)
        array = diagnostic_array(stamp if stamp is not None else self.node.get_clock().now().to_msg(), [status])
        self.publisher.publish(array)
        return array


# ---------------------------------------------------------------------- reading


def level_of(status) -> int:
    """The level of a DiagnosticStatus as an int (the message field is a byte)."""
    level = status.level
    return level[0] if isinstance(level, (bytes, bytearray)) else int(level)


def parse_value(text: str) -> int | float | str:
    """A value string back as an int (counters), a float (measurements) or the text."""
    if _INTEGER.fullmatch(text):
        return int(text)
    try:
        return float(text)
    except ValueError:
        return text


def status_values(status) -> dict[str, int | float | str]:
    """The key-value pairs of a DiagnosticStatus, parsed."""
    return {pair.key: parse_value(pair.value) for pair in status.values}


def status_of(array, node_name: str):
    """The status named `node_name` (a fully qualified node name) in a DiagnosticArray, or None."""
    return next((status for status in array.status if status.name == node_name), None)


def split_node_name(name: str) -> tuple[str, str]:
    """'/ns/sub/node' -> ('/ns/sub', 'node'); '/node' -> ('/', 'node')."""
    namespace, _, base = name.rpartition("/")
    return namespace or "/", base
