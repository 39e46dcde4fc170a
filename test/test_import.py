"""Bring your own robot (issue 31): another robot's bag of standard messages -> `hopper import`, and
`hopper diagnose` -> `hopper identify` -> `hopper diagnose` with an effect concealed in the robot (named, then
modelled); without one, `identify` -> `diagnose` finds the robot's parameters and nothing missing.

The robot is config/robots/hopper_b/ (other masses, spring, leg length and boom than the thesis's),
simulated by hopper_ros/sim configured with its model file and its boom, an effect switched on that
its model lacks, every sensor noise on. Its recording is written by an independent writer, rosbags,
as a researcher's robot would record it: sensor_msgs/JointState (boom joints and the hip, the hip
turning the other way round) and geometry_msgs/PointStamped (the body in mm from the boom's pivot
height) at 500 Hz, header stamps, gaps between the experiments.
"""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hopper_ros.hardware.config import load_hardware
from hopper_ros.harness.collect import CollectionSettings, collect
from hopper_ros.physics.aas import predict_aas
from hopper_ros.physics.params import load_params
from hopper_ros.recording.mapping import noise_level
from hopper_ros.recording.recordings import load_csv
from hopper_ros.sim.config import SENSORS, load_sim_config

pytestmark = pytest.mark.compute   # CPU-bound: `make test` runs these beside the node tests (tools/test.sh)

ROBOT = "robots/hopper_b/model.yaml"
HARDWARE = "robots/hopper_b/hardware.yaml"
CONCEALED = "quadratic_drag"
STRIDES = 30
REPO = Path(__file__).resolve().parent.parent
PIVOT = 0.16          # [m] the boom's parallel_height: PointStamped's z is measured from there, in mm

MAPPING = (REPO / "config" / "robots" / "hopper_b" / "import_map.yaml").read_text()   # the shipped example


def draws(params, seed: int):
    """Apex, speed, touchdown angle, tau_0 and t_f for the longer leg (the thesis's ranges, heights moved up)."""
    rng = np.random.default_rng(seed)
    while True:
        h, v = rng.uniform(0.32, 0.45), rng.uniform(0.9, 2.4)
        angle, tau = rng.uniform(math.radians(10), math.radians(40)), rng.uniform(3.0, 8.0)
        stance = float(predict_aas(params, h, v, angle, tau).stance_time)
        yield h, v, angle, tau, stance if math.isfinite(stance) else 0.1


