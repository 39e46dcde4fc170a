"""rosbag2 bags as ROS 2 itself writes them with the MCAP storage plugin: a folder holding
`metadata.yaml` and `<folder>_0.mcap` (profile "ros2", messages "cdr", schemas "ros2msg" with
their dependencies as rosbag2 writes them (schemas.py), channels with `offered_qos_profiles`
and `topic_type_hash`, zstd-compressed chunks, message and chunk indexes, statistics, a
summary section and the bag's metadata as the "rosbag2" metadata record).

metadata.yaml is rosbag2's (Kilted, rosbag2_storage metadata version 9): the same keys in the
same order, emitted in yaml-cpp's style (sequences indented under their key, `~` for an empty
custom_data, `""` for empty strings, no newline after the last line), so that it reads as one
`ros2 bag record` wrote (rosbag2_storage/include/rosbag2_storage/yaml.hpp).

Crash safety. Every byte the MCAP writer produces goes straight to the file (no user-space
buffer), and a chunk is closed when it reaches `chunk_size` bytes or `chunk_interval` seconds,
whichever comes first. A recorder killed with SIGKILL therefore leaves complete chunks on
disk and loses at most the chunk it was filling; the file then lacks its summary and footer
and the folder its metadata.yaml. `BagReader` reads such a bag anyway (record by record, up
to the last intact chunk), `bag_info` says it is unfinished, and `recover_bag` rewrites it as
a complete bag (the original MCAP is kept beside it as `*.mcap.unfinished`).
"""

from __future__ import annotations

import copy
import io
import os
import struct
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

import yaml
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Metadata, Schema
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from hopper_ros.runtime.messages import message_class, split_type_name

from .schemas import message_definition, type_hash

BAG_VERSION = 9                    # rosbag2 metadata version (Jazzy/Kilted)
ROS_DISTRO = "kilted"
DEFAULT_CHUNK_SIZE = 256 * 1024    # [bytes] uncompressed chunk size
DEFAULT_CHUNK_INTERVAL = 1.0       # [s] a chunk is closed at least this often while recording
MCAP_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_SIZE = 1 + 8 + 20          # opcode, length, footer body
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


def _topic_name(topic: str) -> str:
    if not topic or topic.strip("/") == "":
        raise BagError(f"topic name {topic!r} is empty")
    return topic if topic.startswith("/") else "/" + topic


def _normalised_type(type_name: str) -> str:
    try:
        package, interface, name = split_type_name(type_name)
    except ValueError as exc:
        raise BagError(str(exc)) from None
    return f"{package}/{interface}/{name}"


class _WriteThrough:
    """File object for the MCAP writer that hands every write to the kernel at once."""

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self._position = 0

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view:
            written = os.write(self._fd, view)
            view = view[written:]
        self._position += len(data)
        return len(data)

    def tell(self) -> int:
        return self._position

    def flush(self) -> None:
        pass

    def fsync(self) -> None:
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


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


def _write_metadata_file(folder: Path, document: dict) -> Path:
    path = folder / "metadata.yaml"
    temporary = folder / "metadata.yaml.tmp"
    temporary.write_text(dump_yaml_cpp_style(document), encoding="utf-8")
    os.replace(temporary, path)
    return path


