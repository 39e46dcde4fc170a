"""`hopper bag info` as text with dates, or as JSON (`--json`), from `recording.bag.bag_info`. No ROS import.

Dates are local time with the zone and the seconds since the epoch beside them, as `ros2 bag info`
shows them: `start:     2026-11-21 10:00:00.123456 CET (1795251600.123456789)`.
"""

from __future__ import annotations

import datetime as dt
import json


def _date(ns: int) -> str:
    moment = dt.datetime.fromtimestamp(ns / 1e9).astimezone()
    return f"{moment.strftime('%Y-%m-%d %H:%M:%S.%f')} {moment.strftime('%Z')} ({ns // 10**9}.{ns % 10**9:09d})"


def iso(ns: int) -> str:
    return dt.datetime.fromtimestamp(ns / 1e9, tz=dt.timezone.utc).isoformat(timespec="microseconds")


def info_text(info) -> str:
    """BagInfo.format() with the start and end as dates."""
    lines = info.format().splitlines()
    out = []
    for line in lines:
        if line.startswith("start:"):
            out.append(f"start:     {_date(info.start_ns)}")
            out.append(f"end:       {_date(info.end_ns)}")
        else:
            out.append(line)
    return "\n".join(out)


def info_document(info) -> dict:
    """The bag's summary for scripts: times in ns since the epoch and as ISO 8601 (UTC)."""
    started = info.message_count > 0
    return {
        "path": str(info.path),
        "complete": info.complete,
        "problems": list(info.problems),
        "files": [f.name for f in info.files],
        "size_bytes": info.size_bytes,
        "message_count": info.message_count,
        "duration_s": info.duration,
        "start_ns": info.start_ns if started else None,
        "end_ns": info.end_ns if started else None,
        "start": iso(info.start_ns) if started else None,
        "end": iso(info.end_ns) if started else None,
        "topics": [{"name": name, "type": t.type, "message_count": t.message_count}
                   for name, t in sorted(info.topics.items())],
        "custom_data": dict(info.custom_data),
    }


def info_json(info) -> str:
    return json.dumps(info_document(info), indent=1)
