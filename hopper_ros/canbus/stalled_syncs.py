"""The SYNCs a simulated drive never saw: its process stopped, and its world with it (no ROS).

The simulated robot (sim/runner.py) skips the time of a stall longer than it catches up; its drive
answers none of the SYNCs that came meanwhile, as a drive that stood still would not have seen them.
They are the next ones it takes, counted by the SYNC period seen (they may still be in transit); the
motor driver counts the SYNCs left unanswered as the time the robot stood still.
"""

from __future__ import annotations

import math
from collections import deque

SYNC_INTERVAL_GUESS = 0.001       # [s] the SYNC period assumed until SYNCs came (the demo's 1 kHz)
SYNC_INTERVAL_MAX = 0.01          # [s] SYNCs further apart than this are no period (a pause, the start)
SYNC_INTERVALS_KEPT = 63          # the SYNC period is their median


class StalledSyncs:
    def __init__(self) -> None:
        self._to_discard = 0
        self._intervals: deque[float] = deque(maxlen=SYNC_INTERVALS_KEPT)   # [s] between SYNCs (drive time)
        self._last = -math.inf

    def stood_still(self, duration: float) -> None:
        """The drive stood still for `duration` [s]: that time's SYNCs are not to be answered."""
        intervals = sorted(self._intervals)
        period = intervals[len(intervals) // 2] if intervals else SYNC_INTERVAL_GUESS   # a missed one is no period
        self._to_discard += max(0, round(duration / period))

    def take(self, now: float) -> bool:
        """A SYNC came at `now` (drive time): False if it is one of a stall's, never to be answered."""
        if self._to_discard > 0:
            self._to_discard -= 1
            return False
        if 0.0 < now - self._last < SYNC_INTERVAL_MAX:
            self._intervals.append(now - self._last)
        self._last = now
        return True
