"""The `hopper` command line: the project's stand-in for the `ros2` CLI.

Subcommands are registered in `COMMANDS` (name -> module). Each module defines
`HELP` (one line), `add_arguments(parser)` and `main(args) -> int`, and imports rclpy only
inside `main`, so `apply_ros_environment()` has run before rclpy is loaded. A later issue adds
a subcommand by writing its module and adding one line here.
"""

from __future__ import annotations

import argparse
import faulthandler
import importlib
import signal
import sys
from typing import Sequence

from hopper_ros.runtime.environment import RosEnvironmentError, apply_ros_environment

COMMANDS = {
    "run": "hopper_ros.cli.run",
    "topic": "hopper_ros.cli.topic",
    "launch": "hopper_ros.cli.launch",
    "predictors": "hopper_ros.cli.predictors",
    "demo": "hopper_ros.cli.demo",
    "bag": "hopper_ros.cli.bag",
    "collect": "hopper_ros.cli.collect",
    "identify": "hopper_ros.cli.identify",
    "report": "hopper_ros.cli.report",
    "diagnose": "hopper_ros.cli.diagnose",
    "import": "hopper_ros.cli.importer",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hopper",
        description="Run, inspect and launch the hopper_ros node graph.",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(module_name)
        sub = subparsers.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(sub)
        sub.set_defaults(_main=module.main)
    from hopper_ros.cli import helpformat

    helpformat.apply(parser)                   # defaults in every help, sub-commands' too
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    try:             # `kill -USR1 PID`: where every thread of a stuck hopper process is, on stderr
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    except (AttributeError, OSError, ValueError):
        pass         # no SIGUSR1 here, or stderr is not a file (called in-process with its output captured)
    try:
        apply_ros_environment()
    except RosEnvironmentError as exc:
        print(f"hopper: error: {exc}", file=sys.stderr)
        return 2
    args = build_parser().parse_args(argv)
    return args._main(args)
