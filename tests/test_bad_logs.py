"""Valid MCAP, wrong content: each kind of bad log is built for real (a sample log rewritten
record by record) and fed to ``read_log`` and to the real ``smc compile`` / ``smc inspect``.

Every one must end in one line naming the file, the topic or attachment and (for a message)
its log time, exit code 2, no traceback, and no output touched.
"""

from __future__ import annotations

import dataclasses
import functools
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from conftest import sha256, smc
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from mcap.writer import CompressionType, Writer

from smccli.errors import LogError
from smccli.logs import log_summary, read_log
from smccli.logs import topics as tp
from smccli.logs.records import RawLog, read_bytes, scan_records
from smccli.logs.robot import robot_model_of

REPO = Path(__file__).resolve().parent.parent
SAMPLE = REPO / "sample_logs" / "pick_place" / "demo1.mcap"
# A scene.xml that is well-formed MJCF XML but that MuJoCo refuses (a geom without size).
REJECTED_MJCF = b"<mujoco><worldbody><geom type='box'/></worldbody></mujoco>"


@functools.cache
def sample_raw() -> RawLog:
    return scan_records(SAMPLE, read_bytes(SAMPLE))


def nth(topic: str, k: int) -> int:
    """Index in file order of the ``k``-th message on ``topic``."""
    raw = sample_raw()
    return [i for i, m in enumerate(raw.messages) if raw.topic(m) == topic][k]


def rewrite(
    dst: Path,
    *,
    edit: tuple[int, Callable[[bytes], bytes]] | None = None,
    attachments: dict[str, bytes | None] | None = None,
    metadata: dict[str, dict[str, str]] | None = None,
    unknown_channel_after: int | None = None,
    messages: bool = True,
) -> int:
    """Copy the sample log to ``dst`` with one change; returns the changed message's log time
    [ns] (0 when no message changed). ``attachments``: name -> new bytes, or None to drop."""
    raw = sample_raw()
    t_ns = 0
    with open(dst, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="test_bad_logs")
        for name, meta in (raw.metadata if metadata is None else metadata).items():
            w.add_metadata(name, meta)
        atts = {a.name: (a.media_type, a.data) for a in raw.attachments}
        for name, data in (attachments or {}).items():
            if data is None:
                atts.pop(name)
            else:
                atts[name] = (atts.get(name, ("application/octet-stream", b""))[0], data)
        for name, (media_type, data) in atts.items():
            w.add_attachment(0, 0, name, media_type, data)
        schema_ids = {
            sid: w.register_schema(s.name, s.encoding, s.data)
            for sid, s in sorted(raw.schemas.items())
        }
        channel_ids = {
            cid: w.register_channel(
                ch.topic, ch.message_encoding, schema_ids.get(ch.schema_id, 0), ch.metadata
            )
            for cid, ch in sorted(raw.channels.items())
        }
        for i, m in enumerate(raw.messages if messages else []):
            data = m.data
            if edit is not None and edit[0] == i:
                data, t_ns = edit[1](data), m.log_time
            w.add_message(channel_ids[m.channel_id], m.log_time, data, m.publish_time)
            if i == unknown_channel_after:
                t_ns = m.log_time
                w.add_message(99, m.log_time, b"{}", m.publish_time)
        w.finish()
    return t_ns


def proto_edit(cls: type, change: Callable[[object], None]) -> Callable[[bytes], bytes]:
    def edit(data: bytes) -> bytes:
        msg = cls()
        msg.ParseFromString(data)
        change(msg)
        return msg.SerializeToString()

    return edit


def _drop_last_joint(msg: JointStates) -> None:
    del msg.joints[-1]


def _set(**values: object) -> Callable[[object], None]:
    def change(msg: object) -> None:
        for k, v in values.items():
            setattr(msg, k, v)

    return change


def _first_field_offset(name: str, offset: int) -> Callable[[PointCloud], None]:
    def change(msg: PointCloud) -> None:
        for f in msg.fields:
            if f.name == name:
                f.offset = offset

    return change


