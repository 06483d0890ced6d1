"""``smc doctor``: check a log as a user would before compiling, and repair a truncated one.

``diagnose(path)`` returns one ``Check`` per aspect of a log (bytes and CRCs, summary,
reading it as compile does, metadata, attachments, schemas, topics, time order, NaN/inf,
saliency marks and fragments) and never raises for a bad log. Statuses:

- ``error``: compile would reject the log (or would read NaN/inf from it);
- ``warn``: compile accepts it, but look (truncated, no marks, interrupted, damaged index…);
- ``ok``.

The bytes are walked by :mod:`smccli.learn.mcap_layout`; ``repair(src, out)``
(:mod:`smccli.learn.repair`) rewrites what a truncated file holds as a valid, indexed MCAP.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from google.protobuf.descriptor import FieldDescriptor
from mcap.opcode import Opcode
from mcap.records import Channel

from smccli.errors import SmcError
from smccli.learn.mcap_layout import MAGIC, Layout, record_layout
from smccli.learn.repair import RepairResult as RepairResult
from smccli.learn.repair import repair as repair
from smccli.logs import topics as tp
from smccli.logs.decode import decode_points
from smccli.logs.log import Log, parse_task
from smccli.logs.reader import read_log
from smccli.logs.records import RawLog, read_bytes, scan_records
from smccli.logs.ros2_bag import ROLE_OF, ROLES, TopicMap, read_ros2_bag, resolve_bag

Status = Literal["ok", "warn", "error"]

_RANK: dict[str, int] = {"ok": 0, "warn": 1, "error": 2}


@dataclass(frozen=True, slots=True)
class Check:
    """One row of a diagnosis."""

    name: str
    """What was checked: ``file``, ``crc``, ``summary``, ``read``, ``metadata``, ``end``,
    ``attachments``, ``schemas``, ``topics``, ``time order``, ``numbers``, ``saliency``."""
    status: Status
    """``ok``, ``warn`` (compile accepts the log, but look) or ``error`` (compile rejects it)."""
    detail: str
    """One line: what was found."""


@dataclass(frozen=True, slots=True)
class Diagnosis:
    """Everything ``diagnose`` found about one log."""

    path: Path
    """The log file."""
    checks: tuple[Check, ...]
    """The rows, in a fixed order; one row only when the file is not an MCAP at all."""
    status: Status
    """The worst status among ``checks``."""


def exit_code(diagnoses: Iterable[Diagnosis]) -> int:
    """0 if every log is healthy, 1 if there are warnings only, 2 if a log is unusable."""
    return max((_RANK[d.status] for d in diagnoses), default=0)


# --- the checks ---


@dataclass(slots=True)
class _Context:
    """What the checks look at; ``raw`` and ``log`` are None when they could not be read."""

    path: Path
    data: bytes
    layout: Layout
    raw: RawLog | None = None
    log: Log | None = None
    read_error: str = ""
    warnings: list[str] = field(default_factory=list)
    topic_map: TopicMap | None = None
    """The map a bag is read through: its topics are named as the bag names them."""


def _one_line(path: Path, msg: str) -> str:
    """A reader message without the ``PATH: `` prefix (the table is titled with the path)."""
    msg = " ".join(msg.split())
    prefix = f"{path}: "
    return msg[len(prefix) :] if msg.startswith(prefix) else msg


def _n(count: int, noun: str) -> str:
    return f"{count} {noun}{'' if count == 1 else 's'}"


def _check_file(c: _Context) -> Check:
    size = f"{len(c.data) / 1e6:.2f} MB" if len(c.data) >= 10**5 else f"{len(c.data)} bytes"
    if c.raw is None or c.raw.header is None:
        return Check("file", "ok", f"{size}, MCAP magic")
    h = c.raw.header
    return Check("file", "ok", f"{size}, MCAP written by {h.library or '?'!r}")


def _check_crc(c: _Context) -> Check:
    lay = c.layout
    if lay.bad_data:
        more = f" (+{len(lay.bad_data) - 1} more)" if len(lay.bad_data) > 1 else ""
        return Check("crc", "error", f"{lay.bad_data[0]}{more}")
    if lay.bad_other:
        return Check("crc", "warn", "; ".join(lay.bad_other) + " (compile does not read it)")
    if not lay.crcs:
        return Check("crc", "ok", f"no CRC to check ({_n(lay.chunks, 'chunk')})")
    return Check("crc", "ok", f"{lay.crcs} CRCs match ({_n(lay.chunks, 'chunk')})")


def _check_summary(c: _Context) -> Check:
    lay, size = c.layout, len(c.data)
    n_msgs = len(c.raw.messages) if c.raw is not None else None
    before = _n(lay.chunks, "whole chunk") + (
        f", {_n(n_msgs, 'message')}" if n_msgs is not None else ""
    )
    if lay.footer is None:
        if lay.torn is None:
            where = f"ends at byte {size} after a whole record"
        else:
            kind = "chunk" if lay.torn_opcode == Opcode.CHUNK else "record"
            where = f"ends at byte {size} inside a {kind} that starts at byte {lay.torn}"
        usable = (
            " (compile reads those; --repair OUT writes them as a valid MCAP)"
            if c.log is not None
            else ""
        )
        return Check(
            "summary",
            "warn",
            f"truncated, no footer or summary: {where}; {before} before the cut{usable}",
        )
    if lay.footer.summary_start == 0:
        return Check(
            "summary", "warn", "footer but no summary section (not indexed; --repair OUT adds one)"
        )
    problems = []
    if lay.chunk_indexes != lay.chunks:
        problems.append(f"{lay.chunk_indexes} chunk indexes for {lay.chunks} chunks")
    if lay.statistics is None:
        problems.append("no statistics record")
    elif n_msgs is not None and lay.statistics.message_count != n_msgs:
        problems.append(f"statistics count {lay.statistics.message_count} messages, found {n_msgs}")
    if not lay.closing_magic:
        problems.append("closing magic bytes damaged")
    if problems:
        text = "index does not match the data: " + "; ".join(problems)
        return Check("summary", "warn", text + " (--repair OUT rewrites it)")
    return Check("summary", "ok", f"footer, summary and index present ({before})")


def _check_read(c: _Context) -> Check:
    if c.log is None:
        return Check("read", "error", c.read_error)
    # The summary and metadata rows already say these two.
    said = ("truncated at byte", f"no {tp.METADATA_NAME!r} metadata record")
    others = [w for w in c.warnings if not any(s in w for s in said)]
    counts = c.log.topic_counts
    times = [m.log_time / 1e9 for m in c.raw.messages] if c.raw else [*c.log.poi_t]
    span = max(times) - min(times) if times else 0.0
    text = f"reads as compile reads it: {sum(counts.values())} messages over {span:.2f} s"
    if others:
        return Check("read", "warn", text + "; " + "; ".join(_one_line(c.path, w) for w in others))
    return Check("read", "ok", text)


def _check_metadata(c: _Context) -> Check:
    assert c.raw is not None
    meta = c.raw.metadata.get(tp.METADATA_NAME)
    if meta is None:
        names = ", ".join(sorted(c.raw.metadata)) or "none"
        return Check("metadata", "warn", f"no {tp.METADATA_NAME!r} record (records: {names})")
    missing = [k for k in ("scene", "scene_digest", "smc_version") if not meta.get(k)]
    shown = ", ".join(
        f"{k} {meta[k]}" for k in ("scene", "smc_version", "operator", "seed") if k in meta
    )
    if missing:
        return Check(
            "metadata", "warn", f"{', '.join(missing)} missing ({shown or 'nothing else'})"
        )
    return Check("metadata", "ok", shown)


def _check_end(c: _Context) -> Check:
    assert c.raw is not None
    end = c.raw.metadata.get(tp.END_METADATA_NAME)
    if end is None:
        why = (
            "the file was cut before the recorder closed it"
            if c.raw.truncated
            else "an older recorder, or not written by smc record"
        )
        return Check("end", "ok", f"no {tp.END_METADATA_NAME!r} record ({why})")
    state = end.get("end", "")
    last = f", last message at {end['last_log_time_s']} s" if "last_log_time_s" in end else ""
    task = parse_task(end)
    if state == "complete" and task is not None and task["success"] is False:
        why = task.get("reason", "?")
        failed = f"the demonstration failed its task: {why}"
        return Check("end", "warn", f"recording complete{last}; {failed}")
    if state == "complete":
        done = f"; task achieved: {task.get('reason', '')}" if task and task["success"] else ""
        return Check("end", "ok", f"recording complete{last}{done}")
    if state == "interrupted":
        reason = f" by {end['reason']}" if end.get("reason") else ""
        return Check("end", "warn", f"recording interrupted{reason}{last}")
    return Check("end", "warn", f"unknown end {state!r} (expected complete or interrupted)")


def _check_attachments(c: _Context) -> Check:
    from smccli.world.scene import scene_of_log  # MuJoCo: only when a log reaches this far

    assert c.raw is not None
    att = {a.name: a.data for a in c.raw.attachments}
    names = ", ".join(sorted(att)) or "none"
    if "scene.xml" not in att:
        return Check("attachments", "error", f"scene.xml missing (compile needs it; have {names})")
    if "scene.yaml" not in att:
        return Check("attachments", "warn", f"scene.yaml missing (have {names})")
    # Raises LogError naming the attachment; _guarded makes it this row's error.
    scene = scene_of_log(att, c.path)
    meta = c.raw.metadata.get(tp.METADATA_NAME, {})
    text = (
        f"scene.xml compiles in MuJoCo, scene.yaml parses (scene {scene.name}), "
        f"robot {scene.robot.name} fits its MJCF"
    )
    if "robot.yaml" not in att:
        text += " (no robot.yaml: a log from before robot files, robot arm)"
    if meta.get("scene_digest") not in (None, scene.digest):
        return Check("attachments", "warn", text + "; digest differs from the metadata's")
    if meta.get("scene") not in (None, scene.name):
        return Check("attachments", "warn", text + f"; metadata says scene {meta['scene']}")
    return Check("attachments", "ok", text)


def _expected_schema(topic: str) -> tuple[str, str, str] | None:
    """(message encoding, schema encoding, schema name) the writer uses, None if not ours."""
    if topic in tp.PROTO_TOPICS:
        return "protobuf", "protobuf", tp.PROTO_TOPICS[topic].DESCRIPTOR.full_name
    if topic in tp.JSON_TOPICS:
        return "json", "jsonschema", tp.json_schema_name(topic)
    return None


def _schema_problem(raw: RawLog, ch: Channel) -> str | None:
    """What differs from what the writer uses for ``ch.topic``, None if nothing (or not ours)."""
    want = _expected_schema(ch.topic)
    if want is None:
        return None
    s = raw.schemas.get(ch.schema_id)
    have = (ch.message_encoding, s.encoding if s else "none", s.name if s else "none")
    fields = ("message encoding", "schema encoding", "schema")
    diffs = [
        f"{what} {h or '(empty)'} (expected {w})"
        for what, h, w in zip(fields, have, want, strict=True)
        if h != w
    ]
    return f"{ch.topic}: {', '.join(diffs)}" if diffs else None


def _check_schemas(c: _Context) -> Check:
    assert c.raw is not None
    raw = c.raw
    counts = _counts(raw)
    bad_error: list[str] = []
    bad_warn: list[str] = []
    unknown: list[str] = []
    for ch in sorted(raw.channels.values(), key=lambda ch: ch.id):
        if _expected_schema(ch.topic) is None:
            unknown.append(ch.topic)
            continue
        problem = _schema_problem(raw, ch)
        if problem:
            # Compile decodes the topics it reads and fails on the first wrong one.
            rejects = ch.topic in tp.READ_TOPICS and counts.get(ch.id, 0) > 0
            (bad_error if rejects else bad_warn).append(problem)
    note = f"; unknown topics, not read: {', '.join(unknown)}" if unknown else ""
    if bad_error or bad_warn:
        status: Status = "error" if bad_error else "warn"
        return Check("schemas", status, "; ".join(bad_error + bad_warn) + note)
    n = len(raw.channels) - len(unknown)
    return Check("schemas", "ok", f"{n} channels with the expected encoding and schema{note}")


def _counts(raw: RawLog) -> dict[int, int]:
    counts: dict[int, int] = {}
    for m in raw.messages:
        counts[m.channel_id] = counts.get(m.channel_id, 0) + 1
    return counts


def _check_topics(c: _Context) -> Check:
    # learn.chain pulls in open3d and MuJoCo (seconds of imports): only for a log that
    # gets this far, so a damaged file is reported at once.
    from smccli.learn.chain import required_topics

    assert c.log is not None
    needed = sorted(required_topics(c.log))
    counts = c.log.topic_counts
    scene = c.log.metadata.get("scene", "?")
    missing = [t for t in needed if counts.get(t, 0) == 0]
    m = c.topic_map
    if m is not None:  # in the bag's terms: the map's roles and the bag's topics
        role = {native: r for r, (native, _) in ROLES.items() if r in m.topics}
        role.setdefault(tp.POI, "poi")
        name = {t: m.topics.get(role.get(t, ""), f"the map's {role.get(t, t)}") for t in needed}
        missing = [f"the map's {ROLE_OF.get(t, t)} topic" for t in missing]
    else:
        name = {t: t for t in needed}
    if missing:
        return Check("topics", "error", f"{', '.join(missing)} missing (scene {scene} needs it)")
    low = min(needed, key=lambda t: counts[t])
    return Check(
        "topics",
        "ok",
        f"all {len(needed)} topics scene {scene} needs (fewest: {name[low]}, "
        f"{counts[low]} messages)",
    )


def _check_time_order(c: _Context) -> Check:
    assert c.raw is not None
    raw = c.raw
    last: dict[int, int] = {}
    back: dict[int, tuple[int, int, int]] = {}  # channel -> (count, first time, previous)
    for m in raw.messages:
        prev = last.get(m.channel_id)
        if prev is not None and m.log_time < prev:
            n, t0, p0 = back.get(m.channel_id, (0, m.log_time, prev))
            back[m.channel_id] = (n + 1, t0, p0)
        last[m.channel_id] = m.log_time
    if back:
        parts = [
            f"{raw.channels[cid].topic} goes back {n}x "
            f"(first {t / 1e9:.3f} s after {p / 1e9:.3f} s)"
            for cid, (n, t, p) in sorted(back.items())
        ]
        return Check("time order", "error", "; ".join(parts))
    times = [m.log_time for m in raw.messages]
    span = f"; {min(times) / 1e9:.3f}-{max(times) / 1e9:.3f} s" if times else ""
    return Check("time order", "ok", f"{len(last)} channels, each in time order{span}")


def _floats(obj: Any) -> Iterator[float]:
    """Every float in a protobuf message or a decoded JSON value."""
    if isinstance(obj, float):
        yield obj
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from _floats(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _floats(v)
    elif hasattr(obj, "ListFields"):
        for fd, value in obj.ListFields():
            if fd.type in (FieldDescriptor.TYPE_DOUBLE, FieldDescriptor.TYPE_FLOAT):
                yield from (value if fd.is_repeated else (value,))
            elif fd.type == FieldDescriptor.TYPE_MESSAGE:
                for sub in value if fd.is_repeated else (value,):
                    yield from _floats(sub)


def _finite(topic: str, t: float, data: bytes) -> bool:
    if topic in tp.JSON_TOPICS:
        return all(math.isfinite(x) for x in _floats(json.loads(data)))
    msg = tp.PROTO_TOPICS[topic].FromString(data)
    if not all(math.isfinite(x) for x in _floats(msg)):
        return False
    if topic == tp.POINTS:  # packed float32 coordinates, not protobuf floats
        return bool(np.all(np.isfinite(decode_points(t, msg).points)))
    return True


def _check_numbers(c: _Context) -> Check:
    assert c.raw is not None
    raw = c.raw
    bad: dict[str, tuple[int, float]] = {}  # topic -> (count, first time [s])
    undecodable: dict[str, int] = {}
    checked = 0
    # Unknown or mislabelled channels are the schemas row's business; images hold no numbers.
    numeric = {
        cid
        for cid, ch in raw.channels.items()
        if _expected_schema(ch.topic) is not None
        and _schema_problem(raw, ch) is None
        and ch.topic not in (tp.COLOR, tp.DEPTH)
    }
    for m in raw.messages:
        if m.channel_id not in numeric:
            continue
        ch = raw.channels[m.channel_id]
        t = m.log_time / 1e9
        try:
            ok = _finite(ch.topic, t, m.data)
        except Exception:  # any decode failure: counted, not fatal
            undecodable[ch.topic] = undecodable.get(ch.topic, 0) + 1
            continue
        checked += 1
        if not ok:
            n, t0 = bad.get(ch.topic, (0, t))
            bad[ch.topic] = (n + 1, t0)
    parts = [
        f"NaN/inf in {n} {topic} messages (first at {t0:.3f} s)" for topic, (n, t0) in bad.items()
    ]
    parts += [f"{n} {topic} messages do not decode" for topic, n in undecodable.items()]
    if not parts:
        return Check("numbers", "ok", f"no NaN or inf in {checked} messages")
    status: Status = "error" if any(t in tp.READ_TOPICS for t in [*bad, *undecodable]) else "warn"
    return Check("numbers", status, "; ".join(parts))


def _check_saliency(c: _Context) -> Check:
    from smccli.learn.chain import fragments  # open3d, MuJoCo: see _check_topics
    from smccli.learn.params import SmcParams

    assert c.log is not None
    marks = c.log.marks
    ops = [m for m in marks if m.source == "operator"]
    frags = fragments(c.log, SmcParams())
    spans = ", ".join(f"{f.t0:.2f}-{f.t1:.2f} s" for f in frags) or "none"
    auto = len(marks) - len(ops)
    more = f" (+{auto} automatic)" if auto else ""
    if not ops:
        return Check(
            "saliency",
            "warn",
            f"no operator marks{more}: compile makes {_n(len(frags), 'fragment')} of it ({spans}); "
            "try compile --segment auto",
        )
    shown = ", ".join(f"{m.label or '?'} {m.t:.2f} s" for m in ops)
    text = (
        f"{_n(len(ops), 'operator mark')}{more} ({shown}) -> {_n(len(frags), 'fragment')}: {spans}"
    )
    return Check("saliency", "ok" if frags else "warn", text)


def _check_smcs(c: _Context) -> Check:
    """What compile extracts from the log with its scene's parameters (a fresh tree): an
    SMC per fragment, or the error compile would stop on."""
    from smccli.learn.chain import extract_chain, scene_params
    from smccli.learn.segmentation import SegmentMode
    from smccli.world.scene import scene_of_log

    assert c.log is not None
    try:
        scene = scene_of_log(c.log.attachments, c.path)
        chain = extract_chain(c.log, scene_params(scene), SegmentMode.markers, scene)
    except SmcError as e:
        return Check("smcs", "error", _one_line(c.path, str(e)))
    frames = {s.action.goal_frame for s in chain.smcs}
    text = f"compile extracts {_n(len(chain.smcs), 'SMC')} (goals in {', '.join(sorted(frames))})"
    if chain.warnings:
        return Check("smcs", "warn", text + "; " + "; ".join(chain.warnings))
    return Check("smcs", "ok", text)


_CHECKS: tuple[tuple[str, Callable[[_Context], Check], bool], ...] = (
    ("metadata", _check_metadata, False),
    ("end", _check_end, False),
    ("attachments", _check_attachments, False),
    ("schemas", _check_schemas, False),
    ("topics", _check_topics, True),
    ("time order", _check_time_order, False),
    ("numbers", _check_numbers, False),
    ("saliency", _check_saliency, True),
    ("smcs", _check_smcs, True),
)
"""The rows after ``read``: (name, check, whether it needs the log as read_log decodes it)."""


def _guarded(name: str, fn: Callable[[_Context], Check], c: _Context) -> Check:
    try:
        return fn(c)
    except SmcError as e:
        return Check(name, "error", _one_line(c.path, str(e)))
    except Exception as e:  # a bad log must give a row, never a traceback
        return Check(name, "error", _one_line(c.path, f"{type(e).__name__}: {e}"))


def diagnose(path: str | os.PathLike[str], topic_map: TopicMap | None = None) -> Diagnosis:
    """Check one log; never raises for a bad or missing file (its rows say why). With
    ``topic_map`` the log is a ROS 2 bag, checked through the map."""
    path = Path(path)
    try:
        if topic_map is not None:
            path = resolve_bag(path)
            if path.is_dir() or path.suffix == ".bag":  # rosbag2 directory, ROS 1 bag
                return _diagnose_bag(path, None, topic_map)
        data = read_bytes(path)
    except SmcError as e:
        return _diagnosis(path, [Check("file", "error", _one_line(path, str(e)))])
    if not data.startswith(MAGIC):
        why = f"not an MCAP file (starts with {data[:8]!r}, {len(data)} bytes)"
        return _diagnosis(path, [Check("file", "error", why)])
    if topic_map is not None:
        return _diagnose_bag(path, data, topic_map)
    c = _Context(path=path, data=data, layout=record_layout(data))
    try:
        c.raw = scan_records(path, data)
    except SmcError as e:
        c.read_error = _one_line(path, str(e))
    except Exception as e:  # e.g. zstd's own error on a damaged chunk, which the reader lets by
        c.read_error = f"reader failed: {type(e).__name__}: {e}"
    if c.raw is not None:
        try:
            c.log = read_log(path, topics=tp.READ_TOPICS, on_warning=c.warnings.append)
        except SmcError as e:
            c.read_error = _one_line(path, str(e))
        except Exception as e:  # the reader failing in an unplanned way is a finding too
            c.read_error = f"reader failed: {type(e).__name__}: {e}"
    checks = [_check_file(c), _check_crc(c), _check_summary(c), _check_read(c)]
    if c.raw is not None:
        checks += [
            _guarded(name, fn, c)
            for name, fn, needs_log in _CHECKS
            if c.log is not None or not needs_log
        ]
    return _diagnosis(path, checks)


def _diagnose_bag(path: Path, data: bytes | None, topic_map: TopicMap) -> Diagnosis:
    """A bag: the file (an MCAP file's records and CRCs; a rosbag2 directory's or a ROS 1
    bag's storage is checked by ``rosbags`` as it reads it), then reading it through the
    map (topics present and of the mapped types, decoding, transforms), then what compile
    needs (topics, marks, the SMCs it extracts)."""
    c = _Context(
        path=path, data=data or b"", layout=record_layout(data or b""), topic_map=topic_map
    )
    try:
        c.log = read_ros2_bag(path, topic_map, on_warning=c.warnings.append)
    except SmcError as e:
        c.read_error = _one_line(path, str(e))
    except Exception as e:  # a bag the reader chokes on is a finding, not a traceback
        c.read_error = f"reader failed: {type(e).__name__}: {e}"
    if data is None:
        files = [path] if path.is_file() else sorted(q for q in path.iterdir() if q.is_file())
        kind = "ROS 1 bag" if path.is_file() else "rosbag2 directory"
        size = sum(f.stat().st_size for f in files)
        checks = [Check("file", "ok", f"{kind}: {_n(len(files), 'file')}, {size} bytes")]
    else:
        checks = [_check_file(c), _check_crc(c)]
    checks.append(_check_read(c))
    if c.log is not None:
        checks += [_guarded(n, fn, c) for n, fn, needs in _CHECKS if needs]
    return _diagnosis(path, checks)


def _diagnosis(path: Path, checks: list[Check]) -> Diagnosis:
    worst = max(checks, key=lambda ch: _RANK[ch.status]).status
    return Diagnosis(path=path, checks=tuple(checks), status=worst)
