"""`hopper launch FILE`: start a set of nodes as separate processes and supervise them.

File format, output and stop behaviour: hopper_ros/launcher.py (example: config/launch/).
"""

from __future__ import annotations

import argparse
import shlex
import sys

HELP = "start the nodes of a launch file, each in its own process (like `ros2 launch`)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="launch file: a path, or relative to the config directory (launch/...)")
    parser.add_argument("--print", action="store_true", dest="print_only", help="print the commands and exit")


def main(args: argparse.Namespace) -> int:
    from hopper_ros.launcher import LaunchFileError, Launcher, load_launch

    try:
        description = load_launch(args.file)
    except (LaunchFileError, FileNotFoundError) as exc:
        print(f"hopper launch: error: {exc}", file=sys.stderr)
        return 2
    if args.print_only:
        for child in description.children:
            print(f"{child.label}: {shlex.join(child.argv)}")
        return 0
    launcher = Launcher(
        description.children,
        sigint_timeout=description.sigint_timeout,
        sigterm_timeout=description.sigterm_timeout,
    )
    return launcher.run()
