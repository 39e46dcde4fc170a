"""Offline tools given bad files (issue 17): one line naming the file and the problem, a non-zero
exit, no traceback, bounded memory; and nothing already recorded lost (a damaged bag is still
read up to its damage and recovered).

The table runs the real command line (`hopper_ros.cli.main`) in this process; the huge CSV and
a folder of random bytes also run as processes under a memory limit, as a user runs them.
"""

from __future__ import annotations

import os
import random
import resource
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

GOOD_ROWS = "".join(f"{i * 0.001:.6f},0.1,0.3,0.2,1.0\n" for i in range(200))


def _random_bytes(count: int, seed: int) -> bytes:
    return random.Random(seed).randbytes(count)


def _bag(folder: Path, messages: int = 300) -> Path:
    """A small finished bag of BodyMeasurement messages."""
    from hopper_ros.msg import BodyMeasurement
    from hopper_ros.recording.bag import BagWriter

    with BagWriter(folder, chunk_size=4096) as bag:
        for k in range(messages):
            msg = BodyMeasurement(sequence=k, y=0.001 * k, z=0.3)
            msg.header.stamp.sec, msg.header.stamp.nanosec = 100, k * 1_000_000
            bag.write_message("/body_measurement", msg, 10**18 + k * 10**6)
    return folder


def _mcap(folder: Path) -> Path:
    return next(folder.glob("*.mcap"))


# name -> function(tmp) -> path of the bad input
def _make(tmp: Path, name: str) -> Path:
    p = tmp / name
    if name == "empty.csv":
        p.write_bytes(b"")
    elif name == "random.csv":
        p.write_bytes(_random_bytes(50_000, 1))
    elif name == "nul.csv":
        p.write_bytes(b"t,y,z,theta,tau\n0,0,0\x00,0,0\n")
    elif name == "header_only.csv":
        p.write_text("t,y,z,theta,tau\n")
    elif name == "wrong_header.csv":
        p.write_text("time,x,height\n0,0,0\n")
    elif name == "truncated.csv":
        p.write_text("t,y,z,theta,tau\n" + GOOD_ROWS + "0.200000,0.1,0.3")
    elif name == "text_values.csv":
        p.write_text("t,y,z,theta,tau\n0,a,b,c,d\n")
    elif name == "one_row.csv":
        p.write_text("t,y,z,theta,tau\n0,0,0,0,0\n")
    elif name == "nan.csv":
        p.write_text("t,y,z,theta,tau\n0,0,0,0,0\n0.001,nan,0,0,0\n")
    elif name == "backwards.csv":
        p.write_text("t,y,z,theta,tau\n0.002,0,0,0,0\n0.001,0,0,0,0\n")
    elif name == "long_line.csv":
        p.write_bytes(b"t,y,z,theta,tau\n" + b"1" * (2 << 20))
    elif name == "latin1.csv":
        p.write_bytes("t,y,z,theta,tau\n0,0,0,0,0\xe9\n".encode("latin-1"))
    elif name == "huge.csv":
        with open(p, "wb") as handle:                  # sparse: 1 GiB on paper, nothing on disk
            handle.write(b"t,y,z,theta,tau\n")
            handle.truncate(1 << 30)
    elif name == "folder.csv":
        p.mkdir()
    elif name == "notes.txt":
        p.write_text("hello")
    elif name == "missing.csv":
        pass
    elif name == "empty.mcap":
        p.write_bytes(b"")
    elif name == "random.mcap":
        p.write_bytes(_random_bytes(50_000, 2))
    elif name == "empty_bag":
        p.mkdir()
    elif name == "random_bytes_bag":                   # a folder of random bytes (the audit's)
        p.mkdir()
        (p / "metadata.yaml").write_bytes(_random_bytes(4000, 3))
        (p / "random_bytes_bag_0.mcap").write_bytes(_random_bytes(50_000, 4))
    elif name == "yaml_garbage_bag":
        p.mkdir()
        (p / "metadata.yaml").write_text("{{{: not yaml\n  - [")
    elif name == "wrong_metadata_bag":
        p.mkdir()
        (p / "metadata.yaml").write_text("rosbag2_bagfile_information:\n  storage_identifier: mcap\n"
                                         "  relative_file_paths: [12, null]\n")
    elif name == "string_metadata_bag":
        p.mkdir()
        (p / "metadata.yaml").write_text("rosbag2_bagfile_information: just a string\n")
    elif name == "huge_chunk.mcap":                    # a chunk claiming 2^62 bytes uncompressed
        body = struct.pack("<QQQI", 0, 0, 1 << 62, 0) + struct.pack("<I", 4) + b"zstd" + struct.pack("<Q", 8) + bytes(8)
        p.write_bytes(b"\x89MCAP0\r\n" + bytes([6]) + struct.pack("<Q", len(body)) + body)
    elif name == "no_body_measurement_bag":            # a good bag, but not of the robot
        from hopper_ros.msg import GroundReactionForce
        from hopper_ros.recording.bag import BagWriter

        with BagWriter(p) as bag:
            bag.write_message("/force_plate", GroundReactionForce(), 10**18)
    else:
        raise AssertionError(name)
    return p


