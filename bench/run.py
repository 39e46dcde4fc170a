#!/usr/bin/env python3
"""Benchmark harness: runs run() of every bench/bench_*.py and records the figures.

Each bench module defines ``run(quick=False)`` (the ``quick`` argument is optional) returning
an iterable of dicts ``{"name": str, "value": number, "unit": str}``. The figures of this
run overwrite ``bench/out/results.jsonl`` (one JSON object per figure, with the module that
produced it) and are printed as a table. A module that raises is reported and makes the
harness exit 1 after the others ran.

usage: bench/run.py [--quick] [--only NAME ...]      (`make bench BENCH_ARGS=--quick`)
"""
import argparse
import importlib.util
import inspect
import json
import math
import os
import sys
import time
import traceback
from pathlib import Path

# Keep DDS on loopback for every bench that uses rclpy (unless the user chose otherwise).
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

BENCH_DIR = Path(__file__).resolve().parent
OUT_FILE = BENCH_DIR / "out" / "results.jsonl"


def discover(only=None):
    modules = sorted(BENCH_DIR.glob("bench_*.py"))
    if only:
        wanted = {name if name.startswith("bench_") else f"bench_{name}" for name in only}
        unknown = wanted - {path.stem for path in modules}
        if unknown:
            raise SystemExit(f"bench: no such bench module: {', '.join(sorted(unknown))}")
        modules = [path for path in modules if path.stem in wanted]
    return modules


def load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def call_run(module, quick):
    run = getattr(module, "run")
    if "quick" in inspect.signature(run).parameters:
        return run(quick=quick)
    return run()


def check_figure(figure, module_name):
    if not isinstance(figure, dict) or not {"name", "value", "unit"} <= figure.keys():
        raise ValueError(f"{module_name}: a figure must be a dict with name, value, unit: {figure!r}")
    value = figure["value"]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{module_name}: {figure['name']}: value must be a number: {value!r}")
    return {"name": str(figure["name"]), "value": value, "unit": str(figure["unit"]),
            "module": module_name}


def format_value(value):
    if isinstance(value, int):
        return str(value)
    if math.isnan(value) or math.isinf(value):
        return str(value)
    return f"{value:.6g}"


def print_table(figures):
    rows = [("name", "value", "unit", "module")]
    rows += [(f["name"], format_value(f["value"]), f["unit"], f["module"]) for f in figures]
    widths = [max(len(row[i]) for row in rows) for i in range(4)]
    for index, row in enumerate(rows):
        print(f"{row[0]:<{widths[0]}}  {row[1]:>{widths[1]}}  {row[2]:<{widths[2]}}  {row[3]}")
        if index == 0:
            print("  ".join("-" * width for width in widths))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs (smoke test)")
    parser.add_argument("--only", nargs="+", metavar="NAME",
                        help="run only these modules (bench_NAME.py or NAME)")
    args = parser.parse_args(argv)
    # a bench started with `&` from a script inherits SIGINT ignored; the processes it stops with SIGINT too
    from hopper_ros.runtime.environment import restore_default_stop_signals

    restore_default_stop_signals()

    figures, failed = [], []
    for path in discover(args.only):
        started = time.monotonic()
        print(f"bench: {path.stem} ...", flush=True)
        try:
            produced = [check_figure(f, path.stem) for f in call_run(load(path), args.quick)]
        except Exception:  # noqa: BLE001 - report and go on with the other modules
            traceback.print_exc()
            failed.append(path.stem)
            print(f"bench: {path.stem} FAILED", flush=True)
            continue
        figures += produced
        print(f"bench: {path.stem} done in {time.monotonic() - started:.1f} s", flush=True)

    OUT_FILE.parent.mkdir(parents=True, exist_ok=True)
    with open(OUT_FILE, "w", encoding="utf-8") as out:
        for figure in figures:
            out.write(json.dumps(figure) + "\n")
    print()
    print_table(figures)
    print(f"\n{len(figures)} figures written to {OUT_FILE.relative_to(BENCH_DIR.parent)}")
    if failed:
        print(f"bench: failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
