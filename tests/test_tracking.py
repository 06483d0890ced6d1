"""Looking again without perceiving again (smccli.execute.tracking): the object is still
where it was unless its own pixels say otherwise."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from smccli.execute import executor as executor_module  # noqa: E402
from smccli.execute.episode import episode, layout_for, resolve  # noqa: E402
from smccli.execute.sensing import Sensors  # noqa: E402
from smccli.execute.tracking import still_there, track_of  # noqa: E402
from smccli.perception import PerceptionParams, clusters_from_frame  # noqa: E402
from smccli.perception.reach import workspace_box  # noqa: E402
from smccli.world.scene import load_scene  # noqa: E402
from smccli.world.sensors import PoiCommand  # noqa: E402
from smccli.world.sim import Sim  # noqa: E402
from smccli.world.truth import Push, Truth  # noqa: E402


def test_the_arm_in_front_is_not_a_move_a_push_of_a_centimetre_is():
    scene = load_scene("bench_pick")
    sim = Sim(scene)
    try:
        sensors = Sensors(sim)
        assert sensors.camera_windows  # ideal camera: a window is read alone
        lo, hi = workspace_box(scene)
        params = replace(PerceptionParams(), crop_min=lo, crop_max=hi)
        whole = sensors.render_camera()
        seen = min(
            clusters_from_frame(whole, sensors.robot_geometry(), params),
            key=lambda c: np.hypot(*(c.centroid[:2] - np.array([0.45, -0.05]))),
        )
        near = sensors.camera_view()[3]
        track = track_of(seen, whole, near, params)
        assert track is not None
        v0, v1, u0, u1 = track.region
        assert (v1 - v0) * (u1 - u0) < 0.1 * whole.depth.size  # the object's surroundings

        def look() -> tuple[bool, int]:
            frame = sensors.render_camera(track.region, colour=False)
            assert not frame.rgb.any()  # the depth pass alone
            changed = np.abs(frame.depth[v0:v1, u0:u1] - track.depth) > track.tolerance
            return still_there(track, frame, sensors.robot_geometry(), params), int(changed.sum())

        assert look() == (True, 0)  # nothing moved (a window against the whole frame)
        # The hand comes down over the box and hides part of it: still there.
        above = np.r_[seen.centroid[:2], seen.centroid[2] + 0.12, 0.0]
        for _ in range(300):
            sensors.step(PoiCommand(sensors.t, above, 1.0))
        there, changed = look()
        assert changed > 20 and there
        Truth(sim).push_object("white_box", 0.01, 0.0)
        assert look()[0] is False
        # A partly hidden view is no reference: a look must see it whole first.
        hidden = replace(seen, hidden=params.hidden_min_points)
        assert track_of(hidden, whole, near, params) is None
    finally:
        sim.close()


def test_an_undisturbed_episode_perceives_only_at_its_decisions(sample_trees, monkeypatch):
    """Looks that find the object where it was spare perception; a push does not."""
    tree, scene = resolve(sample_trees["bench_pick"], None)
    calls = []
    perceive = executor_module.look

    def counted(*args, **kwargs):
        calls.append(1)
        return perceive(*args, **kwargs)

    monkeypatch.setattr(executor_module, "look", counted)
    quiet = episode(tree, scene, layout_for(scene, 0, 0), look_period=0.5)
    assert quiet.success and calls == []
    pushed = episode(
        tree,
        scene,
        layout_for(scene, 0, 0),
        push=Push("white_box", 1.0, 0.04, 0.0),
        look_period=0.5,
    )
    assert pushed.success and len(calls) >= 1