class BagWriter:
    """Write a rosbag2 bag (MCAP storage) into a new folder.

        with BagWriter("out/run1") as bag:
            bag.add_topic("/force_plate", "hopper_ros/msg/GroundReactionForce")
            bag.write("/force_plate", cdr_bytes, log_time_ns)      # serialized, e.g. from a raw subscription
            bag.write_message("/sim/truth", body_state, log_time_ns)  # a message object

    The folder must not exist or be empty: nothing recorded before is ever overwritten.
    """

    def __init__(self, path: str | os.PathLike, *, chunk_size: int = DEFAULT_CHUNK_SIZE,
                 chunk_interval: float = DEFAULT_CHUNK_INTERVAL, compression: str = "zstd",
                 custom_data: Mapping[str, str] | None = None) -> None:
        self.path = Path(path)
        if self.path.exists() and (not self.path.is_dir() or any(self.path.iterdir())):
            raise BagError(f"{self.path} already exists and is not an empty folder; choose a new output folder "
                           f"(a bag is never written over existing files)")
        if chunk_size < 1024:
            raise BagError(f"chunk size must be at least 1024 bytes, got {chunk_size}")
        if compression not in ("zstd", "none"):
            raise BagError(f"compression must be 'zstd' or 'none', got {compression!r}")
        self.path.mkdir(parents=True, exist_ok=True)
        self.file_name = f"{self.path.name}_0.mcap"
        self._stream = _WriteThrough(self.path / self.file_name)
        self._writer = McapWriter(self._stream, chunk_size=chunk_size,
                                  compression=CompressionType.ZSTD if compression == "zstd" else CompressionType.NONE)
        self._writer.start(profile="ros2", library="hopper_ros recording (mcap-python)")
        self.chunk_interval = chunk_interval
        self.custom_data: dict[str, str] = dict(custom_data or {})
        self.topics: dict[str, TopicInfo] = {}
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._serializers: dict[type, Any] = {}
        self._last_chunk = time.monotonic()
        self.start_ns: int | None = None
        self.end_ns = 0
        self.closed = False

    # ------------------------------------------------------------------ topics
    def add_topic(self, topic: str, type_name: str, qos_profiles: list | None = None) -> str:
        """Declare a topic and its message type (idempotent); returns the full topic name."""
        self._check_open()
        name = _topic_name(topic)
        type_name = _normalised_type(type_name)
        known = self.topics.get(name)
        if known is not None:
            if known.type != type_name:
                raise BagError(f"topic {name} is recorded as {known.type}, not {type_name}")
            return name
        schema_id = self._schemas.get(type_name)
        if schema_id is None:
            schema_id = self._writer.register_schema(type_name, "ros2msg", message_definition(type_name).encode())
            self._schemas[type_name] = schema_id
        qos = copy.deepcopy(list(qos_profiles) if qos_profiles is not None else [DEFAULT_QOS])
        digest = type_hash(type_name)
        # as rosbag2's MCAP storage plugin (mcap_storage.cpp create_topic)
        self._channels[name] = self._writer.register_channel(
            topic=name, message_encoding="cdr", schema_id=schema_id,
            metadata={"offered_qos_profiles": dump_yaml_cpp_style(qos), "topic_type_hash": digest})
        self.topics[name] = TopicInfo(name, type_name, 0, qos, digest)
        return name

    # ------------------------------------------------------------------ messages
    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        """Append one serialized (CDR) message of a declared topic."""
        self._check_open()
        name = topic if topic in self._channels else _topic_name(topic)
        channel = self._channels.get(name)
        if channel is None:
            raise BagError(f"topic {name} was not declared with add_topic")
        info = self.topics[name]
        self._writer.add_message(channel, log_time_ns, data, publish_time_ns if publish_time_ns is not None else log_time_ns,
                                 info.message_count)
        info.message_count += 1
        if self.start_ns is None or log_time_ns < self.start_ns:
            self.start_ns = log_time_ns
        if log_time_ns > self.end_ns:
            self.end_ns = log_time_ns
        if self.chunk_interval and time.monotonic() - self._last_chunk > self.chunk_interval:
            self.flush()

    def write_message(self, topic: str, message: Any, log_time_ns: int) -> None:
        """Serialize a message object (rclpy's CDR serializer) and append it; declares the topic."""
        name = topic if topic in self._channels else _topic_name(topic)
        if name not in self._channels:
            from hopper_ros.runtime.messages import type_name_of

            self.add_topic(name, type_name_of(message))
        serialize = self._serializers.get(type(message))
        if serialize is None:
            from rclpy.serialization import serialize_message as serialize

            self._serializers[type(message)] = serialize
        self.write(name, serialize(message), log_time_ns)

    def flush(self) -> None:
        """Close the chunk being filled and hand it to the kernel (survives a kill of this process)."""
        self._check_open()
        self._writer.flush()
        self._last_chunk = time.monotonic()

    # ------------------------------------------------------------------ closing
    @property
    def message_count(self) -> int:
        return sum(t.message_count for t in self.topics.values())

    def metadata(self) -> dict:
        return metadata_document(self.file_name, self.topics, self.start_ns or 0, self.end_ns, self.custom_data)

    def close(self) -> Path:
        """Finish the MCAP (summary, footer) and write metadata.yaml; returns the folder."""
        if self.closed:
            return self.path
        document = self.metadata()
        self._writer.add_metadata("rosbag2", {"serialized_metadata": dump_yaml_cpp_style(
            document["rosbag2_bagfile_information"])})
        self._writer.finish()
        self._stream.fsync()
        self._stream.close()
        self.closed = True
        _write_metadata_file(self.path, document)
        return self.path

    def _check_open(self) -> None:
        if self.closed:
            raise BagError(f"bag {self.path} is closed")

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ---------------------------------------------------------------------- reading


