#!/usr/bin/env python3
"""`make soak`: the whole demo graph on the simulated robot for an hour (issue 29). Not a test, not part
of `make bench` (bench/run.py runs bench_*.py only).

usage: bench/soak.py [--minutes M] [-o DIR]            (default 60 minutes, bench/out/soak)

launch/demo.launch.yaml under `hopper launch` on a ROS domain of its own, the robot thrown and
hopping the Fig 5.5 schedule (its last setpoint, 0.38 m at 2.5 m/s, from the 31st stride on; thrown
again should it fall), recorded by `hopper bag record` (zstd) on the loop's topics: body_state
(1 kHz), gait_event, apex, stride_command, motor_command (333 Hz), motor_status (100 Hz),
/diagnostics. Every minute the resident memory (VmRSS) of every process of the graph. At the end:
- soak_rss_growth_pct: the largest growth of a process's resident memory from one minute after the
  throw (start-up and first allocations done) to the end; per process soak_rss_<node>_start_mb,
  _end_mb (rss.csv has the minutes);
- soak_falls (the simulated robot's count), soak_strides (apexes heard);
- soak_late_samples_pct, soak_ramps_cancelled, soak_stances_without_ramp, soak_stances_ramp_late,
  soak_command_gap_max_ms, soak_watchdog_stops (hopper_ros/cli/demo.py loop_health, from the throw);
- soak_bag_mb, soak_bag_messages, soak_bag_dropped (the recorder's own count of sequence gaps and
  full queues), soak_gc_pause_warnings (garbage collections over 5 ms, logged by the nodes).
summary.json and rss.csv in the output folder with launch.log and the recorder's log; the bag itself
is deleted after it was measured (its metadata.yaml is kept).
"""
import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from hopper_ros.runtime.environment import apply_ros_environment, free_domain_id, restore_default_stop_signals  # noqa: E402
from _common import stop_recorder  # noqa: E402 (bench/ is on sys.path)

TOPICS = ("body_state", "gait_event", "apex", "stride_command", "motor_command", "motor_status", "/diagnostics")
WARM_UP = 60.0       # [s] after the throw: the memory taken as the start
SAMPLE = 60.0        # [s] between memory samples
DROPPED = re.compile(r"^\s+(\S+): (\d+) messages .*dropped (\d+)")