def write_rosbags_bag(folder: Path, rec, every: int = 2) -> Path:
    """The 1 kHz recording as the other robot's 500 Hz bag, written by rosbags (MCAP)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    JointState = store.types["sensor_msgs/msg/JointState"]
    PointStamped = store.types["geometry_msgs/msg/PointStamped"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    Point = store.types["geometry_msgs/msg/Point"]
    hw = load_hardware(HARDWARE).boom
    origin = 1_700_000_000 * 10**9
    bag = folder / "hopper_b_bag"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        joints = writer.add_connection("/hopper_b/joint_states", JointState.__msgtype__, typestore=store)
        body = writer.add_connection("/hopper_b/body", PointStamped.__msgtype__, typestore=store)
        for i in range(0, len(rec), every):
            ns = origin + int(round(rec.t[i] * 1e9))
            header = Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="boom_pivot")
            azimuth = rec.y[i] / (hw.length + hw.leg_offset)
            elevation = math.asin((rec.z[i] + hw.ground_height - hw.parallel_height) / hw.length)
            js = JointState(header=header, name=["boom_yaw", "boom_pitch", "hip"],
                            position=np.array([azimuth, elevation, -rec.theta[i]]),
                            velocity=np.zeros(0), effort=np.array([0.0, 0.0, -rec.tau[i]]))
            writer.write(joints, ns + 20_000, store.serialize_cdr(js, JointState.__msgtype__))
            point = Point(x=rec.y[i] * 1e3, y=0.0, z=(rec.z[i] - PIVOT) * 1e3)
            writer.write(body, ns + 30_000, store.serialize_cdr(PointStamped(header=header, point=point),
                                                                PointStamped.__msgtype__))
    return bag


def hopper(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "hopper_ros.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def robot_b(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hopper_b")
    params = load_params(ROBOT)
    cfg = (load_sim_config().with_physics(**params.as_dict()).with_sensors(**{s: True for s in SENSORS})
           .with_effects(**{CONCEALED: True}))
    c = collect(folder / "sim_bag", cfg, load_hardware(HARDWARE), CollectionSettings(strides=STRIDES, seed=1),
                csv_path=folder / "truth.csv", draws=draws(params, 5))
    rec = load_csv(c.csv)
    bag = write_rosbags_bag(folder, rec)
    mapping = folder / "hopper_b_map.yaml"
    mapping.write_text(MAPPING)
    return folder, rec, bag, mapping, cfg.enabled_effects()[CONCEALED]


def test_import_writes_the_table_and_says_what_it_did(robot_b):
    folder, rec, bag, mapping, _ = robot_b
    out = folder / "imported.csv"
    proc = hopper("import", bag, "--map", mapping, "-o", out)
    assert proc.returncode == 0, proc.stderr
    assert "import: 500 Hz recorded: resampled to 1000 Hz" in proc.stdout, proc.stdout
    assert f"{len(rec.segments()) - 1} gap(s)" in proc.stdout, proc.stdout
    imported = load_csv(out)
    assert imported.period == pytest.approx(1e-3, rel=1e-6)
    # the recorded samples come back in SI at their instants: the torque as it was, the positions with the
    # noise near the new Nyquist frequency that makes their noise estimate the 500 Hz sensor's (x sqrt 2)
    t0 = rec.t[0]
    assert len(imported.segments()) == len(rec.segments())
    at = np.searchsorted(imported.t, rec.t[::2] - t0 - 1e-7)
    kept = np.abs(imported.t[np.clip(at, 0, len(imported) - 1)] - (rec.t[::2] - t0)) < 1e-7
    assert kept.mean() > 0.99
    idx = at[kept]
    np.testing.assert_allclose(imported.tau[idx], rec.tau[::2][kept], atol=1e-9)
    for name in ("y", "z", "theta"):
        recorded = getattr(rec, name)[::2]
        sigma = noise_level(recorded)
        difference = getattr(imported, name)[idx] - recorded[kept]
        assert 0.2 * sigma < np.std(difference) < 1.2 * sigma, name
        assert noise_level(getattr(imported, name)) == pytest.approx(math.sqrt(2) * sigma, rel=0.15), name
    # the samples between them: within the noise of the 1 kHz truth
    odd = np.searchsorted(imported.t, rec.t[1::2] - t0 - 1e-7)
    inside = np.abs(imported.t[np.clip(odd, 0, len(imported) - 1)] - (rec.t[1::2] - t0)) < 1e-7
    assert np.std(imported.z[odd[inside]] - rec.z[1::2][inside]) < 3 * noise_level(rec.z)


def test_import_diagnose_identify_diagnose_names_and_models_the_concealed_effect(robot_b, tmp_path):
    """The researcher's loop on the other robot's bag: diagnose against the robot's own model file names the
    concealed effect; identify fits it with the parameters (the robot's weighed mass and measured leg held);
    diagnose against the identified model no longer misses it, and predicts the held-out apexes better."""
    folder, rec, bag, mapping, magnitude = robot_b
    proc = hopper("diagnose", bag, "--map", mapping, "--model", ROBOT, "-q", "--json", tmp_path / "first.json")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "hopper diagnose: import: 500 Hz recorded: resampled to 1000 Hz" in proc.stderr
    first = json.loads((tmp_path / "first.json").read_text())
    assert [entry["name"] for entry in first["verdict"]] == [CONCEALED], proc.stdout
    assert first["verdict"][0]["magnitude"] == pytest.approx(magnitude, rel=0.2)

    proc = hopper("identify", bag, "--map", mapping, "--model", ROBOT, "--effects", CONCEALED, "--folds", "3",
                  "--no-progress", "-o", tmp_path / "id", "--json", tmp_path / "id.json")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    model = tmp_path / "id" / "identified_model.yaml"
    identified = load_params(model)
    truth = load_params(ROBOT)
    assert identified.body_mass == truth.body_mass and identified.rest_length == truth.rest_length   # held
    for name in ("stiffness", "gravity", "damping"):
        assert getattr(identified, name) == pytest.approx(getattr(truth, name), rel=0.1), name
    doc = json.loads((tmp_path / "id.json").read_text())
    assert doc["parameters"]["stiffness"]["value"] == pytest.approx(identified.stiffness, rel=1e-6)
    assert doc["effects"][CONCEALED]["value"] == pytest.approx(magnitude, rel=0.2)

    proc = hopper("diagnose", bag, "--map", mapping, "--model", model, "-q", "--json", tmp_path / "again.json")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    again = json.loads((tmp_path / "again.json").read_text())
    assert CONCEALED not in [entry["name"] for entry in again["verdict"]], proc.stdout
    assert again["held_out"]["before"]["E_p"] < first["held_out"]["before"]["E_p"]


@pytest.fixture(scope="module")
def clean_robot_b(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hopper_b_clean")
    params = load_params(ROBOT)
    cfg = load_sim_config().with_physics(**params.as_dict()).with_sensors(**{s: True for s in SENSORS})
    c = collect(folder / "sim_bag", cfg, load_hardware(HARDWARE), CollectionSettings(strides=STRIDES, seed=1),
                csv_path=folder / "truth.csv", draws=draws(params, 5))
    bag = write_rosbags_bag(folder, load_csv(c.csv))
    mapping = folder / "hopper_b_map.yaml"
    mapping.write_text(MAPPING)
    return bag, mapping


def test_identify_then_diagnose_on_the_other_robot(clean_robot_b, tmp_path):
    """Nothing concealed: identify (from plain guesses, the weighed and measured values held) finds the other
    robot's parameters, and diagnose against them finds nothing missing. (The same strides as the concealed
    effect's. Drawn with other seeds, seed 2 and draws 6, the diagnosis flags the leg angle in decompression at
    11 x the noise level by trajectory, on the 1 kHz original against the true model as well: the trajectory
    test's yardstick, docs/diagnosis.md, not the import.)"""
    bag, mapping = clean_robot_b
    proc = hopper("identify", bag, "--map", mapping, "--model", ROBOT, "-p", "corrected", "--folds", "3",
                  "--no-progress", "-o", tmp_path / "id")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    identified = load_params(tmp_path / "id" / "identified_model.yaml")
    truth = load_params(ROBOT)
    for name, tolerance in (("stiffness", 0.03), ("gravity", 0.01), ("damping", 0.1), ("toe_mass", 0.2)):
        assert getattr(identified, name) == pytest.approx(getattr(truth, name), rel=tolerance), name
    proc = hopper("diagnose", bag, "--map", mapping, "--model", tmp_path / "id" / "identified_model.yaml", "-q")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "no significant mismatch" in proc.stdout.splitlines(), proc.stdout


def test_the_other_robots_files_are_valid_and_agree():
    """hopper_b's model file and boom pass their schemas; its gravity is (4.7) for its boom; its boom reaches
    every height the robot hops at, with a finer resolution than the thesis's (a longer boom, same encoders)."""
    from hopper_ros.config.schemas import load_model
    from hopper_ros.hardware.encoders import BoomKinematics
    from hopper_ros.physics.boom import boom_effective_gravity

    model = load_model(ROBOT)
    thesis = load_params()
    assert all(getattr(model, n) != getattr(thesis, n) for n in ("body_mass", "toe_mass", "stiffness", "rest_length"))
    assert model.gravity == pytest.approx(boom_effective_gravity(model.body_mass + model.toe_mass, 2.0), abs=0.01)
    boom = BoomKinematics.from_config(load_hardware(HARDWARE))
    assert boom.boom_length != BoomKinematics.from_config(load_hardware()).boom_length
    for z in (0.15, 0.25, 0.5):
        y_step, z_step = boom.position_resolution(z)
        assert 0 < z_step < 3e-4 and 0 < y_step < 3e-4
        boom.counts(1.0, z, 0.3)                                  # within the boom's reach
