"""One typed, validated schema per config file (issues 17, 30: pydantic models): hopper_ros/config/schema.py,
hopper_ros/config/schemas.py.

A table of bad configuration files, each given to a node or tool as a user gives it: the process
exits 1 and its stderr is one line naming the file, the key and what is wrong (the audit had 9 of
43 bad files accepted or ending in a traceback: a negative max_torque commanded as feasible, a
negative stiffness or boom length simulated, a missing microcontroller.port a KeyError, `port:
fifteen` naming neither file nor key).
"""

from __future__ import annotations

import copy
import dataclasses
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Annotated, List, Literal

import pytest
import yaml
from pydantic import Field

from conftest import REPO
from hopper_ros.canbus.driver import NODE_KEYS, load_motor_driver
from hopper_ros.config import load_yaml
from hopper_ros.config.schemas import CONTROL, HARDWARE, IDENTIFICATION, MODEL, MOTOR_DRIVER, SCHEDULE, SENSING, SIM
from hopper_ros.control.config import load_control
from hopper_ros.hardware.config import load_hardware
from hopper_ros.config.schema import ConfigError, Section, load_config, unit, validate

DELETE = object()

# ------------------------------------------------------------------ the validator itself


class _A(Section):
    x: float = unit("m", gt=0)
    n: int = 3
    name: Literal["p", "q"]


class _File(Section):
    a: _A
    list: List[Annotated[float, Field(ge=0)]] = Field(min_length=1)


def test_the_validator_names_the_key_and_converts():
    assert validate(_File, {"a": {"x": 1, "name": "p"}, "list": [1, 2.5]}, "f.yaml") == \
        {"a": {"x": 1.0, "n": 3, "name": "p"}, "list": [1.0, 2.5]}
    cases = [({"a": {"x": -1, "name": "p"}, "list": [1]}, "f.yaml: a.x: must be > 0 m, got -1"),
             ({"a": {"x": True, "name": "p"}, "list": [1]}, "f.yaml: a.x: must be a number (> 0 m), got True"),
             ({"a": {"x": float("nan"), "name": "p"}, "list": [1]}, "f.yaml: a.x: must be finite"),
             ({"a": {"x": 1, "n": 2.5, "name": "p"}, "list": [1]}, "f.yaml: a.n: must be an integer, got 2.5"),
             ({"a": {"x": 1, "name": "r"}, "list": [1]}, "f.yaml: a.name: must be one of ['p', 'q'], got 'r'"),
             ({"a": {"name": "p"}, "list": [1]}, "f.yaml: a.x: missing (required: a number (> 0 m))"),
             ({"a": {"x": 1, "name": "p", "y": 2}, "list": [1]}, "f.yaml: a.y: unknown key; known here: x, n, name"),
             ({"a": {"x": 1, "name": "p"}, "list": [-1]}, "f.yaml: list[0]: must be >= 0, got -1"),
             ({"a": {"x": 1, "name": "p"}, "list": []}, "f.yaml: list: must hold at least 1 entries, got 0"),
             ([1, 2], "f.yaml: the file: must be a mapping of keys")]
    for data, message in cases:
        with pytest.raises(ConfigError) as info:
            validate(_File, data, "f.yaml")
        assert str(info.value).startswith(message), (str(info.value), message)
        assert "\n" not in str(info.value)


@pytest.mark.parametrize("name,schema", [
    ("hardware.yaml", HARDWARE), ("demo/hardware_500hz.yaml", HARDWARE), ("model.yaml", MODEL), ("sim.yaml", SIM),
    ("sensing.yaml", SENSING), ("control.yaml", CONTROL), ("motor_driver.yaml", MOTOR_DRIVER),
    ("demo/motor_driver_500hz.yaml", MOTOR_DRIVER),
    ("identification.yaml", IDENTIFICATION),
    ("setpoints/fig5_5.yaml", SCHEDULE)])
def test_every_shipped_config_file_passes_its_schema(name, schema):
    load_config(name, schema)