CASES = [
    # (tool, input, words the one line must hold)
    ("identify", "empty.csv", "empty file"),
    ("identify", "random.csv", "not a text CSV file"),
    ("identify", "nul.csv", "expected numbers"),
    ("identify", "header_only.csv", "no samples"),
    ("identify", "wrong_header.csv", "header lacks column(s)"),
    ("identify", "truncated.csv", "the file looks cut short"),
    ("identify", "text_values.csv", "expected numbers"),
    ("identify", "one_row.csv", "is not a recording"),
    ("identify", "nan.csv", "column y is not finite"),
    ("identify", "backwards.csv", "time does not increase"),
    ("identify", "long_line.csv", "line longer than"),
    ("identify", "latin1.csv", "is not UTF-8"),
    ("identify", "huge.csv", "is more than this tool loads"),
    ("identify", "folder.csv", "not a bag"),
    ("identify", "notes.txt", "expected a bag folder"),
    ("identify", "missing.csv", "no such file"),
    ("identify", "random_bytes_bag", "not a rosbag2 metadata file"),
    ("identify", "no_body_measurement_bag", "no 'body_measurement' topic"),
    ("diagnose", "random.csv", "not a text CSV file"),
    ("diagnose", "huge.csv", "is more than this tool loads"),
    ("diagnose", "truncated.csv", "the file looks cut short"),
    ("diagnose", "empty.mcap", "not an MCAP file"),
    ("diagnose", "huge_chunk.mcap", "the bag holds no messages"),
    ("diagnose", "string_metadata_bag", "not a rosbag2 metadata file"),
    ("report", "random.mcap", "not an MCAP file"),
    ("report", "latin1.csv", "is not UTF-8"),
    ("bag info", "random_bytes_bag", "not a rosbag2 metadata file"),
    ("bag info", "empty_bag", "not a bag"),
    ("bag info", "yaml_garbage_bag", "invalid YAML at line"),
    ("bag info", "wrong_metadata_bag", "relative_file_paths must be a list"),
    ("bag info", "string_metadata_bag", "no `rosbag2_bagfile_information` mapping"),
    ("bag info", "random.mcap", "not an MCAP file"),
    ("bag info", "notes.txt", "neither a bag folder nor an .mcap file"),
    ("bag recover", "random_bytes_bag", "not a rosbag2 metadata file"),
    ("bag recover", "empty.csv", "not a bag folder"),
    ("bag recover", "empty_bag", "not a bag"),
    ("bag recover", "wrong_metadata_bag", "relative_file_paths must be a list"),
]


def _argv(tool: str, path: Path, tmp: Path) -> list[str]:
    if tool == "identify":
        return ["identify", "--no-progress", str(path)]
    if tool == "diagnose":
        return ["diagnose", str(path)]
    if tool == "report":
        return ["report", str(tmp / "report_out"), "--recording", str(path), "--no-grf", "--no-progress"]
    return [*tool.split(), str(path)]


@pytest.mark.parametrize("tool,name,words", CASES, ids=[f"{t.replace(' ', '_')}-{n}" for t, n, _ in CASES])
def test_a_bad_input_gives_one_line_naming_the_file(tool, name, words, tmp_path, capsys):
    from hopper_ros.cli import main

    path = _make(tmp_path, name)
    status = main(_argv(tool, path, tmp_path))
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert status != 0, (out, err)
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith(f"hopper {tool}: error: "), lines
    assert str(path) in lines[0] and words in lines[0], lines[0]


def _limited(memory_bytes: int):
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    return limit


@pytest.mark.parametrize("tool,name", [("identify", "huge.csv"), ("diagnose", "huge.csv"), ("bag info", "random_bytes_bag")])
def test_bad_inputs_as_a_user_runs_them_under_a_memory_limit(tool, name, tmp_path):
    """1 GiB of CSV used to take 2.2 GB of memory before a traceback: refused before reading, in a
    process limited to 1.5 GiB of address space (the interpreter with numpy and rclpy needs ~1)."""
    path = _make(tmp_path, name)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    result = subprocess.run([sys.executable, "-m", "hopper_ros.cli", *_argv(tool, path, tmp_path)],
                            capture_output=True, text=True, timeout=120, env=env, cwd=REPO,
                            preexec_fn=_limited(3 << 29))
    lines = result.stderr.strip().splitlines()
    assert result.returncode != 0 and len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert str(path) in lines[0]


def test_a_damaged_bag_keeps_what_was_recorded(tmp_path, capsys):
    """Garbage after the last good chunk: info reads up to it and says so, recover keeps every message."""
    from hopper_ros.cli import main
    from hopper_ros.recording.bag import BagReader

    folder = _bag(tmp_path / "bag")
    mcap = _mcap(folder)
    data = mcap.read_bytes()
    mcap.write_bytes(data[:len(data) // 2] + _random_bytes(3000, 5))   # cut in the middle, garbage after
    (folder / "metadata.yaml").unlink()
    survived = [m.sequence for _, _, m in BagReader(folder).messages()]
    assert len(survived) > 50 and survived == list(range(len(survived)))
    assert main(["bag", "info", str(folder)]) == 0
    out, _ = capsys.readouterr()
    assert "UNFINISHED" in out and "hopper bag recover" in out
    assert main(["bag", "recover", str(folder)]) == 0
    out, _ = capsys.readouterr()
    assert f"recovered {len(survived)} messages" in out
    assert [m.sequence for _, _, m in BagReader(folder).messages()] == survived
    assert (folder / "metadata.yaml").exists()
