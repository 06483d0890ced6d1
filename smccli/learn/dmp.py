"""Action encoding: a Dynamic Movement Primitive of a fragment's POI path (section 3.4, eq. 27-30).

An action ``A(omega, x_s, x_f, tau)`` (eq. 27) is the POI path of one fragment encoded as
``omega`` = forcing weights (eq. 28), rolled out from a new start ``x_s`` to a new goal
``x_f`` over a duration ``tau``. The POI is ``n_pos`` positions followed by unwrapped
angles: arm ``[x, y, z, yaw]`` (n_pos 3), mobile base ``[x, y, theta]`` (n_pos 2).

Formulation (see docs/dmp.md for the measurements behind it):

* **Canonical frame.** Positions are translated to the start, rotated about z by the
  heading of the horizontal start-to-goal displacement and divided by the start-to-goal
  distance; angles are only translated to their start value (never rotated or scaled).
* **Moving-target DMP.** On normalised time ``s = t / tau`` in [0, 1], with phase
  ``x = exp(-alpha s)``, the canonical path is ``c = b + e``: ``b`` is the min-jerk line
  from 0 to the canonical goal and ``e`` obeys the spring-damper with the learned forcing
  term, ``e'' = -K e - D e' + f(x)``. That is ``c'' = K (b - c) - D (c' - b') + b'' + f``:
  the spring pulls towards the moving target ``b(s)`` instead of a fixed goal, so the
  heavily overdamped K 90 / D 60 (damping ratio 3.2) no longer lags behind a moved goal
  (the textbook form misses by 22 % of the goal shift at s = 1); ``e`` does not depend on
  the goal at all.
* **Fit in trajectory space.** ``e`` is linear in the weights, so they are the ridge
  least-squares fit of the rollout from rest to the demonstration's ``e``; no second
  derivative of a noisy demonstration is taken.
* **Goal-converging correction.** The residual ``e(1)`` of the fitted forcing term (about
  1e-4 mm on a smooth demonstration) is removed with a min-jerk blend, so the rollout ends
  on the goal to rounding error.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.linalg import expm
from threadpoolctl import threadpool_limits

from smccli.errors import LogError, TreeError

__all__ = [
    "Dmp",
    "DmpParams",
    "fit",
    "from_dict",
    "merge",
    "min_jerk",
    "rollout",
    "shape_distance",
    "to_dict",
]


@dataclass(frozen=True, slots=True)
class DmpParams:
    """DMP settings; defaults from the paper (section 4, 'SMCs control execution')."""

    n_basis: int = 100
    """Number of Gaussian basis functions of the forcing term."""
    dt: float = 0.01
    """Resampling step of the demonstration [s]."""
    alpha: float = 10.0
    """Decay of the canonical system ``x = exp(-alpha s)`` (s = normalised time)."""
    K: float = 90.0
    """Spring stiffness on normalised time [1/s^2 with tau = 1]."""
    D: float = 60.0
    """Damping on normalised time [1/s with tau = 1]."""
    ridge: float = 1e-4
    """Tikhonov regularisation of the weight fit, relative to the mean basis energy; keeps
    the weights of a noisy demonstration bounded (1e-4 costs < 0.01 mm of reproduction)."""
    min_scale: float = 0.02
    """Floor of the start-to-goal distance used as canonical scale [m]; avoids dividing by ~0."""
    min_heading: float = 0.01
    """Horizontal displacement below which the heading is undefined and not used [m]."""


@dataclass(frozen=True, slots=True)
class Dmp:
    """A fitted DMP: the action parameterisation omega (eq. 28) plus its demonstration context."""

    weights: np.ndarray
    """Forcing-term weights in the canonical frame, shape (n_dims, n_basis) [dimensionless]."""
    start: np.ndarray
    """POI at the start of the demonstration, shape (n_dims,) [m, rad]."""
    goal: np.ndarray
    """POI at the end of the demonstration, shape (n_dims,) [m, rad]."""
    duration: float
    """Duration of the demonstration tau [s]."""
    n_pos: int
    """Number of leading position dimensions; the rest are unwrapped angles [rad]."""
    params: DmpParams = field(default_factory=DmpParams)
    """Settings the DMP was fitted with."""

    @property
    def n_dims(self) -> int:
        """Number of POI dimensions."""
        return int(self.weights.shape[0])


@dataclass(frozen=True, slots=True)
class _Frame:
    """Canonical frame of a start/goal pair: world = start + scale * Rz(heading) * canonical."""

    heading: float
    """Rotation about z [rad]; 0 when the POI has fewer than two positions."""
    scale: float
    """Start-to-goal distance of the positions, floored at ``min_scale`` [m]."""


def _frame(
    start: np.ndarray, goal: np.ndarray, n_pos: int, p: DmpParams, fallback_heading: float = 0.0
) -> _Frame:
    d = goal[:n_pos] - start[:n_pos]
    heading = fallback_heading
    # A heading needs a horizontal displacement; for vertical or in-place moves keep the
    # fallback (the demonstration's heading) instead of an angle of pure noise.
    if n_pos >= 2 and np.hypot(d[0], d[1]) > p.min_heading:
        heading = float(np.arctan2(d[1], d[0]))
    return _Frame(heading, max(float(np.linalg.norm(d)), p.min_scale))


def _rot(heading: float) -> np.ndarray:
    c, s = np.cos(heading), np.sin(heading)
    return np.array([[c, -s], [s, c]])


def _to_canonical(y: np.ndarray, start: np.ndarray, fr: _Frame, n_pos: int) -> np.ndarray:
    c = y - start
    if n_pos >= 2:
        c[:, :2] = c[:, :2] @ _rot(fr.heading)  # row-vector form of Rz(-heading) @ v
    c[:, :n_pos] /= fr.scale
    return c


def _from_canonical(c: np.ndarray, start: np.ndarray, fr: _Frame, n_pos: int) -> np.ndarray:
    y = c.copy()
    y[:, :n_pos] *= fr.scale
    if n_pos >= 2:
        y[:, :2] = y[:, :2] @ _rot(fr.heading).T
    return y + start


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Min-jerk profile 10s^3 - 15s^4 + 6s^5 from 0 to 1, rest to rest, shape (N,)."""
    return s**3 * (10 - 15 * s + 6 * s**2)


