"""`hopper launch`: the launch file format, and the supervisor starting, relaying and stopping."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from hopper_ros.launcher import LaunchFileError, load_launch, parse_launch
from hopper_ros.nodes.registry import NODES

STARTED_CHILD = r"^\[launch\] started {}: pid (\d+)$"


def test_example_launch_file_is_valid():
    description = load_launch("launch/example.yaml")
    child, predictor = description.children
    assert child.label == "hopper/setpoint_scheduler"
    assert child.argv[1:] == [
        "-m", "hopper_ros.cli", "run", "setpoint_scheduler", "--ros-args",
        "-r", "__node:=setpoint_scheduler", "-r", "__ns:=/hopper",
        "-p", "schedule_file:=setpoints/fig5_5.yaml", "-r", "apex:=apex", "--",
    ]  # fmt: skip
    assert child.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] in ("LOCALHOST", "OFF", "SUBNET", "SYSTEM_DEFAULT")
    assert predictor.label == "hopper/stride_predictor"
    assert predictor.argv[4:] == [
        "stride_predictor", "--ros-args", "-r", "__ns:=/hopper",
        "-p", "predictor:=corrected", "-p", "model_file:=model.yaml", "--",
    ]  # fmt: skip


def test_entry_fields_become_ros_arguments(tmp_path):
    (tmp_path / "params.yaml").write_text("x: {ros__parameters: {a: 1}}\n")
    description = parse_launch(
        {
            "nodes": [
                {
                    "node": "setpoint_scheduler",
                    "parameters": {"gains": {"kp": 1.5}, "name": "0.5", "flags": [True, False], "n": 3},
                    "params_file": "params.yaml",
                    "args": ["--extra", 1],
                    "label": "sched",
                }
            ],
            "sigint_timeout": 1,
            "sigterm_timeout": 0.5,
        },
        "t.yaml",
        base_dir=tmp_path,
    )
    [child] = description.children
    ros_args = child.argv[child.argv.index("--ros-args") + 1 :]
    assert ros_args == [
        "-p", "gains.kp:=1.5", "-p", "name:='0.5'", "-p", "flags:=[true, false]", "-p", "n:=3",
        "--params-file", str(tmp_path / "params.yaml"), "--", "--extra", "1",
    ]  # fmt: skip
    assert (child.label, description.sigint_timeout, description.sigterm_timeout) == ("sched", 1.0, 0.5)


def test_realtime_priority_goes_to_that_node_only():
    from hopper_ros.environment import REALTIME_PRIORITY_VAR

    rt, normal = parse_launch({"nodes": [{"node": "encoder_bridge", "realtime_priority": 60},
                                         {"node": "setpoint_scheduler"}]}, "t.yaml").children
    assert rt.env[REALTIME_PRIORITY_VAR] == "60" and REALTIME_PRIORITY_VAR not in normal.env


@pytest.mark.parametrize(
    "data, message",
    [
        ({"nodes": [{"node": "nope"}]}, f"entry 1 (nope): unknown node 'nope'; registered nodes: {', '.join(sorted(NODES))}"),
        ({"nodes": [{"name": "x"}]}, "entry 1: missing 'node'"),
        ({"nodes": [{"node": "setpoint_scheduler", "remap": {}}]}, "entry 1 (setpoint_scheduler): unknown key(s) 'remap'"),
        ({"nodes": [{"node": "setpoint_scheduler"}, {"node": "setpoint_scheduler"}]}, "entry 2 (setpoint_scheduler): label 'setpoint_scheduler' is already used by entry 1"),
        ({"nodes": [{"node": "setpoint_scheduler", "params_file": "missing.yaml"}]}, "params_file 'missing.yaml' not found"),
        ({"nodes": [{"node": "setpoint_scheduler", "parameters": {"a": None}}]}, "parameter 'a' has no value"),
        ({"nodes": [{"node": "setpoint_scheduler", "remappings": ["a:=b"]}]}, "'remappings' must be a mapping"),
        ({"nodes": []}, "non-empty 'nodes' list"),
        ({"nodes": [{"node": "setpoint_scheduler"}], "sigint_timeout": -1}, "'sigint_timeout' must be a number"),
        ({"nodes": [{"node": "setpoint_scheduler", "realtime_priority": 100}]}, "'realtime_priority' must be a SCHED_FIFO priority 1-99"),
    ],
)  # fmt: skip
def test_bad_launch_files_name_the_entry(data, message):
    with pytest.raises(LaunchFileError) as info:
        parse_launch(data, "t.yaml")
    assert str(info.value).startswith("t.yaml")
    assert message in str(info.value)


# --------------------------------------------------------------------------- supervisor, no ROS

_SUPERVISE = textwrap.dedent(
    """
    import sys
    from hopper_ros.launcher import ChildSpec, Launcher
    # 'stubborn' ignores SIGINT (so does its grandchild, a sleep): only SIGTERM stops them.
    stubborn = "trap '' INT; sleep 120 & echo grandchild $!; wait"
    polite = "echo ready; exec sleep 120"
    children = [ChildSpec("stubborn", ["sh", "-c", stubborn]), ChildSpec("polite", ["sh", "-c", polite])]
    sys.exit(Launcher(children, sigint_timeout=0.5, sigterm_timeout=5).run())
    """
)


def test_supervisor_escalates_and_leaves_no_grandchild():
    from conftest import REPO, SAFETY_TIMEOUT, process_alive, process_group_members

    process = subprocess.Popen(
        [sys.executable, "-c", _SUPERVISE],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        lines = []
        while not (any(l.startswith("[stubborn] grandchild") for l in lines) and "[polite] ready" in lines):
            line = process.stdout.readline()
            assert line, f"launcher ended early: {lines} {process.stderr.read()}"
            lines.append(line.rstrip("\n"))
        pids = {l.split()[2].rstrip(":"): int(l.split()[-1]) for l in lines if l.startswith("[launch] started")}
        grandchild = int(next(l for l in lines if l.startswith("[stubborn] grandchild")).split()[-1])
        assert process_alive(grandchild)
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=SAFETY_TIMEOUT)
        lines += out.splitlines()
        # polite stopped on SIGINT; stubborn needed SIGTERM: not a clean stop, so non-zero.
        assert process.returncode == 1, (lines, err)
        assert "[launch] sending SIGTERM to stubborn" in lines
        assert "[launch] polite stopped (signal SIGINT)" in lines
        assert "[launch] stubborn stopped (signal SIGTERM)" in lines
        for pid in [*pids.values(), grandchild]:
            assert not process_alive(pid), f"pid {pid} left behind"
        for pgid in pids.values():
            assert process_group_members(pgid) == []
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


# --------------------------------------------------------------------------- with real nodes


def _two_schedulers(tmp_path):
    (tmp_path / "schedule.yaml").write_text("segments:\n  - {apex_height: 0.4, forward_speed: 2.0}\n")
    launch_file = tmp_path / "two.yaml"
    launch_file.write_text(
        textwrap.dedent(
            f"""
            nodes:
              - node: setpoint_scheduler
                name: scheduler_a
                parameters: {{schedule_file: {tmp_path / 'schedule.yaml'}}}
              - node: setpoint_scheduler
                name: scheduler_b
                namespace: other
                parameters: {{schedule_file: {tmp_path / 'schedule.yaml'}}}
            sigint_timeout: 10
            """
        )
    )
    return launch_file


def _start_and_wait_for_both(hopper_cli, launch_file):
    launcher = hopper_cli("launch", str(launch_file))
    pids = {
        label: int(launcher.wait_for_line(STARTED_CHILD.format(label), stream="stdout").group(1))
        for label in ("scheduler_a", "other/scheduler_b")
    }
    # Their log lines arrive prefixed with their labels (rclpy logs to stderr).
    launcher.wait_for_line(r"^\[scheduler_a\] \[INFO\] \[[\d.]+\] \[scheduler_a\]: started: pid")
    launcher.wait_for_line(r"^\[other/scheduler_b\] \[INFO\] \[[\d.]+\] \[other.scheduler_b\]: started: pid")
    launcher.wait_for_line(r"^\[scheduler_a\] .*setpoint 1/1: apex height 0.4 m, forward speed 2 m/s")
    return launcher, pids


def test_launch_two_nodes_and_stop_on_sigint(hopper_cli, tmp_path):
    from conftest import process_alive, process_group_members

    launcher, pids = _start_and_wait_for_both(hopper_cli, _two_schedulers(tmp_path))
    launcher.signal(signal.SIGINT)
    assert launcher.wait() == 0, launcher.stdout + launcher.stderr
    assert "[scheduler_a] " in launcher.stderr and "stopping on SIGINT" in launcher.stderr
    assert "[launch] scheduler_a stopped (exit status 0)" in launcher.stdout
    assert "[launch] other/scheduler_b stopped (exit status 0)" in launcher.stdout
    for pid in pids.values():
        assert not process_alive(pid), f"pid {pid} left behind"
        assert process_group_members(pid) == []


def test_a_dying_node_stops_the_others(hopper_cli, tmp_path):
    from conftest import process_alive, process_group_members

    launcher, pids = _start_and_wait_for_both(hopper_cli, _two_schedulers(tmp_path))
    os.kill(pids["other/scheduler_b"], signal.SIGKILL)
    status = launcher.wait()
    assert status == 128 + signal.SIGKILL, launcher.stdout + launcher.stderr
    assert "[launch] other/scheduler_b ended by itself (signal SIGKILL); stopping the others" in launcher.stdout
    assert "[launch] scheduler_a stopped (exit status 0)" in launcher.stdout
    for pid in pids.values():
        assert not process_alive(pid), f"pid {pid} left behind"
        assert process_group_members(pid) == []


def test_nodes_of_a_killed_launcher_stop_too():
    import time

    from conftest import REPO, SAFETY_TIMEOUT, process_alive

    script = textwrap.dedent(
        """
        from hopper_ros.launcher import ChildSpec, Launcher
        Launcher([ChildSpec("orphan", ["sh", "-c", "echo ready; exec sleep 120"])]).run()
        """
    )
    process = subprocess.Popen(
        [sys.executable, "-c", script],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    child = None
    try:
        started = process.stdout.readline()
        assert started.startswith("[launch] started orphan: pid"), started
        assert process.stdout.readline() == "[orphan] ready\n"
        child = int(started.split()[-1])
        process.kill()  # SIGKILL: the launcher cannot stop anything itself
        process.wait(SAFETY_TIMEOUT)
        end = time.monotonic() + SAFETY_TIMEOUT
        while process_alive(child) and time.monotonic() < end:
            time.sleep(0.05)
        assert not process_alive(child), "the node outlived its killed launcher"
    finally:
        if process.poll() is None:
            process.kill()
        if child is not None and process_alive(child):
            os.kill(child, signal.SIGKILL)
        process.stdout.close()
