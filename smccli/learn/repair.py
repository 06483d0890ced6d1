"""``smc doctor --repair``: what a truncated MCAP file holds (every record of every whole
chunk, e.g. a killed recorder's ``NAME.mcap.part``) rewritten as a valid, indexed MCAP."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path

from smccli.errors import LogError, OutputError, SmcError
from smccli.learn.mcap_layout import record_layout
from smccli.logs import topics as tp
from smccli.logs.records import read_bytes, scan_records
from smccli.logs.rewrite import copy_log
from smccli.outputs import check_output, write_atomic


@dataclass(frozen=True, slots=True)
class RepairResult:
    """What ``repair`` wrote."""

    path: Path
    """The repaired log."""
    messages: int
    """Messages copied: every message of every whole chunk of the source, in file order."""
    chunks: int
    """Whole chunks found in the source."""
    truncated: bool
    """Whether the source was truncated (False: it was complete and has just been copied)."""
    source_bytes: int
    """Size of the source [bytes]."""


def _same_file(a: Path, b: Path) -> bool:
    if a.exists() and b.exists():
        return os.path.samefile(a, b)
    return a.resolve() == b.resolve()


def repair(
    src: str | os.PathLike[str], out: str | os.PathLike[str], *, force: bool = False
) -> RepairResult:
    """Write every whole chunk of ``src`` (e.g. a killed recorder's ``.mcap.part``) to
    ``out`` as a valid, indexed MCAP, atomically; ``src`` is only read.

    A complete ``src`` is simply copied. Raises OutputError if ``out`` is ``src``,
    OutputExistsError if it exists without ``force``, LogError if ``src`` is not an MCAP
    file or a chunk before the cut is damaged.
    """
    src, out = Path(src), Path(out)
    if _same_file(src, out):
        raise OutputError(f"{out}: is the log being repaired; write the repair elsewhere")
    check_output(out, force=force)
    data = read_bytes(src)
    try:
        raw = scan_records(src, data)
    except SmcError:
        raise
    except Exception as e:  # e.g. zstd's own error on a damaged chunk, which the reader lets by
        raise LogError(f"{src}: corrupt MCAP ({type(e).__name__}: {e})") from None
    extra: dict[str, dict[str, str]] = {}
    if raw.truncated and tp.END_METADATA_NAME not in raw.metadata:
        # The repaired log says it was cut short, as a SIGINT-ended recording does, so
        # compile keeps only its complete fragments and doctor warns.
        last = max((m.log_time for m in raw.messages), default=0)
        extra[tp.END_METADATA_NAME] = {
            "end": "interrupted",
            "reason": f"truncated at byte {raw.cut_at}; repaired by smc doctor",
            "last_log_time_s": f"{last / 1e9:.3f}",
        }
    buf = io.BytesIO()
    n = copy_log(raw, buf, extra_metadata=extra)
    # write_atomic's temp name is unique: `smc doctor X.mcap.part --repair X.mcap` must not
    # write X.mcap.part, the very file being repaired.
    write_atomic(out, buf.getvalue())
    return RepairResult(
        path=out,
        messages=n,
        chunks=record_layout(data).chunks,
        truncated=raw.truncated,
        source_bytes=len(data),
    )