def _basis(s: np.ndarray, p: DmpParams) -> np.ndarray:
    """Normalised Gaussian basis psi_i(x) / sum_j psi_j(x) on the phase, shape (N, n_basis)."""
    x = np.exp(-p.alpha * s)
    centres = np.exp(-p.alpha * np.linspace(0, 1, p.n_basis))
    # Width from the gap to the next centre (Ijspeert 2013): uniform overlap in time.
    gaps = np.abs(np.diff(centres))
    widths = 1.0 / np.append(gaps, gaps[-1]) ** 2
    psi = np.exp(-widths * (x[:, None] - centres) ** 2)
    return psi / np.maximum(psi.sum(axis=1, keepdims=True), 1e-300)


def _integrate(weights: np.ndarray, p: DmpParams, s_out: np.ndarray) -> np.ndarray:
    """Integrate e'' = -K e - D e' + f(x) from rest at e = 0, sampled at ``s_out``, (N, n_dims).

    Exact zero-order-hold discretisation (stable for any step, unlike Euler with the fast
    pole -58 of K 90 / D 60), forcing held at each substep's midpoint.
    """
    n_sub = max(1, int(np.ceil((s_out[1] - s_out[0]) * 4 * p.n_basis)))  # >= 4 steps per basis
    h = (s_out[1] - s_out[0]) / n_sub
    aug = np.zeros((3, 3))
    aug[:2, :2] = [[0.0, 1.0], [-p.K, -p.D]]
    aug[1, 2] = 1.0
    m = expm(aug * h)
    ad, bd = m[:2, :2], m[:2, 2]
    s_mid = (np.arange((len(s_out) - 1) * n_sub) + 0.5) * h
    forcing = _basis(s_mid, p) @ weights.T  # (n_steps, n_dims)
    # Each step's np.outer(bd, f), all at once: the same products (a rollout 40 % faster).
    kicks = bd[None, :, None] * forcing[:, None, :]  # (n_steps, 2, n_dims)
    state = np.zeros((2, weights.shape[0]))
    out = np.zeros((len(s_out), weights.shape[0]))
    for k, kick in enumerate(kicks):
        state = ad @ state + kick
        if (k + 1) % n_sub == 0:
            out[(k + 1) // n_sub] = state[0]
    return out


def fit(
    t: np.ndarray, y: np.ndarray, params: DmpParams = DmpParams(), *, n_pos: int | None = None
) -> Dmp:
    """Fit a DMP to a demonstration (eq. 28): ``t`` shape (T,) [s], ``y`` shape (T, n_dims).

    ``t`` may be non-uniform; the path is resampled every ``params.dt``. ``n_pos`` leading
    dimensions are positions [m] (default ``n_dims - 1``: the last one is an angle [rad]).
    """
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    if t.ndim != 1 or y.ndim != 2 or len(t) != len(y) or len(t) < 2:
        raise ValueError(
            f"fit: expected t (T,) and y (T, n_dims) with T >= 2, got {t.shape}, {y.shape}"
        )
    n_pos = y.shape[1] - 1 if n_pos is None else n_pos
    if not 0 <= n_pos <= y.shape[1]:
        raise ValueError(f"fit: n_pos must be in [0, {y.shape[1]}], got {n_pos}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y)) and np.all(np.diff(t) >= 0)):
        raise LogError("DMP demonstration: expected finite values and non-decreasing times")
    keep = np.append(np.diff(t) > 0, True)  # samples sharing a time: the last one wins
    t, y = t[keep], y[keep]
    if len(t) < 2:
        raise LogError("DMP demonstration: expected a duration > 0, all samples share one time")
    duration = float(t[-1] - t[0])
    s = np.linspace(0.0, 1.0, max(int(round(duration / params.dt)), 2) + 1)
    yr = np.stack([np.interp(t[0] + s * duration, t, y[:, i]) for i in range(y.shape[1])], 1)
    start, goal = yr[0], yr[-1]
    c = _to_canonical(yr, start, _frame(start, goal, n_pos, params), n_pos)
    # Deviation from the min-jerk line; fitted in trajectory space: the rollout of e is
    # linear in the weights, e = G w with G the responses to each basis function from rest.
    # Unlike regressing the forcing target e'' + K e + D e', this needs no second
    # derivative of a noisy demonstration and matches the rollout's start from rest.
    e = c - np.outer(min_jerk(s), c[-1])
    g = _integrate(np.eye(params.n_basis), params, s)
    # One BLAS thread: OpenBLAS splits a product and a solve by its thread count, which
    # changes the weights' last bits (from the 8th digit), so a tree would depend
    # on the machine's cores and on OPENBLAS_NUM_THREADS (Dask sets it to 1 in the
    # process that starts its workers). One thread is no slower at this size (n_basis^2).
    with threadpool_limits(limits=1, user_api="blas"):
        gram = g.T @ g
        lam = params.ridge * np.trace(gram) / params.n_basis
        w = np.linalg.solve(gram + lam * np.eye(params.n_basis), g.T @ e)
    return Dmp(w.T.copy(), start.copy(), goal.copy(), duration, n_pos, params)


def rollout(
    dmp: Dmp,
    *,
    start: np.ndarray | None = None,
    goal: np.ndarray | None = None,
    duration: float | None = None,
    n_steps: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Roll the DMP out from ``start`` to ``goal`` (eq. 27): times (N,) [s], POI (N, n_dims).

    Defaults are the demonstration's start, goal and duration and one step per ``dt``.
    """
    p = dmp.params
    start = dmp.start if start is None else np.asarray(start, dtype=float)
    goal = dmp.goal if goal is None else np.asarray(goal, dtype=float)
    duration = dmp.duration if duration is None else float(duration)
    if start.shape != (dmp.n_dims,) or goal.shape != (dmp.n_dims,):
        raise ValueError(
            f"rollout: expected start and goal of shape ({dmp.n_dims},), got "
            f"{start.shape}, {goal.shape}"
        )
    if n_steps is None:
        n_steps = max(int(round(duration / p.dt)), 2) + 1
    if n_steps < 2 or not duration > 0:
        raise ValueError(
            f"rollout: expected n_steps >= 2 and duration > 0, got {n_steps}, {duration}"
        )
    fr_demo = _frame(dmp.start, dmp.goal, dmp.n_pos, p)
    fr = _frame(start, goal, dmp.n_pos, p, fallback_heading=fr_demo.heading)
    goal_c = _to_canonical(goal[None], start, fr, dmp.n_pos)[0]
    s = np.linspace(0.0, 1.0, n_steps)
    mj = min_jerk(s)
    e = _integrate(dmp.weights, p, s)
    e -= np.outer(mj, e[-1])  # goal-converging correction of the fit residual e(1)
    y = _from_canonical(np.outer(mj, goal_c) + e, start, fr, dmp.n_pos)
    return s * duration, y


def _by_arc_length(c: np.ndarray, n: int) -> np.ndarray:
    """Resample a path (N, d) at ``n`` points evenly spaced along its length.

    Comparing paths by arc length rather than time makes the shape distance blind to how
    the operator timed the move: pauses, hesitations and uneven speed (a still path keeps
    its time sampling).
    """
    seg = np.linalg.norm(np.diff(c, axis=0), axis=1)
    arc = np.r_[0.0, np.cumsum(seg)]
    if arc[-1] < 1e-9:
        return c[np.linspace(0, len(c) - 1, n).round().astype(int)]
    u = np.linspace(0.0, arc[-1], n)
    return np.stack([np.interp(u, arc, c[:, k]) for k in range(c.shape[1])], axis=1)


def shape_distance(a: Dmp, b: Dmp, n_samples: int = 100) -> float:
    """Shape part of D_A (eq. 29) [m]: RMS gap of the canonical-frame paths.

    Each DMP is rolled out at its own start and goal, expressed in its canonical frame,
    resampled at ``n_samples`` points evenly spaced along its length (so speed, pauses and
    hesitation do not count), and the RMS distance is rescaled to metres by the mean
    start-to-goal distance. Angles are left out (they are compared by the goal term of
    D_A) unless the POI has no positions, in which case the result is in [rad].
    """
    if a.n_dims != b.n_dims or a.n_pos != b.n_pos:
        raise ValueError(
            f"shape_distance: POI layouts differ ({a.n_dims}, {a.n_pos}) vs ({b.n_dims}, {b.n_pos})"
        )
    dims = slice(0, a.n_pos) if a.n_pos else slice(0, a.n_dims)
    cs, scales = [], []
    for d in (a, b):
        fr = _frame(d.start, d.goal, d.n_pos, d.params)
        _, y = rollout(d, n_steps=8 * n_samples)
        cs.append(_by_arc_length(_to_canonical(y, d.start, fr, d.n_pos)[:, dims], n_samples))
        scales.append(fr.scale if a.n_pos else 1.0)
    rms = np.sqrt(np.mean(np.sum((cs[0] - cs[1]) ** 2, axis=1)))
    return float(rms * np.mean(scales))


def merge(dmps: Sequence[Dmp], weights: Sequence[float]) -> Dmp:
    """Support-weighted mean of the parameters of DMPs with the same layout (tree merge, 3.8).

    The dynamics are linear in the forcing weights, so the merged canonical path is the
    weighted mean of the inputs' canonical paths.
    """
    if not dmps or len(dmps) != len(weights) or min(weights) <= 0:
        raise ValueError(
            f"merge: expected as many positive weights as DMPs (>= 1), got "
            f"{len(dmps)} DMPs, weights {list(weights)}"
        )
    first = dmps[0]
    for d in dmps[1:]:
        if (d.weights.shape, d.n_pos, d.params) != (first.weights.shape, first.n_pos, first.params):
            raise ValueError("merge: DMPs differ in shape, n_pos or params")
    w = np.asarray(weights, dtype=float) / float(np.sum(weights))

    def mean(values: list[np.ndarray]) -> np.ndarray:
        return np.tensordot(w, np.stack(values), axes=1)

    return Dmp(
        mean([d.weights for d in dmps]),
        mean([d.start for d in dmps]),
        mean([d.goal for d in dmps]),
        float(np.dot(w, [d.duration for d in dmps])),
        first.n_pos,
        first.params,
    )


def to_dict(dmp: Dmp) -> dict:
    """JSON-ready dict of plain lists and floats; ``from_dict(to_dict(d))`` is exact."""
    return {
        "weights": dmp.weights.tolist(),
        "start": dmp.start.tolist(),
        "goal": dmp.goal.tolist(),
        "duration": float(dmp.duration),
        "n_pos": dmp.n_pos,
        "params": asdict(dmp.params),
    }


def from_dict(d: dict) -> Dmp:
    """Inverse of :func:`to_dict`; raises ``TreeError`` on missing keys or bad shapes."""
    keys = ("weights", "start", "goal", "duration", "n_pos", "params")
    missing = [k for k in keys if k not in d]
    if missing:
        raise TreeError(f"DMP entry: missing {missing} (expected keys {list(keys)})")
    try:
        params = DmpParams(**d["params"])
        w = np.asarray(d["weights"], dtype=float)
        start, goal = np.asarray(d["start"], dtype=float), np.asarray(d["goal"], dtype=float)
    except (TypeError, ValueError) as exc:
        raise TreeError(f"DMP entry: invalid values ({exc})") from exc
    n_pos = int(d["n_pos"])
    if (
        w.ndim != 2
        or w.shape[1] != params.n_basis
        or start.shape != (w.shape[0],)
        or goal.shape != start.shape
        or not 0 <= n_pos <= w.shape[0]
    ):
        raise TreeError(
            f"DMP entry: expected weights (n_dims, {params.n_basis}), start and goal "
            f"(n_dims,), 0 <= n_pos <= n_dims; got {w.shape}, {start.shape}, "
            f"{goal.shape}, n_pos {n_pos}"
        )
    return Dmp(w, start, goal, float(d["duration"]), n_pos, params)
