"""What a bag is besides its messages: the errors, the topics, and metadata.yaml as rosbag2 writes it
(Kilted, rosbag2_storage metadata version 9, yaml-cpp's style). The package's docstring says more."""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

from hopper_ros.runtime.messages import split_type_name

BAG_VERSION = 9                    # rosbag2 metadata version (Jazzy/Kilted)
ROS_DISTRO = "kilted"
DEFAULT_QOS = {                    # what `ros2 bag` writes for a reliable keep-last publisher
    "history": "keep_last", "depth": 100, "reliability": "reliable", "durability": "volatile",
    "deadline": {"sec": 9223372036, "nsec": 854775807}, "lifespan": {"sec": 9223372036, "nsec": 854775807},
    "liveliness": "automatic", "liveliness_lease_duration": {"sec": 9223372036, "nsec": 854775807},
    "avoid_ros_namespace_conventions": False,
}


class BagError(ValueError):
    """A bag that cannot be written or read as asked; the message names what is wrong."""


@dataclass
class TopicInfo:
    name: str
    type: str
    message_count: int = 0
    qos: list = field(default_factory=list)
    type_hash: str = ""


@dataclass(frozen=True)
class RawMessage:
    topic: str
    type: str
    log_time: int          # [ns]
    data: bytes            # CDR


def topic_name(topic: str) -> str:
    if not topic or topic.strip("/") == "":
        raise BagError(f"topic name {topic!r} is empty")
    return topic if topic.startswith("/") else "/" + topic


def normalised_type(type_name: str) -> str:
    try:
        package, interface, name = split_type_name(type_name)
    except ValueError as exc:
        raise BagError(str(exc)) from None
    return f"{package}/{interface}/{name}"


def metadata_document(file_name: str, topics: Mapping[str, TopicInfo], start_ns: int, end_ns: int,
                      custom_data: Mapping[str, str] | None = None) -> dict:
    """The `rosbag2_bagfile_information` of metadata.yaml for one MCAP file."""
    count = sum(t.message_count for t in topics.values())
    start = start_ns if count else 0
    duration = max(0, end_ns - start_ns) if count else 0
    return {"rosbag2_bagfile_information": {
        "version": BAG_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": t.name, "type": t.type, "serialization_format": "cdr",
                                "offered_qos_profiles": copy.deepcopy(list(t.qos)), "type_description_hash": t.type_hash},
             "message_count": t.message_count}
            for t in topics.values()],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [{"path": file_name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": count}],
        "custom_data": dict(custom_data) if custom_data else None,
        "ros_distro": ROS_DISTRO,
    }}


class _YamlCppStyle(yaml.SafeDumper):
    """PyYAML emitting what yaml-cpp's emitter (rosbag2's) writes for the same document."""

    def increase_indent(self, flow: bool = False, indentless: bool = False):
        return super().increase_indent(flow, False)      # "key:\n  - item", as yaml-cpp

    def choose_scalar_style(self):
        style = super().choose_scalar_style()
        return '"' if style in ("'", "|", ">") else style  # yaml-cpp quotes what cannot be plain with ""


_YamlCppStyle.add_representer(type(None), lambda dumper, _: dumper.represent_scalar("tag:yaml.org,2002:null", "~"))
_YamlCppStyle.add_representer(
    str, lambda dumper, value: dumper.represent_scalar("tag:yaml.org,2002:str", value,
                                                       style='"' if value == "" or "\n" in value else None))


def dump_yaml_cpp_style(data: Any) -> str:
    """`YAML::Dump` of `data` as rosbag2 writes it (no newline after the last line)."""
    return yaml.dump(data, Dumper=_YamlCppStyle, sort_keys=False, default_flow_style=False, allow_unicode=True,
                     width=1 << 30).rstrip("\n")


def write_metadata_file(folder: Path, document: dict) -> Path:
    path = folder / "metadata.yaml"
    temporary = folder / "metadata.yaml.tmp"
    temporary.write_text(dump_yaml_cpp_style(document), encoding="utf-8")
    os.replace(temporary, path)
    return path


_MAX_METADATA_BYTES = 16 << 20   # [bytes] a metadata.yaml larger than this is not one


def read_metadata(meta_path: Path) -> dict:
    """The `rosbag2_bagfile_information` mapping of a metadata.yaml; BagError naming the file otherwise."""
    if meta_path.stat().st_size > _MAX_METADATA_BYTES:
        raise BagError(f"{meta_path}: {meta_path.stat().st_size / 1e6:.0f} MB is not a rosbag2 metadata file")
    try:
        loaded = yaml.safe_load(meta_path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise BagError(f"{meta_path}: not a rosbag2 metadata file (byte {exc.start} is not UTF-8 text)") from None
    except yaml.YAMLError as exc:
        where = getattr(exc, "problem_mark", None)
        at = f" at line {where.line + 1}" if where is not None else ""
        raise BagError(f"{meta_path}: not a rosbag2 metadata file (invalid YAML{at}: "
                       f"{getattr(exc, 'problem', None) or type(exc).__name__})") from None
    document = loaded.get("rosbag2_bagfile_information") if isinstance(loaded, dict) else None
    if not isinstance(document, dict):
        raise BagError(f"{meta_path}: not a rosbag2 metadata file (no `rosbag2_bagfile_information` mapping)")
    return document
