"""An MCAP file's records walked byte by byte, trusting none of them: where the records
lie, which CRCs match, where a truncated file was cut (``smc doctor``'s first rows and
its repair)."""

from __future__ import annotations

import io
import zlib
from dataclasses import dataclass
from typing import Any

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Chunk, Footer, Statistics

from smccli.logs.records import ChunkCrcError, decompressed

MAGIC = b"\x89MCAP0\r\n"
"""The magic bytes an MCAP file opens (and closes) with."""
_HEAD = 9
"""Bytes before a record's body: opcode (1) + length (8)."""


@dataclass(frozen=True, slots=True)
class Layout:
    """Where a file's records lie and which CRCs match."""

    chunks: int
    """Whole chunk records."""
    crcs: int
    """Non-zero CRCs checked."""
    bad_data: tuple[str, ...]
    """Damage the reader rejects: chunk CRC or decompression, data section CRC."""
    bad_other: tuple[str, ...]
    """Damage compile does not see: attachment and summary CRCs."""
    footer: Footer | None
    """The footer, None when the file ends before it (truncated)."""
    end: int
    """Byte offset just after the last whole record."""
    torn: int | None
    """Offset of the record cut by the end of the file, if one is."""
    torn_opcode: int | None
    """Opcode of that record (None if even its 9-byte head is cut)."""
    chunk_indexes: int
    """Chunk index records in the summary."""
    statistics: Statistics | None
    """The summary's statistics record, if any."""
    closing_magic: bool
    """Whether the magic bytes follow the footer."""


def _record(cls: Any, body: bytes) -> Any:
    return cls.read(ReadDataStream(io.BytesIO(body)))


def _chunk_problem(body: bytes) -> tuple[str | None, bool]:
    """(problem or None, whether a CRC was checked) for one chunk record's body."""
    try:
        chunk = _record(Chunk, body)
        decompressed(chunk)  # the reader's own decompression and CRC check
    except ChunkCrcError as e:
        return f"CRC mismatch (stored {e.expected:#010x}, computed {e.actual:#010x})", True
    except Exception as e:  # any codec or framing failure means the chunk is unreadable
        return f"unreadable ({type(e).__name__}: {e})", False
    return None, chunk.uncompressed_crc != 0


def record_layout(data: bytes) -> Layout:
    """Walk the records after the opening magic without trusting any of them."""
    off, n = len(MAGIC), len(data)
    chunks = crcs = indexes = 0
    bad_data: list[str] = []
    bad_other: list[str] = []
    footer: Footer | None = None
    stats: Statistics | None = None
    torn: int | None = None
    torn_op: int | None = None
    while off < n:
        if off + _HEAD > n:
            torn = off
            break
        opcode = data[off]
        end = off + _HEAD + int.from_bytes(data[off + 1 : off + _HEAD], "little")
        if end > n:
            torn, torn_op = off, opcode
            break
        body = data[off + _HEAD : end]
        if opcode == Opcode.CHUNK:
            chunks += 1
            problem, checked = _chunk_problem(body)
            crcs += checked
            if problem:
                bad_data.append(f"chunk {chunks} at byte {off}: {problem}")
        elif opcode == Opcode.ATTACHMENT and len(body) >= 4:
            stored = int.from_bytes(body[-4:], "little")
            if stored:
                crcs += 1
                if zlib.crc32(body[:-4]) != stored:
                    name = _attachment_name(body)
                    bad_other.append(f"attachment {name} at byte {off}: CRC mismatch")
        elif opcode == Opcode.DATA_END and len(body) >= 4:
            stored = int.from_bytes(body[:4], "little")
            if stored:  # 0 = not computed (the Python mcap writer leaves it 0)
                crcs += 1
                if zlib.crc32(data[:off]) != stored:
                    bad_data.append("data section: CRC mismatch")
        elif opcode == Opcode.CHUNK_INDEX:
            indexes += 1
        elif opcode == Opcode.STATISTICS:
            try:
                stats = _record(Statistics, body)
            except Exception:  # a damaged statistics record is reported as missing
                stats = None
        elif opcode == Opcode.FOOTER:
            footer = _record(Footer, body)
            if footer.summary_crc:
                crcs += 1
                start = footer.summary_start or off
                # The CRC covers the summary through the footer's summary_offset_start field.
                if zlib.crc32(data[start : off + _HEAD + 16]) != footer.summary_crc:
                    bad_other.append("summary: CRC mismatch")
            off = end
            break
        off = end
    return Layout(
        chunks=chunks,
        crcs=crcs,
        bad_data=tuple(bad_data),
        bad_other=tuple(bad_other),
        footer=footer,
        end=off,
        torn=torn,
        torn_opcode=torn_op,
        chunk_indexes=indexes,
        statistics=stats,
        closing_magic=footer is not None and data[off : off + len(MAGIC)] == MAGIC,
    )


def _attachment_name(body: bytes) -> str:
    try:
        return str(_record(Attachment, body).name)
    except Exception:  # the name itself may be what is damaged
        return "?"
