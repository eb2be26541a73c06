"""The fall model's per-knot quantities for many knots at once (numpy over knots).

Same formulas as :mod:`executive.risk.gaussian_polygon` and :mod:`executive.risk.fall_support`
(see their module docs for the sources), arranged so a trajectory of K knots costs a few array
operations instead of K Python-level calls:

* support polygons: the convex hull (Andrew's monotone chain, :func:`executive.world.polygon.convex_hull`)
  of one knot is reused for the next knots as long as it is still their hull: the same point
  indices form a strictly convex counter-clockwise polygon (every turn's height above its chord
  beyond the hull's tolerance) with every point inside or within that tolerance; otherwise
  ``convex_hull`` runs for that knot. Feet that stay put keep one hull for the whole motion.
* margins, per-edge probabilities, the exact probability (Owen's T, Owen 1956) and the capture
  point margin, for all knots with the same number of polygon vertices in one go.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr, owens_t

from executive.world.polygon import convex_hull

__all__ = [
    "KnotPolygons",
    "edge_probabilities_batch",
    "halfplanes_batch",
    "hulls",
    "probability_outside_batch",
    "signed_margin_batch",
]

FloatArray = NDArray[np.float64]


class KnotPolygons(NamedTuple):
    """Polygons of K knots grouped by vertex count: ``groups[m] = (knot indices, (n, m, 2) vertices)``."""

    groups: dict[int, tuple[NDArray[np.int_], FloatArray]]

    def polygon(self, k: int) -> FloatArray:
        for knots, verts in self.groups.values():
            hit = np.flatnonzero(knots == k)
            if len(hit):
                return verts[int(hit[0])]
        raise IndexError(k)


def _valid_hull(points: FloatArray, idx: NDArray[np.int_]) -> NDArray[np.bool_]:
    """Per knot (points (n, P, 2)): do the points ``idx`` form the hull ``convex_hull`` would return
    (to its 1e-12 x extent tolerance)?"""
    v = points[:, idx]  # (n, m, 2)
    extent = np.max(np.ptp(points, axis=1), axis=1)  # (n,)
    tol = 1e-12 * extent
    nxt = np.roll(v, -1, axis=1)
    prev = np.roll(v, 1, axis=1)
    chord = nxt - prev
    length = np.hypot(chord[..., 0], chord[..., 1])
    turn = (v[..., 0] - prev[..., 0]) * (nxt[..., 1] - prev[..., 1]) - (v[..., 1] - prev[..., 1]) * (
        nxt[..., 0] - prev[..., 0]
    )
    edge = nxt - v
    edge_len = np.hypot(edge[..., 0], edge[..., 1])
    # Every vertex a proper corner (not removable by convex_hull) ...
    ok = np.all((turn > tol[:, None] * length) & (edge_len > tol[:, None]) & (length > tol[:, None]), axis=1)
    # ... and every point inside or within the tolerance of every edge.
    rel = points[:, None, :, :] - v[:, :, None, :]  # (n, m, P, 2)
    cross = edge[:, :, None, 0] * rel[..., 1] - edge[:, :, None, 1] * rel[..., 0]
    ok &= np.all(cross >= -tol[:, None, None] * edge_len[:, :, None], axis=(1, 2))
    return np.asarray(ok, dtype=bool)


def _hull_indices(points: FloatArray) -> NDArray[np.int_]:
    """Indices into ``points`` (P, 2) of ``convex_hull(points)``'s vertices, in its order."""
    hull = convex_hull(points)
    return np.array([int(np.flatnonzero(np.all(points == h, axis=1))[0]) for h in hull], dtype=int)


def hulls(points: FloatArray, on_ground: NDArray[np.bool_]) -> KnotPolygons:
    """Support polygons of K knots: the convex hull of ``points[k][on_ground[k]]`` ((K, P, 2), (K, P)).

    Raises ValueError (naming the knot) when a knot's points span no polygon.
    """
    parts: dict[int, list[tuple[NDArray[np.int_], FloatArray]]] = {}
    masks, which = np.unique(on_ground, axis=0, return_inverse=True)
    for m, mask in enumerate(masks):
        knots = np.flatnonzero(which.reshape(-1) == m)
        pts = points[knots][:, mask]  # (n, P', 2)
        todo = np.ones(len(knots), dtype=bool)
        while np.any(todo):
            first = int(np.flatnonzero(todo)[0])
            idx = _hull_indices(pts[first])
            if len(idx) < 3:
                raise ValueError(
                    f"support_polygon: {pts.shape[1]} foot geometry points on the ground do not span "
                    f"a polygon at knot {int(knots[first])}"
                )
            rest = np.flatnonzero(todo)
            good = rest[_valid_hull(pts[rest], idx)]
            good = np.union1d(good, [first]).astype(int)
            parts.setdefault(len(idx), []).append((knots[good], pts[good][:, idx]))
            todo[good] = False
    groups = {}
    for size, chunks in parts.items():
        knots = np.concatenate([k for k, _ in chunks])
        verts = np.concatenate([v for _, v in chunks])
        order = np.argsort(knots, kind="stable")
        groups[size] = (knots[order], verts[order])
    return KnotPolygons(groups)


