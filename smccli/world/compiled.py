"""MJCF text compiled once per process: every caller gets a copy of the same model.

One command compiles the same scene text several times over (the scene file loaded, the
log's copy of it rebuilt, the robot model of the self-filter, the simulator's): a vendor
robot's meshes take 0.2-0.6 s each time. A model depends on its text, the files handed
with it (``assets``) and the files on disk it names (a tree's copy of a vendor scene names
its meshes by path): the key holds the first two and the size and modification time of
the others.
"""

from __future__ import annotations

import copy
import os
import re
from collections.abc import Mapping

import mujoco

_MODELS: dict[tuple, mujoco.MjModel] = {}
"""(MJCF text, its files, the named files' stats on disk) -> the model compiled."""

_NAMED_FILE = re.compile(r'\bfile\w*="([^"]*)"')
"""An MJCF attribute naming a file: ``file``, a cube texture's ``fileright`` and so on."""


def _on_disk(xml: str, assets: Mapping[str, bytes]) -> tuple | None:
    """(path, size, mtime) of each file the text names that ``assets`` does not hold,
    with the working folder relative paths resolve from; None when one cannot be read
    (MuJoCo then says what is wrong)."""
    named = sorted({f for f in _NAMED_FILE.findall(xml) if f not in assets})
    if not named:
        return ()
    try:
        stats = [(f, os.stat(f).st_size, os.stat(f).st_mtime_ns) for f in named]
    except OSError:
        return None
    return (os.getcwd(), *stats)


def compile_mjcf(xml: str, assets: Mapping[str, bytes] | None = None) -> mujoco.MjModel:
    """``mujoco.MjModel.from_xml_string(xml, assets)``, as a fresh copy of the model this
    process compiled from the same text and files; MuJoCo's ValueError where it rejects
    them (nothing is remembered then)."""
    files = tuple(sorted((assets or {}).items()))
    disk = _on_disk(xml, dict(files))
    if disk is None:
        return mujoco.MjModel.from_xml_string(xml, dict(files) or None)
    key = (xml, files, disk)
    model = _MODELS.get(key)
    if model is None:
        model = mujoco.MjModel.from_xml_string(xml, dict(files) or None)
        if len(_MODELS) >= 4:  # a few scenes per process; never grows without bound
            _MODELS.clear()
        _MODELS[key] = model
    return copy.copy(model)
