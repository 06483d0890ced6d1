"""The mean and scatter matrix of a plane's inliers summed as numpy sums them in
``inl.mean(axis=0)`` and ``np.einsum("ni,nj->ij", c, c)``: the table planes trees were
compiled with (:func:`~smccli.perception.cloud.fit_table_plane`), in less time."""

from __future__ import annotations

import numpy as np


def moments(inl: np.ndarray, out: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mean (3,) of rows ``inl`` (k, 3) float64 [m] and the scatter matrix (3, 3) [m^2]
    of the rows centred on it, to the bit as ``inl.mean(axis=0)`` and ``np.einsum("ni,nj->ij",
    c, c)`` make them; ``out`` (k, 4) float64 is scratch for the centred rows."""
    # ``inl.mean(axis=0)`` sums each column row after row, as ``einsum("ni->i")`` does (its
    # three sums interleaved, row by row): the same mean, 0.9 to 0.2 ms on a table's 60 k
    # points.
    mean = np.einsum("ni->i", inl) / len(inl)
    for i in range(3):  # column by column: (k, 3) - (3,) loops over rows of 3, 3 times slower
        np.subtract(inl[:, i], mean[i], out=out[:, i])
    out[:, 3] = out[:, 0]
    return mean, scatter(out)


def scatter(c: np.ndarray) -> np.ndarray:
    """``np.einsum("ni,nj->ij", c[:, :3], c[:, :3])`` (3, 3) of rows ``c`` (k, 4) float64
    whose last column repeats the first, to the bit.

    That einsum sums each of its nine products row after row (sequentially); so does
    ``einsum("ni,ni->i")`` over three columns at once, and a product's two orders give the
    same bits: the squares, then (with the repeated column) ``c0 c1, c1 c2, c2 c0``, its
    six distinct sums in two passes, 0.9 to 0.55 ms on a table's 60 k points (equal on
    3000 random sizes and every campaign frame tried; over one column alone einsum sums
    in SIMD lanes, another order)."""
    d = np.einsum("ni,ni->i", c[:, 0:3], c[:, 0:3])  # c0 c0, c1 c1, c2 c2
    o = np.einsum("ni,ni->i", c[:, 0:3], c[:, 1:4])  # c0 c1, c1 c2, c2 c0
    return np.array([[d[0], o[0], o[2]], [o[0], d[1], o[1]], [o[2], o[1], d[2]]])
