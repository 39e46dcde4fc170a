"""Mapping files and what `hopper import` does with bad ones and bad recordings: one line naming the file,
the key or topic, and what is wrong (issue 31). CSVs with their own names and rates; other message types
(PoseStamped, Odometry) written by rosbags; the generic decoder against rosbags' own decoding."""

import math
import subprocess
import sys

import numpy as np
import pytest

from hopper_ros.recording.mapping import load_mapped, load_mapping
from hopper_ros.recording.recordings import RecordingError
from hopper_ros.config.schema import ConfigError

BAG_MAP = """\
import:
  channels:
    y:     {topic: /odom, field: pose.pose.position.x, unit: m}
    z:     {topic: /odom, field: pose.pose.position.z, unit: cm}
    theta: {topic: /joints, field: "position[hip]", unit: deg}
    tau:   {topic: /joints, field: "effort[hip]", unit: N m}
"""


def hopping(rate: float, seconds: float = 2.0, gap_at: float | None = None):
    """A hopping-like motion at `rate` Hz: t, y [m], z [m], theta [rad], tau [N m]."""
    t = np.arange(0.0, seconds, 1.0 / rate)
    if gap_at is not None:
        t = np.where(t > gap_at, t + 0.5, t)
    y = 1.5 * t
    z = 0.3 + 0.05 * np.abs(np.sin(2 * np.pi * 2.5 * t))
    theta = 0.3 * np.sin(2 * np.pi * 2.5 * t)
    tau = 2.0 * np.cos(2 * np.pi * 2.5 * t)
    return t, y, z, theta, tau


