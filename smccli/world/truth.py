"""What only evaluation and the episode harness may read of a simulation: the truth.

:class:`Truth` answers from the simulator's state what no sensor gives: object poses and
speeds, a mobile base's true pose, what the robot touches, a door's opening, and whether
the scene's success criterion holds (:meth:`Truth.success`). It also holds the harness's
one hand in the world: :meth:`Truth.push_object`, a disturbance for benchmarks.

The honesty rule (docs/design.md section 2) is an import rule here: no control module
(the executor, the policy, the sensing facade, perception, what compile learnt) imports
this module (``tests/test_layout.py``); control reaches the simulator only through
:class:`smccli.execute.sensing.Sensors`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import mujoco
import numpy as np

from smccli.errors import SceneError
from smccli.world.geometry import wrap, yaw_of
from smccli.world.robot import robot_geoms
from smccli.world.scene import Condition, Group, ObjectSpec
from smccli.world.sim import Sim, model_id

ON_TOP_TOL = 0.015
"""How far an object's lowest corner may be from the target's top face to rest on it [m]."""
INSIDE_TOL = 0.005
"""How far below the container's bottom an object's lowest corner may be [m] (contact
penetration)."""
REST_SPEED = (0.02, 0.2)
"""At rest: linear [m/s] and angular [rad/s] speed below these."""


@dataclass(frozen=True, slots=True)
class Success:
    """Outcome of the scene's success criterion; truthy when the task succeeded."""

    ok: bool
    """Whether a task's criterion holds."""
    reason: str
    """Which task and condition held, or why none did."""
    criteria: tuple[tuple[str, str, bool], ...] = ()
    """Every condition tried: (task, what it found, whether it held)."""

    def __bool__(self) -> bool:
        return self.ok


@dataclass(frozen=True, slots=True)
class Push:
    """Someone moves an object while the robot works (:meth:`Truth.push_object`): a
    disturbance for benchmarks and tests, never seen by control but through the camera."""

    object: str
    """The free object moved."""
    at: float
    """Simulation time of the push [s]."""
    dx: float
    """Displacement along world x [m]."""
    dy: float
    """Displacement along world y [m]."""


