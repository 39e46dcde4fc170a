"""A node of the demo that dies mid-run (issue 29): kill -9 each process of launch/demo.launch.yaml in
turn while the robot hops, and see what happens.

The graph under `hopper launch` (every node `respawn: true`, `respawn_delay: 1.0`), followed from
this process (hopper_ros/harness/live_graph.py: a monitor node, a spy on the simulated robot's CAN
hub). Per process, in this order (the robot hopping before each: thrown, four strides):
sensing (the container of encoder_bridge, state_estimator, event_detector, deadbeat_controller),
setpoint_scheduler, motor_driver, sim_robot. Figures per process:
- `respawn_<node>_drive_off_ms`: from the last motor command the drive had to the drive switched off:
  the driver's log (its watchdog: "no motor command for X ms", then the drive's own report of
  SWITCH ON DISABLED); a killed driver: from its last frame on the bus to the drive's EMCY of its
  heartbeat consumer (0x8130). NaN where the command stream did not stop (the scheduler) or the
  drive died with the robot (sim_robot);
- `respawn_<node>_s`: from the kill to the node doing its work again (estimates and a controller
  hearing apexes; the drive's status; the latched setpoint; estimates from the new robot);
- `respawn_<node>_resumed`: 1 when the robot, thrown again, hopped four strides without a fall;
- `respawn_<node>_others_ended`: other processes that ended meanwhile (the driver, whose hub died
  with the robot, ends and is respawned by design).
The launch output is bench/out/demo_respawn/launch.log.
"""
import os
import sys
import time

from _common import REPO  # noqa: E402 (bench/ is on sys.path)

sys.path.insert(0, str(REPO))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from hopper_ros.runtime.environment import apply_ros_environment, free_domain_id  # noqa: E402

ORDER = ("sensing", "setpoint_scheduler", "motor_driver", "sim_robot")
STRIDES = 4


def run(quick=False):
    os.environ["ROS_DOMAIN_ID"] = str(free_domain_id(77))
    apply_ros_environment()
    from hopper_ros.harness.live_graph import LiveGraph

    out = REPO / "bench" / "out" / "demo_respawn"
    figures = []
    started = time.monotonic()
    with LiveGraph("demo.launch.yaml", out) as graph:
        if not graph.wait_up():
            raise RuntimeError(f"the demo graph did not come up (see {out / 'launch.log'})")
        graph.start_spy(graph.can_port)
        if not graph.hop(STRIDES, throw=True):
            raise RuntimeError("the robot did not hop before the first kill")
        for label in ORDER:
            kill = graph.kill(label)
            graph.wait_up(enabled=False)
            resumed = graph.hop(STRIDES, throw=True)
            print(f"  {label}: drive off {kill.drive_off_ms:.1f} ms after the last command, back in "
                  f"{kill.respawn_s:.1f} s, hopping {'resumed' if resumed else 'NOT resumed'} after a throw"
                  + (f", also ended: {', '.join(kill.others_ended)}" if kill.others_ended else ""), flush=True)
            figures += [
                {"name": f"respawn_{label}_drive_off_ms", "value": kill.drive_off_ms, "unit": "ms"},
                {"name": f"respawn_{label}_s", "value": kill.respawn_s, "unit": "s"},
                {"name": f"respawn_{label}_resumed", "value": int(resumed), "unit": "1 = hopping again"},
                {"name": f"respawn_{label}_others_ended", "value": len(kill.others_ended), "unit": "processes"},
            ]
    figures.append({"name": "respawn_bench_s", "value": time.monotonic() - started, "unit": "s"})
    return figures


if __name__ == "__main__":
    for figure in run():
        print(figure)
