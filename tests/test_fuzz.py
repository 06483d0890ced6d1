"""Fuzzing the readers: whatever the bytes, ``read_log``, ``log_summary`` and ``load_tree``
either return or raise an ``SmcError`` (one line for the CLI); nothing else ever escapes.

Inputs: arbitrary bytes; a small real log with bytes flipped, inserted, deleted or cut
(chunked, where CRCs catch most damage, and unchunked, where they do not); the same log
rewritten with one message's payload replaced (valid MCAP, wrong content); a real tree with
keys dropped, values of other types, and its text damaged.
"""

from __future__ import annotations

import copy
import functools
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.writer import CompressionType, Writer

from smccli.errors import SmcError
from smccli.learn.tree import load_tree, tree_from_dict
from smccli.logs import LogWriter, log_summary, read_log
from smccli.logs import topics as tp
from smccli.logs.checks import _FAST_OK
from smccli.logs.records import RawLog, scan_records
from smccli.world.sensors import CameraFrame, JointState, PoiCommand, SaliencyMark

# numpy's overflow and invalid-value warnings mean garbage got through unnoticed.
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")
SAMPLE = Path(__file__).resolve().parent.parent / "sample_logs" / "pick_place" / "demo1.mcap"
FUZZ = settings(
    # A deeper hunt: SMC_FUZZ_EXAMPLES=20000 (the default keeps the file under ~30 s), with
    # new random inputs each run. The default run draws the same inputs every time, so
    # `make test` gives the same verdict on every run; what a random hunt finds becomes a
    # case of its own (tests/test_bad_logs.py).
    max_examples=int(os.environ.get("SMC_FUZZ_EXAMPLES", "300")),
    derandomize="SMC_FUZZ_EXAMPLES" not in os.environ,
    deadline=None,  # no test may depend on the machine's speed
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
    database=None,  # nothing written into the working tree
)


def quiet(msg: str) -> None:
    """Warnings (truncated log, no metadata) are expected here."""


def survives(fn: Callable[[], Any]) -> None:
    """Run ``fn``; an SmcError is a fine answer to bad input, anything else fails the test."""
    try:
        fn()
    except SmcError as exc:
        assert str(exc).strip(), "an SmcError must say what is wrong"


def read_everything(path: Path) -> None:
    survives(lambda: read_log(path, on_warning=quiet))
    survives(lambda: log_summary(path))


# --- a small real log --------------------------------------------------------------------


def write_small_log(path: Path) -> None:
    """Every topic read_log decodes, in a few KB: 0.2 s of state, two tiny camera frames."""
    K = np.array([[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]])
    rgb = np.zeros((12, 16, 3), np.uint8)
    rgb[4:8, 5:10] = (200, 30, 30)
    depth = np.full((12, 16), 0.8, np.float32)
    with LogWriter(
        path,
        metadata={"scene": "fuzz", "seed": "0"},
        attachments={
            "scene.xml": ("application/xml", b"<mujoco/>"),
            "scene.yaml": ("application/yaml", b"name: fuzz\nobjects: []\n"),
        },
        wall_clock_flush=False,
        flush_period_s=0.05,  # several chunks
    ) as w:
        for k in range(20):
            t = k / 100
            w.write_command(PoiCommand(t, np.array([0.4, 0.0, 0.3, 0.1 * t]), 1.0))
            w.write_joint_state(
                JointState(t, ("j1", "finger"), np.ones(2), np.zeros(2), np.zeros(2))
            )
            w.write_poi(t, np.array([0.4, 0.0, 0.3, 0.1 * t]))
            if k % 10 == 0:
                w.write_camera(CameraFrame(t, rgb, depth, K, np.eye(4)))
                w.write_weight(t, 0.1)
                w.write_ground_truth(t, {"cube": np.array([0.5, 0, 0.02, 1, 0, 0, 0])})
        w.write_saliency(SaliencyMark(0.1, "operator", "grasp"))
        pts = np.arange(12, dtype=np.float32).reshape(4, 3)
        w.write_point_cloud(0.1, pts, np.full((4, 3), 9, np.uint8))
        w.write_scan(0.1, np.linspace(0.5, 1.0, 5), start_angle=-0.5, end_angle=0.5)
        w.write_json(tp.DECISION, 0.15, {"node": "n0", "candidates": [], "chosen": None})