class Truth:
    """The truth of ``sim`` as it is now: each query reads its current state (cheap to
    build; one per episode or per check)."""

    def __init__(self, sim: Sim) -> None:
        self.sim = sim
        self.scene = sim.scene
        self.model, self.data = sim.model, sim.data

    @cached_property
    def _robot_geoms(self) -> np.ndarray:
        """Ids of the robot's own geoms (:func:`smccli.world.robot.robot_geoms`)."""
        return robot_geoms(self.sim.robot, self.model)

    def _id(self, kind: mujoco.mjtObj, name: str) -> int:
        return model_id(self.model, kind, name, self.scene.name)

    # --- poses and contacts ----------------------------------------------------------------

    def ground_truth(self) -> dict[str, np.ndarray]:
        """Object and furniture poses ``[x, y, z, qw, qx, qy, qz]`` (never for perception)."""
        d = self.data
        return {n: np.concatenate([d.xpos[b], d.xquat[b]]) for n, b in self.sim.bodies.items()}

    def object_pose(self, name: str) -> np.ndarray:
        """Object ``[x, y, z, yaw]`` (for the simulated operator and evaluation); also any
        body of the MJCF by name (a handle on a moving door)."""
        b = self.sim.bodies.get(name)
        if b is None:
            b = self._id(mujoco.mjtObj.mjOBJ_BODY, name)
        return np.array([*self.data.xpos[b], yaw_of(self.data.xmat[b])])

    def has_body(self, name: str) -> bool:
        """Whether the scene's MJCF has a body ``name`` (a door's handle, for the operator)."""
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name) >= 0

    def object_speed(self, name: str) -> float:
        """Linear speed of an object's body [m/s]."""
        if name not in self.sim.free_joints:
            return 0.0
        _, va = self.sim.free_joints[name]
        return float(np.linalg.norm(self.data.qvel[va : va + 3]))

    def base_pose(self) -> np.ndarray:
        """The mobile base's true pose ``[x, y, yaw]`` (control reads
        :meth:`Sim.poi`, odometry)."""
        q = self.data.qpos[self.sim.base_qpos]
        return np.array([q[0], q[1], wrap(float(q[2]))])

    def robot_contacts(self) -> list[str]:
        """Names of what the robot's collision geoms touch now, floor excluded (a mobile
        base's collisions; a mobile manipulator's hand is left out)."""
        m, d, robot = self.model, self.data, self.sim.robot
        if d.ncon == 0:  # a base in free space, most periods: the sets below cost 1.5 us
            return []
        mine = set(self._robot_geoms)
        if self.sim.mobile_manipulator:
            # Its hand is meant to touch: the fingers and the body they ride on (the palm)
            # grasp handles and objects; the base and the arm's links must touch nothing.
            fingers = robot.gripper.joints if robot.gripper else ()
            hand = {int(m.jnt_bodyid[m.joint(j).id]) for j in fingers}
            hand |= {int(m.body_parentid[b]) for b in hand}
            mine = {g for g in mine if int(m.geom_bodyid[g]) not in hand}
        out = []
        for i in range(d.ncon):
            c = d.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            if (g1 in mine) == (g2 in mine):
                continue
            other = g2 if g1 in mine else g1
            if m.geom_type[other] == mujoco.mjtGeom.mjGEOM_PLANE:
                continue
            out.append(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, other) or f"geom {other}")
        return out

    def door_opening(self, joint: str) -> float:
        """A door's joint value now [m or rad]."""
        return float(
            self.data.qpos[self.model.jnt_qposadr[self._id(mujoco.mjtObj.mjOBJ_JOINT, joint)]]
        )

    def fingers_on(self, geom: str) -> int:
        """How many finger bodies touch ``geom`` now (a handle held)."""
        m, d, robot = self.model, self.data, self.sim.robot
        g = self._id(mujoco.mjtObj.mjOBJ_GEOM, geom)
        fingers = robot.gripper.joints if robot.gripper else ()
        bodies = {int(m.jnt_bodyid[m.joint(j).id]) for j in fingers}
        touching = set()
        for i in range(d.ncon):
            c = d.contact[i]
            for a, b in ((c.geom1, c.geom2), (c.geom2, c.geom1)):
                if a == g and int(m.geom_bodyid[b]) in bodies:
                    touching.add(int(m.geom_bodyid[b]))
        return len(touching)

    # --- the disturbance -------------------------------------------------------------------

    def push_object(self, name: str, dx: float, dy: float) -> None:
        """Move a free object by ``dx``, ``dy`` [m] on the table and stop it: someone pushed
        it (a disturbance for benchmarks; control learns of it only through the camera)."""
        if name not in self.sim.free_joints:
            raise ValueError(f"push_object: {name!r} is not a free object of the scene")
        qa, va = self.sim.free_joints[name]
        self.data.qpos[qa : qa + 2] += (dx, dy)
        self.data.qvel[va : va + 6] = 0.0
        mujoco.mj_forward(self.model, self.data)

    # --- the success criterion -------------------------------------------------------------

    def success(self, task: str | None = None) -> Success:
        """The scene's success criterion for ``task`` (default: any task succeeds)."""
        scene = self.scene
        crits = [c for c in scene.success if task is None or c.task == task]
        if task is None:  # only the criteria of the variant on show
            crits = [c for c in crits if c.variant is None or self.shows(c.variant)]
            if not crits:
                return Success(False, "no task's criterion applies to this layout")
        if not crits:
            valid = ", ".join(c.task for c in scene.success)
            raise SceneError(f"scene {scene.name}: no task {task!r} (tasks: {valid})")
        reasons, details = [], []
        for crit in crits:
            ok, results = self._holds_group(crit.rule)
            details += [(crit.task, text, held) for text, held, _ in results]
            if ok:
                # What made it hold: every all_of condition, the first any_of one that held.
                shown = _explain(results, True)
                return Success(True, f"{crit.task}: {'; '.join(shown)}", tuple(details))
            reasons.append(f"{crit.task}: " + "; ".join(_explain(results, False)))
        return Success(False, " | ".join(reasons), tuple(details))

    def shows(self, variant: str) -> bool:
        """Whether the layout shows every object of ``variant``."""
        return set(dict(self.scene.variants)[variant]) <= set(self.sim.present)

    def _holds_group(self, group: Group) -> tuple[bool, list[tuple[str, bool, str]]]:
        """Whether ``group`` holds, and each of its conditions' (text, held, the kind of
        the group right above it), in file order."""
        oks, results = [], []
        for item in group.items:
            if isinstance(item, Group):
                ok, inner = self._holds_group(item)
            else:
                held, text = self.holds(item)
                ok = bool(held)  # numpy's bool from a comparison is no JSON boolean
                inner = [(text, ok, group.kind)]
            oks.append(ok)
            results += inner
        if group.kind == "all_of":
            return all(oks), results
        if group.kind == "any_of":
            return any(oks), results
        return not any(oks), results

    def holds(self, cond: Condition) -> tuple[bool, str]:
        """Whether ``cond`` holds now: the object rests on top of / inside the target, or
        the base stands at the place."""
        if cond.relation == "at":
            return self._base_at(cond)
        obj, tgt = self.scene.object(cond.object), self.scene.object(cond.target)
        po, pt = self.object_pose(obj.name), self.object_pose(tgt.name)
        # The object's corners (its geoms' bounding boxes) in the target's yawed frame,
        # relative to the target's centre.
        c, s = math.cos(pt[3]), math.sin(pt[3])
        R_t = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        corners = (self._corners(obj.name) - pt[:3]) @ R_t
        t_top, t_bottom = tgt.size[2] / 2, -tgt.size[2] / 2
        still, touching = self._at_rest(obj.name), self._touching(obj.name)
        others = sorted(touching - {tgt.name})
        if cond.relation == "on_top_of":
            # Resting on the top face: the centre over the face, the bottom on it, and held
            # by the target alone (a box hanging over an edge also touches the table). Not
            # the whole footprint: pick_place's cube (diagonal 7.07 cm) overhangs the
            # 7 cm cylinder by a hair when perfectly centred (docs/choices.md).
            lx, ly = (po[:3] - pt[:3]) @ R_t[:, :2]
            over = _in_footprint(tgt, lx, ly, margin=0.0)
            seated = abs(corners[:, 2].min() - t_top) < ON_TOP_TOL
            ok = over and seated and still and touching == {tgt.name}
            why = f"{obj.name} {'on' if ok else 'not resting on'} {tgt.name}"
        else:  # inside: every corner within the inner walls, above the floor
            inner = tgt.wall if tgt.shape == "open_box" else 0.0
            within = all(_in_footprint(tgt, x, y, margin=inner) for x, y in corners[:, :2])
            above = corners[:, 2].min() > t_bottom - INSIDE_TOL
            ok = (
                within
                and above
                and corners[:, 2].min() < t_top
                and still
                and not (touching - {tgt.name})
            )
            why = f"{obj.name} {'inside' if ok else 'not resting inside'} {tgt.name}"
        if not ok:
            detail = [] if still else ["moving"]
            if others:
                detail.append(f"touching {', '.join(others)}")
            if detail:
                why += f" ({'; '.join(detail)})"
        return ok, why

    def _base_at(self, cond: Condition) -> tuple[bool, str]:
        """Whether the base stands at the place ``cond.target`` within its tolerance."""
        gx, gy, gyaw = self.scene.place(cond.target)
        x, y, yaw = self.base_pose()
        dist, dyaw = math.hypot(x - gx, y - gy), abs(wrap(float(yaw - gyaw)))
        ok = dist <= cond.tolerance[0] and dyaw <= cond.tolerance[1]
        return ok, (
            f"base {'at' if ok else 'not at'} {cond.target} ({dist * 100:.1f} cm, "
            f"{math.degrees(dyaw):.1f} deg off)"
        )

    def _corners(self, name: str) -> np.ndarray:
        """World corners of the bounding boxes of a body's geoms, shape (8 * geoms, 3) [m]."""
        m, d = self.model, self.data
        b = self.sim.bodies[name]
        signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
        out = []
        for g in np.flatnonzero(m.geom_bodyid == b):
            centre, half = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
            local = centre + signs * half
            out.append(d.geom_xpos[g] + local @ d.geom_xmat[g].reshape(3, 3).T)
        return np.concatenate(out)

    def _at_rest(self, name: str) -> bool:
        """Linear and angular speed under :data:`REST_SPEED` (free objects; fixed: True)."""
        if name not in self.sim.free_joints:
            return True
        _, va = self.sim.free_joints[name]
        v = self.data.qvel[va : va + 6]
        return bool(np.linalg.norm(v[:3]) < REST_SPEED[0] and np.linalg.norm(v[3:]) < REST_SPEED[1])

    def _touching(self, name: str) -> set[str]:
        """Names of what touches the object: scene objects and furniture (a body inside
        one, like a scale's platform, counts as it), the robot, else the body's name
        (the table, the floor)."""
        m, d, bodies = self.model, self.data, self.sim.bodies
        b = bodies[name]
        robot = {int(m.geom_bodyid[g]) for g in self._robot_geoms}
        owner = {v: k for k, v in bodies.items()}
        out = set()
        for i in range(d.ncon):
            con = d.contact[i]
            b1, b2 = int(m.geom_bodyid[con.geom1]), int(m.geom_bodyid[con.geom2])
            if b not in (b1, b2):
                continue
            other = b2 if b1 == b else b1
            if other in robot:
                out.add("robot")
                continue
            while other not in owner and m.body_parentid[other] != 0:
                other = int(m.body_parentid[other])
            out.add(
                owner.get(other) or mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, other) or "world"
            )
        return out


def _in_footprint(tgt: ObjectSpec, lx: float, ly: float, margin: float) -> bool:
    if tgt.shape == "cylinder":
        return math.hypot(lx, ly) < tgt.size[0] / 2 - margin
    return abs(lx) < tgt.size[0] / 2 - margin and abs(ly) < tgt.size[1] / 2 - margin


def _explain(results: list[tuple[str, bool, str]], ok: bool) -> list[str]:
    """The conditions that say why a criterion held (``ok``: every one under an all_of,
    the first that held under an any_of) or failed (a none_of condition that held; else
    every one that did not)."""
    if ok:
        shown = [t for t, held, kind in results if held and kind == "all_of"]
        first = next((t for t, held, kind in results if held and kind == "any_of"), None)
        return shown + ([first] if first else [])
    bad = [t for t, held, kind in results if held and kind == "none_of"]
    if bad:
        return bad
    return [t for t, held, kind in results if kind != "none_of" and not held] or [
        t for t, _, _ in results
    ]