def _short_k(msg: CameraCalibration) -> None:
    del msg.K[-1]


@dataclass(frozen=True)
class Case:
    """One kind of bad log."""

    name: str
    build: Callable[[Path], tuple[Path, list[str]]]
    """Writes the bad log under the given folder; returns its path and the substrings the
    one-line error must hold (beyond the file name)."""
    cli: tuple[str, ...] = ()
    """Commands run on it, each of which must refuse it: one representative per class runs
    both (a command costs ~2 s, mostly imports); compile does not read every topic."""
    read_log_fails: bool = True
    """False when the log reads fine and only its consumer (the robot model) refuses it."""


def at(t_ns: int) -> str:
    return f"at t={t_ns / 1e9:.3f} s"


def message_case(
    name: str,
    topic: str,
    k: int,
    edit: Callable[[bytes], bytes],
    problem: str,
    cli: tuple[str, ...] = (),
) -> Case:
    def build(folder: Path) -> tuple[Path, list[str]]:
        path = folder / "bad.mcap"
        t_ns = rewrite(path, edit=(nth(topic, k), edit))
        return path, [f"{topic} {at(t_ns)}: ", problem]

    return Case(name, build, cli)


def attachment_case(
    name: str, attachment: str, data: bytes | None, problem: str, **kw: object
) -> Case:
    def build(folder: Path) -> tuple[Path, list[str]]:
        path = folder / "bad.mcap"
        rewrite(path, attachments={attachment: data})
        return path, [f"attachment {attachment}", problem]

    return Case(name, build, **kw)  # type: ignore[arg-type]


def _unknown_channel(folder: Path) -> tuple[Path, list[str]]:
    path = folder / "bad.mcap"
    t_ns = rewrite(path, unknown_channel_after=nth(tp.COMMAND, 300))
    return path, [f"message {at(t_ns)} on unknown channel 99", "no Channel record"]


def _no_messages(folder: Path) -> tuple[Path, list[str]]:
    path = folder / "bad.mcap"
    rewrite(path, messages=False)
    return path, ["no readable message (the log holds no messages)"]


def _cut_in_first_chunk(folder: Path) -> tuple[Path, list[str]]:
    """A killed recorder's ``.part`` that ends inside its first chunk."""
    data = SAMPLE.read_bytes()
    pos = 8  # magic; then records: opcode (1 byte), length (uint64 LE), content
    while data[pos] != 0x06:  # Chunk
        pos += 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
    path = folder / "bad.mcap.part"
    path.write_bytes(data[: pos + 100])
    return path, ["no readable message (truncated at byte", "before its first chunk ended"]


def _zstd_frame_claims_terabytes(folder: Path) -> tuple[Path, list[str]]:
    """A chunk whose zstd frame header claims 32 TiB of content:
    zstandard tries to allocate that and raises MemoryError."""
    data = bytearray(SAMPLE.read_bytes())
    i = data.index(b"\x28\xb5\x2f\xfd")  # the first zstd frame's magic
    data[i + 4] = 0xC0  # frame header: an 8-byte content size after the window byte
    data[i + 5] = 0x60
    data[i + 6 : i + 14] = (2**45).to_bytes(8, "little")
    path = folder / "bad.mcap"
    path.write_bytes(bytes(data))
    return path, ["corrupt MCAP (a zstd chunk claims more data than memory holds)"]


