"""Helpers shared by the bench modules (not a bench itself: bench/run.py runs bench_*.py only)."""
import math
import os
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
