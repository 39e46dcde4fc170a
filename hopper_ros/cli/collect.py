"""`hopper collect`: section 4.1's single-stride experiments on the simulated robot, recorded.

  hopper collect (-n N | --strides N) -o DIR [--noise] [--effects a,b=VALUE] [--torque ramp|constant|none]
                 [--seed S] [--csv FILE [--csv-phase]]

Runs in lockstep in this process (SimRobot + the experiment, no ROS graph, as fast as it goes)
and writes a bag with the topics a live recording holds: body_measurement, force_plate,
sim/truth, stride_command, sim/events. Failed strides are discarded. `--csv` also writes
`t,y,z,theta,tau` (docs/recording.md). Code: hopper_ros/harness/collect.py.
"""

from __future__ import annotations

import argparse
import sys

HELP = "run single-stride experiments on the simulated robot (lockstep) and record them as a bag (and CSV)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    count = parser.add_mutually_exclusive_group(required=True)
    count.add_argument("-n", "--experiments", type=int, metavar="N", help="run N experiments (failures discarded)")
    count.add_argument("--strides", type=int, metavar="N", help="run experiments until N strides are kept")
    parser.add_argument("-o", "--output", required=True, metavar="DIR", help="new bag folder")
    parser.add_argument("--noise", action="store_true", help="switch on every sensor noise of config/sim.yaml")
    parser.add_argument("--effects", default="", metavar="A,B=VALUE",
                        help="effects of the library (hopper_ros/physics/effects.py) to switch on, with "
                             "config/sim.yaml's magnitude or NAME=VALUE (the parameter's unit), "
                             "e.g. leg_friction,actuation_delay=0.006")
    parser.add_argument("--no-effects", default="", metavar="A,B", help="effects to switch off")
    parser.add_argument("--torque", choices=("ramp", "constant", "none"), default="ramp", help="stance torque profile")
    parser.add_argument("--seed", type=int, default=0, help="seed of the drawn initial conditions and inputs")
    parser.add_argument("--csv", metavar="FILE", help="also write the samples as t,y,z,theta,tau")
    parser.add_argument("--csv-phase", action="store_true", help="add the true phase as a 6th CSV column")
    parser.add_argument("--sim", default="sim.yaml", help="simulated robot configuration (config/ name or path)")
    parser.add_argument("--hardware", default="hardware.yaml", help="hardware configuration (config/ name or path)")


def _names(text: str) -> list[str]:
    return [name.strip() for name in text.split(",") if name.strip()]


def _switches(on: str, off: str) -> dict:
    """`--effects a,b=VALUE` and `--no-effects c` as `SimConfig.with_effects` arguments."""
    from hopper_ros.sim.config import EFFECTS

    switches: dict = {}
    for item in _names(on):
        name, _, value = (part.strip() for part in item.partition("="))
        if not value:
            switches[name] = True
            continue
        try:
            magnitude = float(value)
        except ValueError:
            raise ValueError(f"--effects {item}: {value!r} is not a number") from None
        switches[name] = {EFFECTS[name]: magnitude} if name in EFFECTS else True    # unknown: with_effects says so
    return switches | {name: False for name in _names(off)}


def main(args: argparse.Namespace) -> int:
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.harness.collect import CollectionSettings, collect
    from hopper_ros.identification.progress import ProgressBar
    from hopper_ros.recording.bag import BagError
    from hopper_ros.config.schema import ConfigError
    from hopper_ros.sim.config import SENSORS, load_sim_config

    try:
        settings = CollectionSettings(experiments=args.experiments, strides=args.strides, seed=args.seed,
                                      torque_profile=args.torque)
        config = load_sim_config(args.sim)
        config = config.with_effects(**_switches(args.effects, args.no_effects))
        if args.noise:
            config = config.with_sensors(**{name: True for name in SENSORS})
        hardware = load_hardware(args.hardware)
    except (ValueError, FileNotFoundError) as exc:
        print(f"hopper collect: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)
    total = args.experiments if args.experiments is not None else args.strides
    bar = ProgressBar(total, "collect")

    def progress(kept: int, run: int) -> None:
        if args.experiments is not None:
            bar.step(f"{kept} kept")
        elif kept > bar.done:
            bar.step(f"{run} experiments")

    try:
        result = collect(args.output, config, hardware, settings, csv_path=args.csv, csv_phase=args.csv_phase,
                         progress=progress)
    except (BagError, ValueError, OSError) as exc:
        print(f"hopper collect: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)
    bar.close()
    discarded = ", ".join(f"{count} {reason}" for reason, count in sorted(result.discarded.items())) or "none"
    print(f"kept {len(result.kept)} of {result.experiments} experiments (discarded: {discarded})")
    print(f"bag {result.bag}: {result.messages} messages in {result.wall_time:.1f} s")
    if result.csv is not None:
        print(f"csv {result.csv}")
    if not result.kept:
        print("hopper collect: error: no stride succeeded; the bag holds no samples", file=sys.stderr)
        return 1
    if args.strides is not None and len(result.kept) < args.strides:
        print(f"hopper collect: error: only {len(result.kept)} of {args.strides} strides succeeded", file=sys.stderr)
        return 1
    return 0
