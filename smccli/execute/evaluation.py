"""Scoring a replay episode once control is over: the outcome and why it failed.

It reads the simulator's truth (object poses, the scene's success criterion) through
:class:`smccli.world.truth.Truth`; the executor (:mod:`smccli.execute.executor`) and the
sensors it sees (:mod:`smccli.execute.sensing`) import neither (``tests/test_layout.py``),
so control cannot read ground truth.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from smccli.execute.executor import CONTROL_OUTCOMES, ActionTrace
from smccli.world.scene import ROBOT_KEY, DoorSpec, Layout, Scene
from smccli.world.sensors import PoiCommand
from smccli.world.sim import Sim
from smccli.world.truth import Truth

OUTCOMES = (
    *CONTROL_OUTCOMES,
    "grasp_missed",
    "object_dropped",
    "placed_outside",
    "task_incomplete",
    "collision",
    "wrong_room",
    "goal_missed",
    "handle_slipped",
    "door_not_opened",
)
"""Episode outcomes: success, the three control stops, then the failure causes found at
evaluation time from the trace and the final state (an arm's: grasp_missed,
object_dropped, placed_outside, task_incomplete; a mobile base's: collision, wrong_room,
goal_missed; a mobile manipulator's, before its object's: handle_slipped,
door_not_opened)."""

SLIP_TIME = 0.2
"""A handle held by both fingers, lost for this long while the hand stays closed, slipped [s]."""


class HandleWatch:
    """Evaluation's watch beside control (simulator truth): a door's handle that both
    fingers held and that then leaves the closed hand has slipped."""

    def __init__(self, doors: Sequence[DoorSpec]) -> None:
        self.doors = tuple(doors)
        self._held: dict[str, float | None] = {d.name: None for d in self.doors}
        """Door -> since when the handle is lost while held (None: held or not held)."""
        self._holding: dict[str, bool] = {d.name: False for d in self.doors}
        self.slipped: list[str] = []
        """``<door> at t=... s`` for each slip."""

    def holding(self, door: str) -> bool:
        """Both fingers hold ``door``'s handle (or lost it less than SLIP_TIME ago)."""
        return self._holding[door]

    def watch(self, truth: Truth, cmd: PoiCommand) -> None:
        """One control period: ``cmd`` was sent, the simulator of ``truth`` stepped."""
        closed = cmd.gripper < 0.5
        for d in self.doors:
            on = truth.fingers_on(d.handle)
            if not closed:  # let go on purpose
                self._holding[d.name], self._held[d.name] = False, None
            elif on >= 2:
                self._holding[d.name], self._held[d.name] = True, None
            elif self._holding[d.name]:
                since = self._held[d.name]
                if since is None:
                    self._held[d.name] = truth.sim.t
                elif truth.sim.t - since >= SLIP_TIME:
                    self.slipped.append(f"{d.name} at t={since:.1f} s")
                    self._holding[d.name], self._held[d.name] = False, None


EMPTY_GRIP = 0.08
"""A closed gripper whose opening is below this holds nothing [fraction of full opening]."""


@dataclass(frozen=True, slots=True)
class Verdict:
    """The evaluation of one episode."""

    outcome: str
    """One of :data:`OUTCOMES`."""
    success: bool
    """The scene's success criterion at the end."""
    reason: str
    """Why: the success criterion's text, or what stopped control."""
    manipulated: str | None
    """The object the task moves (:func:`manipulated_object`)."""
    final_poses: dict[str, list[float]]
    """Object [x, y, z, yaw] at the end [m, rad]."""
    criteria: tuple[tuple[str, str, bool], ...] = ()
    """Every success condition tried at a leaf: (task, what it found, whether it held)."""


