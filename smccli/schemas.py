"""JSON Schemas of the project's files and messages, kept in the repository's ``schemas/``.

One place finds them: ``schemas/`` beside the package (a checkout, an editable install) or
inside it (a wheel built with the schemas copied in).

The files people write (scene files, teleop scripts, layouts, robot files) are YAML checked
against a schema by :func:`validate_yaml`: a problem becomes one line naming the file, the key
path, the line and what is wrong, e.g. ``scene.yaml: objects[2].range.yaw (line 31): expected
a number, found 'abc'``.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import jsonschema
import yaml

from smccli.errors import SmcError

_PACKAGE = Path(__file__).resolve().parent

KeyPath = tuple[str | int, ...]
"""Keys and list indices from a document's root to a value, e.g. ``("objects", 2, "size")``."""


@cache
def schema_dir() -> Path:
    """The folder holding ``<name>.schema.json`` files."""
    for candidate in (_PACKAGE.parent / "schemas", _PACKAGE / "_schemas"):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"schemas/ not found near {_PACKAGE}")


def schema_path(name: str) -> Path:
    """Path of ``<name>.schema.json``."""
    return schema_dir() / f"{name}.schema.json"


@cache
def load_schema(name: str) -> dict[str, Any]:
    """The schema ``<name>.schema.json`` as a dict."""
    return json.loads(schema_path(name).read_text(encoding="utf-8"))


@cache
def _validator(name: str) -> jsonschema.Draft202012Validator:
    schema = load_schema(name)
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


# --- YAML with line numbers ----------------------------------------------------------------


def yaml_problem(exc: yaml.YAMLError) -> str:
    """One line for a YAML error: the problem and where (line, column, 1-based)."""
    mark = getattr(exc, "problem_mark", None)
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{problem}{at}"


def key_path(path: Sequence[str | int]) -> str:
    """``("objects", 2, "range", "yaw")`` -> ``objects[2].range.yaw``; ``()`` -> ``top level``."""
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "top level"


@dataclass(frozen=True, slots=True)
class YamlDocument:
    """A YAML file parsed once into data and the node tree that knows each value's line."""

    source: str
    """The file's path (or a label such as ``<embedded scene.yaml>``), for messages."""
    data: Any
    """The document as plain Python (``yaml.safe_load`` types)."""
    root: yaml.Node | None
    """Its node tree; None for an empty document."""

    def line(self, path: Sequence[str | int], *, of_key: bool = False) -> int | None:
        """Line (1-based) of the value at ``path``, or of its key when ``of_key``; None when
        the path leaves the document (a missing key)."""
        node: yaml.Node | None = self.root
        key_node: yaml.Node | None = None
        for part in path:
            key_node, node = _child(node, part)
            if node is None:
                return None
        target = key_node if of_key and key_node is not None else node
        return None if target is None else target.start_mark.line + 1

    def where(self, path: Sequence[str | int], *, of_key: bool = False) -> str:
        """``objects[2].range.yaw (line 31)``: the key path, and its line where known."""
        line = self.line(path, of_key=of_key)
        return key_path(path) + (f" (line {line})" if line is not None else "")


def _child(node: yaml.Node | None, part: str | int) -> tuple[yaml.Node | None, yaml.Node | None]:
    """(key node, value node) of ``part`` under ``node``; (None, None) if absent."""
    if isinstance(node, yaml.SequenceNode) and isinstance(part, int):
        return (None, node.value[part]) if 0 <= part < len(node.value) else (None, None)
    if isinstance(node, yaml.MappingNode):
        found: tuple[yaml.Node | None, yaml.Node | None] = (None, None)
        for key, value in node.value:
            # The last duplicate wins, as in the constructed data.
            if isinstance(key, yaml.ScalarNode) and key.value == str(part):
                found = (key, value)
        return found
    return None, None


def parse_yaml(text: str, source: str, error_cls: type[SmcError]) -> YamlDocument:
    """Parse ``text`` once, keeping node positions; ``error_cls`` if it is not valid YAML."""
    loader = yaml.SafeLoader(text)
    try:
        root = loader.get_single_node()
        data = loader.construct_document(root) if root is not None else None
    except yaml.YAMLError as exc:
        raise error_cls(f"{source}: not valid YAML: {yaml_problem(exc)}") from exc
    finally:
        loader.dispose()
    return YamlDocument(source, data, root)


# --- schema problems in words ---------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SchemaProblem:
    """The one problem reported for a document that does not fit its schema."""

    path: KeyPath
    """Where: the offending value (an unknown key: that key; a missing key: its mapping)."""
    line: int | None
    """Line (1-based) of ``path`` in the file, where YAML knows it."""
    message: str
    """What is wrong, e.g. ``expected a number, found 'abc'``."""

    def where(self) -> str:
        """``objects[2].range.yaw (line 31)``."""
        return key_path(self.path) + (f" (line {self.line})" if self.line is not None else "")


