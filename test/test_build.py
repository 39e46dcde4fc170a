"""Checks of the build (make setup): generated messages, console scripts, idempotent setup.

Run by `make test` with .venv/bin/python.
"""
import importlib
import importlib.metadata
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
VENV = ROOT / ".venv"
MSG_FILES = sorted((ROOT / "msg").glob("*.msg"))

in_venv = pytest.mark.skipif(
    Path(sys.prefix).resolve() != VENV.resolve(),
    reason="needs the project's .venv (make setup); run through `make test`")

# .msg primitive type -> type string of get_fields_and_field_types()
PRIMITIVES = {
    "bool": "boolean", "byte": "octet", "char": "uint8", "float32": "float",
    "float64": "double", "int8": "int8", "uint8": "uint8", "int16": "int16",
    "uint16": "uint16", "int32": "int32", "uint32": "uint32", "int64": "int64",
    "uint64": "uint64", "string": "string", "wstring": "wstring",
}


def parse_msg(path):
    """(fields [(name, type string)], constants {name: value text}) of a .msg file."""
    fields, constants = [], {}
    for raw in path.read_text(encoding="utf-8").splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        type_text, rest = line.split(None, 1)
        if "=" in rest:
            name, value = (part.strip() for part in rest.split("=", 1))
            constants[name] = value
        else:
            fields.append((rest.split()[0], idl_type(type_text)))
    return fields, constants


def idl_type(type_text):
    match = re.fullmatch(r"([\w/]+?)(?:<=(\d+))?(?:\[(<=)?(\d*)\])?", type_text)
    assert match, type_text
    base, string_bound, array_bounded, array_size = match.groups()
    array = "[" in type_text
    if base in PRIMITIVES:
        element = PRIMITIVES[base]
        if string_bound:
            element = f"{element}<{string_bound}>"
    elif "/" in base:
        element = base
    else:
        element = f"hopper_ros/{base}"
    if not array:
        return element
    if array_bounded:
        return f"sequence<{element}, {array_size}>"
    if array_size:
        return f"{element}[{array_size}]"
    return f"sequence<{element}>"


def test_there_are_messages():
    assert len(MSG_FILES) >= 9


@in_venv
@pytest.mark.parametrize("msg_file", MSG_FILES, ids=lambda path: path.stem)
def test_message_imports_with_its_fields(msg_file):
    module = importlib.import_module("hopper_ros.msg")
    msg_class = getattr(module, msg_file.stem)
    fields, constants = parse_msg(msg_file)
    assert list(msg_class.get_fields_and_field_types().items()) == fields
    for name, value in constants.items():
        assert str(getattr(msg_class, name)) == value
    instance = msg_class()
    for name, _ in fields:
        assert hasattr(instance, name)


@in_venv
def test_generated_code_merges_with_the_source_package():
    import hopper_ros
    import hopper_ros.msg

    assert Path(hopper_ros.__file__).resolve() == ROOT / "hopper_ros" / "__init__.py"
    msg_dir = Path(hopper_ros.msg.__file__).resolve().parent
    assert msg_dir.is_relative_to(VENV.resolve()), msg_dir
    assert str(ROOT / "hopper_ros") in hopper_ros.__path__


@in_venv
def test_serialization_round_trip():
    from rclpy.serialization import deserialize_message, serialize_message

    from hopper_ros.msg import BodyState, GaitEvent

    event = GaitEvent(type=GaitEvent.TOUCHDOWN, stride_index=7, detection_delay=0.002)
    event.state = BodyState(y=1.5, z=0.9, covariance_diagonal=[float(i) for i in range(8)])
    back = deserialize_message(serialize_message(event), GaitEvent)
    assert back == event


def node_registry():
    path = ROOT / "hopper_ros" / "nodes" / "registry.py"
    namespace = {}
    exec(compile(path.read_text(encoding="utf-8"), str(path), "exec"), namespace)
    return namespace["NODES"]


@in_venv
def test_console_scripts_match_the_node_registry():
    expected = {"hopper": "hopper_ros.cli:main", **node_registry()}
    entry_points = importlib.metadata.distribution("hopper_ros").entry_points
    scripts = {ep.name: ep.value for ep in entry_points if ep.group == "console_scripts"}
    assert scripts == expected
    for name, target in expected.items():
        script = VENV / "bin" / name
        assert script.is_file() and os.access(script, os.X_OK), script
        module, function = target.split(":")
        assert f"from {module} import {function}" in script.read_text(encoding="utf-8")


def run_python(code, **env_changes):
    env = {k: v for k, v in os.environ.items() if k not in env_changes}
    env.update({k: v for k, v in env_changes.items() if v is not None})
    return subprocess.run([str(VENV / "bin" / "python"), "-c", textwrap.dedent(code)],
                          env=env, cwd="/", capture_output=True, text=True, timeout=120)


