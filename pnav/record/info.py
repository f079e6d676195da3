"""``pnav record info FILE``: what a recording holds, read with the ``mcap`` package.

Channels (topic, schema, encoding, messages), the sim time it spans and the robots in it. A
recording whose writer was killed before it finished has no summary: its messages are then
counted by reading them all.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader

from common.errors import UsageError


@dataclass
class ChannelInfo:
    topic: str
    schema: str
    encoding: str
    messages: int = 0


@dataclass
class RecordingInfo:
    path: str
    channels: list[ChannelInfo] = field(default_factory=list)
    messages: int = 0
    start_s: float = 0.0  # sim time of the first message
    end_s: float = 0.0
    robots: list[str] = field(default_factory=list)
    complete: bool = True  # the file has its summary (closed cleanly)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def summarize(path: Path) -> RecordingInfo:
    if not path.is_file():
        raise UsageError(f"no recording at {path}")
    try:
        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()
            if summary is not None and summary.statistics is not None:
                return _from_summary(path, summary)
            stream.seek(0)
            return _by_reading(path, stream)
    except (McapError, ValueError, EOFError) as exc:
        raise UsageError(f"{path} is not a readable MCAP file: {exc}") from None


def _from_summary(path: Path, summary: Any) -> RecordingInfo:
    stats = summary.statistics
    info = RecordingInfo(str(path))
    for channel_id, channel in sorted(summary.channels.items(), key=lambda c: c[1].topic):
        schema = summary.schemas.get(channel.schema_id)
        info.channels.append(
            ChannelInfo(
                channel.topic,
                schema.name if schema is not None else "",
                channel.message_encoding,
                stats.channel_message_counts.get(channel_id, 0),
            )
        )
    info.messages = stats.message_count
    info.start_s, info.end_s = stats.message_start_time / 1e9, stats.message_end_time / 1e9
    info.robots = _robots(info.channels)
    return info


def _by_reading(path: Path, stream: Any) -> RecordingInfo:
    info = RecordingInfo(str(path), complete=False)
    by_id: dict[int, ChannelInfo] = {}
    times: list[int] = []
    for schema, channel, message in make_reader(stream).iter_messages():
        entry = by_id.get(channel.id)
        if entry is None:
            name = schema.name if schema is not None else ""
            entry = by_id[channel.id] = ChannelInfo(channel.topic, name, channel.message_encoding)
        entry.messages += 1
        times.append(message.log_time)
    info.channels = sorted(by_id.values(), key=lambda c: c.topic)
    info.messages = len(times)
    if times:
        info.start_s, info.end_s = min(times) / 1e9, max(times) / 1e9
    info.robots = _robots(info.channels)
    return info


def _robots(channels: list[ChannelInfo]) -> list[str]:
    """Robots are the first part of the per-robot topics (``/r1/scan``)."""
    return sorted({c.topic.split("/")[1] for c in channels if c.topic.count("/") >= 2})


def text(info: RecordingInfo) -> str:
    width = max([len(c.topic) for c in info.channels] + [5])
    lines = [
        f"{info.path}: {info.messages} messages, sim time {info.start_s:.2f} to "
        f"{info.end_s:.2f} s ({info.end_s - info.start_s:.2f} s)",
        f"robots: {', '.join(info.robots) or '-'}",
    ]
    if not info.complete:
        lines.append("no summary: the recording was not closed cleanly (counted by reading it)")
    lines.append(f"{'topic':<{width}}  {'messages':>8}  schema (encoding)")
    for c in info.channels:
        lines.append(f"{c.topic:<{width}}  {c.messages:>8}  {c.schema} ({c.encoding})")
    return "\n".join(lines)


def run(path: Path, json_out: str | None = None) -> int:
    info = summarize(path)
    if json_out == "-":
        print(json.dumps(info.as_dict(), indent=2))
        return 0
    print(text(info))
    if json_out:
        Path(json_out).write_text(json.dumps(info.as_dict(), indent=2) + "\n")
    return 0