def halfplanes_batch(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(n, m, 2) unit outward normals and (n, m) offsets of counter-clockwise polygons (n, m, 2)."""
    e = np.roll(v, -1, axis=1) - v
    length = np.hypot(e[..., 0], e[..., 1])
    a = np.stack([e[..., 1], -e[..., 0]], axis=-1) / length[..., None]
    return a, np.einsum("nij,nij->ni", a, v)


def signed_margin_batch(v: FloatArray, x: FloatArray) -> FloatArray:
    """:func:`executive.world.polygon.signed_margin` of points x (n, 2) in polygons v (n, m, 2)."""
    a, b = halfplanes_batch(v)
    slack = b - np.einsum("nij,nj->ni", a, x)
    inside = np.min(slack, axis=1)
    e = np.roll(v, -1, axis=1) - v
    rel = x[:, None, :] - v
    t = np.clip(np.einsum("nij,nij->ni", rel, e) / np.einsum("nij,nij->ni", e, e), 0.0, 1.0)
    gap = v + t[..., None] * e - x[:, None, :]
    outside = -np.min(np.hypot(gap[..., 0], gap[..., 1]), axis=1)
    return np.asarray(np.where(np.all(slack >= 0.0, axis=1), inside, outside), dtype=float)


def edge_probabilities_batch(v: FloatArray, mu: FloatArray, cov: FloatArray) -> FloatArray:
    """:func:`executive.risk.gaussian_polygon.edge_probabilities` for polygons v (n, m, 2),
    means mu (n, 2)."""
    a, b = halfplanes_batch(v)
    slack = b - np.einsum("nij,nj->ni", a, mu)
    var = np.einsum("nij,jk,nik->ni", a, cov, a)
    p = np.where(slack < 0.0, 1.0, 0.0)
    pos = var > 0.0
    p[pos] = ndtr(-slack[pos] / np.sqrt(var[pos]))
    return np.asarray(p, dtype=float)


def probability_outside_batch(v: FloatArray, mu: FloatArray, cov: FloatArray) -> FloatArray:
    """:func:`executive.risk.gaussian_polygon.probability_outside` (Owen's T) for polygons v (n, m, 2),
    means mu (n, 2).

    Whitened by the Cholesky factor of ``cov``; with the mean strictly inside the tails beyond
    the edges are summed (T(h, s_b/h) - T(h, s_a/h)), otherwise 1 - the signed triangles' mass.
    """
    scale = float(np.max(np.abs(cov)))
    if scale == 0.0:
        return np.asarray(signed_margin_batch(v, mu) < 0.0, dtype=float)
    try:
        chol = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:  # singular but non-zero: a negligible isotropic jitter
        chol = np.linalg.cholesky(cov + 1e-12 * scale * np.eye(2))
    z = np.linalg.solve(chol, (v - mu[:, None, :]).reshape(-1, 2).T).T.reshape(v.shape)
    nxt = np.roll(z, -1, axis=1)
    e = nxt - z
    t = e / np.hypot(e[..., 0], e[..., 1])[..., None]
    c = t[..., 1] * z[..., 0] - t[..., 0] * z[..., 1]
    sa = np.einsum("nij,nij->ni", t, z)
    sb = np.einsum("nij,nij->ni", t, nxt)
    h = np.abs(c)
    safe_h = np.where(h > 0.0, h, 1.0)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        tail = owens_t(safe_h, sb / safe_h) - owens_t(safe_h, sa / safe_h)
        angle = (np.arctan2(sb, safe_h) - np.arctan2(sa, safe_h)) / (2.0 * np.pi)
    keep = h > 0.0
    inside = np.sum(np.where(keep, np.sign(c) * (angle - tail), 0.0), axis=1)
    outside = np.where(np.all(c > 0.0, axis=1), np.sum(np.where(keep, tail, 0.0), axis=1), 1.0 - inside)
    return np.asarray(np.clip(outside, 0.0, 1.0), dtype=float)
