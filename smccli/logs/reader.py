"""Reading logs: :func:`read_log` (decoded, checked). The layers under it: records and
chunks (:mod:`~smccli.logs.records`), checks (:mod:`~smccli.logs.checks`), images
(:mod:`~smccli.logs.images`), decoding (:mod:`~smccli.logs.decode`); rewriting in
:mod:`~smccli.logs.rewrite`."""

from __future__ import annotations

import hashlib
import logging
import os
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from smccli.errors import LogError
from smccli.logs import topics as tp
from smccli.logs.checks import check_attachments, check_channels, check_times
from smccli.logs.decode import Decoder, unwrap_yaw
from smccli.logs.log import Log
from smccli.logs.records import RawLog, read_bytes, scan_records

_log = logging.getLogger(__name__)


def read_log(
    path: str | os.PathLike[str],
    *,
    topics: Iterable[str] | None = None,
    required_topics: Iterable[str] = (),
    on_warning: Callable[[str], None] | None = None,
    lazy_frames: bool = False,
) -> Log:
    """Read and check a log; decode only ``topics`` (all if None), and decompress only
    the chunks that may hold them (:func:`scan_records`): a check of a message (its schema, its
    time order) covers the chunks read.

    Raises LogError (one line naming the file; for a message also its topic and time) for
    a missing file, not MCAP, empty, corrupt, no readable message, a message on an unknown
    channel, a required topic without messages, a decoded message that does not hold what
    its topic promises (schema, protobuf, image, point layout, NaN in poses), time going
    backwards, a ``scene.xml`` / ``scene.yaml`` attachment that is not XML / YAML.
    A truncated log is read up to its last whole chunk and ``on_warning`` is told; so is a
    log without the ``smc`` metadata record.

    ``lazy_frames``: for a reader that looks at a few frames (compile), ``Log.camera``
    instead of ``Log.frames``: every image is checked from its header and decoded only when
    asked for (:meth:`Decoder.camera` says what that check does not see).
    """
    path = Path(path)
    warn = on_warning or _log.warning
    data = read_bytes(path)
    wanted = None if topics is None else set(topics)
    raw = scan_records(path, data, wanted)
    if not raw.messages and not raw.skipped:
        why = (
            f"truncated at byte {raw.cut_at} of {len(data)}, before its first chunk ended"
            if raw.truncated
            else "the log holds no messages"
        )
        raise LogError(f"{path}: no readable message ({why})")
    if raw.truncated:
        warn(
            f"{path}: truncated at byte {raw.cut_at} of {len(data)} (recorder killed?); "
            f"read {len(raw.messages)} messages from the whole chunks before the cut"
        )
    check_channels(path, raw)
    check_attachments(path, raw)
    if tp.METADATA_NAME not in raw.metadata:
        warn(
            f"{path}: no {tp.METADATA_NAME!r} metadata record (scene, seed and rates unknown; "
            "not written by smc?)"
        )
    check_times(path, raw)
    counts = _topic_counts(path, raw, required_topics)
    d = Decoder(path, raw, wanted, warn)
    for m in raw.messages:
        d.add(m)
    return Log(
        path=path,
        sha256=hashlib.sha256(data).hexdigest(),
        metadata=raw.metadata.get(tp.METADATA_NAME, {}),
        end=raw.metadata.get(tp.END_METADATA_NAME, {}),
        attachments={a.name: a.data for a in raw.attachments},
        commands=d.commands,
        joint_states=d.joint_states,
        poi_t=np.array(d.poi_t, dtype=float),
        poi=unwrap_yaw(np.array(d.poi, dtype=float).reshape(-1, 4)),
        frames=[] if lazy_frames else d.frames(),
        weight_t=np.array(d.weight_t, dtype=float),
        weight=np.array(d.weight, dtype=float),
        marks=d.marks,
        ground_truth=d.ground_truth,
        decisions=d.decisions,
        topic_counts=counts,
        truncated=raw.truncated,
        point_clouds=d.point_clouds,
        scans=d.scans,
        base_t=np.array(d.base_t, dtype=float),
        base=unwrap_yaw(np.array(d.base, dtype=float).reshape(-1, 3), column=2),
        camera=d.camera() if lazy_frames else None,
    )


def _topic_counts(path: Path, raw: RawLog, required: Iterable[str]) -> dict[str, int]:
    """Messages per topic, those in chunks left compressed counted by their indexes;
    LogError when a ``required`` topic has none."""
    counts: dict[str, int] = {c.topic: 0 for c in raw.channels.values()}
    for m in raw.messages:
        counts[raw.topic(m)] += 1
    for cid, n in raw.skipped.items():
        counts[raw.channels[cid].topic] += n
    missing = [t for t in required if counts.get(t, 0) == 0]
    if missing:
        have = ", ".join(sorted(t for t, n in counts.items() if n)) or "none"
        raise LogError(f"{path}: topic {', '.join(missing)} missing (topics present: {have})")
    return counts
