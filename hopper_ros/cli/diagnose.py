"""`hopper diagnose RECORDING [--model FILE.yaml] [-o DIR] [--json FILE]`: the mismatch tool (docs/diagnosis.md)."""

from __future__ import annotations

import argparse
import sys

HELP = "locate, name and model what the model misses in a recording (bag or t,y,z,theta,tau CSV)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", help="bag folder, .mcap or CSV of 1 kHz samples t,y,z,theta,tau[,phase]")
    parser.add_argument("--map", metavar="FILE", help="read another robot's bag or CSV through this mapping file "
                        "(hopper import; docs/bring_your_own_robot.md)")
    parser.add_argument("--model", default="model.yaml", help="model parameters (config/ name or path)")
    parser.add_argument("--settings", default="diagnosis.yaml", help="candidates and statistics (config/ name or path)")
    parser.add_argument("-o", "--output", default=None, metavar="DIR", help="write diagnosis.md and diagnosis.png here")
    parser.add_argument("--json", default=None, metavar="FILE", help="write the verdict and the location as JSON")
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="no progress on stderr (it is shown only on a terminal anyway)")


def main(args: argparse.Namespace) -> int:
    from hopper_ros.cli.errors import run_tool

    return run_tool("diagnose", [args.recording, args.model, args.settings, args.map], lambda: _main(args))


def _main(args: argparse.Namespace) -> int:
    from hopper_ros.cli.importer import load_for_tool
    from hopper_ros.diagnosis import DiagnosisError, diagnose_file
    from hopper_ros.diagnosis.progress import Progress
    from hopper_ros.diagnosis.settings import load_settings
    from hopper_ros.recording.recordings import RecordingError

    from hopper_ros.config.schemas import load_model

    try:
        load_model(args.model)                          # the schemas first: one line naming file and key
        settings = load_settings(args.settings)
        recording = load_for_tool(args.recording, args.map, "diagnose")
        progress = Progress(enabled=False if args.quiet else None)
        result = diagnose_file(recording, args.model, args.output, settings, args.json, progress)
    except (DiagnosisError, RecordingError, ValueError, FileNotFoundError, KeyError) as exc:
        print(f"hopper diagnose: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)
    from hopper_ros.diagnosis.report import location_line, timing_line

    print(f"{len(result.data.strides)} strides, {result.wall_time:.1f} s")
    print(location_line(result.location, result.settings.locate_threshold))
    if timing_line(result.data):
        print(timing_line(result.data))
    print(result.verdict)
    b, a = result.before, result.after
    print(f"held-out E_p {b.E_p:.3f} -> {a.E_p:.3f} %, E_v {b.E_v:.3f} -> {a.E_v:.3f} %, "
          f"E_t {b.E_t:.3f} -> {a.E_t:.3f} %")
    if args.output:
        print(f"report: {result.report}")
    if args.json:
        print(f"json: {result.json}")
    return 0
