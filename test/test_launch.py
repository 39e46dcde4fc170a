"""`hopper launch`: the launch file format, and the supervisor starting, relaying and stopping."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import yaml

from hopper_ros.launch import LaunchFileError, load_launch, parse_launch
from hopper_ros.nodes.registry import NODES

STARTED_CHILD = r"^\[launch\] started {}: pid (\d+)$"


def node(exec_name: str, **attributes) -> dict:
    return {"node": {"pkg": "hopper_ros", "exec": exec_name, **attributes}}


def test_example_launch_file_is_valid():
    description = load_launch("example.launch.yaml")
    child, predictor = description.children
    assert description.arguments == {"namespace": "/hopper"}
    assert child.label == "hopper/setpoint_scheduler"
    assert child.argv[1:] == [
        "-m", "hopper_ros.cli", "run", "setpoint_scheduler", "--ros-args",
        "-r", "__node:=setpoint_scheduler", "-r", "__ns:=/hopper",
        "-p", "schedule_file:=setpoints/fig5_5.yaml", "-r", "apex:=apex", "--",
    ]  # fmt: skip
    assert child.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] in ("LOCALHOST", "OFF", "SUBNET", "SYSTEM_DEFAULT")
    assert predictor.label == "hopper/stride_predictor"
    assert predictor.argv[4:] == [
        "stride_predictor", "--ros-args", "-r", "__node:=stride_predictor", "-r", "__ns:=/hopper",
        "-p", "predictor:=corrected", "-p", "model_file:=model.yaml", "--",
    ]  # fmt: skip
    # a launch argument, as `ros2 launch hopper_ros example.launch.yaml namespace:=/robot2`
    moved = load_launch("example.launch.yaml", {"namespace": "/robot2"})
    assert [c.label for c in moved.children] == ["robot2/setpoint_scheduler", "robot2/stride_predictor"]


@pytest.mark.parametrize("name", sorted(p.name for p in (Path(__file__).resolve().parents[1] / "launch").glob("*")))
def test_every_installed_launch_file_is_ros2_launch_yaml(name):
    """launch/ holds only ros2 launch YAML files, each with one root 'launch' and nodes of this
    package; hopper launch reads them (the keys it accepts are a subset of launch_ros's)."""
    from hopper_ros.config import launch_dir

    assert name.endswith(".launch.yaml")
    data = yaml.safe_load((launch_dir() / name).read_text())
    assert list(data) == ["launch"]
    description = load_launch(name)
    assert description.children and all(c.argv[3] == "run" for c in description.children)
    for entity in data["launch"]:
        if "node" in entity:
            assert entity["node"]["pkg"] == "hopper_ros" and entity["node"]["exec"] in NODES


def test_node_attributes_become_ros_arguments(tmp_path):
    (tmp_path / "params.yaml").write_text("x: {ros__parameters: {a: 1}}\n")
    description = parse_launch(
        {"launch": [node(
            "setpoint_scheduler", name="sched", namespace="ns",
            param=[{"name": "gains", "param": [{"name": "kp", "value": 1.5}]}, {"name": "text", "value": "0.5"},
                   {"name": "flags", "value": [True, False]}, {"name": "n", "value": 3}, {"from": "params.yaml"}],
            remap=[{"from": "apex", "to": "/events/apex"}],
            args="--extra 1", ros_args="--log-level debug", output="screen", on_exit="shutdown",
            sigterm_timeout=1, sigkill_timeout="0.5")]},
        "t.yaml",
        base_dir=tmp_path,
    )
    [child] = description.children
    ros_args = child.argv[child.argv.index("--ros-args") + 1 :]
    assert ros_args == [
        "-r", "__node:=sched", "-r", "__ns:=/ns",
        "-p", "gains.kp:=1.5", "-p", "text:=0.5", "-p", "flags:=[true, false]", "-p", "n:=3",
        "--params-file", str(tmp_path / "params.yaml"), "-r", "apex:=/events/apex", "--log-level", "debug",
        "--", "--extra", "1",
    ]  # fmt: skip
    assert (child.label, description.sigint_timeout, description.sigterm_timeout) == ("ns/sched", 1.0, 0.5)


def test_realtime_priority_is_the_node_environment_of_that_node_only():
    from hopper_ros.runtime.environment import REALTIME_PRIORITY_VAR

    rt, normal = parse_launch({"launch": [node("encoder_bridge", env=[{"name": REALTIME_PRIORITY_VAR, "value": "60"}]),
                                          node("setpoint_scheduler")]}, "t.yaml").children
    assert rt.env[REALTIME_PRIORITY_VAR] == "60" and REALTIME_PRIORITY_VAR not in normal.env


def test_arguments_lets_substitutions_and_conditions(monkeypatch):
    monkeypatch.setenv("HOPPER_TEST_SCHEDULE", "setpoints/fig5_5.yaml")
    data = {"launch": [
        {"arg": {"name": "ns", "default": "/a"}},
        {"arg": {"name": "with_predictor", "default": "false"}},
        {"let": {"name": "sub", "value": "$(var ns)/b"}},
        node("setpoint_scheduler", namespace="$(var sub)",
             param=[{"name": "schedule_file", "value": "$(env HOPPER_TEST_SCHEDULE)"},
                    {"name": "where", "value": "$(find-pkg-share hopper_ros)/config"},
                    {"name": "missing", "value": "$(env HOPPER_NOT_SET fallback)"}]),
        node("stride_predictor", **{"if": "$(var with_predictor)"}),
        node("event_detector", **{"unless": "$(var with_predictor)"}),
    ]}
    description = parse_launch(data, "t.yaml")
    assert [c.label for c in description.children] == ["a/b/setpoint_scheduler", "event_detector"]
    scheduler = description.children[0].argv
    from hopper_ros.config import config_dir

    assert "schedule_file:=setpoints/fig5_5.yaml" in scheduler and "missing:=fallback" in scheduler
    assert f"where:={config_dir()}" in scheduler
    given = parse_launch(data, "t.yaml", arguments={"ns": "/c", "with_predictor": "true"})
    assert [c.label for c in given.children] == ["c/b/setpoint_scheduler", "stride_predictor"]
    assert given.arguments == {"ns": "/c", "with_predictor": "true"}


@pytest.mark.parametrize(
    "data, message",
    [
        ({"nodes": [{"node": "setpoint_scheduler"}]}, "expected one root key 'launch' (ros2 launch's YAML format), found 'nodes'"),
        ({"launch": [node("nope")]}, f"entry 1 (node): unknown exec 'nope'; hopper_ros's nodes: {', '.join(sorted(set(NODES) - {'component_container'}))}"),
        ({"launch": [{"node": {"exec": "sim_robot"}}]}, "entry 1 (node): missing 'pkg'"),
        ({"launch": [{"node": {"pkg": "demo_nodes_py", "exec": "talker"}}]}, "pkg 'demo_nodes_py': hopper launch starts the nodes of hopper_ros only"),
        ({"launch": [node("setpoint_scheduler", realtime_priority=50)]}, "entry 1 (node): 'realtime_priority' is not a key of ros2 launch's node: give the SCHED_FIFO priority as env [{name: HOPPER_REALTIME_PRIORITY, value: \"N\"}]"),
        ({"launch": [node("setpoint_scheduler", respawn_period=1)]}, "entry 1 (node): unknown key(s) 'respawn_period' of 'node' (hopper launch supports: args, env,"),
        ({"launch": [node("setpoint_scheduler", respawn=True, on_exit="shutdown")]}, "'respawn: true' with 'on_exit: shutdown': ros2 launch shuts everything down"),
        ({"launch": [node("setpoint_scheduler", respawn="often")]}, "'respawn' must be true or false, got 'often'"),
        ({"launch": [node("setpoint_scheduler", respawn=True, respawn_delay="soon")]}, "'respawn_delay' must be a number of seconds >= 0"),
        ({"launch": [{"group": {}}]}, "entry 1: entity 'group' is not supported by hopper launch (supported: arg, let, node, node_container)"),
        ({"launch": [node("setpoint_scheduler"), node("setpoint_scheduler")]}, "entry 2 (node): a node 'setpoint_scheduler' is already started by entry 1"),
        ({"launch": [node("setpoint_scheduler", param=[{"from": "missing.yaml"}])]}, "parameter file 'missing.yaml' not found"),
        ({"launch": [node("setpoint_scheduler", param=[{"name": "a"}])]}, "parameter 'a' needs either 'value' or nested 'param'"),
        ({"launch": [node("setpoint_scheduler", remap={"a": "b"})]}, "'remap' must be a list of mappings"),
        ({"launch": [node("setpoint_scheduler", sigterm_timeout=-1)]}, "'sigterm_timeout' must be a number of seconds >= 0"),
        ({"launch": [node("setpoint_scheduler", env=[{"name": "HOPPER_REALTIME_PRIORITY", "value": "100"}])]}, "must be a SCHED_FIFO priority 1-99"),
        ({"launch": [node("setpoint_scheduler", namespace="$(var nope)")]}, "$(var nope): no launch argument or 'let' of that name"),
        ({"launch": [node("setpoint_scheduler", namespace="$(command ls)")]}, "substitution '$(command ls)' is not supported"),
        ({"launch": [{"arg": {"name": "x"}}, node("setpoint_scheduler")]}, "launch argument 'x' is required: give it as x:=VALUE"),
        ({"launch": [node("setpoint_scheduler", **{"if": "maybe"})]}, "'if' must be true, false, 1 or 0"),
        ({"launch": [node("setpoint_scheduler", on_exit="restart")]}, "'on_exit' can only be 'shutdown'"),
    ],
)  # fmt: skip
def test_bad_launch_files_name_the_entry(data, message):
    with pytest.raises(LaunchFileError) as info:
        parse_launch(data, "t.yaml")
    assert str(info.value).startswith("t.yaml")
    assert message in str(info.value)


def test_an_undeclared_launch_argument_is_refused():
    with pytest.raises(LaunchFileError, match=r"no launch argument 'nmaespace' in this file \(its arguments: namespace\)"):
        load_launch("example.launch.yaml", {"nmaespace": "/x"})


def test_bad_command_lines_get_one_line(hopper_cli, tmp_path):
    (tmp_path / "bad.launch.yaml").write_text("launch:\n  - node: {pkg: hopper_ros, exec: nope}\n")
    for words, message in [
        (["no_such.launch.yaml"], "launch file 'no_such.launch.yaml' not found (a path, or one of hopper_ros's: "
                                  "demo.launch.yaml, demo_500hz.launch.yaml, example.launch.yaml)"),
        ([str(tmp_path / "bad.launch.yaml")], "entry 1 (node): unknown exec 'nope'"),
        (["other_pkg", "demo.launch.yaml"], "package 'other_pkg': hopper launch runs hopper_ros's launch files only"),
        (["hopper_ros", "example.launch.yaml", "namespace"], "expected [PACKAGE] FILE, got hopper_ros example.launch.yaml namespace"),
    ]:
        process = hopper_cli("launch", *words)
        assert process.wait() == 3
        assert process.stderr.startswith("hopper launch: error: ") and message in process.stderr, process.stderr
        assert len(process.stderr.splitlines()) == 1 and "Traceback" not in process.stderr


def test_show_args_and_print(hopper_cli):
    shown = hopper_cli("launch", "hopper_ros", "demo.launch.yaml", "realtime_priority:=0", "driver_priority:=0",
                       "--show-args")
    assert shown.wait() == 0 and shown.stdout == ("realtime_priority:=0\nrobot_priority:=50\ndriver_priority:=0\n"
                                                  "hardware_file:=hardware.yaml\nperiod:=0.001\n"
                                                  "driver_config:=motor_driver.yaml\n"
                                                  "encoder_port:=0\ncan_port:=0\nrobot_cpu:=\nloop_cpu:=\n")
    # what `hopper demo` runs where SCHED_FIFO is not permitted: the robot, its drive and the sensing at 500 Hz
    from hopper_ros.cli.demo import NORMAL_SCHEDULING
    normal = hopper_cli("launch", "demo.launch.yaml", *NORMAL_SCHEDULING, "--print")
    assert normal.wait() == 0
    lines = dict(line.split(": ", 1) for line in normal.stdout.splitlines())
    assert "-p period:=0.002 -p hardware_file:=demo/hardware_500hz.yaml" in lines["sim_robot"], lines["sim_robot"]
    assert "-p config_file:=demo/motor_driver_500hz.yaml -p sync_period:=0.002" in lines["motor_driver"]
    assert lines["sensing"].count("hardware_file:=demo/hardware_500hz.yaml") == 3, lines["sensing"]   # bridge, estimator, detector
    printed = hopper_cli("launch", "demo_500hz.launch.yaml", "--print")
    assert printed.wait() == 0
    assert [line.split(":")[0] for line in printed.stdout.splitlines()] == [
        "sim_robot", "motor_driver", "encoder_bridge", "state_estimator", "event_detector", "setpoint_scheduler",
        "deadbeat_controller"]  # fmt: skip


# --------------------------------------------------------------------------- supervisor, no ROS

_SUPERVISE = textwrap.dedent(
    """
    import sys
    from hopper_ros.launch import ChildSpec, Launcher
    # 'stubborn' ignores SIGINT (so does its grandchild, a sleep): only SIGTERM stops them.
    stubborn = "trap '' INT; sleep 120 & echo grandchild $!; wait"
    polite = "echo ready; exec sleep 120"
    children = [ChildSpec("stubborn", ["sh", "-c", stubborn]), ChildSpec("polite", ["sh", "-c", polite])]
    sys.exit(Launcher(children, sigint_timeout=0.5, sigterm_timeout=5).run())
    """
)


def test_respawn_and_its_delay_are_read_as_launch_ros_does():
    data = {"launch": [{"arg": {"name": "again", "default": "true"}},
                       node("setpoint_scheduler", respawn="$(var again)", respawn_delay=0.5),
                       node("stride_predictor", respawn=False), node("event_detector")]}
    children = parse_launch(data, "t.yaml").children
    assert [(c.respawn, c.respawn_delay) for c in children] == [(True, 0.5), (False, 0.0), (False, 0.0)]
    assert not parse_launch(data, "t.yaml", arguments={"again": "false"}).children[0].respawn


_RESPAWN = textwrap.dedent(
    """
    import sys
    from hopper_ros.launch import ChildSpec, Launcher
    # both end cleanly (exit 0) on the launcher's SIGINT, as nodes do
    node = "import signal, sys, time; signal.signal(signal.SIGINT, lambda *a: sys.exit(0)); print({!r}, flush=True); time.sleep(120)"
    children = [ChildSpec("flaky", [sys.executable, "-c", node.format("up")], respawn=True, respawn_delay=0.3),
                ChildSpec("steady", [sys.executable, "-c", node.format("ready")])]
    sys.exit(Launcher(children, sigint_timeout=5, sigterm_timeout=5).run())
    """
)


def test_a_respawned_node_comes_back_after_its_delay_and_the_others_run_on():
    """`respawn: true`: a node killed (SIGKILL) is started again `respawn_delay` later, the launch and
    its other nodes go on, and a stop requested afterwards is clean (exit status 0)."""
    from conftest import REPO, SAFETY_TIMEOUT, process_alive

    process = subprocess.Popen([sys.executable, "-c", _RESPAWN], cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)},
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        lines = []

        def until(predicate):
            while not predicate():
                line = process.stdout.readline()
                assert line, f"launcher ended early: {lines} {process.stderr.read()}"
                lines.append(line.rstrip("\n"))

        until(lambda: lines.count("[flaky] up") == 1 and "[steady] ready" in lines)
        started = {l.split()[2].rstrip(":"): int(l.split()[-1]) for l in lines if l.startswith("[launch] started")}
        os.kill(started["flaky"], signal.SIGKILL)
        killed = time.monotonic()
        until(lambda: lines.count("[flaky] up") == 2)
        assert time.monotonic() - killed >= 0.3
        assert "[launch] flaky ended by itself (signal SIGKILL); respawning it in 0.3 s (respawn 1)" in lines
        again = [int(l.split()[-1]) for l in lines if l.startswith("[launch] started flaky")]
        assert len(again) == 2 and again[1] != started["flaky"] and process_alive(again[1])
        assert process_alive(started["steady"])
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=SAFETY_TIMEOUT)
        assert process.returncode == 0, (lines, out, err)
        assert not process_alive(again[1]) and not process_alive(started["steady"])
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


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
        # each node a session of its own, its children in it: the kernel's autogroups weigh every node as one job
        # against a busy session beside the graph, not the graph as one (supervisor._start)
        assert all(os.getsid(pid) == pid for pid in pids.values()), {pid: os.getsid(pid) for pid in pids.values()}
        assert os.getsid(grandchild) == pids["stubborn"]
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
    launch_file = tmp_path / "two.launch.yaml"
    launch_file.write_text(
        textwrap.dedent(
            f"""
            launch:
              - node:
                  pkg: hopper_ros
                  exec: setpoint_scheduler
                  name: scheduler_a
                  param: [{{name: schedule_file, value: {tmp_path / 'schedule.yaml'}}}]
                  sigterm_timeout: 10
              - node:
                  pkg: hopper_ros
                  exec: setpoint_scheduler
                  name: scheduler_b
                  namespace: other
                  param: [{{name: schedule_file, value: {tmp_path / 'schedule.yaml'}}}]
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
        from hopper_ros.launch import ChildSpec, Launcher
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


def _ignored_signals(pid: int) -> set[int]:
    """The signals process `pid` ignores (SigIgn of /proc/PID/status)."""
    from pathlib import Path

    line = next(l for l in Path(f"/proc/{pid}/status").read_text().splitlines() if l.startswith("SigIgn:"))
    mask = int(line.split()[1], 16)
    return {signum for signum in range(1, 65) if mask & (1 << (signum - 1))}


def test_a_launcher_started_with_sigint_ignored_still_stops_its_nodes_with_sigint(tmp_path):
    """`hopper launch FILE &` in a script starts the launcher with SIGINT (and SIGQUIT) ignored;
    its nodes get the default dispositions all the same, and stop on the launcher's SIGINT."""
    from conftest import REPO, SAFETY_TIMEOUT, process_alive

    def as_a_background_job():       # what bash does for `cmd &` without job control
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGQUIT, signal.SIG_IGN)

    process = subprocess.Popen(
        [sys.executable, "-m", "hopper_ros.cli", "launch", str(_two_schedulers(tmp_path))],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        preexec_fn=as_a_background_job,
    )
    try:
        assert {signal.SIGINT, signal.SIGQUIT} <= _ignored_signals(process.pid)
        pids = {}
        while len(pids) < 2:
            line = process.stdout.readline()
            assert line, f"launcher ended early: {process.stderr.read()}"
            if line.startswith("[launch] started"):
                pids[line.split()[2].rstrip(":")] = int(line.split()[-1])
        for label, pid in pids.items():
            assert not {signal.SIGINT, signal.SIGTERM, signal.SIGQUIT} & _ignored_signals(pid), label
        started = 0
        while started < 2:            # both nodes up (their start line comes once rclpy runs)
            line = process.stderr.readline()
            assert line, "launcher ended early"
            started += "started: pid" in line
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=SAFETY_TIMEOUT)
        assert process.returncode == 0, out + err
        assert "sending SIGTERM" not in out                       # SIGINT was enough
        assert err.count("stopping on SIGINT") == 2, err
        assert not any(process_alive(pid) for pid in pids.values())
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
