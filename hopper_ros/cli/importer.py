"""`hopper import RECORDING --map FILE -o OUT.csv`: another robot's recording as the tools' table.

RECORDING is a bag (folder or .mcap) of any messages with numeric fields (sensor_msgs/JointState,
geometry_msgs/PointStamped or PoseStamped, nav_msgs/Odometry, the robot's own types) or a CSV with
its own column names; the mapping file (recording/mapping.py, docs/bring_your_own_robot.md) says
where y, z, theta and tau are and in which units. Writes `t,y,z,theta,tau` in SI, one row per
sample (recordings.py), at the mapping's rate; says on stdout what it did (rate, resampling, gaps).
`hopper diagnose` and `hopper identify` read the same recording directly with `--map FILE`.
"""

from __future__ import annotations

import argparse

HELP = "turn another robot's bag or CSV into t,y,z,theta,tau (SI) through a mapping file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", help="bag folder, .mcap file or CSV of the other robot")
    parser.add_argument("--map", required=True, metavar="FILE", dest="mapping",
                        help="mapping file: topics/columns, field paths, units, scale and offset, rate")
    parser.add_argument("-o", "--output", required=True, metavar="CSV", help="the CSV to write (must not exist)")


def main(args: argparse.Namespace) -> int:
    from hopper_ros.cli.errors import run_tool

    return run_tool("import", [args.recording, args.mapping], lambda: _main(args))


def _main(args: argparse.Namespace) -> int:
    from hopper_ros.recording.mapping import load_mapped
    from hopper_ros.recording.recordings import write_csv

    imported = load_mapped(args.recording, args.mapping)
    for note in imported.notes:
        print(f"import: {note}")
    rec = imported.recording
    path = write_csv(args.output, rec)
    print(f"{path}: {len(rec)} samples, {len(rec.segments())} run(s), {rec.t[-1]:.3f} s")
    return 0


def load_for_tool(recording: str, mapping: str | None, tool: str):
    """The recording for `hopper TOOL --map`: the path itself without a mapping, else the imported
    Recording (its notes on stderr, `hopper TOOL: import: ...`)."""
    import sys

    if not mapping:
        return recording
    from hopper_ros.recording.mapping import load_mapped

    imported = load_mapped(recording, mapping)
    for note in imported.notes:
        print(f"hopper {tool}: import: {note}", file=sys.stderr)
    return imported.recording