@pytest.mark.parametrize("name", ["hardware.yaml", "demo/hardware_500hz.yaml"])
def test_the_typed_hardware_config_holds_exactly_the_checked_file(name):
    typed = dataclasses.asdict(load_hardware(name))
    for key, encoder in typed["encoders"].items():
        assert encoder.pop("name") == key
    typed["can"] = {key: value for key, value in typed["can"].items() if value is not None}
    checked = load_config(name, HARDWARE)
    assert typed == checked
    assert all(type(typed[s][k]) is type(v) for s in checked for k, v in checked[s].items() if s != "encoders")


@pytest.mark.parametrize("name", ["motor_driver.yaml", "demo/motor_driver_500hz.yaml"])
def test_the_typed_motor_driver_config_holds_the_checked_file(name):
    config, checked = load_motor_driver(name), load_config(name, MOTOR_DRIVER)["motor_driver"]
    typed = {**dataclasses.asdict(config.driver), **{key: getattr(config, key) for key in NODE_KEYS}}
    assert {key: typed[key] for key in checked} == checked


def test_the_typed_control_config_holds_the_checked_file():
    config, checked = load_control(), load_config("control.yaml", CONTROL)
    assert dataclasses.asdict(config.deadbeat) == checked["deadbeat"]
    assert {key: getattr(config.stride, key) for key in checked["stride"]} == checked["stride"]


# ------------------------------------------------------------------ bad files given to nodes and tools

# file -> how each consumer is told to read it
CONSUMERS = {
    "sim_robot:sim": ("sim.yaml", ["run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", "sim_file:={}"]),
    "sim_robot:hardware": ("hardware.yaml", ["run", "sim_robot", "--ros-args", "-p", "can:=none", "-p", "hardware_file:={}"]),
    "motor_driver:config": ("motor_driver.yaml", ["run", "motor_driver", "--ros-args", "-p", "config_file:={}"]),
    "motor_driver:hardware": ("hardware.yaml", ["run", "motor_driver", "--ros-args", "-p", "hardware_file:={}"]),
    "deadbeat_controller:config": ("control.yaml", ["run", "deadbeat_controller", "--ros-args", "-p", "config_file:={}"]),
    "deadbeat_controller:model": ("model.yaml", ["run", "deadbeat_controller", "--ros-args", "-p", "model_file:={}"]),
    "stride_predictor:model": ("model.yaml", ["run", "stride_predictor", "--ros-args", "-p", "model_file:={}"]),
    "encoder_bridge:sensing": ("sensing.yaml", ["run", "encoder_bridge", "--ros-args", "-p", "sensing_file:={}"]),
    "encoder_bridge:hardware": ("hardware.yaml", ["run", "encoder_bridge", "--ros-args", "-p", "hardware_file:={}"]),
    "state_estimator:sensing": ("sensing.yaml", ["run", "state_estimator", "--ros-args", "-p", "sensing_file:={}"]),
    "state_estimator:hardware": ("hardware.yaml", ["run", "state_estimator", "--ros-args", "-p", "hardware_file:={}"]),
    "event_detector:sensing": ("sensing.yaml", ["run", "event_detector", "--ros-args", "-p", "sensing_file:={}"]),
    "event_detector:model": ("model.yaml", ["run", "event_detector", "--ros-args", "-p", "model_file:={}"]),
    "setpoint_scheduler:schedule": ("setpoints/fig5_5.yaml", ["run", "setpoint_scheduler", "--ros-args", "-p", "schedule_file:={}"]),
    "identify:config": ("identification.yaml", ["identify", "--no-progress", "--config", "{}", "missing.csv"]),
    "report:config": ("identification.yaml", ["report", "{out}", "--config", "{}", "--no-grf"]),
    "diagnose:model": ("model.yaml", ["diagnose", "--model", "{}", "missing.csv"]),
    "predictors:model": ("model.yaml", ["predictors", "-n", "10", "--model", "{}", "-o", "{out}"]),
    "collect:sim": ("sim.yaml", ["collect", "-n", "1", "-o", "{out}", "--sim", "{}"]),
    "collect:hardware": ("hardware.yaml", ["collect", "-n", "1", "-o", "{out}", "--hardware", "{}"]),
}

