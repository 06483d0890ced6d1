"""Logs written from another's records: a summary of counts, a copy with topics left out."""

from __future__ import annotations

import io
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import IO, Any

from mcap.records import (
    Channel,
)
from mcap.writer import CompressionType, Writer

from smccli.errors import LogError
from smccli.logs import topics as tp
from smccli.logs.checks import BadContent, check_channels, json_message, message_error
from smccli.logs.records import RawLog, read_bytes, scan_records
from smccli.outputs import check_output, write_atomic


def log_summary(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Duration, topics with counts and rates, saliency marks and size, without decoding images."""
    path = Path(path)
    data = read_bytes(path)
    raw = scan_records(path, data)
    check_channels(path, raw)
    per: dict[str, list[int]] = {c.topic: [] for c in raw.channels.values()}
    marks = []
    for m in raw.messages:
        topic = raw.topic(m)
        per[topic].append(m.log_time)
        if topic == tp.SALIENCY and raw.channels[m.channel_id].message_encoding == "json":
            try:
                obj = json_message(topic, m.data)
            except BadContent as e:
                raise message_error(path, topic, m.log_time, str(e)) from None
            marks.append({"t": m.log_time / 1e9, "source": obj["source"], "label": obj["label"]})
    times = [m.log_time for m in raw.messages]
    start, end = (min(times), max(times)) if times else (0, 0)
    topics = {}
    for topic, ts in sorted(per.items()):
        span = (ts[-1] - ts[0]) / 1e9 if len(ts) > 1 else 0.0
        rate = (len(ts) - 1) / span if span > 0 else 0.0
        topics[topic] = {"count": len(ts), "rate_hz": rate}
    return {
        "path": str(path),
        "size_bytes": len(data),
        "start_s": start / 1e9,
        "end_s": end / 1e9,
        "duration_s": (end - start) / 1e9,
        "truncated": raw.truncated,
        "metadata": raw.metadata.get(tp.METADATA_NAME, {}),
        "attachments": sorted(a.name for a in raw.attachments),
        "topics": topics,
        "marks": marks,
    }


def copy_log(
    raw: RawLog,
    out: IO[bytes],
    *,
    keep: Callable[[Channel], bool] | None = None,
    extra_metadata: Mapping[str, Mapping[str, str]] | None = None,
) -> int:
    """Write ``raw`` as a complete, indexed MCAP (zstd chunks, summary) to ``out``.

    Header profile and library, metadata, attachments, the schemas, the channels ``keep``
    accepts (all by default) and their messages, in file order with their times and
    sequence numbers, then ``extra_metadata`` records. Schemas no channel uses are kept
    too. Returns the messages written.
    """
    w = Writer(out, compression=CompressionType.ZSTD)
    header = raw.header
    w.start(profile=header.profile if header else "", library=header.library if header else "smc")
    for name, meta in raw.metadata.items():
        w.add_metadata(name, meta)
    for a in raw.attachments:
        w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    for cid, ch in sorted(raw.channels.items()):
        if keep is not None and not keep(ch):
            continue
        if ch.schema_id and ch.schema_id not in schema_ids and ch.schema_id in raw.schemas:
            s = raw.schemas[ch.schema_id]
            schema_ids[ch.schema_id] = w.register_schema(s.name, s.encoding, s.data)
        channel_ids[cid] = w.register_channel(
            ch.topic, ch.message_encoding, schema_ids.get(ch.schema_id, 0), ch.metadata
        )
    used = {ch.schema_id for ch in raw.channels.values()}
    for sid, s in sorted(raw.schemas.items()):
        if sid not in used:
            w.register_schema(s.name, s.encoding, s.data)
    n = 0
    for m in raw.messages:
        if m.channel_id in channel_ids:
            w.add_message(channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
            n += 1
    for extra_name, extra_meta in (extra_metadata or {}).items():
        w.add_metadata(extra_name, dict(extra_meta))
    w.finish()
    return n


def strip_topic(
    src: str | os.PathLike[str],
    dst: str | os.PathLike[str],
    topic: str,
    *,
    force: bool = False,
) -> Path:
    """Copy ``src`` to ``dst`` without ``topic`` (e.g. ``/sim/ground_truth``); other messages
    keep their bytes, times and order. ``dst`` is written atomically."""
    src, dst = Path(src), Path(dst)
    raw = scan_records(src, read_bytes(src))
    check_channels(src, raw)
    topics = sorted({c.topic for c in raw.channels.values()})
    if topic not in topics:
        raise LogError(f"{src}: no topic {topic} (topics: {', '.join(topics)})")
    check_output(dst, force=force)
    buf = io.BytesIO()
    copy_log(raw, buf, keep=lambda ch: ch.topic != topic)
    write_atomic(dst, buf.getvalue())
    return dst
