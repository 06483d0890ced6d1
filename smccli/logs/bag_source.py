"""Opening a bag, whatever its storage: one MCAP file (``mcap-ros2-support``), a rosbag2
directory in sqlite3 or MCAP, split or not, or a ROS 1 bag (``rosbags``); each gives its
topics, counts and messages decoded from the definitions the bag stores."""

from __future__ import annotations

import hashlib
import io
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from smccli.errors import LogError


def resolve_bag(path: str | Path) -> Path:
    """The file or directory to read a bag from: an MCAP file as it is; a bag directory
    as ``ros2 bag record`` writes it (``metadata.yaml`` and its storage files): its one
    ``.mcap`` file when it holds only that (the file is self-contained, and keeps the
    attachments of ``smc export``), else the directory (rosbag2 split into several files,
    or sqlite3 storage); a ROS 1 ``.bag``. LogError (one line) for anything else."""
    p = Path(path)
    if p.is_dir():
        parts = sorted(p.glob("*.mcap"))
        if len(parts) == 1 and not list(p.glob("*.db3")):
            return parts[0]
        if not (p / "metadata.yaml").is_file():
            found = ", ".join(q.name for q in sorted(p.iterdir())) or "nothing"
            raise LogError(f"{p}: a bag directory needs its metadata.yaml (rosbag2), found {found}")
        return p
    if not p.is_file():
        raise LogError(f"{p}: no such file")
    if p.suffix == ".db3":
        raise LogError(f"{p}: one file of a sqlite3 bag: give its directory (with metadata.yaml)")
    listed = _bag_files(p.parent)
    if p.suffix == ".mcap" and len(listed) > 1 and p.name in listed:
        raise LogError(
            f"{p}: one file of a bag split into {len(listed)}: give its directory {p.parent} "
            "(one demonstration)"
        )
    return p


def _bag_files(folder: Path) -> list[str]:
    """The storage files a rosbag2 directory's metadata.yaml lists (none without one)."""
    import yaml

    try:
        meta = yaml.safe_load((folder / "metadata.yaml").read_text())
        return [str(f) for f in meta["rosbag2_bagfile_information"]["relative_file_paths"]]
    except (OSError, yaml.YAMLError, KeyError, TypeError):
        return []


@dataclass
class BagSource:
    """A bag opened for reading: its topics and their types, message counts, smc's
    attachments and metadata (MCAP files only), its digest, and its messages decoded."""

    types: dict[str, str]
    """Topic -> message type (``sensor_msgs/msg/Image``)."""
    counts: dict[str, int]
    attachments: dict[str, bytes]
    metadata: dict[str, dict[str, str]]
    sha256: str
    start_ns: int
    """Log time of its first message [ns]."""
    end_ns: int
    """Log time of its last message [ns]."""
    messages: Callable[[list[str]], Iterator[tuple[str, int, Any]]]
    """Topics -> (topic, log time [ns], decoded message) in log-time order."""
    close: Callable[[], None] = lambda: None


def _open_mcap(path: Path) -> BagSource:
    """A ROS 2 bag in one MCAP file, decoded from the definitions it stores
    (``mcap-ros2-support``: it also gives the attachments ``smc export`` writes)."""
    data = path.read_bytes()
    try:
        reader = make_reader(io.BytesIO(data), decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        attachments = {a.name: bytes(a.data) for a in reader.iter_attachments()}
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    except (McapError, ValueError, EOFError, KeyError) as exc:
        raise LogError(f"{path}: not a readable MCAP file ({exc})") from None
    if summary is None or not summary.channels:
        raise LogError(f"{path}: the bag holds no topics")
    types = {}
    for c in summary.channels.values():
        schema = summary.schemas[c.schema_id]
        ros2 = schema.encoding == "ros2msg"
        types[c.topic] = schema.name if ros2 else f"{schema.name} ({schema.encoding}, not ROS 2)"
    counts: dict[str, int] = {}
    stats = summary.statistics
    if stats is not None:
        for cid, n in stats.channel_message_counts.items():
            counts[summary.channels[cid].topic] = n

    def messages(topics: list[str]) -> Iterator[tuple[str, int, Any]]:
        for _schema, channel, message, decoded in reader.iter_decoded_messages(
            topics=topics, log_time_order=True
        ):
            yield channel.topic, message.log_time, decoded

    sha = hashlib.sha256(data).hexdigest()
    t0, t1 = (stats.message_start_time, stats.message_end_time) if stats else (0, 0)
    return BagSource(types, counts, attachments, metadata, sha, t0, t1, messages)


def _open_rosbags(path: Path) -> BagSource:
    """A rosbag2 directory (sqlite3 or MCAP storage, any number of files) or a ROS 1 bag,
    read with ``rosbags``: messages decoded from the definitions the bag stores, else
    (a sqlite3 bag before Iron stores none) from ROS 2 Humble's standard types."""
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection
    from rosbags.typesys import Stores, get_typestore

    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags' own errors name the file's problem
        raise LogError(f"{path}: not a readable bag ({type(exc).__name__}: {exc})") from None
    conns: dict[str, list[Connection]] = {}
    for c in reader.connections:
        conns.setdefault(c.topic, []).append(c)
    if not conns:
        reader.close()
        raise LogError(f"{path}: the bag holds no topics")
    types = {t: cs[0].msgtype for t, cs in conns.items()}
    counts = {t: sum(c.msgcount for c in cs) for t, cs in conns.items()}
    files = [path] if path.is_file() else sorted(q for q in path.iterdir() if q.is_file())
    h = hashlib.sha256()
    for f in files:
        h.update(f.read_bytes())

    def messages(topics: list[str]) -> Iterator[tuple[str, int, Any]]:
        wanted = [c for t in topics for c in conns.get(t, [])]
        for conn, t_ns, raw in reader.messages(connections=wanted):
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # a message its definition does not fit
                raise ValueError(f"{conn.topic}: {type(exc).__name__}: {exc}") from None
            yield conn.topic, t_ns, msg

    t0, t1 = reader.start_time, reader.end_time
    return BagSource(types, counts, {}, {}, h.hexdigest(), t0, t1, messages, reader.close)


def open_bag(path: Path) -> BagSource:
    """A bag resolved by :func:`resolve_bag`, opened: a rosbag2 directory or a ROS 1 bag
    through rosbags, an MCAP file through mcap-ros2-support. Close it when done."""
    return _open_rosbags(path) if path.is_dir() or path.suffix == ".bag" else _open_mcap(path)
