"""BagWriter: a rosbag2 bag (MCAP storage) written crash-safe, every byte straight to the file and
a chunk closed at least every `chunk_interval` seconds. The package's docstring says more."""

from __future__ import annotations

import copy
import os
import time
from pathlib import Path
from typing import Any, Mapping

from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from ..schemas import message_definition, type_hash
from .metadata import (DEFAULT_QOS, BagError, TopicInfo, dump_yaml_cpp_style, metadata_document, normalised_type,
                       topic_name, write_metadata_file)

DEFAULT_CHUNK_SIZE = 256 * 1024    # [bytes] uncompressed chunk size
DEFAULT_CHUNK_INTERVAL = 1.0       # [s] a chunk is closed at least this often while recording


class WriteThrough:
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
        self._stream = WriteThrough(self.path / self.file_name)
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
        name = topic_name(topic)
        type_name = normalised_type(type_name)
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
        name = topic if topic in self._channels else topic_name(topic)
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
        name = topic if topic in self._channels else topic_name(topic)
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
        write_metadata_file(self.path, document)
        return self.path

    def _check_open(self) -> None:
        if self.closed:
            raise BagError(f"bag {self.path} is closed")

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
