"""The one geometry module: the wrap, rotations and the group laws of planar and spatial
poses (identity, inverse, associativity, round trips), drawn by Hypothesis as mink tests
its Lie groups; and that no other module writes pose math of its own."""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from smccli.world import geometry as g

# Per test, not a profile: a profile loaded here would change every other module's.
EXAMPLES = settings(max_examples=300, derandomize=True, deadline=None)

PACKAGE = Path(__file__).resolve().parent.parent / "smccli"
coord = st.floats(-5.0, 5.0, allow_nan=False)
angle = st.floats(-20.0, 20.0, allow_nan=False)
planar = st.tuples(coord, coord, angle).map(np.array)
poi = st.tuples(coord, coord, coord, angle).map(np.array)
unit_quat = arrays(np.float64, 4, elements=st.floats(-1, 1)).filter(
    lambda q: np.linalg.norm(q) > 0.1
)


def same_pose(a: np.ndarray, b: np.ndarray, tol: float = 1e-9) -> bool:
    """Equal positions, and yaws equal modulo 2 pi."""
    return bool(
        np.allclose(a[..., :-1], b[..., :-1], atol=tol)
        and np.all(np.abs(np.vectorize(g.wrap)(a[..., -1] - b[..., -1])) < tol)
    )


# --- the wrap ------------------------------------------------------------------------------


@EXAMPLES
@given(angle, st.sampled_from([2 * math.pi, math.pi]))
def test_wrap_lands_in_the_half_open_range_and_keeps_the_angle(a: float, period: float) -> None:
    w = g.wrap(a, period)
    assert -period / 2 < w <= period / 2
    assert abs(math.remainder(w - a, period)) < 1e-12  # a multiple of the period away
    assert abs(g.wrap(w, period) - w) <= 4.5e-16  # idempotent, to one rounding


@EXAMPLES
@given(st.floats(-math.pi, math.pi, exclude_min=True))
def test_an_angle_in_range_comes_back_within_one_rounding(a: float) -> None:
    assert abs(g.wrap(a) - a) <= 4.5e-16


def test_the_ends_of_the_range() -> None:
    assert g.wrap(math.pi) == math.pi
    assert g.wrap(-math.pi) == math.pi  # atan2's side
    assert g.wrap(3 * math.pi) == math.pi
    assert g.wrap(-math.pi / 2, math.pi) == math.pi / 2
    assert g.wrap(0.0) == 0.0


# --- rotations -----------------------------------------------------------------------------


@EXAMPLES
@given(angle)
def test_yaw_quaternion_round_trip(yaw: float) -> None:
    q = g.yaw_quat(yaw)
    assert np.isclose(np.linalg.norm(q), 1.0)
    assert abs(g.wrap(g.quat_yaw(q) - yaw)) < 1e-9
    # scipy, w last, agrees: the order is converted at that boundary only.
    R = Rotation.from_quat(g.xyzw(q)).as_matrix()
    np.testing.assert_allclose(R, g.quat_matrix(q), atol=1e-12)
    assert math.isclose(g.yaw_of(R), g.yaw_of(R.ravel()))


@EXAMPLES
@given(unit_quat)
def test_quaternion_matrix_round_trip(q: np.ndarray) -> None:
    q = q / np.linalg.norm(q)
    back = g.matrix_quat(g.quat_matrix(q))
    assert back[0] >= 0
    assert np.allclose(back, q, atol=1e-9) or np.allclose(back, -q, atol=1e-9)
    np.testing.assert_array_equal(g.wxyz(g.xyzw(q)), q)


@EXAMPLES
@given(arrays(np.float64, (5, 3), elements=coord), angle)
def test_rotate_z_is_the_rotation_about_z(v: np.ndarray, a: float) -> None:
    want = Rotation.from_euler("z", a).apply(v)
    np.testing.assert_allclose(g.rotate_z(v, a), want, atol=1e-9)
    assert abs(g.near(a + 7.0, a) - (a + g.wrap(7.0))) < 1e-9
    assert abs(g.near(a + 7.0, a) - a) <= math.pi


# --- planar poses: SE(2), with a height riding along ---------------------------------------


@EXAMPLES
@given(st.one_of(planar, poi))
def test_identity(a: np.ndarray) -> None:
    e = np.zeros(len(a))
    np.testing.assert_array_equal(g.compose(e, a), a)
    assert same_pose(g.compose(a, e), a)
    assert same_pose(g.between(e, a), a)


@EXAMPLES
@given(st.one_of(planar, poi))
def test_inverse(a: np.ndarray) -> None:
    e = np.zeros(len(a))
    assert same_pose(g.compose(a, g.inverse(a)), e)
    assert same_pose(g.compose(g.inverse(a), a), e)
    assert same_pose(g.inverse(g.inverse(a)), a)


