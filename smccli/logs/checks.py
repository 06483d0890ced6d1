"""Checks of a log's records before and while decoding: channels, attachments, time order,
JSON messages against their topic's schema, finite numbers. Each problem is one line
naming the file (and the topic and time)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from smccli.errors import LogError
from smccli.logs import topics as tp
from smccli.logs.records import RawLog


class BadContent(Exception):
    """A message that parses but does not hold what its topic promises; the caller adds the
    file, topic and time to make it a LogError."""


def check_channels(path: Path, raw: RawLog) -> None:
    """Every message has a Channel record and every channel's schema a Schema record."""
    for cid, ch in sorted(raw.channels.items()):
        if ch.schema_id and ch.schema_id not in raw.schemas:
            raise LogError(
                f"{path}: channel {cid} ({ch.topic}) refers to schema {ch.schema_id}, "
                "which has no Schema record"
            )
    for m in raw.messages:
        if m.channel_id not in raw.channels:
            raise LogError(
                f"{path}: message at t={m.log_time / 1e9:.3f} s on unknown channel "
                f"{m.channel_id} (no Channel record; known: "
                f"{', '.join(str(c) for c in sorted(raw.channels)) or 'none'})"
            )


def check_mjcf(data: bytes) -> str | None:
    """What is wrong with a ``scene.xml`` attachment, or None. Syntax only: whether MuJoCo
    accepts the model is for its consumer (``smccli.logs.robot.robot_model_of``) to find out."""
    if not data.strip():
        return "empty (expected the scene's MJCF)"
    try:
        root = ET.fromstring(data)
    except ET.ParseError as e:
        return f"not XML ({e})"
    if root.tag != "mujoco":
        return f"not MJCF (root element <{root.tag}>, expected <mujoco>)"
    return None


def check_scene_yaml(data: bytes, expected: str = "the scene file") -> str | None:
    """What is wrong with a ``scene.yaml`` (or ``robot.yaml``) attachment, or None (syntax
    and outline only)."""
    if not data.strip():
        return f"empty (expected {expected})"
    try:
        doc = yaml.safe_load(data)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or " ".join(str(e).split())
        return f"not YAML ({problem}{where})"
    if not isinstance(doc, dict):
        return f"not a mapping (found {type(doc).__name__})"
    return None


_ATTACHMENT_CHECKS: dict[str, Callable[[bytes], str | None]] = {
    "scene.xml": check_mjcf,
    "scene.yaml": check_scene_yaml,
    "robot.yaml": lambda data: check_scene_yaml(data, "the robot file"),
}
"""Attachment name -> check; attachments of other names are the user's and not looked at."""


def check_attachments(path: Path, raw: RawLog) -> None:
    for a in raw.attachments:
        check = _ATTACHMENT_CHECKS.get(a.name)
        problem = check(a.data) if check is not None else None
        if problem is not None:
            raise LogError(f"{path}: attachment {a.name}: {problem}")


def check_times(path: Path, raw: RawLog) -> None:
    last: dict[int, int] = {}
    for m in raw.messages:
        prev = last.get(m.channel_id)
        if prev is not None and m.log_time < prev:
            raise LogError(
                f"{path}: time goes backwards on {raw.topic(m)}: {m.log_time / 1e9:.9f} s "
                f"after {prev / 1e9:.9f} s"
            )
        last[m.channel_id] = m.log_time


def finite(path: Path, topic: str, t: float, a: Any) -> np.ndarray:
    try:
        arr = np.asarray(a, dtype=float)
    except OverflowError:  # a JSON integer beyond float range: as good as inf
        arr = np.array(np.inf)
    if not np.isfinite(arr).all():  # the method: np.all's dispatch is most of the cost
        raise LogError(f"{path}: NaN or inf in {topic} at t={t:.3f} s")
    return arr


_NUMBER = (int, float)  # JSON numbers as json.loads returns them; bool is excluded by `type(x) in`


def _numbers(x: Any, n: int) -> bool:
    return type(x) is list and len(x) == n and all(type(v) in _NUMBER for v in x)


def _command_ok(obj: Any) -> bool:
    """Sufficient (not necessary) for ``teleop_command.schema.json``."""
    if type(obj) is not dict or not 2 <= len(obj) <= 3:
        return False
    if len(obj) == 3 and not _numbers(obj.get("base_target"), 3):
        return False
    g = obj.get("gripper")
    return (
        _numbers(obj.get("target"), 4)
        and isinstance(g, _NUMBER)
        and type(g) is not bool
        and 0 <= g <= 1
    )


def _weight_ok(obj: Any) -> bool:
    """Sufficient for ``weight.schema.json``."""
    return type(obj) is dict and len(obj) == 1 and type(obj.get("kg")) in _NUMBER


# jsonschema is slow per message, so the two 100 Hz JSON topics get a hand check that
# accepts what the schema accepts in the usual form; only what it does not accept goes to
# jsonschema (exact verdict and message). The 10 Hz and rarer topics go to jsonschema
# directly.
_FAST_OK: dict[str, Callable[[Any], bool]] = {tp.COMMAND: _command_ok, tp.WEIGHT: _weight_ok}


def _json_type(x: Any) -> str:
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, _NUMBER):
        return "a number"
    names = {dict: "an object", list: "an array", str: "a string", type(None): "null"}
    return names.get(type(x), type(x).__name__)


def schema_problem(topic: str, obj: Any) -> str | None:
    """Why ``obj`` does not match the topic's JSON Schema (one short phrase), or None."""
    fast = _FAST_OK.get(topic)
    if fast is not None and fast(obj):
        return None
    from jsonschema.exceptions import best_match

    err = best_match(tp.json_validator(topic).iter_errors(obj))
    if err is None:
        return None
    where = "/".join(str(p) for p in err.absolute_path)
    at = f" in '{where}'" if where else ""
    inst = err.instance
    if err.validator == "required" and isinstance(inst, dict):
        missing = [k for k in err.validator_value if k not in inst]
        return f"missing field {missing[0]!r}{at}"
    if err.validator == "additionalProperties" and isinstance(inst, dict):
        known = set(err.schema.get("properties", {}))
        extra = sorted(str(k) for k in inst if k not in known)
        return f"unexpected field {extra[0]!r}{at}" if extra else err.message[:120]
    if err.validator == "type":
        what = f"field '{where}'" if where else "message"
        return f"{what} is {_json_type(inst)}, expected {err.validator_value}"
    what = f"field '{where}'" if where else "message"
    return f"{what}: {' '.join(err.message.split())[:120]}"


def json_message(topic: str, data: bytes) -> Any:
    """Parse and validate one message of a JSON topic; BadContent says what is wrong."""
    try:
        obj = json.loads(data)
    except ValueError as e:  # JSONDecodeError and UnicodeDecodeError
        raise BadContent(f"not JSON ({e})") from None
    except RecursionError:
        raise BadContent("not JSON (nested too deeply)") from None
    problem = schema_problem(topic, obj)
    if problem is not None:
        raise BadContent(problem)
    return obj


def message_error(path: Path, topic: str, t_ns: int, problem: str) -> LogError:
    """The one error format for a message: ``demo.mcap: /topic at t=1.230 s: problem``."""
    return LogError(f"{path}: {topic} at t={t_ns / 1e9:.3f} s: {problem}")
