"""Helpers shared by the bench modules (not a bench itself: bench/run.py runs bench_*.py only)."""
import math
import os
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def percentile(values, fraction):
    """Nearest-rank percentile (NaN for no values)."""
    ordered = sorted(values)
    if not ordered:
        return float("nan")
    rank = min(max(1, math.ceil(fraction * len(ordered))), len(ordered))
    return ordered[rank - 1]


def child_env(unbuffered=False):
    """Environment for a bench's child processes: loopback DDS, this checkout importable."""
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    if unbuffered:
        env["PYTHONUNBUFFERED"] = "1"
    return env


class Paced:
    """`for index in Paced(count, period_s)`: each index at its slot on CLOCK_MONOTONIC (sleeping
    until it; a late slot comes at once), the first `start_delay_s` from now; afterwards
    `rate_hz` is the rate achieved."""

    def __init__(self, count, period_s, start_delay_s=0.0):
        self.count, self.period_ns, self.start_delay_ns = count, int(round(period_s * 1e9)), int(start_delay_s * 1e9)
        self.elapsed = 0.0

    def __iter__(self):
        start = time.monotonic_ns() + self.start_delay_ns
        for index in range(self.count):
            left = start + index * self.period_ns - time.monotonic_ns()
            if left > 0:
                time.sleep(left / 1e9)
            yield index
        self.elapsed = (time.monotonic_ns() - start) / 1e9

    @property
    def rate_hz(self):
        return (self.count - 1) / self.elapsed if self.elapsed else 0.0


def serve_emulated_drive(drive, stop):
    """Run an emulated EPOS2 (`Epos2Emulator`) every 0.5 ms until `stop` is set: a thread target."""
    import time

    while not stop.is_set():
        now = time.monotonic()
        drive.poll(now)
        drive.control(now, 0, 0.0, drive.demand)
        time.sleep(0.0005)
