"""An MCAP file's records in file order (mcap's non-seeking ``StreamReader``): a log cut
short by a killed recorder (no summary, torn last chunk) still yields every whole chunk
before the cut. The message indexes that follow each chunk say which channels it holds: a
reader asking for some topics leaves the chunks that hold none of them compressed."""

from __future__ import annotations

import io
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zstandard
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    Footer,
    Header,
    McapRecord,
    Message,
    MessageIndex,
    Metadata,
    Schema,
)
from mcap.stream_reader import StreamReader
from zstandard import ZstdError

from smccli.errors import LogError


@dataclass(slots=True)
class RawLog:
    """The records of a file in file order, before decoding."""

    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[Attachment] = field(default_factory=list)
    messages: list[Message] = field(default_factory=list)
    truncated: bool = False
    cut_at: int = 0
    skipped: dict[int, int] = field(default_factory=dict)
    """Messages per channel in chunks left compressed (no wanted topic in them)."""
    chunks_read: int = 0
    """Chunks decompressed."""

    def topic(self, msg: Message) -> str:
        """Topic of ``msg``'s channel (``check_channels`` first: KeyError on an unknown one)."""
        return self.channels[msg.channel_id].topic


def read_bytes(path: Path) -> bytes:
    if not path.exists():
        raise LogError(f"{path}: no such file")
    if not path.is_file():
        raise LogError(f"{path}: not a file")
    data = path.read_bytes()
    if not data:
        raise LogError(f"{path}: empty file (0 bytes), expected an MCAP log")
    return data


# A chunk is read here, record by record with ``struct``: mcap has no public call that reads
# one chunk (its ``breakup_chunk`` is not in ``mcap.stream_reader.__all__``), and leaving the
# unwanted chunks compressed needs one. The records are mcap's classes, so mcap is pinned in
# pyproject.toml to the versions tests/test_logs.py checked this walker against.
_RECORD = struct.Struct("<BQ")  # opcode, length
_MESSAGE = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_SCHEMA, _CHANNEL, _MESSAGE_OP = 0x03, 0x04, 0x05
"""The MCAP spec's opcodes of the records a chunk holds."""


class ChunkError(ValueError):
    """A chunk that does not read: its compression unknown, its CRC wrong, a record or a
    field running past its end."""


class ChunkCrcError(ChunkError):
    """A chunk whose decompressed bytes do not match its stored CRC."""

    def __init__(self, expected: int, actual: int) -> None:
        super().__init__(
            f"crc validation failed in Chunk, expected: {expected}, calculated: {actual}"
        )
        self.expected = expected
        """The CRC-32 the chunk stores."""
        self.actual = actual
        """The CRC-32 of its decompressed bytes."""


def _chunk_records(chunk: Chunk) -> list[McapRecord]:
    """The schemas, channels and messages of ``chunk`` in order, as mcap's record classes
    (a record of another kind is skipped, as the spec allows); ChunkError when it does not
    read."""
    data = decompressed(chunk)
    out: list[McapRecord] = []
    pos, size = 0, len(data)
    while pos < size:
        if pos + _RECORD.size > size:
            raise ChunkError(f"chunk: a record's head cut at byte {pos} of {size}")
        opcode, length = _RECORD.unpack_from(data, pos)
        pos += _RECORD.size
        end = pos + length
        if end > size:
            raise ChunkError(f"chunk: a record of {length} bytes at byte {pos} of {size}")
        if opcode == _MESSAGE_OP:
            if length < _MESSAGE.size:
                raise ChunkError(f"chunk: a message of {length} bytes at byte {pos}")
            channel_id, sequence, log_time, publish_time = _MESSAGE.unpack_from(data, pos)
            out.append(
                Message(
                    channel_id=channel_id,
                    log_time=log_time,
                    data=data[pos + _MESSAGE.size : end],
                    publish_time=publish_time,
                    sequence=sequence,
                )
            )
        elif opcode == _CHANNEL:
            out.append(_channel(data, pos, end))
        elif opcode == _SCHEMA:
            out.append(_schema(data, pos, end))
        pos = end
    return out


