"""JSON Schemas of the project's files and messages, kept in the repository's ``schemas/``.

One place finds them: ``schemas/`` beside the package (a checkout, an editable install) or
inside it (a wheel built with the schemas copied in).
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import Any

_PACKAGE = Path(__file__).resolve().parent


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