# (consumer, key path, new value or DELETE, words the line must hold)
CASES = [
    ("deadbeat_controller:config", "deadbeat.max_torque", -12.0, "must be > 0 N m, got -12"),
    ("deadbeat_controller:config", "deadbeat.min_torque", 13.0, "must be above min_torque"),
    ("deadbeat_controller:config", "deadbeat.predictor", "magic", "must be one of"),
    ("deadbeat_controller:config", "deadbeat.adaptation_gain", 1.5, "must be <= 1, got 1.5"),
    ("deadbeat_controller:config", "deadbeat.max_angle", 2.0, "must be < 1.5708 rad"),
    ("deadbeat_controller:config", "deadbeat.angle_points", 2.5, "must be an integer"),
    ("deadbeat_controller:config", "stride.keep_alive", 0.0, "must be > 0 s"),
    ("deadbeat_controller:config", "stride.keepalive", 0.003, "unknown key"),
    ("deadbeat_controller:model", "model.stiffness", -10.0, "must be > 0 N/m"),
    ("stride_predictor:model", "model.body_mass", "heavy", "must be a number"),
    ("stride_predictor:model", "model.rest_length", DELETE, "missing"),
    ("event_detector:model", "model.damping", -1.0, "must be >= 0 N s/m"),
    ("diagnose:model", "model.gravity", 0.0, "must be > 0 m/s^2"),
    ("predictors:model", "model.toe_mas", 0.03, "unknown key"),
    ("sim_robot:sim", "sim.physics.stiffness", -4696.0, "must be > 0 N/m"),
    ("sim_robot:sim", "sim.period", 0.0, "must be > 0 s"),
    ("sim_robot:sim", "sim.substeps", 0, "must be >= 1"),
    ("sim_robot:sim", "sim.initial_apex.apex_height", -0.4, "must be > 0 m"),
    ("sim_robot:sim", "sim.sensors.encoder_noise.enabled", "yes", "must be true or false"),
    ("sim_robot:sim", "sim.force_plate", DELETE, "missing"),
    ("collect:sim", "sim.physics.body_mass", 0.0, "must be > 0 kg"),
    ("sim_robot:sim", "sim.physics.toe_mass", -0.03, "must be >= 0 kg"),
    ("collect:sim", "sim.physics.flight_damping_vertical", -0.2, "must be >= 0 1/s"),
    ("collect:sim", "sim.physics.rest_length", 0.0, "must be > 0 m"),
    ("sim_robot:sim", "sim.physics.gravity", DELETE, "missing"),
    ("collect:sim", "sim.effects.leg_fiction", {"enabled": True, "F_c": 2.0}, "unknown effect 'leg_fiction'"),
    ("sim_robot:sim", "sim.effects.leg_friction.F_c", -2.0, "must be a non-negative number [N]"),
    ("sim_robot:hardware", "boom.length", -1.65, "must be > 0 m"),
    ("sim_robot:hardware", "microcontroller.port", DELETE, "missing (required: an integer"),
    ("encoder_bridge:hardware", "microcontroller.port", "fifteen", "must be an integer (>= 1 and <= 65535), got 'fifteen'"),
    ("state_estimator:hardware", "encoders.azimuth.lines", 0, "must be > 0 lines"),
    ("motor_driver:hardware", "drive.node_id", 200, "must be <= 127"),
    ("motor_driver:hardware", "drive.continuous_current", 30.0, "must not exceed current_limit"),
    ("motor_driver:hardware", "motor.torque_constant", -0.02, "must be > 0 N m/A"),
    ("collect:hardware", "encoders.motor.direction", 2, "must be one of [-1, 1]"),
    ("motor_driver:config", "motor_driver.command_timeout", -0.01, "must be > 0 s"),
    ("motor_driver:config", "motor_driver.comand_timeout", 0.01, "unknown key"),
    ("motor_driver:config", "motor_driver.command_timeout", 0.0005, "must be longer than sync_period"),
    ("motor_driver:config", "motor_driver.master_node_id", 0, "must be >= 1"),
    ("encoder_bridge:sensing", "sensing.bridge.resync_after", 1, "must be >= 2 packets"),
    ("encoder_bridge:sensing", "sensing.queue_depth", "deep", "must be an integer"),
    ("state_estimator:sensing", "sensing.estimator.measurement_noise", "guess", "must be one of"),
    ("state_estimator:sensing", "sensing.estimator.outlier_gate", DELETE, "missing"),
    ("event_detector:sensing", "sensing.detector.track_velocity_std", 0.01, "must not exceed track_velocity_std"),
    ("event_detector:sensing", "sensing.detector.acquire_windw", 0.02, "unknown key"),
    ("setpoint_scheduler:schedule", "segments", [], "must hold at least 1 entries"),
    ("setpoint_scheduler:schedule", "repeat", "yes", "must be true or false"),
    ("identify:config", "identification.folds", 1, "must be >= 2"),
    ("identify:config", "identification.fitted", ["gravity", "gravity"], "names an entry twice"),
    ("identify:config", "identification.bounds.stiffness", [5000.0, 500.0], "low < high"),
    ("report:config", "identification.predictor", "best", "must be one of"),
    ("report:config", "identification.nelder_mead.max_evaluations", 5, "must be >= 10"),
    ("identify:config", "identification.effects", ["leg_fiction"], "unknown effect 'leg_fiction'"),
    ("identify:config", "identification.effects", ["leg_stiffness"], "leg_stiffness sets stiffness"),
    ("report:config", "identification.effects", "leg_friction", "must be a list"),
    ("identify:config", "identification.lanes.step", 0.01, "must be <= 0.002 s"),
    ("report:config", "identification.lanes.batch_lanes", 0, "must be >= 1 lanes"),
    ("identify:config", "identification.lanes.max_iteration", 30, "unknown key"),
    ("diagnose:model", "effects", {"leg_fiction": 1.0}, "effects.leg_fiction: unknown effect"),
    ("stride_predictor:model", "effects", {"leg_friction": "strong"}, "effects.leg_friction must be a number"),
]
# the key the error names: where the check lands (a cross-key check names the later key)
NAMED_KEY = {"deadbeat.min_torque": "deadbeat.max_torque", "sim.effects.leg_fiction": "sim.effects",
             "effects": "effects.leg_f",
             "sensing.detector.track_velocity_std": "sensing.detector.acquire_velocity_std",
             "motor_driver.command_timeout@0.0005": "motor_driver.command_timeout"}