Where = Callable[[SchemaProblem, YamlDocument], str | None]
"""Custom wording of a problem's place (e.g. ``step 3 (line 12)``); None: the default."""


def schema_problem(doc: YamlDocument, schema_name: str) -> SchemaProblem | None:
    """The most useful problem of ``doc`` against ``<schema_name>.schema.json``, or None.

    Several problems: the shallowest, then the first in the file; a value that fits none of
    ``oneOf`` alternatives is explained by the alternative it was meant to be (the one whose
    distinguishing key it has) when there is one.
    """
    validator = _validator(schema_name)
    errors = list(validator.iter_errors(doc.data))
    if not errors:
        # JSON has no NaN or infinity, so a schema cannot refuse YAML's .nan and .inf.
        bad = _non_finite(doc.data, ())
        if bad is None:
            return None
        path, value = bad
        return SchemaProblem(path, doc.line(path), f"expected a finite number, found {value}")
    path, message, of_key = _explain(_pick(errors, doc), validator.schema, doc)
    return SchemaProblem(path, doc.line(path, of_key=of_key), message)


def check_yaml(
    doc: YamlDocument, schema_name: str, error_cls: type[SmcError], *, where: Where | None = None
) -> None:
    """Raise ``error_cls`` with one line if ``doc`` does not fit ``<schema_name>.schema.json``:
    ``<source>: <key path> (line <n>): <what is wrong>``."""
    problem = schema_problem(doc, schema_name)
    if problem is not None:
        place = (where(problem, doc) if where is not None else None) or problem.where()
        raise error_cls(f"{doc.source}: {place}: {problem.message}")


def validate_yaml(
    text: str,
    schema_name: str,
    source: str,
    error_cls: type[SmcError],
    *,
    where: Where | None = None,
) -> Any:
    """Parse YAML ``text`` and check it against ``schemas/<schema_name>.schema.json``.

    Returns the data; raises ``error_cls`` with one line naming ``source``, the key path, the
    line and the problem (see :func:`check_yaml`). ``where`` rewords the place for a file kind
    with its own landmarks (teleop scripts say ``step 3 (line 12)``).
    """
    doc = parse_yaml(text, source, error_cls)
    check_yaml(doc, schema_name, error_cls, where=where)
    return doc.data


_WEAK = ("anyOf", "oneOf")
_TYPE_NAMES = {
    "object": "a mapping",
    "array": "a list",
    "number": "a number",
    "integer": "an integer",
    "string": "a string",
    "boolean": "true or false",
    "null": "null",
}


def _pick(
    errors: Iterable[jsonschema.ValidationError], doc: YamlDocument
) -> jsonschema.ValidationError:
    # Shallowest first (a missing mapping explains the errors under it), then file order, and
    # a plain error before an "any of these alternatives" one at the same place.
    def key(e: jsonschema.ValidationError) -> tuple[int, int, bool]:
        path = tuple(e.absolute_path)
        return len(path), doc.line(path) or 0, e.validator in _WEAK

    return min(errors, key=key)


def _explain(
    err: jsonschema.ValidationError, root: dict[str, Any], doc: YamlDocument
) -> tuple[KeyPath, str, bool]:
    """(path, message, whether the line is that of the path's key) for one error."""
    path: KeyPath = tuple(err.absolute_path)
    kind, value, inst = err.validator, err.validator_value, err.instance
    if kind in _WEAK and err.context:
        return _explain_alternatives(err, root, doc)
    if kind == "type":
        types = [value] if isinstance(value, str) else list(value)
        return (
            path,
            f"expected {' or '.join(_TYPE_NAMES[t] for t in types)}, found {_show(inst)}",
            False,
        )
    if kind in ("additionalProperties", "unevaluatedProperties") and isinstance(inst, dict):
        known = list(err.schema.get("properties", {}))
        patterns = list(err.schema.get("patternProperties", {}))
        extra = [
            k for k in inst if k not in known and not any(re.search(p, str(k)) for p in patterns)
        ]
        if extra:
            valid = ", ".join(known) or "none"
            return path + (extra[0],), f"unknown key {extra[0]!r} (valid: {valid})", True
    if kind == "required" and isinstance(inst, dict):
        missing = [k for k in value if k not in inst]
        return path, f"missing required key {missing[0]!r}", False
    if kind == "enum":
        choices = ", ".join(str(v) for v in value)
        return path, f"unknown value {_show(inst)} (valid: {choices})", False
    if kind in ("minItems", "maxItems") and isinstance(inst, list):
        lo, hi = err.schema.get("minItems", 0), err.schema.get("maxItems")
        count = f"{lo}" if lo == hi else (f"{lo} to {hi}" if hi is not None else f"at least {lo}")
        noun = "item" if (hi if hi is not None else lo) == 1 else "items"
        return path, f"expected {count} {noun}, found {len(inst)}: {_show(inst)}", False
    if kind in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        return path, f"expected {_describe(err.schema)}, found {_show(inst)}", False
    if kind == "minLength" and value == 1:
        return path, "expected a non-empty string", False
    if kind == "minProperties" and isinstance(inst, dict):
        return path, f"expected at least {value} entries, found {len(inst)}", False
    return path, err.message, False