def score(
    sim: Sim,
    scene: Scene,
    layout: Layout,
    *,
    outcome: str,
    reason: str,
    actions: Sequence[ActionTrace],
    collisions: Sequence[str] = (),
    slips: Sequence[str] = (),
) -> Verdict:
    """Score an episode whose control ended with ``outcome`` (:data:`CONTROL_OUTCOMES`):
    read the final object poses and, when a leaf was reached, the scene's success criterion;
    a leaf without success gets its failure cause (:func:`classify_failure`,
    :func:`classify_base_failure`). ``collisions``: what a mobile base touched during the
    episode (the floor aside); a base that touched anything failed, wherever it ended.
    A failed episode of a scene with doors: ``handle_slipped`` when a handle left the
    closed hand (``slips``, :class:`HandleWatch`), else ``door_not_opened`` when a leaf
    was reached with a door shut; a slip comes first (it explains a later stop), a shut
    door before the object's cause (a control stop and a collision say more)."""
    truth = Truth(sim)
    final = {o.name: [float(v) for v in truth.object_pose(o.name)] for o in scene.objects}
    if scene.robot.base is not None:
        x, y, yaw = truth.base_pose()
        final[ROBOT_KEY] = [float(x), float(y), 0.0, float(yaw)]
    obj = manipulated_object(scene, layout, final)
    ok = False
    criteria: tuple[tuple[str, str, bool], ...] = ()
    if outcome == "success":
        criterion = truth.success()
        criteria = criterion.criteria
        ok = bool(criterion)
        reason = criterion.reason
        if collisions:
            ok, outcome = False, "collision"
            reason = f"the base touched {', '.join(sorted(set(collisions)))}; {reason}"
        elif not ok and scene.robot.base is not None and not scene.robot.arm_joints:
            outcome = classify_base_failure(scene, truth, final[ROBOT_KEY])
        elif not ok:
            outcome = incomplete_task(scene, truth, layout, final) or classify_failure(
                scene, layout, final, actions, obj
            )
    if not ok and scene.doors:
        # The first cause: a slipped handle leaves its door shut and the base runs into it.
        closed = [d.name for d in scene.doors if truth.door_opening(d.joint) < d.open]
        if slips:
            outcome, reason = "handle_slipped", f"handle slipped: {'; '.join(slips)}; {reason}"
        elif closed and outcome not in ("collision", *CONTROL_OUTCOMES[1:]):
            outcome, reason = "door_not_opened", f"{', '.join(closed)} closed; {reason}"
    return Verdict(outcome, ok, reason, obj, final, criteria)


def manipulated_object(scene: Scene, layout: Layout, final: dict[str, list[float]]) -> str | None:
    """The object the task moves: of the success criteria's objects, the one that moved
    most (the first one when none moved)."""
    names = [c.object for crit in scene.success for c in crit.conditions() if c.object in layout]
    if not names:
        return None
    moved = [
        (math.dist(layout[n][:2], final[n][:2]) if n in final else 0.0, -i, n)
        for i, n in enumerate(names)
    ]
    best = max(moved)
    return best[2] if best[0] > 0.02 else names[0]


def classify_base_failure(scene: Scene, truth: Truth, final: Sequence[float]) -> str:
    """Why a mobile base that reached a leaf missed its goal: ``wrong_room`` when it ended
    in another region (room) than the goal place of the task on show, else ``goal_missed``."""
    goals = [
        scene.place(c.target)
        for crit in scene.success
        if crit.variant is None or truth.shows(crit.variant)
        for c in crit.conditions()
        if c.relation == "at"
    ]
    here = scene.region_of(final[0], final[1])
    if goals and all(scene.region_of(g[0], g[1]) != here for g in goals):
        return "wrong_room"
    return "goal_missed"


def incomplete_task(
    scene: Scene, truth: Truth, layout: Layout, final: dict[str, list[float]]
) -> str | None:
    """``task_incomplete`` when the tree reached its leaf with part of the task done: some
    of a criterion's conditions hold and the objects of those that do not never moved
    (under 2 cm), i.e. the tree was taught less than the task (half of a two-object task
    scored with ``all_of``), not an action that went wrong; else None."""
    for crit in scene.success:
        if crit.variant is not None and not truth.shows(crit.variant):
            continue
        conds = [c for c in crit.conditions() if c.relation != "at" and c.object in layout]
        held = [bool(truth.holds(c)[0]) for c in conds]
        left = [c.object for c, h in zip(conds, held, strict=True) if not h]
        if (
            any(held)
            and left
            and all(math.dist(layout[o][:2], final[o][:2]) < UNMOVED for o in left)
        ):
            return "task_incomplete"
    return None


UNMOVED = 0.02
"""An object that ends nearer its start than this [m] was not moved (its grasp missed, or
nothing went for it)."""


def classify_failure(
    scene: Scene,
    layout: Layout,
    final: dict[str, list[float]],
    actions: Sequence[ActionTrace],
    obj: str | None,
) -> str:
    """Why an episode that reached a leaf failed: grasp_missed, object_dropped, placed_outside.

    From the trace (gripper openings after close events, before open events) and the final
    poses: fingers closed on nothing or the object never left its place -> grasp_missed;
    fingers closed on nothing later, or the object ended far from any target ->
    object_dropped; else placed_outside.
    """
    closes = [a for a in actions if a.event == "close"]
    if any(a.opening_after < EMPTY_GRIP for a in closes[:1]):
        return "grasp_missed"
    if obj is None:
        return "placed_outside"
    if math.dist(layout[obj][:2], final[obj][:2]) < UNMOVED:
        return "grasp_missed"
    opens = [a for a in actions if a.event == "open"]
    if any(a.opening_before < EMPTY_GRIP for a in opens):
        return "object_dropped"
    targets = [c.target for crit in scene.success for c in crit.conditions() if c.object == obj]
    near = min(
        (
            math.dist(final[obj][:2], final[t][:2]) - scene.object(t).footprint_radius
            for t in targets
            if t in final
        ),
        default=0.0,
    )
    return "object_dropped" if near > 0.05 else "placed_outside"