def _mutated(base: str, path: str, value) -> dict:
    data = copy.deepcopy(load_yaml(base))
    keys = path.split(".")
    node = data
    for key in keys[:-1]:
        node = node[key]
    if value is DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return data


def _run(case, tmp: Path) -> tuple:
    consumer, path, value, words = case
    base, argv = CONSUMERS[consumer]
    folder = tmp / f"{consumer.replace(':', '_')}_{path}_{abs(hash(repr(value))) % 10**6}"
    folder.mkdir()
    bad = folder / Path(base).name
    bad.write_text(yaml.safe_dump(_mutated(base, path, value), sort_keys=False))
    args = [a.format(bad, out=folder / "out") if "{}" in a else a.replace("{out}", str(folder / "out")) for a in argv]
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONFAULTHANDLER="1")   # a crash says where
    result = subprocess.run([sys.executable, "-m", "hopper_ros.cli", *args], capture_output=True, text=True,
                            timeout=120, env=env, cwd=folder)
    return case, bad, result


def test_a_model_file_with_library_effects_passes_its_schema(tmp_path):
    """An identified model with effects (`hopper identify --effects`): the nodes read its parameters."""
    import math

    from hopper_ros.config.schemas import load_model
    from hopper_ros.physics.params import load_params, save_params

    path = save_params(load_params(), tmp_path / "identified.yaml",
                       effects={"leg_friction": 2.5, "torque_saturation": math.inf})
    assert load_model(path) == load_params()


def test_a_table_of_bad_config_files_across_every_node_and_tool(tmp_path):
    assert len(CASES) >= 40
    assert {c[0] for c in CASES} == set(CONSUMERS)                       # every node and tool that reads one
    with ThreadPoolExecutor(max_workers=4) as pool:
        results = list(pool.map(lambda case: _run(case, tmp_path), CASES))
    failures = []
    for (consumer, path, value, words), bad, result in results:
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        key = NAMED_KEY.get(f"{path}@{value}", NAMED_KEY.get(path, path))
        ok = (result.returncode == 3 and len(lines) == 1 and "Traceback" not in result.stderr
              and str(bad) in lines[0] and f"{key}" in lines[0] and words in lines[0])
        if not ok:
            failures.append(f"{consumer} {path}={value!r}: exit {result.returncode}, stderr {result.stderr[-600:]!r}")
    assert not failures, "\n".join(failures)