def rss_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("-o", "--output", default=str(REPO / "bench" / "out" / "soak"))
    args = parser.parse_args()
    # started with `&` from a script, SIGINT is ignored and the recorder inherits that: it never stopped
    restore_default_stop_signals()
    out = Path(args.output)
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    os.environ["ROS_DOMAIN_ID"] = str(free_domain_id(91))
    apply_ros_environment()
    from hopper_ros.cli.demo import loop_health
    from hopper_ros.harness.live_graph import LiveGraph

    recorder = subprocess.Popen([sys.executable, "-m", "hopper_ros.cli", "bag", "record", "-o", str(out / "bag"),
                                 "--compression", "zstd", *TOPICS], stdout=open(out / "recorder.log", "w"),
                                stderr=subprocess.STDOUT, start_new_session=True, env=dict(os.environ))
    samples, falls_seen, throws = [], 0, 0
    try:
        with LiveGraph("demo.launch.yaml", out) as graph:
            if not graph.wait_up():
                print("soak: the graph did not come up (see launch.log)", file=sys.stderr)
                return 1
            if not graph.hop(4, throw=True):
                print("soak: the robot did not hop after the throw", file=sys.stderr)
                return 1
            thrown = time.monotonic()
            at_throw = {name: dict(values) for name, values in graph.health.items()}
            end = thrown + 60.0 * args.minutes
            next_sample = thrown + WARM_UP
            print(f"soak: hopping; {args.minutes:g} minutes to go", flush=True)
            while time.monotonic() < end:
                graph.spin_until(lambda: time.monotonic() >= min(next_sample, end) or graph.seen["falls"] > falls_seen,
                                 max(0.0, min(next_sample, end) - time.monotonic()) + 0.1)
                if graph.seen["falls"] > falls_seen:                # should not happen: counted, thrown again
                    falls_seen = graph.seen["falls"]
                    throws += 1
                    print(f"soak: FALL {falls_seen} after {(time.monotonic() - thrown) / 60:.1f} min", flush=True)
                    graph.hop(4, throw=True)
                if time.monotonic() >= next_sample:
                    minute = (time.monotonic() - thrown) / 60.0
                    rss = {label: rss_mb(pid) for label, pid in graph.pids.items()}
                    samples.append({"minute": round(minute, 2), **rss})
                    print(f"soak: {minute:5.1f} min, {graph.seen['apexes']} strides, falls {graph.seen['falls']}, "
                          "rss MB " + ", ".join(f"{k} {v:.1f}" for k, v in rss.items()), flush=True)
                    next_sample += SAMPLE
            samples.append({"minute": round((time.monotonic() - thrown) / 60.0, 2),
                            **{label: rss_mb(pid) for label, pid in graph.pids.items()}})
            health = loop_health(graph.health, at_throw)
            strides, falls = graph.seen["apexes"], graph.seen["falls"]
            respawns = sum(1 for _, line in graph.lines if "respawning it" in line)
            gc_warnings = sum(1 for _, line in graph.lines if "garbage collection" in line)
    except KeyboardInterrupt:
        print(f"soak: interrupted; the recording so far is in {out / 'bag'}", file=sys.stderr)
        return 130
    finally:            # the recorder has a session of its own: an interrupt or an early return does not reach it
        stop_recorder(recorder, 60.0)   # SIGTERM: it closes the bag
    topics = [DROPPED.match(line) for line in (out / "recorder.log").read_text().splitlines()]
    messages = sum(int(m.group(2)) for m in topics if m)
    dropped = sum(int(m.group(3)) for m in topics if m)
    bag_bytes = sum(p.stat().st_size for p in (out / "bag").glob("*") if p.is_file())
    for path in (out / "bag").glob("*.mcap"):
        path.unlink()
    with open(out / "rss.csv", "w", encoding="utf-8") as handle:
        labels = [k for k in samples[0] if k != "minute"]
        handle.write("minute," + ",".join(f"{label}_mb" for label in labels) + "\n")
        for sample in samples:
            handle.write(f"{sample['minute']}," + ",".join(f"{sample.get(label, float('nan')):.2f}" for label in labels) + "\n")
    first, last = samples[0], samples[-1]
    growth = {label: 100.0 * (last[label] / first[label] - 1.0) for label in first if label != "minute"}
    summary = {
        "soak_minutes": last["minute"], "soak_rss_growth_pct": max(growth.values()),
        **{f"soak_rss_{label}_start_mb": first[label] for label in growth},
        **{f"soak_rss_{label}_end_mb": last[label] for label in growth},
        "soak_falls": falls, "soak_strides": strides, "soak_respawns": respawns,
        "soak_late_samples_pct": health["late_samples_pct"], "soak_ramps_cancelled": health["ramps_cancelled"],
        "soak_stances_without_ramp": health["stances_without_torque"], "soak_stances_ramp_late": health["stances_torque_late"],
        "soak_command_gap_p99_ms": health["command_gap_p99_ms"], "soak_command_gap_max_ms": health["command_gap_max_ms"],
        "soak_watchdog_stops": health["watchdog_stops"], "soak_bag_mb": bag_bytes / 2**20,
        "soak_bag_messages": messages, "soak_bag_dropped": dropped, "soak_gc_pause_warnings": gc_warnings,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    for name, value in summary.items():
        print(f"{name:40s} {value:.6g}" if isinstance(value, float) else f"{name:40s} {value}")
    ok = summary["soak_rss_growth_pct"] < 5.0 and falls == 0
    print(f"soak: {'OK' if ok else 'FAILED'}: memory growth {summary['soak_rss_growth_pct']:.2f} % (< 5 %), "
          f"{falls} falls", flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
