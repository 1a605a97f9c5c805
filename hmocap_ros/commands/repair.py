"""``hmocap repair BAG``: rewrite a bag whose recording did not close, with its MCAP summary.

The MCAP file is read up to its last complete record (:mod:`~hmocap_ros.io.summaryless_mcap`)
and every schema, channel, message, metadata and attachment record in it is copied into a new
file beside it, which then replaces the original; a rosbag2 directory also gets its
``metadata.yaml``. A bag that is whole already is left as it is.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import yaml
from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer as McapWriter

from hmocap_ros.io.bag_writer import (
    SealedMcapFile,
    TopicRecord,
    mcap_rosbag2_metadata,
    open_mcap_writer,
    rosbag2_info,
    write_rosbag2_metadata,
)
from hmocap_ros.io.summaryless_mcap import has_summary, recording_file, summaryless_view


@dataclass(frozen=True)
class RepairResult:
    """What a repair did: messages kept per topic, and bytes of a cut record left out."""

    path: Path
    counts: dict[str, int]
    dropped_bytes: int
    error: str = ""


def repair(path: str | Path) -> RepairResult | None:
    """Rewrite the bag at ``path`` whole; None when it has its summary already."""
    path = Path(path)
    if has_summary(recording_file(path)) and (path.is_file() or (path / "metadata.yaml").exists()):
        return None
    view = summaryless_view(path, salvage=True)
    if view is None:
        raise SystemExit(f"hmocap repair: {path} is not an MCAP file with a complete header; nothing to recover")
    staging = view.path.with_name(f".{view.path.name}.repair")
    staging.unlink(missing_ok=True)
    stream = SealedMcapFile(staging)
    writer: McapWriter | None = None
    channels: dict[int, tuple[int, Channel, str]] = {}
    schemas: dict[int, tuple[int, str]] = {}
    counts: dict[int, int] = {}
    start_ns, end_ns = 2**63 - 1, 0
    error = ""
    with view.open() as source:
        records = StreamReader(source, validate_crcs=True).records
        try:
            for record in records:
                if isinstance(record, Header):
                    writer = open_mcap_writer(stream)
                elif writer is None:  # an MCAP file opens with its Header: a record before it is damage
                    raise ValueError(f"a {type(record).__name__} record before the MCAP header")
                elif isinstance(record, Schema):
                    schemas[record.id] = (writer.register_schema(record.name, record.encoding, record.data),
                                          record.name)
                elif isinstance(record, Channel) and record.id not in channels:
                    schema_id, msgtype = schemas.get(record.schema_id, (0, ""))
                    new_id = writer.register_channel(record.topic, record.message_encoding, schema_id,
                                                     record.metadata)
                    channels[record.id] = (new_id, record, msgtype)
                    counts[record.id] = 0
                elif isinstance(record, Message) and record.channel_id in channels:
                    writer.add_message(channels[record.channel_id][0], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                    counts[record.channel_id] += 1
                    start_ns, end_ns = min(start_ns, record.log_time), max(end_ns, record.log_time)
                elif isinstance(record, Metadata) and record.name != "rosbag2":
                    writer.add_metadata(record.name, record.metadata)
                elif isinstance(record, Attachment):
                    writer.add_attachment(record.create_time, record.log_time, record.name,
                                          record.media_type, record.data)
        except Exception as err:  # a damaged chunk: keep what came before it
            error = f"stopped at a damaged record: {err}"
    return _finish(path, view, staging, stream, writer, channels, counts, start_ns, end_ns, error)


def _finish(path, view, staging, stream, writer, channels, counts, start_ns, end_ns, error) -> RepairResult:
    """Close the rewritten file with its summary and put it in place of the original."""
    if writer is None:
        stream.abandon()
        staging.unlink(missing_ok=True)
        raise SystemExit(f"hmocap repair: {view.path} holds no MCAP header; nothing to recover")
    topics = [TopicRecord(channel.topic, msgtype, _qos(channel), counts[cid])
              for cid, (_, channel, msgtype) in channels.items()]
    info = rosbag2_info(view.path.name, topics, start_ns, end_ns)
    writer.add_metadata("rosbag2", mcap_rosbag2_metadata(info))
    writer.finish()
    stream.close()
    staging.replace(view.path)
    if path.is_dir():
        write_rosbag2_metadata(path, info)
    return RepairResult(path, {t.topic: t.count for t in topics}, view.dropped_bytes, error)


def _qos(channel: Channel) -> list:
    """The offered QoS profiles a rosbag2 channel keeps in its metadata (YAML text)."""
    text = channel.metadata.get("offered_qos_profiles", "")
    return (yaml.safe_load(text) or []) if text else []


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", help=".mcap file or rosbag2 directory of a recording that did not close")


def main_from_args(ns: argparse.Namespace) -> int:
    path = Path(ns.bag)
    if not path.exists():
        print(f"hmocap repair: {path}: does not exist", file=sys.stderr)
        return 2
    if path.is_dir() and not (path / "metadata.yaml").exists() and not list(path.glob("*.mcap")):
        print(f"hmocap repair: {path}: a folder without a bag in it", file=sys.stderr)
        return 2
    try:
        result = repair(path)
    except (OSError, ValueError) as err:
        print(f"hmocap repair: {path}: {err}", file=sys.stderr)
        return 2
    if result is None:
        print(f"{ns.bag} is whole already (it has its MCAP summary); nothing to do")
        return 0
    total = sum(result.counts.values())
    print(f"repaired {result.path}: {total} messages on {len(result.counts)} topic(s)"
          + (f", {result.dropped_bytes} bytes of a cut record left out" if result.dropped_bytes else ""))
    for topic, count in sorted(result.counts.items()):
        print(f"  {topic}: {count} messages")
    if result.error:
        print(f"  {result.error}")
    return 0
