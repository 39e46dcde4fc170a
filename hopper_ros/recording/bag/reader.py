"""BagReader: the messages of a bag in recording order, finished or not (an unfinished MCAP is read
record by record up to its last intact chunk; `McapScan` says how far and why it stopped)."""

from __future__ import annotations

import io
import os
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Metadata, Schema

from hopper_ros.runtime.messages import message_class

from .metadata import BagError, RawMessage, TopicInfo, read_metadata, topic_name

MCAP_MAGIC = b"\x89MCAP0\r\n"
_FOOTER_SIZE = 1 + 8 + 20          # opcode, length, footer body


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


def iter_mcap(path: Path, scan: McapScan) -> Iterator[tuple]:
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


def bag_files(path: Path) -> tuple[dict | None, list[Path]]:
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
        document = read_metadata(meta_path)
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


class BagReader:
    """Messages of a bag (finished or not) in recording order.

        reader = BagReader("out/run1")
        for topic, log_time_ns, msg in reader.messages(["/force_plate"]):
            ...
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.metadata, self.files = bag_files(self.path)
        self.scans: list[McapScan] = []
        self._classes: dict[str, type] = {}

    def raw_messages(self, topics=None) -> Iterator[RawMessage]:
        """Serialized messages; `topics` (full names) restricts them."""
        wanted = None if topics is None else {topic_name(t) for t in topics}
        self.scans = []
        for path in self.files:
            scan = McapScan(path)
            self.scans.append(scan)
            for channel_id, log_time, _, _, data in iter_mcap(path, scan):
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
            for channel_id, log_time, _, _, data in iter_mcap(path, scan):
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