def write_bag(path, rate=500.0, reverse_at=None, joints=("boom", "hip"), joint_delay=0.0):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    T = store.types
    Odometry, JointState = T["nav_msgs/msg/Odometry"], T["sensor_msgs/msg/JointState"]
    Header, Time = T["std_msgs/msg/Header"], T["builtin_interfaces/msg/Time"]
    t, y, z, theta, tau = hopping(rate, gap_at=1.0)
    stamps = (1_700_000_000 + t) * 1e9
    if reverse_at is not None:
        stamps[reverse_at] = stamps[reverse_at - 2]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        odom = writer.add_connection("/odom", Odometry.__msgtype__, typestore=store)
        js = writer.add_connection("/joints", JointState.__msgtype__, typestore=store)
        cov = np.zeros(36)
        for i, ns in enumerate(stamps.astype(np.int64)):
            header = Header(stamp=Time(sec=int(ns // 10**9), nanosec=int(ns % 10**9)), frame_id="odom")
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=y[i], y=0.0, z=z[i] * 100),
                                                 orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
                covariance=cov)
            twist = T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=1.5, y=0.0, z=0.0),
                                                   angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
                covariance=cov)
            msg = Odometry(header=header, child_frame_id="body", pose=pose, twist=twist)
            writer.write(odom, int(ns), store.serialize_cdr(msg, Odometry.__msgtype__))
            late = int(ns + joint_delay * 1e9)         # the joints sampled at other instants than the body
            at = Header(stamp=Time(sec=late // 10**9, nanosec=late % 10**9), frame_id="odom")
            angle = 0.3 * math.sin(2 * math.pi * 2.5 * (t[i] + joint_delay))
            joint = JointState(header=at, name=list(joints), position=np.array([0.0, math.degrees(angle)]),
                               velocity=np.zeros(2), effort=np.array([0.0, tau[i]]))
            writer.write(js, late, store.serialize_cdr(joint, JointState.__msgtype__))
    return path


@pytest.fixture
def bag(tmp_path):
    return write_bag(tmp_path / "bag")


def mapping(tmp_path, text=BAG_MAP, name="map.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_odometry_and_joint_states_in_si(tmp_path, bag):
    imported = load_mapped(bag, mapping(tmp_path))
    rec = imported.recording
    t, y, z, theta, tau = hopping(1000.0, gap_at=1.0)
    assert rec.period == pytest.approx(1e-3)
    assert any("1 gap(s)" in n for n in imported.notes) and len(rec.segments()) == 2
    assert any(n.startswith("500 Hz recorded: resampled to 1000 Hz") for n in imported.notes), imported.notes
    # against the motion itself (no noise here: nothing added), the gap where it was; z's kinks (the
    # bounces of |sin|) cost the cubic interpolation up to 0.3 mm next to them
    inside = rec.t < 0.99
    np.testing.assert_allclose(rec.z[inside], 0.3 + 0.05 * np.abs(np.sin(2 * np.pi * 2.5 * rec.t[inside])), atol=3e-4)
    np.testing.assert_allclose(rec.theta[inside], 0.3 * np.sin(2 * np.pi * 2.5 * rec.t[inside]), atol=1e-4)
    np.testing.assert_allclose(rec.tau[inside], 2.0 * np.cos(2 * np.pi * 2.5 * rec.t[inside]), atol=2e-3)


def test_topics_at_other_instants_are_interpolated_and_said(tmp_path):
    bag = write_bag(tmp_path / "bag", joint_delay=0.0007)
    imported = load_mapped(bag, mapping(tmp_path))
    assert "theta, tau: /joints sampled at other instants than z's /odom: interpolated linearly onto them" in imported.notes
    assert "1 of z's samples outside the other topics' times left out" in imported.notes
    rec = imported.recording                        # its time starts at z's first sample kept: 2 ms in
    inside = rec.t < 0.99
    np.testing.assert_allclose(rec.theta[inside], 0.3 * np.sin(2 * np.pi * 2.5 * (rec.t[inside] + 0.002)), atol=2e-4)


def test_decoder_agrees_with_rosbags(bag):
    """Every field of every message: our decoder of the bag's ros2msg text against rosbags' own types."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from hopper_ros.recording.bag import BagReader
    from hopper_ros.recording.msgdef import MessageDecoder

    store = get_typestore(Stores.ROS2_KILTED)

    def plain(value):
        if hasattr(value, "__dataclass_fields__"):
            return {k: plain(getattr(value, k)) for k in value.__dataclass_fields__ if k != "__msgtype__"}
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        if isinstance(value, np.ndarray):
            return value.tolist()
        if isinstance(value, list):
            return [plain(v) for v in value]
        return value

    ours = BagReader(bag)
    decoders = {}
    mine = []
    for raw in ours.raw_messages():
        if raw.type not in decoders:
            schema = next(s for scan in ours.scans for s in scan.schemas.values() if s.name == raw.type)
            decoders[raw.type] = MessageDecoder(raw.type, schema.data.decode())
        mine.append(plain(decoders[raw.type].decode(raw.data)))
    with Reader(bag) as reader:
        theirs = [plain(store.deserialize_cdr(data, c.msgtype)) for c, _, data in reader.messages()]
    assert len(mine) == len(theirs) > 1000
    assert mine == theirs


def test_csv_with_its_own_names_at_2_khz(tmp_path):
    t, y, z, theta, tau = hopping(2000.0)
    path = tmp_path / "run.csv"
    rows = ["time_ms,x_mm,height_mm,hip_deg,torque_Nmm"] + [
        f"{a * 1e3:.4f},{b * 1e3:.6f},{c * 1e3:.6f},{math.degrees(d):.8f},{e * 1e3:.6f}" for a, b, c, d, e in zip(t, y, z, theta, tau)]
    path.write_text("\n".join(rows) + "\n")
    m = mapping(tmp_path, """\
import:
  time: {column: time_ms, unit: ms}
  channels:
    y:     {column: x_mm, unit: mm}
    z:     {column: height_mm, unit: mm}
    theta: {column: hip_deg, unit: deg}
    tau:   {column: torque_Nmm, unit: N mm}
""")
    imported = load_mapped(path, m)
    rec = imported.recording
    assert rec.period == pytest.approx(1e-3)
    assert any(n.startswith("2000 Hz recorded: resampled to 1000 Hz") for n in imported.notes), imported.notes
    np.testing.assert_allclose(rec.theta, 0.3 * np.sin(2 * np.pi * 2.5 * rec.t), atol=1e-6)
    np.testing.assert_allclose(rec.tau, 2.0 * np.cos(2 * np.pi * 2.5 * rec.t), atol=1e-5)
    m2 = mapping(tmp_path, m.read_text().replace("import:\n", "import:\n  rate: recorded\n"), "as_is.yaml")
    as_is = load_mapped(path, m2)
    assert as_is.recording.period == pytest.approx(5e-4) and "used as they are" in as_is.notes[-1]


BAD_MAPPINGS = [
    (BAG_MAP.replace("unit: deg", "unit: mm"), "import.channels.theta.unit: 'mm' is a unit of length; theta is a angle"),
    (BAG_MAP.replace("unit: cm", "unit: furlong"), "import.channels.z.unit: 'furlong' is not a known unit"),
    (BAG_MAP.replace("    tau:   {topic: /joints, field: \"effort[hip]\", unit: N m}\n", ""),
     "import.channels.tau: missing"),
    (BAG_MAP.replace("field: pose.pose.position.x, ", ""), "import.channels.y.field: missing"),
    (BAG_MAP.replace("pose.pose.position.x", "pose..x"), "import.channels.y.field: 'pose..x' is not a field path"),
    (BAG_MAP + "  colour: blue\n", "import.colour: unknown key"),
    (BAG_MAP.replace("import:\n", "import:\n  rate: fast\n"), "import.rate: must be a number"),
]


@pytest.mark.parametrize("text,expected", BAD_MAPPINGS)
def test_bad_mapping_one_line(tmp_path, text, expected):
    path = mapping(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_mapping(path)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and expected in message and "\n" not in message, message


BAD_RECORDINGS = [
    ("/odom", "/odometry", "import.channels.y.topic: no topic /odometry in"),
    ("pose.pose.position.x", "pose.pose.positon.x", "import.channels.y.field: /odom message 0: nav_msgs/msg/Odometry "
                                                    "has no field 'positon' (fields there: position, orientation)"),
    ("effort[hip]", "effort[knee]", "import.channels.tau.field: /joints message 0: effort[knee]: no entry 'knee' in "
                                    "name ['boom', 'hip']"),
    ("unit: cm", "unit: m", "import.channels.z: values from 30 to 35 in SI after the unit 'm'"),
    ("position[hip]\", unit: deg", "position[hip]\", unit: rad", "import.channels.theta: values from -17"),
    ("pose.pose.position.x", "pose.pose", "the field path ends at a dict, not a number"),
]


@pytest.mark.parametrize("old,new,expected", BAD_RECORDINGS)
def test_bad_recording_one_line(tmp_path, bag, old, new, expected):
    path = mapping(tmp_path, BAG_MAP.replace(old, new))
    with pytest.raises(RecordingError) as info:
        load_mapped(bag, path)
    assert expected in str(info.value) and "\n" not in str(info.value), str(info.value)


def test_time_going_back_one_line(tmp_path):
    bag = write_bag(tmp_path / "bag", reverse_at=100)
    with pytest.raises(RecordingError, match=r"/odom \(header stamps\): time does not increase at sample 100 "):
        load_mapped(bag, mapping(tmp_path))


def test_cli_one_line_no_traceback(tmp_path, bag):
    path = mapping(tmp_path, BAG_MAP.replace("/odom", "/odometry"))
    for tool in (["import", str(bag), "--map", str(path), "-o", str(tmp_path / "out.csv")],
                 ["diagnose", str(bag), "--map", str(path)], ["identify", str(bag), "--map", str(path)]):
        proc = subprocess.run([sys.executable, "-m", "hopper_ros.cli", *tool], capture_output=True, text=True, timeout=120)
        assert proc.returncode != 0 and proc.stdout == ""
        (line,) = proc.stderr.strip().splitlines()
        assert line.startswith(f"hopper {tool[0]}: error: {path}: import.channels.y.topic: no topic /odometry"), line
