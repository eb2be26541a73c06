"""Convex polygons in the ground plane: the support polygon's geometry.

Shared by the planner (the CoM-in-polygon limit) and the fall risk model: one
convex hull (Andrew's monotone chain), one half-plane form, one signed margin.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["check_polygon", "clip_polygon", "convex_hull", "halfplanes", "polygon_area", "signed_margin"]

FloatArray = NDArray[np.float64]


def _cross(o: FloatArray, a: FloatArray, b: FloatArray) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def _monotone_chain(pts: FloatArray) -> list[FloatArray]:
    """Andrew's monotone chain on lexicographically sorted distinct points, exact turn test.

    A point is dropped only on a right turn or an exactly straight one (cross <= 0 in floating
    point). No tolerance here: with one, a corner whose x differs from its neighbour's by a
    rounding error (a near-vertical edge sorted out of its geometric order) was dropped as
    "collinear" although it lies beyond the segment, cutting a corner off the polygon.
    """
    lower: list[FloatArray] = []
    for p in pts:
        while len(lower) >= 2 and _cross(lower[-2], lower[-1], p) <= 0.0:
            lower.pop()
        lower.append(p)
    upper: list[FloatArray] = []
    for p in pts[::-1]:
        while len(upper) >= 2 and _cross(upper[-2], upper[-1], p) <= 0.0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def _removable(prev: FloatArray, v: FloatArray, nxt: FloatArray, tol: float) -> bool:
    """True if dropping vertex ``v`` moves the boundary by at most ``tol``: it nearly repeats
    ``nxt``, does not turn left, or lies within ``tol`` of the chord prev-nxt and between its ends."""
    chord = nxt - prev
    length = float(np.hypot(chord[0], chord[1]))
    if float(np.hypot(nxt[0] - v[0], nxt[1] - v[1])) <= tol or length <= tol:
        return True
    cross = _cross(prev, v, nxt)
    if cross <= 0.0:
        return True
    t = float(np.dot(v - prev, chord)) / (length * length)
    return cross / length <= tol and 0.0 <= t <= 1.0


def convex_hull(points: ArrayLike) -> FloatArray:
    """Convex hull (V, 2) of 2D points, counter-clockwise, no repeated or collinear vertices.

    Andrew's monotone chain (A. M. Andrew, Inf. Process. Lett. 9(5):216-219, 1979): sort by
    (x, y), build the lower and the upper chain keeping only left turns (exact test). Then
    vertices that nearly repeat their successor or lie within 1e-12 x (the points' extent) of
    the chord between their neighbours (and between its ends) are removed one at a time, so the
    polygon has no slivers or near-zero edges and moves by at most that distance; a true corner
    is never removed. The first vertex is the lexicographically smallest. Fewer than 3 distinct
    non-collinear points give 1 or 2 rows.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(pts)):
        raise ValueError("convex_hull: points must be finite")
    pts = np.unique(pts, axis=0)  # sorted lexicographically by (x, y)
    if len(pts) <= 2:
        return pts
    tol = 1e-12 * float(np.max(np.ptp(pts, axis=0)))
    hull = _monotone_chain(pts)
    removed = True
    while removed and len(hull) > 2:
        n = len(hull)
        drop = [i for i in range(n) if _removable(hull[i - 1], hull[i], hull[(i + 1) % n], tol)]
        removed = bool(drop)
        if removed:  # one at a time: its neighbours' chords change
            del hull[drop[0]]
    out = np.array(hull, dtype=float).reshape(-1, 2)
    if len(out) == 2 and float(np.hypot(*(out[1] - out[0]))) <= tol:
        out = out[:1]
    start = int(np.lexsort((out[:, 1], out[:, 0]))[0])
    return np.roll(out, -start, axis=0)


def polygon_area(polygon: ArrayLike) -> float:
    """Signed area (shoelace formula); positive for a counter-clockwise polygon."""
    v = np.asarray(polygon, dtype=float).reshape(-1, 2)
    if len(v) < 3:
        return 0.0
    w = np.roll(v, -1, axis=0)
    return 0.5 * float(np.sum(v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]))


def check_polygon(polygon: ArrayLike) -> FloatArray:
    """The polygon as (V, 2) vertices; ValueError unless counter-clockwise with positive area."""
    v = np.asarray(polygon, dtype=float).reshape(-1, 2)
    if len(v) < 3 or polygon_area(v) <= 0.0:
        raise ValueError(
            f"expected a counter-clockwise convex polygon with at least 3 vertices and positive "
            f"area, got {len(v)} vertices (area {polygon_area(v):.3g})"
        )
    return v


def halfplanes(polygon: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(A, b) with A's rows the edges' unit outward normals: x inside <=> A x <= b.

    Edge i runs from vertex i to vertex i+1 (cyclically) of the counter-clockwise polygon.
    """
    v = check_polygon(polygon)
    e = np.roll(v, -1, axis=0) - v
    length = np.hypot(e[:, 0], e[:, 1])
    if np.any(length <= 0.0):
        raise ValueError("halfplanes: the polygon has repeated vertices")
    a = np.column_stack([e[:, 1], -e[:, 0]]) / length[:, None]
    b = np.einsum("ij,ij->i", a, v)
    return a, b


def signed_margin(polygon: ArrayLike, point: ArrayLike) -> float:
    """Signed distance of ``point`` to the polygon's boundary, positive inside.

    Inside: min_i (b_i - a_i.x) (for a convex polygon that is the distance to the nearest
    edge). Outside: minus the Euclidean distance to the nearest edge segment (so near a vertex
    it is the distance to that vertex, not to an edge's line).
    """
    v = check_polygon(polygon)
    x = np.asarray(point, dtype=float).reshape(-1)[:2]
    a, b = halfplanes(v)
    slack = b - a @ x
    if np.all(slack >= 0.0):
        return float(np.min(slack))
    w = np.roll(v, -1, axis=0)
    e = w - v
    t = np.clip(np.einsum("ij,ij->i", x - v, e) / np.einsum("ij,ij->i", e, e), 0.0, 1.0)
    nearest = v + t[:, None] * e
    gap = nearest - x
    return -float(np.min(np.hypot(gap[:, 0], gap[:, 1])))


def clip_polygon(polygon: ArrayLike, normal: ArrayLike, offset: float) -> FloatArray:
    """The part of a convex polygon with ``normal . x <= offset`` (Sutherland-Hodgman, one plane).

    Returns the (possibly empty, shape (0, 2)) clipped polygon, counter-clockwise.
    """
    v = np.asarray(polygon, dtype=float).reshape(-1, 2)
    n = np.asarray(normal, dtype=float).reshape(2)
    if len(v) == 0:
        return v
    d = v @ n - offset
    if np.all(d <= 0.0):
        return v
    if np.all(d > 0.0):
        return np.zeros((0, 2))
    out: list[FloatArray] = []
    count = len(v)
    for i in range(count):
        j = (i + 1) % count
        if d[i] <= 0.0:
            out.append(v[i])
        if (d[i] <= 0.0) != (d[j] <= 0.0):
            t = d[i] / (d[i] - d[j])
            out.append(v[i] + t * (v[j] - v[i]))
    return convex_hull(np.array(out)) if len(out) >= 3 else np.zeros((0, 2))
