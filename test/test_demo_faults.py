"""Issue 29: a node of the demo graph killed mid-run, on the real processes (launch/demo.launch.yaml
under `hopper launch`, every node respawned). The estimator and the controller (one container in the
demo): killed with SIGKILL, the command stream stops, the motor driver's watchdog disables the
drive (how soon: bench_demo_respawn), nothing else ends, the container comes back and its
controller enables the drive again. The robot stays held (the bench throws it and kills every
node: bench/bench_demo_respawn.py)."""

from __future__ import annotations

import os

from hopper_ros.hardware.config import load_hardware
from hopper_ros.runtime.environment import realtime_scheduling_allowed
from hopper_ros.harness.live_graph import LiveGraph


def test_killing_the_estimator_and_controller_container_disables_the_drive_and_it_comes_back(tmp_path):
    arguments = () if realtime_scheduling_allowed()[0] else ("realtime_priority:=0", "robot_priority:=0",
                                                             "driver_priority:=0")
    with LiveGraph("demo.launch.yaml", tmp_path, arguments, env=dict(os.environ)) as graph:
        assert graph.wait_up(), graph.log_lines(0)[-20:]
        # its robot on ports of its own: this graph beside a demo once took over the demo's drive
        lines = [line for t, line in graph.log_lines(0)]
        assert graph.can_port != load_hardware().can.port
        assert any(f"CAN hub on 127.0.0.1:{graph.can_port}" in line for line in lines)
        assert any(f"socketcand on can0@127.0.0.1:{graph.can_port}" in line for line in lines)
        kill = graph.kill("sensing")
        assert kill.respawned_at > kill.killed_at and kill.up_again_at > kill.respawned_at
        assert kill.others_ended == []
        # the drive goes off after the last command it had, by the driver's watchdog (the stream stopped);
        # how soon (within 20 ms here) is bench_demo_respawn's respawn_sensing_drive_off_ms, not a timed test
        assert kill.drive_off_ms > 0.0, kill
        after = [line for t, line in graph.log_lines(kill.killed_at)]
        assert any("no motor command for" in line and "then disable" in line for line in after), after[-20:]
        assert graph.wait_up(30.0), "the drive was not enabled again"
        assert graph.process.poll() is None
