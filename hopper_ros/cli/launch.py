"""`hopper launch [hopper_ros] FILE [NAME:=VALUE ...]`: start the nodes of a launch file, each node
or node_container a process, and supervise them, like `ros2 launch hopper_ros FILE NAME:=VALUE`.

FILE is a path or a file of launch/ (`demo.launch.yaml`). Launch files are ros2 launch's YAML
format; what is supported of it, output and stop behaviour: hopper_ros/launch/__init__.py.
"""

from __future__ import annotations

import argparse
import shlex
import sys

HELP = "start the nodes of a launch file, each node or container a process (like `ros2 launch`)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("words", nargs="+", metavar="[hopper_ros] FILE [NAME:=VALUE ...]",
                        help="launch file (a path, or a file of hopper_ros's launch/, e.g. demo.launch.yaml), "
                             "optionally after the package name, then launch arguments")
    parser.add_argument("--print", action="store_true", dest="print_only", help="print the commands and exit")
    parser.add_argument("-s", "--show-args", action="store_true", help="show the launch arguments in force and exit")


def split_words(words: list[str]) -> tuple[str | None, str, dict[str, str]]:
    """(package or None, file, launch arguments) of `[PACKAGE] FILE [NAME:=VALUE ...]`."""
    positional = [w for w in words if ":=" not in w]
    assignments = [w for w in words if ":=" in w]
    if words[: len(positional)] != positional:
        raise ValueError("launch arguments (NAME:=VALUE) go after the launch file")
    if len(positional) == 1:
        package, file = None, positional[0]
    elif len(positional) == 2:
        package, file = positional
    else:
        raise ValueError(f"expected [PACKAGE] FILE, got {' '.join(positional)}")
    arguments = {}
    for word in assignments:
        name, _, value = word.partition(":=")
        if not name:
            raise ValueError(f"launch argument {word!r} has no name (NAME:=VALUE)")
        arguments[name] = value
    return package, file, arguments


def main(args: argparse.Namespace) -> int:
    from hopper_ros.launch import LaunchFileError, Launcher, load_launch

    try:
        package, file, arguments = split_words(args.words)
        description = load_launch(file, arguments, package)
    except (LaunchFileError, FileNotFoundError, ValueError) as exc:
        print(f"hopper launch: error: {exc}", file=sys.stderr)
        return 3                     # bad input (cli/exit_codes.py)
    if args.show_args:
        for name, value in description.arguments.items():
            print(f"{name}:={value}")
        return 0
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
