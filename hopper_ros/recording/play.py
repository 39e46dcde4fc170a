"""When each message of a bag is due again (`hopper bag play`), without ROS.

`Schedule` maps the bag's log times to the wall clock: message k is due at
start + (log_time_k - first log time) / rate, loop after loop (each loop starts one median message
period after the previous loop's last message). The player sleeps until a message is due and
publishes it; a message already late is published at once, and `late` counts those more than
`LATE_AFTER` behind.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

LATE_AFTER = 0.005     # [s] a message published this long after it was due counts as late


@dataclass
class Schedule:
    first_ns: int                      # the bag's first log time
    last_ns: int                       # its last
    rate: float = 1.0                  # 2.0 plays twice as fast
    start: float = field(default_factory=time.monotonic)   # [s] monotonic clock of the first message
    loop_gap_ns: int = 0               # between one loop's last message and the next loop's first

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError(f"--rate must be above 0, got {self.rate:g}")

    @property
    def loop_ns(self) -> int:
        """Bag time of one loop [ns]."""
        return self.last_ns - self.first_ns + self.loop_gap_ns

    def due(self, log_time_ns: int, loop: int = 0) -> float:
        """[s] monotonic time at which a message of this log time is due in loop `loop` (0 first)."""
        return self.start + ((log_time_ns - self.first_ns) + loop * self.loop_ns) * 1e-9 / self.rate


@dataclass
class PlayStats:
    published: int = 0
    late: int = 0
    max_late: float = 0.0              # [s]
    loops: int = 0

    def record(self, lateness: float) -> None:
        self.published += 1
        if lateness > LATE_AFTER:
            self.late += 1
        self.max_late = max(self.max_late, lateness)


def wait_until(deadline: float, stop=None, slice_s: float = 0.05) -> bool:
    """Sleep until the monotonic `deadline`; False when `stop.received` is set meanwhile."""
    while True:
        left = deadline - time.monotonic()
        if stop is not None and stop.received is not None:
            return False
        if left <= 0:
            return True
        time.sleep(min(left, slice_s))
