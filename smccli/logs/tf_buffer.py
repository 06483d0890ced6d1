"""ROS transforms (``/tf``, ``/tf_static``) over time: a frame's pose in the world frame
at a time is the chain of the latest transforms up to it."""

from __future__ import annotations

import bisect
from typing import Any

import numpy as np

from smccli.world.geometry import quat_matrix

TF_TOPICS = ("/tf", "/tf_static")


class TfBuffer:
    """Transforms parent -> child over time (``/tf``) and static (``/tf_static``); a frame's
    pose in the world frame at a time is the chain of the latest transforms up to it."""

    def __init__(self, world: str) -> None:
        self.world = world
        self._dynamic: dict[str, tuple[list[int], list[tuple[str, np.ndarray]]]] = {}
        self._static: dict[str, tuple[str, np.ndarray]] = {}

    def add(self, msg: Any, static: bool) -> None:
        for tr in msg.transforms:
            t, r = tr.transform.translation, tr.transform.rotation
            T = np.eye(4)
            T[:3, :3] = quat_matrix([r.w, r.x, r.y, r.z])
            T[:3, 3] = [t.x, t.y, t.z]
            parent = tr.header.frame_id.lstrip("/")
            child = tr.child_frame_id.lstrip("/")
            if static:
                self._static[child] = (parent, T)
            else:
                times, values = self._dynamic.setdefault(child, ([], []))
                times.append(stamp_ns(tr.header.stamp))
                values.append((parent, T))

    def chain_times(self, frame: str) -> list[int]:
        """Every stamp [ns] at which a link between ``frame`` and the world frame moved."""
        times: set[int] = set()
        frame = frame.lstrip("/")
        for _ in range(32):
            if frame == self.world:
                break
            if frame in self._static:
                frame = self._static[frame][0]
            elif frame in self._dynamic:
                stamps, values = self._dynamic[frame]
                times.update(stamps)
                frame = values[-1][0]
            else:
                break
        return sorted(times)

    def freshness(self, frame: str) -> tuple[bool, int | None]:
        """Whether ``frame`` reaches the world frame, and the stamp [ns] of the stalest
        moving link's newest transform on the way (None: static links only): a chain is
        only as fresh as its stalest moving link."""
        oldest: int | None = None
        frame = frame.lstrip("/")
        for _ in range(32):
            if frame == self.world:
                return True, oldest
            if frame in self._static:
                frame = self._static[frame][0]
            elif frame in self._dynamic:
                stamps, values = self._dynamic[frame]
                oldest = stamps[-1] if oldest is None else min(oldest, stamps[-1])
                frame = values[-1][0]
            else:
                return False, oldest
        return False, oldest

    def prune(self, keep: int) -> None:
        """Keep only each moving link's last ``keep`` transforms (a live robot's buffer
        would grow without end)."""
        for times, values in self._dynamic.values():
            if len(times) > 2 * keep:
                del times[:-keep], values[:-keep]

    def lookup(self, frame: str, t_ns: int) -> np.ndarray | None:
        """T_world_frame at ``t_ns`` (the latest transform of each link at or before it, else
        the first one), or None when the chain does not reach the world frame."""
        T = np.eye(4)
        frame = frame.lstrip("/")
        for _ in range(32):
            if frame == self.world:
                return T
            if frame in self._static:
                parent, link = self._static[frame]
            elif frame in self._dynamic:
                times, values = self._dynamic[frame]
                i = max(bisect.bisect_right(times, t_ns) - 1, 0)
                parent, link = values[i]
            else:
                return None
            T = link @ T
            frame = parent
        return None


def stamp_ns(stamp: Any) -> int:
    """A ROS ``builtin_interfaces/Time`` in integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