@in_venv
def test_ament_index_finds_the_package_without_manual_environment():
    # a fresh process of the venv, no AMENT_PREFIX_PATH: the start-up hook sets it
    result = run_python("""
        import os
        from ament_index_python.packages import get_package_share_directory
        print(get_package_share_directory('hopper_ros'))
        print(os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'], os.environ['HOPPER_DDS_LOOPBACK'])
        print(os.environ['FASTDDS_DEFAULT_PROFILES_FILE'])
        """, AMENT_PREFIX_PATH=None, ROS_AUTOMATIC_DISCOVERY_RANGE=None, HOPPER_DDS_LOOPBACK=None,
        FASTDDS_DEFAULT_PROFILES_FILE=None)
    assert result.returncode == 0, result.stderr
    share, discovery, marker, profile = result.stdout.split()
    assert Path(share) == VENV / "share" / "hopper_ros"
    # the loopback profile (hopper_ros.runtime.environment): rcl gets SYSTEM_DEFAULT, the profile keeps DDS on 127.0.0.1
    assert (discovery, marker) == ("SYSTEM_DEFAULT", "1")
    assert Path(profile).read_bytes() == (ROOT / "hopper_ros" / "dds" / "fastdds_loopback.xml").read_bytes()


PUBSUB = """
import sys, time
import rclpy
from hopper_ros.msg import BodyState

role, topic = sys.argv[1], sys.argv[2]
rclpy.init()
node = rclpy.create_node('test_build_' + role)
deadline = time.monotonic() + 60
if role == 'pub':
    pub = node.create_publisher(BodyState, topic, 10)
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    sequence = 0
    while time.monotonic() < deadline and pub.get_subscription_count() > 0:
        pub.publish(BodyState(sequence=sequence, z=0.5, covariance_diagonal=[0.25] * 8))
        sequence += 1
        time.sleep(0.02)
else:
    got = []
    node.create_subscription(BodyState, topic, got.append, 10)
    print('ready', flush=True)
    while len(got) < 5 and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    assert len(got) >= 5, len(got)
    assert got[-1].z == 0.5 and list(got[-1].covariance_diagonal) == [0.25] * 8
    print('received', len(got), flush=True)
node.destroy_node()
rclpy.shutdown()
"""


@in_venv
def test_body_state_between_two_processes():
    topic = f"/hopper_test_build/body_state_{os.getpid()}"
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    python = str(VENV / "bin" / "python")
    sub = subprocess.Popen([python, "-c", PUBSUB, "sub", topic], env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    pub = None
    try:
        assert sub.stdout.readline().strip() == "ready"
        pub = subprocess.Popen([python, "-c", PUBSUB, "pub", topic], env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        out, err = sub.communicate(timeout=90)
        assert sub.returncode == 0, err
        assert out.startswith("received")
        pub.wait(timeout=30)
        assert pub.returncode == 0, pub.stderr.read()
    finally:
        for process in (sub, pub):
            if process is not None and process.poll() is None:
                process.kill()
                process.wait()


def stamp_snapshot():
    stamps = VENV / ".hopper-stamps"
    return {path.name: (path.stat().st_mtime_ns, path.read_text())
            for path in sorted(stamps.iterdir())}


@pytest.mark.skipif(not (VENV / ".hopper-stamps").is_dir(), reason="no make setup yet")
def test_second_make_setup_is_a_no_op():
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MAKELEVEL", "MFLAGS")}
    first = subprocess.run(["make", "-s", "setup"], cwd=ROOT, env=env,
                           capture_output=True, text=True, timeout=3600)
    assert first.returncode == 0, first.stdout + first.stderr
    before = stamp_snapshot()
    interfaces = VENV / "lib" / "hopper_ros_interfaces"
    installed_before = {p: p.stat().st_mtime_ns for p in interfaces.rglob("*")}
    second = subprocess.run(["make", "-s", "setup"], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=3600)
    assert second.returncode == 0, second.stdout + second.stderr
    assert stamp_snapshot() == before
    assert {p: p.stat().st_mtime_ns for p in interfaces.rglob("*")} == installed_before
    for stage in ("deps", "msgs", "pkg"):
        assert f"setup: {stage} up to date" in second.stdout, second.stdout
    assert ("setup: foxglove up to date" in second.stdout) == (shutil.which("node") is not None), second.stdout
    for line in second.stdout.splitlines():
        assert (line.endswith(" up to date") or line.startswith("setup: ready")
                or line.startswith("setup: foxglove skipped: no Node.js")), second.stdout
