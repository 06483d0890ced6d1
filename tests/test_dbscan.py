"""smc's DBSCAN gives open3d's labels, label for label: the trees compiled and the
decisions taken with open3d's stay what they were."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from smccli.perception.dbscan import dbscan_labels


def open3d_labels(points: np.ndarray, eps: float, min_points: int) -> np.ndarray:
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    return np.asarray(pcd.cluster_dbscan(eps=eps, min_points=min_points), dtype=np.int64)


def clumps(rng: np.random.Generator, lattice: bool) -> np.ndarray:
    """A few Gaussian clumps of 5-400 points, touching or apart; on a 5 mm lattice, many
    pairs lie at exactly a multiple of the lattice step (ties at eps)."""
    k, n = int(rng.integers(1, 6)), int(rng.integers(5, 400))
    centres = rng.uniform(0, 0.1, (k, 3))
    points = centres[rng.integers(0, k, n)] + rng.normal(0, rng.uniform(0.002, 0.02), (n, 3))
    return np.round(points / 0.005) * 0.005 if lattice else points


@pytest.mark.parametrize("lattice", [False, True])
def test_labels_are_open3d_labels(lattice: bool) -> None:
    rng = np.random.default_rng(38 + lattice)
    for trial in range(300):
        points = clumps(rng, lattice)
        eps = (0.015, 0.01, 0.005, 0.02)[trial % 4]
        min_points = int(rng.integers(1, 12))
        expected = open3d_labels(points, eps, min_points)
        assert np.array_equal(dbscan_labels(points, eps, min_points), expected), trial


def test_a_pair_at_exactly_eps_is_not_neighbours() -> None:
    """open3d keeps d < eps: a 4 x 4 grid of step eps is all noise with min_points 3, one
    cluster with eps a hair larger."""
    grid = np.stack(np.meshgrid(np.arange(4), np.arange(4), [0]), -1).reshape(-1, 3) * 0.25
    assert (dbscan_labels(grid, 0.25, 3) == -1).all()
    assert (dbscan_labels(grid, 0.2500001, 3) == 0).all()
    assert np.array_equal(dbscan_labels(grid, 0.25, 3), open3d_labels(grid, 0.25, 3))


def test_a_border_point_joins_the_first_cluster_grown() -> None:
    """Two dense clumps and one point within eps of both, not core itself: it takes the
    cluster numbered first (the one holding the lowest index), as open3d's does."""
    a = np.array([[0.0, 0.0005 * i, 0] for i in range(6)])  # 6 points within 2.5 mm
    b = a + [0.018, 0, 0]
    bridge = np.array([[0.009, 0, 0]])  # 2 points of each clump closer than eps: 5 in all
    for points in (np.vstack([bridge, a, b]), np.vstack([b, bridge, a]), np.vstack([a, b, bridge])):
        expected = open3d_labels(points, 0.00902, 6)
        got = dbscan_labels(points, 0.00902, 6)
        assert np.array_equal(got, expected)
        assert got.max() == 1 and (got >= 0).all()


def test_no_points_and_no_core() -> None:
    assert dbscan_labels(np.zeros((0, 3)), 0.01, 5).shape == (0,)
    far = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    assert (dbscan_labels(far, 0.01, 2) == -1).all()
