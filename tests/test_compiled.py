"""compile_mjcf: the same text and files give copies of one model; a changed file named on
disk gives a new one."""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np

from smccli.world.compiled import compile_mjcf

CUBE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"


def _xml(mesh: str) -> str:
    return (
        f'<mujoco><asset><mesh name="m" file="{mesh}"/></asset><worldbody>'
        '<body><freejoint/><geom type="mesh" mesh="m"/></body></worldbody></mujoco>'
    )


def test_copies_of_one_model_and_a_changed_file_compiled_again(tmp_path: Path) -> None:
    mesh = tmp_path / "m.obj"
    mesh.write_text(CUBE)
    a, b = compile_mjcf(_xml(str(mesh))), compile_mjcf(_xml(str(mesh)))
    assert a is not b
    a.geom_rgba[0] = [1, 0, 0, 1]  # a copy: changing it changes no other
    assert not np.array_equal(b.geom_rgba[0], [1, 0, 0, 1])
    mesh.write_text(CUBE.replace("v 1 0 0", "v 2 0 0"))  # a larger mesh, same path
    later = mesh.stat().st_mtime + 2  # MuJoCo's own mesh cache tells files apart by time
    os.utime(mesh, (later, later))
    c = compile_mjcf(_xml(str(mesh)))
    assert c.body_mass[1] > b.body_mass[1]


def test_files_handed_with_the_text_are_part_of_the_key() -> None:
    small = compile_mjcf(_xml("m.obj"), {"m.obj": CUBE.encode()})
    large = compile_mjcf(_xml("m.obj"), {"m.obj": CUBE.replace("v 1 0 0", "v 3 0 0").encode()})
    assert large.body_mass[1] > small.body_mass[1]


def test_a_rejected_text_raises_and_a_missing_file_too(tmp_path: Path) -> None:
    for xml in ("<mujoco><worldbody><bogus/></worldbody></mujoco>", _xml(str(tmp_path / "no.obj"))):
        try:
            compile_mjcf(xml)
        except ValueError:
            continue
        raise AssertionError(f"{xml} compiled")
    assert isinstance(compile_mjcf("<mujoco/>"), mujoco.MjModel)


def test_a_file_on_disk_and_the_same_bytes_handed_over_compile_once(tmp_path, monkeypatch) -> None:
    """A tree's copy of a scene names its meshes on disk, the scene file hands their bytes
    over: one compile serves both."""
    mesh = tmp_path / "once.obj"
    mesh.write_text(CUBE.replace("v 1 0 0", "v 1.5 0 0"))
    calls = []
    compile_xml = mujoco.MjModel.from_xml_string
    monkeypatch.setattr(
        mujoco.MjModel, "from_xml_string", lambda *a: calls.append(1) or compile_xml(*a)
    )
    a = compile_mjcf(_xml(str(mesh)))
    b = compile_mjcf(_xml(str(mesh)), {str(mesh): mesh.read_bytes()})
    assert len(calls) == 1 and a.body_mass[1] == b.body_mass[1]