@dataclass
class McapScan:
    """What a record-by-record pass over one MCAP file found."""

    path: Path
    schemas: dict = field(default_factory=dict)       # id -> Schema
    channels: dict = field(default_factory=dict)      # id -> Channel
    complete: bool = False                           # footer and end magic present
    good_bytes: int = 0                               # file offset up to which every record was intact
    problem: str = ""                                 # why the scan stopped early ("" if it did not)
    metadata: dict = field(default_factory=dict)      # name -> mapping (MCAP metadata records)


MAX_CHUNK_BYTES = 256 << 20       # [bytes] a chunk larger than this (uncompressed) is taken as damaged


def _decompress(chunk: Chunk) -> bytes:
    if not 0 <= chunk.uncompressed_size <= MAX_CHUNK_BYTES:
        raise BagError(f"chunk claims {chunk.uncompressed_size} bytes uncompressed (at most {MAX_CHUNK_BYTES} are read)")
    if chunk.compression == "zstd":
        import zstandard

        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        import lz4.frame

        data = lz4.frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise BagError(f"unsupported chunk compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise BagError(f"chunk holds {len(data)} bytes, its header says {chunk.uncompressed_size}")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise BagError("chunk CRC mismatch")
    return data


_MESSAGE_HEAD = struct.Struct("<HIQQ")     # channel id, sequence, log time, publish time


def _chunk_records(data: bytes, scan: "McapScan") -> list[tuple]:
    """Messages of one decompressed chunk as tuples; schemas and channels go into `scan`."""
    out = []
    position, end = 0, len(data)
    unpack_head, unpack_length = _MESSAGE_HEAD.unpack_from, struct.Struct("<Q").unpack_from
    while position < end:
        opcode = data[position]
        (length,) = unpack_length(data, position + 1)
        body = position + 9
        if body + length > end:
            raise BagError("record overruns its chunk")
        if opcode == Opcode.MESSAGE:
            channel, sequence, log_time, publish_time = unpack_head(data, body)
            out.append((channel, log_time, publish_time, sequence, data[body + 22:body + length]))
        elif opcode == Opcode.SCHEMA:
            record = Schema.read(ReadDataStream(io.BytesIO(data[body:body + length])))
            scan.schemas[record.id] = record
        elif opcode == Opcode.CHANNEL:
            record = Channel.read(ReadDataStream(io.BytesIO(data[body:body + length])))
            scan.channels[record.id] = record
        position = body + length
    return out


def _iter_mcap(path: Path, scan: McapScan) -> Iterator[tuple]:
    """Messages of an MCAP file in file order as (channel id, log time, publish time,
    sequence, data), tolerant of a truncated or damaged end.

    Stops at the first record that is cut short or whose chunk fails its CRC; `scan` then
    says where and why. Schemas and channels are collected into `scan` on the way.
    """
    size = path.stat().st_size
    with open(path, "rb") as handle:
        if handle.read(8) != MCAP_MAGIC:
            raise BagError(f"{path} is not an MCAP file (bad magic)")
        offset = 8
        scan.good_bytes = offset
        while True:
            head = handle.read(9)
            if len(head) < 9:
                scan.problem = "file ends without the MCAP footer (the recording was interrupted)"
                return
            opcode, length = head[0], struct.unpack("<Q", head[1:])[0]
            name = Opcode(opcode).name if opcode in Opcode._value2member_map_ else str(opcode)
            if offset + 9 + length > size:
                scan.problem = f"the last record ({name}) is cut short at byte {size} (the recording was interrupted)"
                return
            if length > MAX_CHUNK_BYTES:
                scan.problem = f"damaged {name} record at byte {offset}: {length} bytes long (at most {MAX_CHUNK_BYTES} are read)"
                return
            body = handle.read(length)
            stream = ReadDataStream(io.BytesIO(body))
            try:
                if opcode == Opcode.CHUNK:
                    records = _chunk_records(_decompress(Chunk.read(stream)), scan)
                    yield from records
                elif opcode == Opcode.MESSAGE:
                    channel, sequence, log_time, publish_time = _MESSAGE_HEAD.unpack_from(body, 0)
                    yield channel, log_time, publish_time, sequence, body[22:]
                elif opcode == Opcode.SCHEMA:
                    record = Schema.read(stream)
                    scan.schemas[record.id] = record
                elif opcode == Opcode.CHANNEL:
                    record = Channel.read(stream)
                    scan.channels[record.id] = record
                elif opcode == Opcode.METADATA:
                    record = Metadata.read(stream)
                    scan.metadata[record.name] = dict(record.metadata)
                elif opcode == Opcode.DATA_END:
                    scan.good_bytes = offset + 9 + length
                    scan.complete = _has_footer(handle, size)
                    if not scan.complete:
                        scan.problem = "file ends without the MCAP footer (the recording was interrupted)"
                    return
            except Exception as exc:  # noqa: BLE001 - a damaged record ends the readable part
                scan.problem = f"damaged {name} record at byte {offset}: {exc}"
                return
            offset += 9 + length
            scan.good_bytes = offset


def _has_footer(handle, size: int) -> bool:
    if size < 8 + _FOOTER_SIZE + 8:
        return False
    handle.seek(size - 8)
    if handle.read(8) != MCAP_MAGIC:
        return False
    handle.seek(size - 8 - _FOOTER_SIZE)
    return handle.read(1)[0] == Opcode.FOOTER


def _bag_files(path: Path) -> tuple[dict | None, list[Path]]:
    """(metadata document or None, MCAP files) of a bag folder or a single .mcap file."""
    if path.is_file():
        if path.suffix != ".mcap":
            raise BagError(f"{path} is neither a bag folder nor an .mcap file")
        return None, [path]
    if not path.is_dir():
        raise BagError(f"no bag at {path}")
    meta_path = path / "metadata.yaml"
    document = None
    if meta_path.exists():
        document = _read_metadata(meta_path)
        if document.get("storage_identifier") != "mcap":
            raise BagError(f"{path}: storage {document.get('storage_identifier')!r} is not supported (mcap only)")
        names = document.get("relative_file_paths", [])
        if not isinstance(names, list) or not all(isinstance(name, str) and name for name in names):
            raise BagError(f"{meta_path}: relative_file_paths must be a list of file names, got {names!r}"[:300])
        files = [path / Path(name).name for name in names]
        missing = [str(f) for f in files if not f.exists()]
        if missing:
            raise BagError(f"{path}: metadata.yaml lists missing file(s) {missing}")
        return document, files
    files = sorted(path.glob("*.mcap"))
    if not files:
        raise BagError(f"{path} holds neither metadata.yaml nor an .mcap file: not a bag")
    return None, files


_MAX_METADATA_BYTES = 16 << 20   # [bytes] a metadata.yaml larger than this is not one


def _read_metadata(meta_path: Path) -> dict:
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


class BagReader:
    """Messages of a bag (finished or not) in recording order.

        reader = BagReader("out/run1")
        for topic, log_time_ns, msg in reader.messages(["/force_plate"]):
            ...
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.metadata, self.files = _bag_files(self.path)
        self.scans: list[McapScan] = []
        self._classes: dict[str, type] = {}

    def raw_messages(self, topics=None) -> Iterator[RawMessage]:
        """Serialized messages; `topics` (full names) restricts them."""
        wanted = None if topics is None else {_topic_name(t) for t in topics}
        self.scans = []
        for path in self.files:
            scan = McapScan(path)
            self.scans.append(scan)
            for channel_id, log_time, _, _, data in _iter_mcap(path, scan):
                channel = scan.channels.get(channel_id)
                if channel is None:
                    raise BagError(f"{path}: message on unknown channel {channel_id}")
                if wanted is not None and channel.topic not in wanted:
                    continue
                schema = scan.schemas.get(channel.schema_id)
                yield RawMessage(channel.topic, schema.name if schema else "", log_time, data)

    def payloads(self) -> dict[str, tuple[str, list[int], list[bytes]]]:
        """Every topic's (type, log times [ns], serialized messages), in one pass."""
        out: dict[str, tuple[str, list[int], list[bytes]]] = {}
        by_channel: dict[tuple[int, int], tuple[list, list]] = {}
        self.scans = []
        for index, path in enumerate(self.files):
            scan = McapScan(path)
            self.scans.append(scan)
            for channel_id, log_time, _, _, data in _iter_mcap(path, scan):
                lists = by_channel.get((index, channel_id))
                if lists is None:
                    channel = scan.channels.get(channel_id)
                    if channel is None:
                        raise BagError(f"{path}: message on unknown channel {channel_id}")
                    schema = scan.schemas.get(channel.schema_id)
                    entry = out.setdefault(channel.topic, (schema.name if schema else "", [], []))
                    lists = by_channel[(index, channel_id)] = (entry[1], entry[2])
                lists[0].append(log_time)
                lists[1].append(data)
        return out

    def messages(self, topics=None) -> Iterator[tuple[str, int, Any]]:
        """(topic, log time [ns], message object) decoded with rclpy's CDR deserializer."""
        from rclpy.serialization import deserialize_message

        for raw in self.raw_messages(topics):
            cls = self._classes.get(raw.type)
            if cls is None:
                cls = self._classes[raw.type] = message_class(raw.type)
            yield raw.topic, raw.log_time, deserialize_message(raw.data, cls)

    def topics(self) -> dict[str, TopicInfo]:
        """Topics with their types and message counts (from a full pass over the files)."""
        found: dict[str, TopicInfo] = {}
        for raw in self.raw_messages():
            info = found.get(raw.topic)
            if info is None:
                info = found[raw.topic] = TopicInfo(raw.topic, raw.type)
            info.message_count += 1
        for scan in self.scans:  # topics declared but without messages
            for channel in scan.channels.values():
                if channel.topic not in found:
                    schema = scan.schemas.get(channel.schema_id)
                    found[channel.topic] = TopicInfo(channel.topic, schema.name if schema else "")
        return found

    @property
    def custom_data(self) -> dict[str, str]:
        return dict((self.metadata or {}).get("custom_data") or {})


# ---------------------------------------------------------------------- info and recovery


@dataclass
class BagInfo:
    path: Path
    files: list[Path]
    size_bytes: int
    complete: bool
    problems: list[str]
    message_count: int
    start_ns: int
    end_ns: int
    topics: dict[str, TopicInfo]
    custom_data: dict[str, str]

    @property
    def duration(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9 if self.message_count else 0.0

    def format(self) -> str:
        state = "complete" if self.complete else "UNFINISHED (" + "; ".join(self.problems) + ")"
        lines = [f"bag:       {self.path}", f"state:     {state}",
                 f"files:     {', '.join(f.name for f in self.files)} ({self.size_bytes / 1e6:.2f} MB)",
                 f"messages:  {self.message_count}", f"duration:  {self.duration:.3f} s"]
        if self.message_count:
            lines.append(f"start:     {self.start_ns / 1e9:.9f} s since epoch")
        lines.append("topics:")
        width = max((len(t) for t in self.topics), default=0)
        for name, info in sorted(self.topics.items()):
            lines.append(f"  {name:<{width}}  {info.message_count:>9} msgs  {info.type}")
        if not self.complete:
            lines.append("recover it with: hopper bag recover " + str(self.path))
        return "\n".join(lines)


def bag_info(path: str | os.PathLike) -> BagInfo:
    """Topics, counts, times and state of a bag; reads unfinished bags record by record."""
    reader = BagReader(path)
    topics: dict[str, TopicInfo] = {}
    start, end, count = None, 0, 0
    for raw in reader.raw_messages():
        info = topics.get(raw.topic)
        if info is None:
            info = topics[raw.topic] = TopicInfo(raw.topic, raw.type)
        info.message_count += 1
        count += 1
        start = raw.log_time if start is None else min(start, raw.log_time)
        end = max(end, raw.log_time)
    problems = [f"{scan.path.name}: {scan.problem}" for scan in reader.scans if scan.problem]
    if reader.metadata is None and reader.path.is_dir():
        problems.append("metadata.yaml is missing")
    for scan in reader.scans:
        for channel in scan.channels.values():
            if channel.topic not in topics:
                schema = scan.schemas.get(channel.schema_id)
                topics[channel.topic] = TopicInfo(channel.topic, schema.name if schema else "")
    return BagInfo(reader.path, reader.files, sum(f.stat().st_size for f in reader.files), not problems, problems,
                   count, start or 0, end, topics, reader.custom_data)


@dataclass
class Recovery:
    path: Path
    already_complete: bool
    messages: int
    kept_original: Path | None
    dropped_bytes: int
    problem: str


def recover_bag(path: str | os.PathLike) -> Recovery:
    """Make an interrupted bag complete: rewrite its MCAP from every intact record (summary,
    indexes, footer) and write metadata.yaml. The unfinished file is kept as `*.mcap.unfinished`."""
    folder = Path(path)
    if not folder.is_dir():
        raise BagError(f"{folder} is not a bag folder")
    document, files = _bag_files(folder)
    if len(files) != 1:
        raise BagError(f"{folder}: recovery handles one MCAP file per bag, found {len(files)}")
    source = files[0]
    scan = McapScan(source)
    count = sum(1 for _ in _iter_mcap(source, scan))           # first pass: counts only (bounded memory)
    if scan.complete and document is not None:
        return Recovery(folder, True, count, None, 0, "")
    messages = _Replay(source)                                  # second pass: streamed again where needed
    size = source.stat().st_size
    topics: dict[str, TopicInfo] = {}
    custom = {}
    stored = scan.metadata.get("rosbag2", {}).get("serialized_metadata")
    if stored:
        custom = (yaml.safe_load(stored) or {}).get("custom_data") or {}
    if scan.complete:  # the MCAP was finished, only metadata.yaml is missing
        recovered = source
        kept = None
        start, end = _count_topics(messages, scan, topics)
    else:
        kept = source.with_name(source.name + ".unfinished")
        if kept.exists():
            raise BagError(f"{kept} exists already: a previous recovery was interrupted; move it away first")
        temporary = source.with_name(source.name + ".recovering")
        if temporary.exists():
            temporary.unlink()
        stream = _WriteThrough(temporary)
        writer = McapWriter(stream, chunk_size=DEFAULT_CHUNK_SIZE, compression=CompressionType.ZSTD)
        writer.start(profile="ros2", library="hopper_ros recording (recovered)")
        schema_ids, channel_ids = {}, {}
        for channel_id, log_time, publish_time, sequence, data in messages:
            channel = _channel(scan, channel_id, source)
            if channel_id not in channel_ids:
                schema = scan.schemas.get(channel.schema_id)
                if schema is not None and schema.id not in schema_ids:
                    schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                channel_ids[channel_id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_ids.get(channel.schema_id, 0), dict(channel.metadata))
            writer.add_message(channel_ids[channel_id], log_time, data, publish_time, sequence)
        start, end = _count_topics(messages, scan, topics)
        document = metadata_document(source.name, topics, start, end, custom)
        writer.add_metadata("rosbag2", {"serialized_metadata": dump_yaml_cpp_style(
            document["rosbag2_bagfile_information"])})
        writer.finish()
        stream.fsync()
        stream.close()
        os.replace(source, kept)
        os.replace(temporary, source)
        recovered = source
    _write_metadata_file(folder, metadata_document(recovered.name, topics, start, end, custom))
    return Recovery(folder, False, count, kept, size - scan.good_bytes, scan.problem)


def _channel(scan: McapScan, channel_id: int, path) -> Channel:
    channel = scan.channels.get(channel_id)
    if channel is None:
        raise BagError(f"{path}: message on unknown channel {channel_id}")
    return channel


class _Replay:
    """The messages of an MCAP file, read again on every iteration (never all held in memory)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __iter__(self):
        return _iter_mcap(self.path, McapScan(self.path))


def _count_topics(messages, scan: McapScan, topics: dict) -> tuple[int, int]:
    start, end = None, 0
    for channel_id, log_time, *_ in messages:
        channel = _channel(scan, channel_id, scan.path)
        info = topics.get(channel.topic)
        if info is None:
            schema = scan.schemas.get(channel.schema_id)
            qos = yaml.safe_load(channel.metadata.get("offered_qos_profiles", "") or "[]") or []
            type_name = schema.name if schema else ""
            info = topics[channel.topic] = TopicInfo(channel.topic, type_name, 0, qos,
                                                     type_hash(type_name) if type_name else "")
        info.message_count += 1
        start = log_time if start is None else min(start, log_time)
        end = max(end, log_time)
    return start or 0, end

