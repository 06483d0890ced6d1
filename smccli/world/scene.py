"""Scenes: an MJCF model (table, camera) plus a scene file (YAML) naming the robot and the objects.

The robot's MJCF (:mod:`smccli.world.robot`) is included beside the scene's, its root at the
world origin; the objects are built from the scene file with ``mujoco.MjSpec`` so their look,
mass and pose have one source of truth. A :class:`Scene` carries the flattened,
self-contained MJCF text of the whole model and the robot file's text, so a log can embed
them and :func:`load_scene_from_text` can rebuild the scene without the original files.

World frame: origin at the robot's base on the table top (z = 0), x away from the robot, z up.
An object's pose is that of its bounding-box centre: ``(x, y, z, yaw)`` [m, m, m, rad].
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import mujoco

from smccli.errors import LogError, SceneError
from smccli.world.compiled import compile_mjcf
from smccli.world.criteria import GROUPS, RELATIONS, Condition, Group, SuccessCriterion
from smccli.world.objects import add_object
from smccli.world.robot import (
    DEFAULT_ROBOT,
    ROBOTS_DIR,
    Robot,
    check_robot,
    kinematics_digest,
    load_robot,
    resolve_robot_path,
    robot_from_text,
    robot_model_spec,
)
from smccli.world.robot_compose import asset_files, names_by_kind
from smccli.world.scene_file import (
    key_at,
    parse_declarations,
    read_scene_yaml,
    scene_from_file,
)
from smccli.world.specs import (
    HIDDEN_GROUP,
    ROBOT_KEY,
    SHAPES,
    CameraSpec,
    DoorSpec,
    FurnitureSpec,
    Layout,
    ObjectSpec,
    Scene,
    StartSpec,
)

__all__ = [
    "ASSET_PREFIX",
    "GROUPS",
    "HIDDEN_GROUP",
    "RELATIONS",
    "ROBOT_KEY",
    "SCENES_DIR",
    "SHAPES",
    "CameraSpec",
    "Condition",
    "DoorSpec",
    "FurnitureSpec",
    "Group",
    "Layout",
    "ObjectSpec",
    "Scene",
    "StartSpec",
    "SuccessCriterion",
    "builtin_names",
    "list_scenes",
    "load_scene",
    "load_scene_from_text",
    "robot_identity",
    "scene_of_log",
    "sensor_identity",
]
"""The scene's vocabulary (:mod:`smccli.world.specs`, :mod:`smccli.world.criteria`) is
importable from here too, where its users look for it."""

ASSET_PREFIX = "asset:"
"""A log attaches each file of :attr:`Scene.assets` as ``asset:<name>``."""
SCENES_DIR = Path(__file__).parent / "scenes"
"""The built-in scenes, one folder each (``scene.yaml``, ``scene.xml``)."""


def builtin_names() -> list[str]:
    """Names of the built-in scenes."""
    return sorted(p.parent.name for p in SCENES_DIR.glob("*/scene.yaml"))


def list_scenes() -> list[Scene]:
    """All built-in scenes."""
    return [load_scene(n) for n in builtin_names()]


def load_scene(name_or_path: str | Path) -> Scene:
    """A built-in scene by name, or a user scene by the path of its ``scene.yaml``."""
    text = str(name_or_path)
    if text in builtin_names():
        path = SCENES_DIR / text / "scene.yaml"
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise SceneError(
                f"{text}: no such scene (built-in scenes: {', '.join(builtin_names())}; "
                "or give the path of a scene.yaml)"
            )
    yaml_text = path.read_text()
    raw = read_scene_yaml(yaml_text, str(path))
    mjcf_file = path.parent / str(raw.get("mjcf", "scene.xml"))
    if not mjcf_file.is_file():
        raise SceneError(f"{path}: MJCF file {mjcf_file} not found")
    ref = raw.get("robot", DEFAULT_ROBOT)
    try:
        if isinstance(ref, str):
            try:
                robot_file = resolve_robot_path(ref, relative_to=path.parent)
            except SceneError as exc:
                raise SceneError(f"{key_at(yaml_text, str(path), ('robot',))}: {exc}") from None
            robot = load_robot(robot_file)
            spec = _with_robot(str(raw["name"]), robot, mjcf_file)
        else:  # a scene file from before robot files: its MJCF includes the built-in arm
            robot = load_robot(DEFAULT_ROBOT)
            spec = mujoco.MjSpec.from_file(str(mjcf_file))
    except ValueError as exc:
        raise SceneError(f"{mjcf_file}: invalid MJCF: {' '.join(str(exc).split())}") from exc
    scene = _build(raw, yaml_text, spec, str(path), robot)
    return _replace_path(scene, path)


def _with_robot(name: str, robot: Robot, mjcf_file: Path) -> mujoco.MjSpec:
    """The scene's spec holding the robot: its MJCF included first (its <option> and
    <compiler> apply, the scene's may refine them), then the scene's. A composed robot
    (:mod:`smccli.world.robot_compose`) is included as the self-contained MJCF it composes
    to, after a check that no name is both the robot's and the scene's."""
    head = f"<mujoco model={quoteattr(name)}>"
    scene_inc = f"<include file={quoteattr(str(mjcf_file.resolve()))}/></mujoco>"
    if robot.composition is None:
        return mujoco.MjSpec.from_string(
            f"{head}<include file={quoteattr(str(robot.mjcf_path))}/>{scene_inc}"
        )
    robot_spec = robot_model_spec(robot)
    _check_names(robot, robot_spec, mjcf_file)
    key = f"{robot.name}.robot.xml"
    return mujoco.MjSpec.from_string(
        f"{head}<include file={quoteattr(key)}/>{scene_inc}",
        include={key: robot_spec.to_xml().encode()},
    )


def _check_names(robot: Robot, robot_spec: mujoco.MjSpec, mjcf_file: Path) -> None:
    """SceneError naming both files for the first element name the robot and the scene
    share (MuJoCo's own message names neither)."""
    mjcf_file = Path(os.path.normpath(mjcf_file))
    theirs = names_by_kind(mujoco.MjSpec.from_file(str(mjcf_file)))
    mine = names_by_kind(robot_spec)
    for kind, names in mine.items():
        both = sorted(names & theirs.get(kind, set()))
        if both:
            comp = robot.composition
            files = [str(robot.path)]
            if comp is not None:
                files = [str(comp.arm)] + ([str(comp.gripper.mjcf)] if comp.gripper else [])
            raise SceneError(
                f"{mjcf_file}: {kind} {both[0]!r} is also a {kind} of robot {robot.name!r} "
                f"({' + '.join(files)}, robot file {robot.path}): rename the scene's"
            )


def load_scene_from_text(
    yaml_text: str,
    mjcf_text: str,
    robot_yaml: str | None = None,
    *,
    log: str | None = None,
    assets: Mapping[str, bytes] | None = None,
) -> Scene:
    """Rebuild a scene from the texts a log embeds (``Scene.yaml_text``, ``Scene.mjcf``,
    ``Robot.yaml_text``) and the files its MJCF names (``assets``, :attr:`Scene.assets`).
    A log from before robot files has no robot file: its scene holds the built-in robot
    its scene file names (the arm).

    ``log``: the log file the texts were attached to; errors are then LogError naming it
    and the attachment (``demo.mcap: attachment scene.yaml: ...``), else SceneError.
    """
    at_yaml = f"{log}: attachment scene.yaml" if log else "<embedded scene.yaml>"
    at_xml = f"{log}: attachment scene.xml" if log else "<embedded MJCF>"
    at_robot = f"{log}: attachment robot.yaml" if log else "<embedded robot.yaml>"
    try:
        raw = read_scene_yaml(yaml_text, at_yaml)
        try:
            model = compile_mjcf(mjcf_text, assets)
        except ValueError as exc:
            raise SceneError(
                f"{at_xml}: MuJoCo rejects the MJCF ({' '.join(str(exc).split())})"
            ) from exc
        if robot_yaml is None:
            ref = raw.get("robot", DEFAULT_ROBOT)
            name = ref if isinstance(ref, str) else DEFAULT_ROBOT
            if not (ROBOTS_DIR / name / "robot.yaml").is_file():
                raise SceneError(f"{at_robot} missing (the scene names robot {name!r})")
            robot_yaml = (ROBOTS_DIR / name / "robot.yaml").read_text()
        robot, doc = robot_from_text(robot_yaml, at_robot)
        check_robot(robot, model, doc, "attachment scene.xml", SceneError)
        scene = scene_from_file(raw, yaml_text, mjcf_text, at_yaml, robot, model)
        return replace(scene, assets=tuple(sorted((assets or {}).items())))
    except SceneError as exc:
        if log is None:
            raise
        raise LogError(str(exc)) from exc


def scene_of_log(attachments: Mapping[str, bytes], log: str | Path) -> Scene:
    """The scene a log's attachments hold (``scene.yaml``, ``scene.xml``, ``robot.yaml``);
    LogError naming the log and the attachment when one is missing or wrong."""
    texts: dict[str, str | None] = {}
    what = {"scene.xml": "the scene's MJCF", "scene.yaml": "the scene file"}
    for name in ("scene.xml", "scene.yaml", "robot.yaml"):
        data = attachments.get(name)
        if data is None:
            if name in what:  # robot.yaml: older logs have none, their robot is the arm
                raise LogError(f"{log}: attachment {name} missing ({what[name]})")
            texts[name] = None
            continue
        try:
            texts[name] = data.decode() if isinstance(data, bytes) else str(data)
        except UnicodeDecodeError as exc:
            raise LogError(f"{log}: attachment {name}: not UTF-8 text ({exc})") from None
    return load_scene_from_text(
        texts["scene.yaml"] or "",
        texts["scene.xml"] or "",
        texts["robot.yaml"],
        log=str(log),
        assets={
            name.removeprefix(ASSET_PREFIX): bytes(data)
            for name, data in attachments.items()
            if name.startswith(ASSET_PREFIX)
        },
    )


def robot_identity(scene: Scene, model: mujoco.MjModel | None = None) -> dict[str, str]:
    """What a tree records of the robot it was taught on: name and kinematics digest."""
    model = model or scene.model()
    return {"name": scene.robot.name, "kinematics": kinematics_digest(scene.robot, model)}


def sensor_identity(scene: Scene, model: mujoco.MjModel | None = None) -> dict[str, Any]:
    """What a tree records of the sensors it perceives through: the camera's resolution and
    vertical field of view [deg], and whether the scene has a scale."""
    model = model or scene.model()
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, scene.camera.name)
    return {
        "camera": {
            "width": scene.camera.width,
            "height": scene.camera.height,
            "fovy": round(float(model.cam_fovy[cam]), 6),
        },
        "scale": scene.scale is not None,
    }


def _build(
    raw: Mapping[str, Any], yaml_text: str, spec: mujoco.MjSpec, where: str, robot: Robot
) -> Scene:
    objects, camera, scale, success = parse_declarations(raw, where, yaml_text)
    for obj in objects:
        add_object(spec, obj)
    try:
        spec.compile()
    except ValueError as exc:
        raise SceneError(f"{where}: model does not compile: {exc}") from exc
    mjcf = spec.to_xml()
    assets = asset_files(spec) if robot.composition is not None else {}
    model = compile_mjcf(mjcf, assets)
    scene = scene_from_file(raw, yaml_text, mjcf, where, robot, model)
    return replace(scene, assets=tuple(sorted(assets.items())))


def _replace_path(scene: Scene, path: Path) -> Scene:
    return replace(scene, yaml_path=path)
