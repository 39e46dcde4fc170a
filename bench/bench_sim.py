"""The simulated robot's speed, all effects on (config/sim.yaml's effects, every one enabled).

- sim_realtime_factor: the sim_robot node in its own process, lockstep mode, running section
  4.1's single-stride experiments itself: simulated time over wall time, with everything a
  period costs (physics, regulator, UDP packet, force plate and ground truth published on ROS).
  Target >= 20 (issue 27: the plant's step compiled by numba, `hopper_ros.sim.plant.kernel`).
- sim_realtime_factor_python: the same run with the plant's step in Python (HOPPER_LANES=numpy, as
  where numba is missing), measured beside it.
- sim_realtime_mode_factor: the same in real-time mode, which must pace at 1.0 (it was a unit
  test's assertion; timing lives here).
- sim_period_p50_us / sim_period_p99_us: cost of one 1 ms period in Python alone (SimRobot.step
  with the experiment, packet encoded and sent over UDP), distribution over the run.
- sim_vs_exact_max_err_pct: largest apex-to-apex difference (height or speed) between the
  lockstep sim with the extra effects off and the exact model at the same inputs (target < 0.1).
"""
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

from _common import child_env, percentile  # noqa: E402 - bench/ is on sys.path (the script's folder)

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from hopper_ros.hardware import packet as packet_format  # noqa: E402
from hopper_ros.hardware.config import load_hardware  # noqa: E402
from hopper_ros.physics.evaluation import sample_thesis_strides  # noqa: E402
from hopper_ros.physics.exact import simulate_stride  # noqa: E402
from hopper_ros.sim.config import EFFECTS, load_sim_config  # noqa: E402
from hopper_ros.sim.experiment import ExperimentSeries, StrideExperiment, drive_hold  # noqa: E402
from hopper_ros.sim.robot import SimRobot  # noqa: E402


def node_realtime_factor(duration: float, mode: str = "lockstep", python_plant: bool = False) -> float:
    """The sim_robot node's own simulated-over-wall time for a run of `duration` simulated seconds (`python_plant`:
    the plant's step in Python, not compiled)."""
    effects = "[" + ", ".join(EFFECTS) + "]"
    env = child_env(unbuffered=True)
    if python_plant:
        env["HOPPER_LANES"] = "numpy"
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        command = [sys.executable, "-m", "hopper_ros.cli", "run", "sim_robot", "--ros-args",
                   "-p", f"mode:={mode}", "-p", "can:=none", "-p", "experiments:=true",
                   "-p", f"duration:={duration}", "-p", f"enable_effects:={effects}",
                   "-p", f"udp_port:={sink.getsockname()[1]}"]
        result = subprocess.run(command, cwd=REPO, env=env, capture_output=True, text=True, timeout=600)
    match = re.search(r"real-time factor ([0-9.]+)", result.stderr)
    if result.returncode != 0 or not match:
        raise RuntimeError(f"sim_robot failed ({result.returncode}):\n{result.stderr[-2000:]}")
    return float(match.group(1))


def period_costs(duration: float) -> list[float]:
    hardware = load_hardware()
    config = load_sim_config().with_effects(**{name: True for name in EFFECTS})
    robot = SimRobot(config, hardware)
    series = ExperimentSeries(robot, seed=3)
    costs = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sink:
        sink.bind(("127.0.0.1", 0))
        address = sink.getsockname()
        for _ in range(int(duration / config.period)):
            start = time.perf_counter()
            if robot.experiment is None or robot.experiment.done:
                series.start_next()
            sample = robot.step()
            sender.sendto(packet_format.encode(sample.packet), address)
            costs.append(time.perf_counter() - start)
    return costs


def exact_agreement(count: int) -> float:
    hardware = load_hardware()
    config = load_sim_config().all_effects_off()
    params = config.model_params()
    worst = 0.0
    for apex_height, speed, angle, tau_0, ramp in zip(*sample_thesis_strides(params, count, seed=11).columns()):
        robot = SimRobot(config, hardware)
        robot.throw(apex_height, speed, angle)
        experiment = StrideExperiment(tau_0, angle, ramp, drive_hold(hardware), config.pre_touchdown_height)
        robot.run_experiment(experiment)
        robot.run_until(lambda sample: experiment.done, 3.0)
        realised = experiment.event("touchdown")
        if realised is None or experiment.fell:
            continue
        exact = simulate_stride(params, apex_height, speed, realised.leg_angle, tau_0, ramp)
        if not exact.ok:
            continue
        apex = experiment.next_apex
        worst = max(worst, abs(apex.z / exact.next_apex.z - 1.0), abs(apex.ydot / exact.next_apex.ydot - 1.0))
    return 100.0 * worst


def run(quick=False):
    costs = period_costs(2.0 if quick else 10.0)
    return [
        {"name": "sim_realtime_factor", "value": node_realtime_factor(5.0 if quick else 30.0), "unit": "x"},
        {"name": "sim_realtime_factor_python", "value": node_realtime_factor(5.0 if quick else 30.0, python_plant=True),
         "unit": "x"},
        {"name": "sim_realtime_mode_factor", "value": node_realtime_factor(3.0, "realtime"), "unit": "x"},
        {"name": "sim_period_p50_us", "value": 1e6 * percentile(costs, 0.5), "unit": "us"},
        {"name": "sim_period_p99_us", "value": 1e6 * percentile(costs, 0.99), "unit": "us"},
        {"name": "sim_vs_exact_max_err_pct", "value": exact_agreement(20 if quick else 100), "unit": "%"},
    ]


if __name__ == "__main__":
    for figure in run(quick="--quick" in sys.argv):
        print(figure)
