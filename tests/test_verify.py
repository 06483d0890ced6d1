"""``smc verify LOG`` (alias ``smc replay --verify LOG``): a log's commands played again
from its first state.

A log recorded by this code replays to the bit; the sample logs (some recorded by an
earlier controller) keep their POI within a millimetre; a log whose commands were edited
is flagged from the edit on; bad input is a one-line error.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from conftest import SAMPLE_LOGS, smc  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap.writer import Writer  # noqa: E402

from smccli.errors import LogError  # noqa: E402
from smccli.execute.verify import POI_TOLERANCE, verify_log  # noqa: E402
from smccli.logs import strip_topic  # noqa: E402
from smccli.logs import topics as tp  # noqa: E402


def _edit_commands(src: Path, dst: Path, after: float, dx: float) -> None:
    """Copy ``src`` to ``dst`` (the mcap package), each command after ``after`` [s] with
    its target moved ``dx`` [m] along x: what a hand-edited or mixed-up log looks like."""
    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = make_reader(f)
        header = reader.get_header()
        w = Writer(g)
        w.start(profile=header.profile, library=header.library)
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        for a in reader.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(
                    channel.topic,
                    channel.message_encoding,
                    schemas.get(schema.id, 0) if schema else 0,
                    channel.metadata,
                )
            data = message.data
            if channel.topic == tp.COMMAND and message.log_time > after * 1e9:
                cmd = json.loads(data)
                cmd["target"][0] += dx
                data = json.dumps(cmd).encode()
            w.add_message(
                channels[channel.id], message.log_time, data, message.publish_time, message.sequence
            )
        w.finish()


def test_a_log_recorded_here_replays_to_the_bit(reseeded_logs) -> None:
    v = verify_log(reseeded_logs[1]["bench_pick"][0])
    assert len(v.t) > 500 and not v.divergent and v.first_divergence is None
    # Bit-identical states; the POI's yaw passes through the log's unwrapping (1e-17).
    assert v.max_poi_error < 1e-12 and v.max_finger_error == 0.0 and v.max_joint_error == 0.0


@pytest.mark.parametrize("log", ["bench_pick/demo.mcap", "rooms/demo1.mcap"])
def test_sample_logs_mean_what_they_recorded(log) -> None:
    r = smc("verify", SAMPLE_LOGS / log)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "reproduces what it recorded" in r.stdout
    assert verify_log(SAMPLE_LOGS / log).max_poi_error < 0.2 * POI_TOLERANCE


def test_edited_commands_are_flagged_from_the_edit_on(tmp_path) -> None:
    edited = tmp_path / "edited.mcap"
    _edit_commands(SAMPLE_LOGS / "bench_pick" / "demo.mcap", edited, after=3.0, dx=0.02)
    v = verify_log(edited)
    assert v.divergent and v.first_divergence is not None
    assert 3.0 < v.first_divergence < 4.0, v.first_divergence
    assert v.max_poi_error > 0.015
    for args in (["verify", edited], ["replay", "--verify", edited]):  # the command, its alias
        r = smc(*args)
        assert r.returncode == 1 and "diverges" in r.stdout, r.stdout + r.stderr


def test_bad_input_is_one_line(tmp_path, sample_trees) -> None:
    missing = tmp_path / "nope.mcap"
    for args in (["verify", missing], ["replay", "--verify", missing]):
        r = smc(*args)
        assert r.returncode == 2 and str(missing) in r.stderr and "Traceback" not in r.stderr
    r = smc("replay", sample_trees["bench_pick"], "--verify", SAMPLE_LOGS / "rooms/demo1.mcap")
    assert r.returncode == 2 and "give no tree" in r.stderr
    # Without its ground truth a log has no first state to start from.
    bare = strip_topic(
        SAMPLE_LOGS / "bench_pick" / "demo.mcap", tmp_path / "bare.mcap", tp.GROUND_TRUTH
    )
    with pytest.raises(LogError) as err:
        verify_log(bare)
    assert str(bare) in str(err.value) and tp.GROUND_TRUTH in str(err.value)