def _explain_alternatives(
    err: jsonschema.ValidationError, root: dict[str, Any], doc: YamlDocument
) -> tuple[KeyPath, str, bool]:
    """A value that fits none of ``oneOf``/``anyOf``: explain the alternative it was meant to
    be, else list what each alternative accepts."""
    path: KeyPath = tuple(err.absolute_path)
    inst = err.instance
    branches = [_resolve(b, root) for b in err.validator_value]
    failures: dict[int, list[jsonschema.ValidationError]] = {}
    for e in err.context or ():
        failures.setdefault(int(e.relative_schema_path[0]), []).append(e)
    # Mappings told apart by a key (a teleop step: move_to, gripper, mark or wait).
    keys = _distinguishing_keys(branches)
    if all(keys) and len(set(keys)) == len(keys):
        names = ", ".join(str(k) for k in keys)
        if not isinstance(inst, dict):
            return (
                path,
                f"expected a mapping with one of the keys {names}, found {_show(inst)}",
                False,
            )
        present = [i for i, k in enumerate(keys) if k in inst]
        if len(present) == 1 and failures.get(present[0]):
            return _explain(_pick(failures[present[0]], doc), root, doc)
        found = ", ".join(str(k) for k in inst) or "none"
        return path, f"expected exactly one of the keys {names}, found {found}", False
    # One alternative of the value's type failing deeper down: that one is meant.
    typed = [
        i
        for i, errs in failures.items()
        if not any(e.validator == "type" and not e.relative_path for e in errs)
    ]
    if len(typed) == 1 and all(e.relative_path for e in failures[typed[0]]):
        return _explain(_pick(failures[typed[0]], doc), root, doc)
    words = [_describe(b) for b in branches]
    if all(words):
        return path, f"expected {' or '.join(str(w) for w in words)}, found {_show(inst)}", False
    return path, err.message, False


def _resolve(schema: Any, root: dict[str, Any]) -> dict[str, Any]:
    """Follow a local ``$ref`` (``#/$defs/step``) within ``root``."""
    while isinstance(schema, dict) and str(schema.get("$ref", "")).startswith("#/"):
        target: Any = root
        for part in schema["$ref"][2:].split("/"):
            target = target[part]
        schema = target
    return schema if isinstance(schema, dict) else {}


def _distinguishing_keys(branches: list[dict[str, Any]]) -> list[str | None]:
    """Per mapping alternative, the first key it requires that no other alternative knows
    (a scene's success condition: ``object`` or ``robot_at``); None where there is none."""
    out: list[str | None] = []
    for i, b in enumerate(branches):
        others = set()
        for j, o in enumerate(branches):
            if j != i:
                others |= set(o.get("properties") or {}) | set(o.get("required") or [])
        own = [str(k) for k in b.get("required") or [] if k not in others]
        out.append(own[0] if b.get("type") == "object" and own else None)
    return out


def _describe(schema: dict[str, Any]) -> str | None:
    """What a simple schema accepts, in words: ``'open' or 'close'``, ``a number in [0, 1]``."""
    if "enum" in schema:
        return " or ".join(repr(v) for v in schema["enum"])
    if "const" in schema:
        return repr(schema["const"])
    kind = schema.get("type")
    if not isinstance(kind, str) or kind not in _TYPE_NAMES:
        return None
    text = _TYPE_NAMES[kind]
    lo, hi = schema.get("minimum"), schema.get("maximum")
    xlo, xhi = schema.get("exclusiveMinimum"), schema.get("exclusiveMaximum")
    if lo is not None and hi is not None:
        return f"{text} in [{lo}, {hi}]"
    bounds = [
        f"{op} {v}" for op, v in ((">=", lo), (">", xlo), ("<=", hi), ("<", xhi)) if v is not None
    ]
    return f"{text} {' and '.join(bounds)}" if bounds else text


def _non_finite(data: Any, path: KeyPath) -> tuple[KeyPath, float] | None:
    """The first NaN or infinite number in ``data``, with its path."""
    if isinstance(data, float) and not math.isfinite(data):
        return path, data
    items = (
        data.items()
        if isinstance(data, dict)
        else enumerate(data)
        if isinstance(data, list)
        else ()
    )
    for key, value in items:
        found = _non_finite(value, (*path, key))
        if found is not None:
            return found
    return None


def _show(value: Any) -> str:
    """A value as the user wrote it, cut to one short phrase."""
    if value is None:
        return "nothing (null)"
    if isinstance(value, dict):
        return "a mapping" + (f" with keys {', '.join(str(k) for k in value)}" if value else " {}")
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
