"""`hopper report DIR`: chapter 4 end to end into a folder (markdown tables, PNG plots).

  hopper report DIR [--recording R] [--strides N] [--predictors aas,exact] [--folds K] [--no-grf]

Without --recording it first collects N strides (default 120, as the thesis's 120 of 132) on
the simulated robot with sensor noise into DIR/data/bag (and DIR/data/strides.csv), whose
true parameters are Table 4.1's. Then: identification with k-fold cross-validation for each
predictor (Tables 4.1, 4.2), the AAS's bias against the exact model, identifiability, a stride
against its predictions (Fig 4.6), the error histograms, and the ground reaction forces of
section 4.4 for no, ramp and constant torque (Figs 4.8, 4.9) -> DIR/report.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "identification, cross-validation and ground reaction forces (chapter 4) into a report folder"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("output", metavar="DIR", help="report folder")
    parser.add_argument("--recording", help="bag or CSV to identify from (default: collect one on the simulated robot)")
    parser.add_argument("--strides", type=int, default=120, help="strides to collect when no recording is given")
    parser.add_argument("--seed", type=int, default=0, help="seed of the collection")
    parser.add_argument("--predictors", default="aas,exact", help="comma-separated: aas, corrected, exact")
    parser.add_argument("--folds", type=int, help="folds of the cross-validation (default: config's)")
    parser.add_argument("--config", default="identification.yaml", help="identification settings")
    parser.add_argument("--no-grf", action="store_true", help="leave out the ground reaction forces")
    parser.add_argument("--no-progress", action="store_true")


def main(args: argparse.Namespace) -> int:
    from hopper_ros.cli.errors import run_tool

    return run_tool("report", [args.recording or args.output, args.config], lambda: _main(args))


def _main(args: argparse.Namespace) -> int:
    from hopper_ros.hardware.config import load_hardware
    from hopper_ros.harness.collect import CollectionSettings, collect
    from hopper_ros.harness.grf import simulate_profiles
    from hopper_ros.identification.pipeline import identify
    from hopper_ros.identification.settings import load_settings
    from hopper_ros.recording.bag import BagError
    from hopper_ros.recording.recordings import RecordingError
    from hopper_ros.reports.identification import write_report
    from hopper_ros.config.schema import ConfigError
    from hopper_ros.sim.config import SENSORS, load_sim_config

    out = Path(args.output)
    methods = tuple(m.strip() for m in args.predictors.split(",") if m.strip())
    try:
        settings = load_settings(args.config)
        if args.folds is not None:
            settings = settings.with_changes(folds=args.folds)
        unknown = [m for m in methods if m not in ("aas", "corrected", "exact")]
        if unknown or not methods:
            raise ValueError(f"--predictors: unknown {unknown}; choose from aas, corrected, exact")
        sim_config = load_sim_config().with_sensors(**{name: True for name in SENSORS})
        hardware = load_hardware("hardware.yaml")
        collection = None
        recording = args.recording
        if recording is None:
            data = out / "data"
            if (data / "bag").exists():
                raise ValueError(f"{data / 'bag'} exists already: pass --recording {data / 'bag'} to use it again, "
                                 f"or choose another report folder")
            print(f"collecting {args.strides} strides on the simulated robot (sensor noise on) ...", file=sys.stderr)
            collection = collect(data / "bag", sim_config, hardware, CollectionSettings(strides=args.strides, seed=args.seed),
                                 csv_path=data / "strides.csv")
            recording = data / "bag"
        result = identify(recording, settings, methods, show_progress=not args.no_progress)
        forces = None
        if not args.no_grf:
            print("ground reaction forces: no, ramp and constant torque ...", file=sys.stderr)
            grf_folder, number = out / "data" / "grf", 1
            while grf_folder.exists():              # earlier reports' recordings stay as they are
                number += 1
                grf_folder = out / "data" / f"grf_{number}"
            forces = simulate_profiles(grf_folder, sim_config, hardware, settings.grf, sim_config.model_params())
    except (RecordingError, BagError, ValueError, FileNotFoundError) as exc:
        print(f"hopper report: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)
    path = write_report(out, result, forces, collection)
    print(f"report written to {path}")
    return 0
