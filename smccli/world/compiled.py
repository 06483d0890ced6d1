"""MJCF text compiled once per process: every caller gets a copy of the same model.

One command compiles the same scene text several times over (the scene file loaded, the
tree's or the log's copy of it rebuilt, the robot model of the self-filter, the
simulator's): a vendor robot's meshes take 0.2-0.6 s each time. A model depends on its
text and the bytes of the files it names, whether they are handed with it (``assets``: a
scene's meshes) or read from disk (a tree's copy of a vendor scene names them by path):
the key holds the text and each file's name and bytes, so the two ways give one model.
"""

from __future__ import annotations

import copy
import os
import re
from collections.abc import Mapping
from pathlib import Path

import mujoco

_MODELS: dict[tuple, mujoco.MjModel] = {}
"""(MJCF text, (file name, bytes) sorted) -> the model compiled. A bytes object keeps its
hash once computed, and the same object compares equal at once: a lookup with the scene's
own files costs nothing after the first."""

_READ: dict[tuple[str, int, int], bytes] = {}
"""(path, size, mtime) -> the bytes read from disk: the same object while the file keeps
its size and modification time (a file that changes is read again)."""

_NAMED_FILE = re.compile(r'\bfile\w*="([^"]*)"')
"""An MJCF attribute naming a file: ``file``, a cube texture's ``fileright`` and so on."""


def _files(xml: str, assets: Mapping[str, bytes]) -> dict[str, bytes] | None:
    """``assets`` with every other file the text names read from disk (by its absolute
    path); None when one is not an absolute path that can be read (MuJoCo then resolves it
    or says what is wrong)."""
    files = dict(assets)
    for name in set(_NAMED_FILE.findall(xml)) - files.keys():
        try:
            if not Path(name).is_absolute():
                return None
            st = os.stat(name)
            key = (name, st.st_size, st.st_mtime_ns)
            if key not in _READ:
                if len(_READ) >= 512:  # a few robots' meshes; never grows without bound
                    _READ.clear()
                _READ[key] = Path(name).read_bytes()
            files[name] = _READ[key]
        except OSError:
            return None
    return files


def compile_mjcf(xml: str, assets: Mapping[str, bytes] | None = None) -> mujoco.MjModel:
    """``mujoco.MjModel.from_xml_string(xml, assets)``, as a fresh copy of the model this
    process compiled from the same text and file contents; MuJoCo's ValueError where it
    rejects them (nothing is remembered then)."""
    files = _files(xml, assets or {})
    if files is None:
        return mujoco.MjModel.from_xml_string(xml, dict(assets or {}) or None)
    key = (xml, tuple(sorted(files.items())))
    model = _MODELS.get(key)
    if model is None:
        model = mujoco.MjModel.from_xml_string(xml, files or None)
        if len(_MODELS) >= 4:  # a few scenes per process; never grows without bound
            _MODELS.clear()
        _MODELS[key] = model
    return copy.copy(model)