CASES = [
    Case("zstd-frame-claims-terabytes", _zstd_frame_claims_terabytes),
    message_case(
        "command-missing-field",
        tp.COMMAND,
        120,
        lambda d: b'{"target":[0.4,0.0,0.3,0.0]}',
        "missing field 'gripper'",
        cli=("compile", "inspect"),
    ),
    message_case("command-not-json", tp.COMMAND, 5, lambda d: d[:-3], "not JSON"),
    message_case(
        "saliency-wrong-type",
        tp.SALIENCY,
        0,
        lambda d: b'{"label":5,"source":"operator"}',
        "field 'label' is a number, expected string",
    ),
    message_case(
        "ground-truth-wrong-type",
        tp.GROUND_TRUTH,
        3,
        lambda d: b'{"poses":{"cube":[1,2,3]}}',
        "field 'poses/cube'",
    ),
    message_case(
        "joint-states-not-protobuf",
        tp.JOINT_STATES,
        50,
        lambda d: b"\xff\xff\xff\xff" + d,
        "protobuf does not decode",
        cli=("compile", "inspect"),
    ),
    message_case(
        "joint-names-differ",
        tp.JOINT_STATES,
        400,
        proto_edit(JointStates, _drop_last_joint),
        "differ from the first message's",
    ),
    message_case(
        "color-not-an-image",
        tp.COLOR,
        10,
        proto_edit(CompressedImage, _set(data=b"not a jpeg at all")),
        "image does not decode (format 'jpeg', 17 bytes)",
        cli=("compile", "inspect"),
    ),
    message_case(
        "depth-not-16-bit",
        tp.DEPTH,
        10,
        proto_edit(
            CompressedImage, _set(data=tp.encode_color(np.zeros((240, 320, 3), np.uint8), 90)[1])
        ),
        "expected a 16-bit one-channel image, found uint8 240x320x3",
    ),
    message_case(
        "depth-size-differs",
        tp.DEPTH,
        10,
        proto_edit(CompressedImage, _set(data=tp.encode_depth(np.ones((120, 160))))),
        "depth 160x120 differs from the colour image's 320x240",
    ),
    message_case(
        "calibration-short-k",
        tp.CALIBRATION,
        2,
        proto_edit(CameraCalibration, _short_k),
        "K holds 8 values, expected 9",
    ),
    message_case(
        "points-bad-stride",
        tp.POINTS,
        0,
        proto_edit(PointCloud, _set(point_stride=13)),
        "not a multiple of point_stride 13",
        cli=("inspect",),
    ),
    message_case(
        "points-stride-0",
        tp.POINTS,
        1,
        proto_edit(PointCloud, _set(point_stride=0)),
        "point_stride is 0",
    ),
    message_case(
        "points-offset-beyond-stride",
        tp.POINTS,
        1,
        proto_edit(PointCloud, _first_field_offset("z", 14)),
        "field 'z' at offset 14 (4 bytes) lies beyond point_stride 16",
    ),
    Case("unknown-channel", _unknown_channel, cli=("compile", "inspect")),
    attachment_case("scene-xml-empty", "scene.xml", b"", "empty (expected the scene's MJCF)"),
    attachment_case(
        "scene-xml-not-xml",
        "scene.xml",
        b"<mujoco><worldbody>",
        "not XML",
        cli=("compile", "inspect"),
    ),
    attachment_case(
        "scene-yaml-not-yaml", "scene.yaml", b"name: [unclosed", "not YAML", cli=("compile",)
    ),
    # Inspect shows such a log without the robot self-filter (a warning): only compile needs
    # the model.
    attachment_case(
        "scene-xml-rejected",
        "scene.xml",
        REJECTED_MJCF,
        "MuJoCo rejects the MJCF",
        cli=("compile",),
        read_log_fails=False,
    ),
    attachment_case(
        "scene-xml-missing",
        "scene.xml",
        None,
        "missing (the scene's MJCF)",
        cli=("compile",),
        read_log_fails=False,
    ),
    Case("no-messages", _no_messages, cli=("compile",)),
    Case("cut-in-first-chunk", _cut_in_first_chunk, cli=("inspect",)),
]
BY_NAME = {c.name: c for c in CASES}