@EXAMPLES
@given(planar, planar, planar)
def test_associativity(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> None:
    assert same_pose(g.compose(g.compose(a, b), c), g.compose(a, g.compose(b, c)))


@EXAMPLES
@given(st.one_of(planar, poi), st.one_of(planar, poi))
def test_between_undoes_compose(a: np.ndarray, b: np.ndarray) -> None:
    assert same_pose(g.between(a, g.compose(a, b)), b)
    assert same_pose(g.compose(a, g.between(a, b)), b)


@EXAMPLES
@given(planar, planar)
def test_compose_is_the_matrix_product(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_allclose(g.se2(g.compose(a, b)), g.se2(a) @ g.se2(b), atol=1e-9)
    assert same_pose(g.se2_pose(g.se2(a)), a)
    assert -math.pi < g.se2_pose(g.se2(a))[2] <= math.pi
    np.testing.assert_allclose(g.planar_se3(a), g.se2_se3(g.se2(a)), atol=1e-12)


@EXAMPLES
@given(poi, arrays(np.float64, (6, 3), elements=coord))
def test_points_in_and_out_of_a_frame(frame: np.ndarray, pts: np.ndarray) -> None:
    inside = g.to_frame(frame, pts)
    np.testing.assert_allclose(g.from_frame(frame, inside), pts, atol=1e-9)
    np.testing.assert_allclose(
        g.se3_apply(g.planar_se3(frame), inside), pts, atol=1e-9
    )  # the same motion as the 4 x 4 transform
    np.testing.assert_allclose(  # a planar frame leaves heights alone
        g.to_frame(frame[[0, 1, 3]], pts)[:, 2], pts[:, 2]
    )


@EXAMPLES
@given(arrays(np.float64, (7, 3), elements=coord), arrays(np.float64, (7, 4), elements=coord))
def test_vectorised_over_frames_and_poses_equals_one_by_one(
    frames: np.ndarray, poses: np.ndarray
) -> None:
    batch = g.between(frames, poses)
    for f, p, got in zip(frames, poses, batch, strict=True):
        np.testing.assert_array_equal(got, g.between(f, p))
    batch = g.compose(frames[0], poses)
    for p, got in zip(poses, batch, strict=True):
        np.testing.assert_array_equal(got, g.compose(frames[0], p))


@EXAMPLES
@given(st.one_of(planar, poi), st.one_of(planar, poi))
def test_pose_floats_are_the_arrays_bits(a: np.ndarray, b: np.ndarray) -> None:
    """The control loop's float path (a base's target through odometry, every period) gives
    compose's and between's bits, whether the poses come as arrays or as Python floats."""
    for inverse_a, f in ((False, g.compose), (True, g.between)):
        want = f(a, b)
        for x, y in ((a, b), (a.tolist(), b.tolist())):
            got = g.pose_floats(x, y, inverse_a=inverse_a)
            assert all(type(v) is float for v in got)
            assert np.array(got).tobytes() == want.tobytes()
    inv = g.pose_floats(a, np.zeros(len(a)).tolist(), inverse_a=True)
    assert np.array(inv).tobytes() == g.inverse(a).tobytes()


# --- spatial poses -------------------------------------------------------------------------


@EXAMPLES
@given(arrays(np.float64, 3, elements=coord), unit_quat, arrays(np.float64, 3, elements=coord))
def test_spatial_round_trips_and_inverse(p: np.ndarray, q: np.ndarray, x: np.ndarray) -> None:
    q = q / np.linalg.norm(q)
    T = g.se3(p, q)
    p2, q2 = g.se3_parts(T)
    np.testing.assert_allclose(g.se3(p2, q2), T, atol=1e-9)
    np.testing.assert_allclose(T @ g.se3_inverse(T), np.eye(4), atol=1e-9)
    np.testing.assert_allclose(g.se3_apply(g.se3_inverse(T), g.se3_apply(T, x)), x, atol=1e-9)


# --- one module holds the pose math --------------------------------------------------------


def _yaw_from_matrix(node: ast.AST) -> bool:
    """``atan2(R[1, 0], R[0, 0])`` (math or numpy), written out."""
    return (
        isinstance(node, ast.Call)
        and getattr(node.func, "attr", getattr(node.func, "id", "")) in ("atan2", "arctan2")
        and len(node.args) == 2
        and all(isinstance(a, ast.Subscript) for a in node.args)
        and ast.unparse(node.args[0]).endswith(("[1, 0]", "[3]"))
        and ast.unparse(node.args[1]).endswith(("[0, 0]", "[0]"))
    )


def test_no_module_but_geometry_writes_a_wrap_or_a_yaw_from_a_matrix() -> None:
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "geometry.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            where = f"{path.relative_to(PACKAGE)}:{getattr(node, 'lineno', 0)}"
            if isinstance(node, ast.FunctionDef) and "wrap" in node.name.replace("unwrap", ""):
                found.append(f"{where} def {node.name}")
            if _yaw_from_matrix(node):
                found.append(f"{where} {ast.unparse(node)}")
            if isinstance(node, ast.Attribute) and node.attr == "remainder":
                found.append(f"{where} {ast.unparse(node)}")
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mod):
                if any(t in ast.unparse(node.right) for t in ("pi", "period", "TWO_PI")):
                    found.append(f"{where} {ast.unparse(node)}")
    assert not found, found