@functools.cache
def small_log() -> bytes:
    """The small log's bytes (a plain function, not a fixture: Hypothesis would print it)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "small.mcap"
        write_small_log(path)
        read_log(path)  # the unmutated log is fine
        return path.read_bytes()


def copy_log(
    raw: RawLog,
    dst: Path,
    *,
    chunked: bool = True,
    payload: tuple[int, bytes] | None = None,
) -> None:
    """Write ``raw``'s records to ``dst``; ``payload`` = (message index, new bytes)."""
    with open(dst, "wb") as f:
        w = Writer(
            f,
            compression=CompressionType.ZSTD if chunked else CompressionType.NONE,
            use_chunking=chunked,
        )
        w.start(profile="", library="fuzz")
        for name, meta in raw.metadata.items():
            w.add_metadata(name, meta)
        for a in raw.attachments:
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        sids = {i: w.register_schema(s.name, s.encoding, s.data) for i, s in raw.schemas.items()}
        cids = {
            i: w.register_channel(c.topic, c.message_encoding, sids.get(c.schema_id, 0))
            for i, c in raw.channels.items()
        }
        for k, m in enumerate(raw.messages):
            data = payload[1] if payload is not None and payload[0] == k else m.data
            w.add_message(cids[m.channel_id], m.log_time, data, m.publish_time)
        w.finish()


@functools.cache
def small_raw(data: bytes) -> RawLog:
    return scan_records(Path("small.mcap"), data)


@st.composite
def mutated(draw: st.DrawFn, data: bytes) -> bytes:
    """``data`` with a few flips, insertions, deletions, or cut short."""
    buf = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "set", "insert", "delete", "truncate"]))
        i = draw(st.integers(0, max(len(buf) - 1, 0)))
        if op == "flip" and buf:
            buf[i] ^= 1 << draw(st.integers(0, 7))
        elif op == "set" and buf:
            buf[i] = draw(st.integers(0, 255))
        elif op == "insert":
            buf[i:i] = draw(st.binary(min_size=1, max_size=16))
        elif op == "delete":
            del buf[i : i + draw(st.integers(1, 16))]
        else:
            del buf[i:]
    return bytes(buf)


# --- logs ------------------------------------------------------------------------------


