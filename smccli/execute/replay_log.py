"""The replay log: an MCAP log of an episode that opens like a recording.

It holds the recorder's topics (camera, joints, POI, commands, scale, and the
``/sim/ground_truth`` evaluation topic, which control never reads) plus, at each decision
point of Algorithm 2, ``/smc/decision`` and the object points the decision saw
(``/perception/points``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from smccli import __version__
from smccli.execute.executor import Decision
from smccli.learn.tree import Tree, digest
from smccli.logs import LogWriter
from smccli.logs.writer import scene_attachments
from smccli.perception.cloud import object_points
from smccli.world.scene import Layout, Scene
from smccli.world.sensors import CameraFrame, PoiCommand
from smccli.world.sim import Sim
from smccli.world.truth import Truth


class ReplayLog:
    """Writes the recorder's topics plus /smc/decision and /perception/points."""

    def __init__(
        self, path: Path, scene: Scene, sim: Sim, tree: Tree, seed: int, layout: Layout, force: bool
    ) -> None:
        meta = {
            "scene": scene.name,
            "scene_digest": scene.digest,
            "smc_version": __version__,
            "seed": str(seed),
            "operator": "replay",
            "control_rate_hz": "100",
            "state_rate_hz": "100",
            "camera_rate_hz": f"{scene.camera.rate:g}",
            "has_scale": "true" if scene.scale else "false",
            "tree_digest": digest(tree),
            "layout": json.dumps(layout),
        }
        self.writer = LogWriter(
            path, metadata=meta, attachments=scene_attachments(scene), force=force
        )
        self.sim = sim
        self.truth = Truth(sim)
        """For the evaluation topic alone."""
        self.scene = scene
        self.params = tree.params
        self.cam_period = 1.0 / scene.camera.rate
        self.gt_period = 0.1
        self.next_cam = self.next_gt = sim.t
        self._state()

    def _state(self) -> None:
        sim, w = self.sim, self.writer
        t = sim.t
        if t >= self.next_cam - 1e-9:
            w.write_camera(sim.render_camera())
            w.write_lidar(sim)  # on the camera's clock, as when recording
            self.next_cam += self.cam_period
        if t >= self.next_gt - 1e-9:
            # The evaluation topic: no control module reads it.
            w.write_ground_truth(t, self.truth.ground_truth())
            self.next_gt += self.gt_period
        w.write_joint_state(sim.joint_state())
        w.write_robot_pose(sim)
        kg = sim.weight()
        if kg is not None:
            w.write_weight(t, kg)

    def on_step(self, cmd: PoiCommand) -> None:
        self.writer.write_command(cmd)
        self._state()

    def on_decision(self, dec: Decision, frame: CameraFrame, _start: np.ndarray) -> None:
        if self.sim.lidar_pose() is None:  # an arm's decision: the objects it saw
            base = self.sim.base_odometry() if self.sim.mobile_manipulator else None
            pts, cols, _ = object_points(
                frame, self.sim.robot_geometry(), self.params.perception, base
            )
            self.writer.write_point_cloud(dec.t, pts, cols)
        else:  # a base's: the scan it matched
            self.writer.write_lidar(self.sim)
        self.writer.write_json("/smc/decision", dec.t, dec.to_json())

    def close(self) -> None:
        self.writer.close()

    def abort(self) -> None:
        self.writer.abort()
