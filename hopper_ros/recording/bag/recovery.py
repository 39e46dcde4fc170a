"""A bag's state (`bag_info`: topics, counts, times, complete or not) and the recovery of an
interrupted one (`recover_bag`: its MCAP rewritten from every intact record, metadata.yaml written)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import yaml
from mcap.records import Channel
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from ..schemas import type_hash
from .metadata import BagError, TopicInfo, dump_yaml_cpp_style, metadata_document, write_metadata_file
from .reader import BagReader, McapScan, bag_files, iter_mcap
from .writer import DEFAULT_CHUNK_SIZE, WriteThrough

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
    document, files = bag_files(folder)
    if len(files) != 1:
        raise BagError(f"{folder}: recovery handles one MCAP file per bag, found {len(files)}")
    source = files[0]
    scan = McapScan(source)
    count = sum(1 for _ in iter_mcap(source, scan))           # first pass: counts only (bounded memory)
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
        stream = WriteThrough(temporary)
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
    write_metadata_file(folder, metadata_document(recovered.name, topics, start, end, custom))
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
        return iter_mcap(self.path, McapScan(self.path))


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
