"""Shadows in the 3D twin: silhouettes cast along the sun vector onto the ground.

Pure geometry (no viser): the scene turns the polygons into flat meshes
(:func:`fan_mesh`). A point X in sunlight casts its shadow where the ray
X − λ s (s the unit vector towards the sun, λ > 0) meets a plane; for the
ground z = 0 that is λ = X_z / s_z. A convex body's shadow is the convex hull
of its projected corners (shapely 2). The tracker's shade on the fixed array
is the twin's own, :func:`sim.array_shade.fixed_shade`.
"""

from __future__ import annotations

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: Below this sun elevation sine the shadow is (nearly) infinite; the scene shows none.
MIN_SUN_Z = np.sin(np.radians(0.5))
#: Ground shadows are drawn this far above z = 0 so they do not flicker with the grid [m].
SHADOW_LIFT_M = 0.004


def box_corners(transform: ArrayLike, dimensions: ArrayLike) -> FloatArray:
    """The 8 corners (8, 3) of a box of ``dimensions`` (x, y, z) [m] centred in ``transform``
    (a 4 × 4 world transform)."""
    t = np.asarray(transform, dtype=float)
    half = np.asarray(dimensions, dtype=float) / 2.0
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    local = signs * half
    return np.asarray(local @ t[:3, :3].T + t[:3, 3], dtype=float)


def ground_shadow(points_enu: ArrayLike, sun_enu: ArrayLike) -> FloatArray:
    """Shadow on the ground z = 0 of the convex body spanned by ``points_enu`` (N, 3).

    Returns the convex polygon (M, 2) of (east, north) [m], counter-clockwise
    and not closed; empty (0, 2) with the sun below :data:`MIN_SUN_Z`.
    """
    p = np.asarray(points_enu, dtype=float).reshape(-1, 3)
    s = np.asarray(sun_enu, dtype=float)
    if s[2] < MIN_SUN_Z:
        return np.zeros((0, 2))
    flat = p[:, :2] - (p[:, 2:3] / s[2]) * s[:2]
    hull = shapely.convex_hull(shapely.multipoints(flat))
    if not isinstance(hull, shapely.Polygon):
        return np.zeros((0, 2))
    ring = np.asarray(shapely.orient_polygons(hull).exterior.coords)[:-1]
    return np.asarray(ring, dtype=float)


def fan_mesh(polygon: ArrayLike, z_m: float = SHADOW_LIFT_M,
             max_vertices: int = 16) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """A convex polygon (M, 2) or (M, 3) as a triangle fan with a fixed vertex count.

    Padding to ``max_vertices`` (the last vertex repeated: zero-area triangles)
    keeps the mesh's buffers one size, so the scene only updates the vertices.
    An empty polygon gives a degenerate mesh (nothing drawn). 2-D points are
    put at height ``z_m``.
    """
    p = np.asarray(polygon, dtype=float)
    if p.shape[1:] == (2,):
        p = np.column_stack([p, np.full(len(p), z_m)])
    if len(p) > max_vertices:
        raise ValueError(f"polygon has {len(p)} vertices, more than {max_vertices}")
    verts = np.zeros((max_vertices, 3))
    if len(p):
        verts[:len(p)] = p
        verts[len(p):] = p[-1]
    k = np.arange(1, max_vertices - 1)
    faces = np.stack([np.zeros_like(k), k, k + 1], axis=-1)
    return verts.astype(np.float32), faces.astype(np.uint32)