@pytest.fixture(scope="module")
def good_tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample log compiled once; each test works on a copy."""
    from smccli.learn.compile import compile_logs

    path = tmp_path_factory.mktemp("tree") / "tree.json"
    compile_logs([SAMPLE], path)
    return path


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_read_log_raises_one_line_naming_file_and_place(case: Case, tmp_path: Path) -> None:
    path, expected = case.build(tmp_path)
    if not case.read_log_fails:
        log = read_log(path, on_warning=lambda m: None)
        with pytest.raises(LogError) as exc:
            robot_model_of(log)
    else:
        with pytest.raises(LogError) as exc:
            read_log(path, on_warning=lambda m: None)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    for part in expected:
        assert part in msg, (part, msg)


CLI_CASES = [(c, cmd) for c in CASES for cmd in c.cli]


@pytest.mark.parametrize(
    ("case", "command"), CLI_CASES, ids=[f"{c.name}-{cmd}" for c, cmd in CLI_CASES]
)
def test_cli_refuses_bad_log(case: Case, command: str, good_tree: Path, tmp_path: Path) -> None:
    bad, expected = case.build(tmp_path)
    tree = tmp_path / "tree.json"
    shutil.copyfile(good_tree, tree)
    rrd = tmp_path / "out.rrd"
    rrd.write_bytes(b"a recording from before")
    before = {p.name: sha256(p) for p in (tree, rrd)}
    if command == "compile":
        proc = smc("compile", bad, "-o", tree)
    else:
        proc = smc("inspect", tree, bad, "--save", rrd, "--force")
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: ") and str(bad) in lines[0], lines[0]
    for part in expected:
        assert part in lines[0], (part, lines[0])
    assert {p.name: sha256(p) for p in (tree, rrd)} == before
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.endswith(".lock")) == sorted(
        [bad.name, "out.rrd", "tree.json"]
    )


def test_missing_metadata_is_a_warning_not_a_traceback(good_tree: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    rewrite(bad, metadata={})
    warnings: list[str] = []
    log = read_log(bad, on_warning=warnings.append)
    assert log.metadata == {} and len(log.commands) > 0
    assert warnings == [
        f"{bad}: no 'smc' metadata record (scene, seed and rates unknown; not written by smc?)"
    ]
    tree = tmp_path / "tree.json"
    shutil.copyfile(good_tree, tree)
    proc = smc("compile", bad, "-o", tree)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert "no 'smc' metadata record" in proc.stderr


def test_log_summary_names_a_bad_saliency_message(tmp_path: Path) -> None:
    path, expected = BY_NAME["saliency-wrong-type"].build(tmp_path)
    with pytest.raises(LogError, match="bad.mcap: /saliency at t="):
        log_summary(path)
    path, _ = BY_NAME["unknown-channel"].build(tmp_path)
    with pytest.raises(LogError, match="unknown channel 99"):
        log_summary(path)


def test_user_topics_with_channels_are_still_ignored(tmp_path: Path) -> None:
    path = tmp_path / "extra.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        cid = w.register_channel("/my/own", "json", 0)
        w.add_message(cid, 0, b"anything at all", 0)
        w.finish()
    warnings: list[str] = []
    log = read_log(path, on_warning=warnings.append)
    assert log.topic_counts == {"/my/own": 1} and len(warnings) == 1  # no smc metadata


def test_scene_from_attachments_names_log_and_attachment() -> None:
    from smccli.world.scene import load_scene_from_text

    atts = {a.name: a.data.decode() for a in sample_raw().attachments}
    scene = load_scene_from_text(atts["scene.yaml"], atts["scene.xml"], log="demo1.mcap")
    assert scene.name == "pick_place"
    with pytest.raises(
        LogError, match=r"^demo1.mcap: attachment scene.xml: MuJoCo rejects the MJCF"
    ):
        load_scene_from_text(atts["scene.yaml"], REJECTED_MJCF.decode(), log="demo1.mcap")
    with pytest.raises(LogError, match=r"^demo1.mcap: attachment scene.yaml: not valid YAML"):
        load_scene_from_text("name: [", atts["scene.xml"], log="demo1.mcap")


def test_robot_model_names_a_joint_the_mjcf_lacks() -> None:
    log = read_log(SAMPLE)
    js = log.joint_states[0]
    renamed = dataclasses.replace(js, names=("elbow_of_another_robot", *js.names[1:]))
    with pytest.raises(LogError, match=r"attachment scene.xml: no joint 'elbow_of_another_robot'"):
        robot_model_of(dataclasses.replace(log, joint_states=[renamed]))