def decompressed(chunk: Chunk) -> bytes:
    """A chunk's records as bytes, its CRC checked (when stored): ChunkCrcError on a
    mismatch, ChunkError for an unknown compression; zstandard's and lz4's own errors
    for a damaged frame."""
    if chunk.compression == "zstd":
        data = zstandard.decompress(chunk.data, chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        import lz4.frame  # mcap's dependency; smc writes zstd

        data = lz4.frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise ChunkError(f"chunk compression {chunk.compression!r}, expected zstd, lz4 or none")
    crc = zlib.crc32(data)
    if chunk.uncompressed_crc != 0 and crc != chunk.uncompressed_crc:
        raise ChunkCrcError(chunk.uncompressed_crc, crc)
    return data


class _Fields:
    """Fields read in order from ``data[pos:end]`` (one record); ChunkError past ``end``."""

    def __init__(self, data: bytes, pos: int, end: int) -> None:
        self.data, self.pos, self.end = data, pos, end

    def take(self, n: int) -> bytes:
        if self.pos + n > self.end:
            raise ChunkError(f"chunk: a field of {n} bytes past its record's end")
        self.pos += n
        return self.data[self.pos - n : self.pos]

    def u16(self) -> int:
        return int(_U16.unpack(self.take(2))[0])

    def u32(self) -> int:
        return int(_U32.unpack(self.take(4))[0])

    def text(self) -> str:
        try:
            return self.take(self.u32()).decode()
        except UnicodeDecodeError as exc:
            raise ChunkError(f"chunk: a string that is not UTF-8 ({exc})") from None

    def done(self) -> None:
        if self.pos != self.end:
            raise ChunkError(f"chunk: {self.end - self.pos} bytes left in a record")


def _channel(data: bytes, pos: int, end: int) -> Channel:
    f = _Fields(data, pos, end)
    cid, schema_id, topic, encoding = f.u16(), f.u16(), f.text(), f.text()
    meta_end = f.u32() + f.pos
    metadata: dict[str, str] = {}
    while f.pos < meta_end:
        key = f.text()
        metadata[key] = f.text()
    f.done()
    return Channel(
        id=cid, topic=topic, message_encoding=encoding, metadata=metadata, schema_id=schema_id
    )


def _schema(data: bytes, pos: int, end: int) -> Schema:
    f = _Fields(data, pos, end)
    sid, name, encoding = f.u16(), f.text(), f.text()
    body = f.take(f.u32())
    f.done()
    return Schema(id=sid, name=name, encoding=encoding, data=body)


def scan_records(path: Path, data: bytes, wanted: set[str] | None = None) -> RawLog:
    """The file's records in file order. With ``wanted`` topics, a chunk is decompressed
    only if it may hold one: its message indexes (the records that follow a chunk) name
    its channels, and a chunk whose channels are all known and all unwanted is counted
    from its indexes and skipped. A chunk without indexes (a torn last chunk, a writer
    that writes none) or with a channel not yet defined is read."""
    raw = RawLog()
    stream = io.BytesIO(data)
    reader = StreamReader(stream, validate_crcs=True, emit_chunks=True)
    footer = False
    pending: list[Any] = []  # [chunk, {channel id: messages}] until its indexes are read

    def settle() -> None:
        if not pending:
            return
        chunk, index = pending
        pending.clear()
        known = bool(index) and all(c in raw.channels for c in index)
        if wanted is not None and known and not {raw.channels[c].topic for c in index} & wanted:
            for c, n in index.items():
                raw.skipped[c] = raw.skipped.get(c, 0) + n
            return
        raw.chunks_read += 1
        for r in _chunk_records(chunk):
            add_record(raw, r)

    try:
        try:
            for rec in reader.records:
                if isinstance(rec, MessageIndex) and pending:
                    pending[1][rec.channel_id] = len(rec.records)
                    continue
                settle()
                if isinstance(rec, Chunk):
                    pending[:] = [rec, {}]
                    continue
                add_record(raw, rec)
                footer = footer or isinstance(rec, Footer)
        finally:
            settle()  # the last chunk before the footer or the cut
    except InvalidMagic:
        if raw.header is None:
            raise LogError(f"{path}: not an MCAP file (bad magic bytes)") from None
        footer = True  # footer read, closing magic damaged: every record is in
    except (EndOfFile, struct.error):
        if raw.header is None:
            raise LogError(f"{path}: not an MCAP file (too short for a header)") from None
    except (McapError, ValueError, ZstdError) as e:  # CRC mismatch, absurd length, bad zstd
        raise LogError(f"{path}: corrupt MCAP ({e})") from None
    except OverflowError:  # a record length beyond what a read can ask for (> 2**63)
        raise LogError(f"{path}: corrupt MCAP (record length out of range)") from None
    except RuntimeError as e:  # how lz4.frame reports a corrupt lz4 chunk
        raise LogError(f"{path}: corrupt MCAP (lz4 chunk: {e})") from None
    except MemoryError:  # zstandard allocates what a damaged frame header claims
        raise LogError(
            f"{path}: corrupt MCAP (a zstd chunk claims more data than memory holds)"
        ) from None
    if not footer:
        raw.truncated = True
        raw.cut_at = stream.tell()
    return raw


def add_record(raw: RawLog, rec: McapRecord) -> None:
    """A record (from a chunk or outside one) into ``raw``."""
    if isinstance(rec, Message):
        raw.messages.append(rec)
    elif isinstance(rec, Channel):
        raw.channels[rec.id] = rec
    elif isinstance(rec, Schema):
        raw.schemas[rec.id] = rec
    elif isinstance(rec, Metadata):
        raw.metadata[rec.name] = dict(rec.metadata)
    elif isinstance(rec, Attachment):
        raw.attachments.append(rec)
    elif isinstance(rec, Header):
        raw.header = rec
