"""The README's commands, run as written (issue 31), in a scratch folder with the checkout's .venv beside it.

Every fenced bash and python block of README.md is read; each command line is run, except `make demo`
and `make test` (the demo is test_demo*.py's, the suite is this one) and the lines for a machine with ROS 2
installed (ros2, colcon, rosdep, sourcing /opt/ros), which are listed here by name so that a new README
line is either run or consciously set aside. Long-running lines (a node) run in the background while the
lines that need them run, then stop on SIGINT as a user's Ctrl-C would stop them.
"""

from __future__ import annotations

import os
import re
import shlex
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
README = (REPO / "README.md").read_text(encoding="utf-8")
ASIDE = {"make demo", "make test"}
ROS_MACHINE_ONLY = [           # need a ROS 2 install (docs: "On the robot's PC with ROS 2 installed")
    "mkdir -p ~/hopper_ws/src && cd ~/hopper_ws/src && git clone <this repository> hopper_ros",
    "cd ~/hopper_ws && source /opt/ros/<distro>/setup.bash",
    "rosdep install --from-paths src -y --ignore-src -t buildtool -t build -t build_export -t exec",
    "pip install --user --break-system-packages filterpy==2.0.0 mcap==1.6.0",
    "colcon build && source install/setup.bash",
    "ros2 run hopper_ros setpoint_scheduler",
    "ros2 launch hopper_ros demo_500hz.launch.yaml",
    'ros2 topic pub --once /sim/throw hopper_ros/msg/ApexState "{apex_height: 0.39, forward_speed: 2.0, leg_angle: 0.25}"',
]
BACKGROUND = {".venv/bin/hopper run sim_robot"}     # runs until Ctrl-C: the lines after it need it


def blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.S)


def commands() -> list[str]:
    out = []
    for block in blocks("bash"):
        for line in block.splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()     # a trailing comment (none of ours quotes a #)
            if line:
                out.append(line)
    return out


def test_every_readme_command_is_run_or_set_aside_by_name():
    lines = commands()
    assert ASIDE <= set(lines)
    assert [line for line in lines if line in ROS_MACHINE_ONLY] == ROS_MACHINE_ONLY
    runnable = [line for line in lines if line not in ASIDE and line not in ROS_MACHINE_ONLY]
    assert all(line.split()[0] in ("hopper", ".venv/bin/hopper") for line in runnable), runnable
    assert len(runnable) >= 5


def _port_free(port: int, kind=socket.SOCK_STREAM) -> bool:
    with socket.socket(socket.AF_INET, kind) as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def test_readme_commands_as_written(tmp_path):
    if not (_port_free(29536) and _port_free(15800, socket.SOCK_DGRAM)):
        pytest.skip("a simulated robot or encoder bridge of another session holds the README's default ports")
    (tmp_path / ".venv").symlink_to(REPO / ".venv")
    env = dict(os.environ, PATH=f"{REPO / '.venv' / 'bin'}{os.pathsep}{os.environ['PATH']}")
    runnable = [line for line in commands() if line not in ASIDE and line not in ROS_MACHINE_ONLY]
    runnable.sort(key=lambda line: line not in BACKGROUND)   # the node first: the throw and the echo need it
    background = []
    try:
        for line in runnable:
            argv = shlex.split(line)
            if line in BACKGROUND:
                process = subprocess.Popen(argv, cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                                           stderr=subprocess.PIPE, text=True, start_new_session=True)
                background.append((line, process))
                continue
            result = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
            assert result.returncode == 0, f"{line}\n{result.stdout[-2000:]}\n{result.stderr[-2000:]}"
            if "topic echo force_plate" in line:
                assert "force_vertical:" in result.stdout, result.stdout
            if "topic pub -1 /sim/throw" in line:
                assert "publishing #1" in result.stdout, result.stdout
        for line, process in background:
            assert process.poll() is None, f"{line} stopped early: {process.communicate()[1][-2000:]}"
            process.send_signal(signal.SIGINT)
            out, err = process.communicate(timeout=60)
            assert process.returncode == 0, f"{line}\n{err[-2000:]}"
    finally:
        for _, process in background:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
    for code in blocks("python"):
        result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                                timeout=600)
        assert result.returncode == 0, f"{code}\n{result.stderr[-2000:]}"
        assert result.stdout.strip(), code
    assert (tmp_path / "run.csv").is_file()
