"""Message stamps (builtin_interfaces/Time) <-> seconds [s] on the host clock: the one conversion
of the nodes (the libraries below them speak seconds)."""

from __future__ import annotations

import math

from builtin_interfaces.msg import Time as TimeMsg


def to_seconds(stamp: TimeMsg) -> float:
    """A stamp in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def to_stamp(seconds: float, stamp: TimeMsg | None = None) -> TimeMsg:
    """Seconds as a stamp (filled in place when `stamp` is given), to the nearest nanosecond of the
    float (whole seconds split off first: seconds * 1e9 would lose the last digits)."""
    whole = math.floor(seconds)
    return stamp_of_ns(int(whole) * 1_000_000_000 + int(round((seconds - whole) * 1e9)), stamp)


def stamp_of_ns(nanoseconds: int, stamp: TimeMsg | None = None) -> TimeMsg:
    """Integer nanoseconds as a stamp (filled in place when `stamp` is given)."""
    stamp = stamp if stamp is not None else TimeMsg()
    stamp.sec, stamp.nanosec = divmod(int(nanoseconds), 1_000_000_000)
    return stamp


def now_seconds(node) -> float:
    """The node's clock now [s]."""
    return node.get_clock().now().nanoseconds * 1e-9