@FUZZ
@given(data=st.binary(max_size=2048))
def test_arbitrary_bytes(data: bytes, tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(data)
    read_everything(path)


@FUZZ
@given(data=st.data())
def test_arbitrary_bytes_after_a_valid_header(data: st.DataObject, tmp_path: Path) -> None:
    # The magic and header record of a real log, then anything: past the first checks.
    log = small_log()
    head = log[: 8 + 9 + int.from_bytes(log[9:17], "little")]
    path = tmp_path / "x.mcap"
    path.write_bytes(head + data.draw(st.binary(max_size=1024)))
    read_everything(path)


@FUZZ
@given(data=st.data())
def test_mutated_chunked_log(data: st.DataObject, tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(data.draw(mutated(small_log())))
    read_everything(path)


@FUZZ
@given(data=st.data())
def test_mutated_unchunked_log(data: st.DataObject, tmp_path: Path) -> None:
    # Without chunks no CRC covers the messages: the damage reaches the decoders.
    plain = tmp_path / "plain.mcap"
    copy_log(small_raw(small_log()), plain, chunked=False)
    path = tmp_path / "x.mcap"
    path.write_bytes(data.draw(mutated(plain.read_bytes())))
    read_everything(path)


def json_values() -> st.SearchStrategy[Any]:
    scalars = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
    return st.recursive(
        scalars,
        lambda inner: (
            st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5)
        ),
        max_leaves=12,
    )


@FUZZ
@given(data=st.data())
def test_message_payload_replaced(data: st.DataObject, tmp_path: Path) -> None:
    """Valid MCAP (CRCs right), one message's payload replaced: random bytes, the original
    with a few bytes changed, or (JSON topics) another JSON value."""
    raw = small_raw(small_log())
    k = data.draw(st.integers(0, len(raw.messages) - 1))
    original = raw.messages[k].data
    kind = data.draw(st.sampled_from(["bytes", "mutated", "json", "json-edit"]))
    if kind == "bytes":
        payload = data.draw(st.binary(max_size=64))
    elif kind == "mutated":
        payload = data.draw(mutated(original))
    elif kind == "json":
        payload = json.dumps(data.draw(json_values())).encode()
    else:
        doc = json.loads(original) if raw.topic(raw.messages[k]) in tp.JSON_TOPICS else {}
        payload = json.dumps(data.draw(edited(doc))).encode()
    path = tmp_path / "x.mcap"
    copy_log(raw, path, payload=(k, payload))
    read_everything(path)


def near_commands() -> st.SearchStrategy[Any]:
    """Objects shaped like /teleop/command and /scale/weight messages, valid or nearly."""
    number = st.integers(-2, 2) | st.floats() | st.booleans()
    value = number | st.lists(number, max_size=5) | st.none() | st.text(max_size=2)
    keys = st.sampled_from(["target", "gripper", "base_target", "kg", "extra"])
    return st.dictionaries(keys, value, max_size=4) | json_values()


@FUZZ
@given(obj=near_commands())
def test_hand_checks_accept_only_what_the_schema_accepts(obj: Any) -> None:
    """The 100 Hz topics' hand checks are a shortcut for jsonschema, never a loosening."""
    for topic, ok in _FAST_OK.items():
        if ok(obj):
            assert tp.json_validator(topic).is_valid(obj), (topic, obj)


# --- trees -----------------------------------------------------------------------------


@functools.cache
def tree_doc() -> dict[str, Any]:
    """A real tree (the sample log compiled) as its JSON document."""
    from smccli.learn.compile import compile_logs

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tree.json"
        compile_logs([SAMPLE], path)
        return json.loads(path.read_text())


def paths_of(doc: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every key path in a JSON document (the root excluded)."""
    out: list[tuple[Any, ...]] = []
    items = (
        doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else []
    )
    for k, v in items:
        out.append((*prefix, k))
        out.extend(paths_of(v, (*prefix, k)))
    return out


@st.composite
def edited(draw: st.DrawFn, doc: Any) -> Any:
    """``doc`` with one to three edits: a key dropped, a value of another type or a random
    value, a number scaled or made NaN / inf / huge, a list emptied or lengthened."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        paths = paths_of(doc)
        if not paths:
            return draw(json_values())
        path = draw(st.sampled_from(paths))
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        key, old = path[-1], parent[path[-1]]
        op = draw(st.sampled_from(["drop", "random", "number", "list"]))
        if op == "drop":
            del parent[key]
        elif op == "random":
            parent[key] = draw(json_values())
        elif op == "number":
            parent[key] = draw(
                st.sampled_from([0, -1, 1e308, -1e308, 10**400, float("nan"), float("inf")])
                | st.floats()
                | st.integers()
            )
        elif isinstance(old, list):
            parent[key] = old[: draw(st.integers(0, len(old)))] + draw(
                st.lists(json_values(), max_size=3)
            )
        else:
            parent[key] = [old]
    return doc


@FUZZ
@given(data=st.data())
def test_edited_tree_dict(data: st.DataObject) -> None:
    doc = data.draw(edited(tree_doc()))
    survives(lambda: tree_from_dict(doc, "tree.json"))


@FUZZ
@given(data=st.data())
def test_edited_tree_file(data: st.DataObject, tmp_path: Path) -> None:
    text = json.dumps(data.draw(edited(tree_doc())))
    if data.draw(st.booleans()):
        text = data.draw(mutated(text.encode())).decode("utf-8", errors="replace")
    path = tmp_path / "tree.json"
    path.write_text(text)
    survives(lambda: load_tree(path))


@FUZZ
@given(data=st.binary(max_size=512))
def test_tree_file_of_arbitrary_bytes(data: bytes, tmp_path: Path) -> None:
    path = tmp_path / "tree.json"
    path.write_bytes(data)
    survives(lambda: load_tree(path))


def test_unmutated_inputs_load(tmp_path: Path) -> None:
    """The fuzzers start from inputs that are fine."""
    assert tree_from_dict(tree_doc()).edges
    path = tmp_path / "x.mcap"
    copy_log(small_raw(small_log()), path, chunked=False)
    log = read_log(path)
    assert len(log.frames) == 2 and len(log.commands) == 20 and len(log.point_clouds) == 1
