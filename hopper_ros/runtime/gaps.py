"""Gaps of a periodic stream (the motor command stream), as a fixed histogram (no ROS)."""

from __future__ import annotations

import math


class GapHistogram:
    """Time between consecutive messages of a stream (the motor driver: valid commands as received;
    the controller: commands as published): a histogram of `BIN` wide bins up to `LIMIT` (longer
    ones in the last) and the longest, for the stream's p99 and max in the diagnostics."""

    BIN, LIMIT = 0.0005, 0.2   # [s]

    def __init__(self) -> None:
        self.counts = [0] * (int(round(self.LIMIT / self.BIN)) + 1)
        self.total = 0
        self.max = 0.0
        self.recent_max = 0.0      # the longest since `take_recent()`

    def add(self, gap: float) -> None:
        self.counts[min(int(gap / self.BIN), len(self.counts) - 1)] += 1
        self.total += 1
        self.max = max(self.max, gap)
        self.recent_max = max(self.recent_max, gap)

    def take_recent(self) -> float:
        """The longest gap since the last call (a diagnostics period's) [s]."""
        recent, self.recent_max = self.recent_max, 0.0
        return recent

    def quantile(self, fraction: float) -> float:
        """The upper edge of the bin holding the `fraction` quantile [s] (NaN without gaps)."""
        if not self.total:
            return math.nan
        rank, seen = fraction * self.total, 0
        for index, count in enumerate(self.counts):
            seen += count
            if seen >= rank:
                return min((index + 1) * self.BIN, self.max)
        return self.max
