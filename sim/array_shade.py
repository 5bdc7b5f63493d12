"""The tracker's shade on the fixed reference array, vectorised over time.

Geometry (seed 004 §2.1, Fig. 1, which projects one collector onto another along
the sun vector s; here between two collectors of different orientation). A
point X of the fixed array is shaded when the ray X + λ s (λ > 0) meets the
tracker's collector, a flat rectangle. Equivalently, the collector's outline
projected along s onto the fixed array's plane, X − ((X − c)·n / (s·n)) s with c
the array's centre and n its front normal, covers X. Only the part of the
collector in front of that plane ((X − c)·n ≥ 0) can shade its front. The
projected outline is a convex polygon; it is clipped to the array's rectangle
(Sutherland–Hodgman, every step at once with numpy) and the shoelace area over
the array's area is the shaded fraction. No shade while the sun is below the
horizon or behind the fixed array (s·n ≤ 0: it gets no beam to lose).

Only steps whose sun ray from the fixed array can pass the collector (the
distance of the tracker's collector centre from the ray through the array's
centre is less than the sum of the two half-diagonals) are clipped.

Loss model: the fixed array loses the shaded fraction of its plane-of-array
beam (area-proportional; :func:`sim.twin.simulate`). A real module loses more:
a shaded cell row drops its whole bypass-diode substring (cf.
``sim.plant.electrical``), so this is a lower bound of the loss.

Where the arrays stand is the site config's ``position_east_m`` /
``position_north_m`` (:class:`Placement`, docs/sites.md); world coordinates here
are East-North-Up metres with the origin on the ground at the foot of the
tracker's pedestal, as in the 3D scene.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.kinematics import TrackerGeometry, joint_transforms
from sim.pv import ArrayConfig, cec_module_parameters

if TYPE_CHECKING:
    from sim.sites import Site

FloatArray = NDArray[np.float64]

#: Gap between neighbouring modules of a collector [m] (assumption).
MODULE_GAP_M = 0.02
#: Height of the tracker's D–H base frame {0} (top of the pedestal) above the ground [m].
#: Seed 000 gives none; chosen so a 2 × 2 collector clears the ground when vertical.
TRACKER_MOUNT_HEIGHT_M = 1.30
#: Height of a fixed array's lower edge above the ground [m] (assumption).
FIXED_MOUNT_HEIGHT_M = 0.5
#: Config keys of a placement (:class:`Placement`), in order.
PLACEMENT_KEYS = ("position_east_m", "position_north_m", "mount_height_m", "width_m",
                  "height_m")


@dataclass(frozen=True)
class Placement:
    """Where an array stands, as configured (``arrays.<name>.position_east_m`` …).

    Parameters
    ----------
    position_east_m, position_north_m : float
        [m] of the site's origin: a tracker's pedestal foot (its azimuth axis on
        the ground); a fixed array's ground point below its collector's centre.
    mount_height_m : float, optional
        [m] a tracker's base frame {0} (top of the pedestal) above the ground,
        default :data:`TRACKER_MOUNT_HEIGHT_M`; a fixed array's lower edge,
        default :data:`FIXED_MOUNT_HEIGHT_M`.
    width_m, height_m : float, optional
        [m] the collector's outline; default :func:`collector_size_m`.
    """

    position_east_m: float
    position_north_m: float
    mount_height_m: float | None = None
    width_m: float | None = None
    height_m: float | None = None


def module_size_m(module: str) -> tuple[float, float] | None:
    """(length, width) [m] of a module from pvlib's CEC table (``Length``, ``Width``;
    KD205GX-LP 1.50 × 0.99), None when the table gives none (about 7 % of its rows)."""
    p = cec_module_parameters(module)
    try:
        size = float(p.get("Length", "")), float(p.get("Width", ""))
    except ValueError:
        return None
    return size if all(math.isfinite(x) and x > 0 for x in size) else None


def collector_size_m(array: ArrayConfig) -> tuple[float, float] | None:
    """Default outline (width, height) [m] of an array's collector: its modules landscape
    (long side horizontal), ceil(√N) across and as many rows as needed, :data:`MODULE_GAP_M`
    apart (4 KD205GX-LP: 2 × 2, 3.02 m × 2.00 m). None when the module has no size."""
    size = module_size_m(array.module)
    if size is None:
        return None
    across = math.ceil(math.sqrt(array.modules))
    rows = math.ceil(array.modules / across)
    return (across * size[0] + (across - 1) * MODULE_GAP_M,
            rows * size[1] + (rows - 1) * MODULE_GAP_M)


@dataclass(frozen=True, eq=False)
class Layout:
    """The tracker's collector and the fixed array in ENU [m], origin at the tracker's
    pedestal foot (:func:`layout_of`).

    ``fixed_axes`` columns: the fixed array's width axis u (horizontal), height axis v
    (up the slope) and front normal n = u × v.
    """

    tracker_mount_height_m: float
    tracker_size_m: tuple[float, float]
    fixed_centre_enu: FloatArray
    fixed_axes: FloatArray
    fixed_size_m: tuple[float, float]
    assumed: bool = False


def fixed_pose(surface_tilt: float, surface_azimuth: float, ground_enu: ArrayLike,
               lower_edge_m: float, height_m: float) -> tuple[FloatArray, FloatArray]:
    """Centre (ENU, m) and axes (columns u, v, n) of a fixed array whose centre is above
    ``ground_enu``, lower edge ``lower_edge_m`` above the ground; the axes are the D–H
    panel frame at the fixed normal (azimuth, 90° − tilt), as the tracker's collector."""
    rot = joint_transforms(surface_azimuth, 90.0 - surface_tilt, TrackerGeometry())[2][:3, :3]
    centre = np.asarray(ground_enu, dtype=float) + np.array(
        [0.0, 0.0, lower_edge_m + height_m / 2.0 * math.sin(math.radians(surface_tilt))])
    return centre, np.asarray(rot, dtype=float)


def layout_of(site: Site, assumed: tuple[Placement, Placement] | None = None
              ) -> Layout | None:
    """The site's layout from its placements (``Site.placements`` of ``tracker`` and
    ``fixed``); when it has none, from the ``assumed`` (tracker, fixed) placements
    (``Layout.assumed``), or None; None too without a tracker and a fixed array.

    Raises ValueError for a module with no size in pvlib's CEC table and no
    ``width_m``/``height_m``.
    """
    tracker, fixed = site.arrays.get("tracker"), site.arrays.get("fixed")
    if tracker is None or fixed is None:
        return None
    placed = (site.placements.get("tracker"), site.placements.get("fixed"))
    pt, pf = placed if None not in placed else assumed or (None, None)
    if pt is None or pf is None:
        return None

    def size(array: ArrayConfig, p: Placement) -> tuple[float, float]:
        default = collector_size_m(array)
        w = p.width_m if p.width_m is not None else default[0] if default else None
        h = p.height_m if p.height_m is not None else default[1] if default else None
        if w is None or h is None:
            raise ValueError(f"array {array.name!r}: module {array.module!r} has no size in "
                             "pvlib's CEC table: give width_m and height_m")
        return w, h

    fixed_size = size(fixed, pf)
    ground = (pf.position_east_m - pt.position_east_m, pf.position_north_m - pt.position_north_m,
              0.0)
    centre, axes = fixed_pose(
        fixed.surface_tilt, fixed.surface_azimuth, ground,
        FIXED_MOUNT_HEIGHT_M if pf.mount_height_m is None else pf.mount_height_m, fixed_size[1])
    return Layout(
        tracker_mount_height_m=(TRACKER_MOUNT_HEIGHT_M if pt.mount_height_m is None
                                else pt.mount_height_m),
        tracker_size_m=size(tracker, pt), fixed_centre_enu=centre, fixed_axes=axes,
        fixed_size_m=fixed_size, assumed=None in placed)


def tracker_panel_frames(layout: Layout, geometry: TrackerGeometry,
                         azimuth_joint_deg: ArrayLike, elevation_joint_deg: ArrayLike,
                         base: ArrayLike | None = None) -> FloatArray:
    """World transforms (..., 4, 4) of the tracker's panel frame (centre of the collector,
    x along its width, y up its slope, z its normal): :func:`sim.kinematics.joint_transforms`
    on the base frame {0} at ``tracker_mount_height_m``, turned by ``base`` (3 × 3, a
    disturbed pedestal, :func:`sim.disturbances.base_rotation`; default level)."""
    t0p = joint_transforms(azimuth_joint_deg, elevation_joint_deg, geometry)[2]
    world = np.eye(4)
    if base is not None:
        world[:3, :3] = np.asarray(base, dtype=float)
    world[2, 3] = layout.tracker_mount_height_m
    return np.asarray(world @ t0p, dtype=float)


@dataclass(frozen=True, eq=False)
class FixedShade:
    """The tracker's shade on the fixed array at each step (:func:`fixed_shade`).

    ``fraction`` (T,) [-]: shaded share of the fixed array's area, 0 without shade.
    ``polygon_enu`` (T, 9, 3) [m]: the shade's outline on the array (a convex polygon),
    its first ``vertices`` (T,) rows valid.
    """

    fraction: FloatArray
    polygon_enu: FloatArray
    vertices: NDArray[np.int64]


def _clip(poly: FloatArray, count: NDArray[np.int64], dist: FloatArray
          ) -> tuple[FloatArray, NDArray[np.int64]]:
    """Sutherland–Hodgman against one half-space, every row at once: the part of each convex
    polygon (rows of ``poly`` (T, K, D), first ``count`` vertices valid) where the signed
    distance ``dist`` (T, K) is ≥ 0. Returns (T, K + 1, D) and the new counts; only the rows
    that the boundary crosses are worked on (the others stay whole or vanish)."""
    t_n, k_n, _ = poly.shape
    valid = np.arange(k_n)[None, :] < count[:, None]
    inside = dist >= 0.0
    n_in = (inside & valid).sum(axis=1)
    out = np.concatenate([poly, poly[:, :1]], axis=1)
    new_count = np.where(n_in == count, count, 0)
    rows = np.nonzero((n_in > 0) & (n_in < count))[0]
    if len(rows) == 0:
        return out, new_count
    p, d, ok, ins = poly[rows], dist[rows], valid[rows], inside[rows]
    nxt = (np.arange(k_n)[None, :] + 1) % count[rows, None]
    b = np.take_along_axis(p, nxt[..., None], axis=1)
    db = np.take_along_axis(d, nxt, axis=1)
    crossing = ok & (ins != (db >= 0.0))
    t = np.where(crossing, d / np.where(crossing, d - db, 1.0), 0.0)
    cand = np.stack([p, p + (b - p) * t[..., None]], axis=2).reshape(len(rows), 2 * k_n, -1)
    keep = np.stack([ok & ins, crossing], axis=2).reshape(len(rows), 2 * k_n)
    order = np.argsort(~keep, axis=1, kind="stable")[:, :k_n + 1]
    out[rows] = np.take_along_axis(cand, order[..., None], axis=1)
    new_count[rows] = keep.sum(axis=1)
    return out, new_count


def _shoelace(poly: FloatArray, count: NDArray[np.int64]) -> FloatArray:
    """Signed area of each polygon (T, K, 2) with ``count`` valid vertices [m²]."""
    i = np.arange(poly.shape[1])
    nxt = (i[None, :] + 1) % np.maximum(count, 1)[:, None]
    b = np.take_along_axis(poly, nxt[..., None], axis=1)
    cross = poly[..., 0] * b[..., 1] - b[..., 0] * poly[..., 1]
    return np.asarray(0.5 * np.where(i[None, :] < count[:, None], cross, 0.0).sum(axis=1))


def fixed_shade(layout: Layout, panel_frames: ArrayLike, sun_enu: ArrayLike) -> FixedShade:
    """The tracker collector's shade on the fixed array (module docstring).

    Parameters
    ----------
    layout : Layout
        Where the arrays stand and their sizes (:func:`layout_of`).
    panel_frames : array_like, shape (T, 4, 4)
        The tracker's panel frame at each step (:func:`tracker_panel_frames`).
    sun_enu : array_like, shape (T, 3)
        Unit vector towards the sun at each step (ENU).

    Returns
    -------
    FixedShade
    """
    frames = np.asarray(panel_frames, dtype=float).reshape(-1, 4, 4)
    s = np.asarray(sun_enu, dtype=float).reshape(-1, 3)
    t_n = len(s)
    c, axes = layout.fixed_centre_enu, layout.fixed_axes
    u, v, n = axes[:, 0], axes[:, 1], axes[:, 2]
    (wf, hf), (wt, ht) = layout.fixed_size_m, layout.tracker_size_m
    fraction = np.zeros(t_n)
    polygon = np.zeros((t_n, 9, 3))
    vertices = np.zeros(t_n, dtype=np.int64)
    sn = s @ n
    d = frames[:, :3, 3] - c
    along = np.einsum("tk,tk->t", d, s)
    reach = (math.hypot(wf, hf) + math.hypot(wt, ht)) / 2.0
    perp2 = np.einsum("tk,tk->t", d, d) - along**2
    idx = np.nonzero((s[:, 2] > 0.0) & (sn > 0.0) & (along > -reach) & (perp2 < reach**2))[0]
    if len(idx) == 0:
        return FixedShade(fraction, polygon, vertices)
    f, s_k, sn_k = frames[idx], s[idx], sn[idx]
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * (wt / 2, ht / 2)
    caster = (f[:, None, :3, 3] + corners[None, :, :1] * f[:, None, :3, 0]
              + corners[None, :, 1:] * f[:, None, :3, 1])          # (k, 4, 3)
    count = np.full(len(idx), 4, dtype=np.int64)
    caster, count = _clip(caster, count, (caster - c) @ n)       # the part in front
    lam = ((caster - c) @ n) / sn_k[:, None]
    hit = caster - lam[..., None] * s_k[:, None, :] - c
    uv = np.stack([hit @ u, hit @ v], axis=-1)
    for axis, half in ((0, wf / 2), (1, hf / 2)):
        uv, count = _clip(uv, count, half - uv[..., axis])
        uv, count = _clip(uv, count, half + uv[..., axis])
    area = np.abs(_shoelace(uv, count))
    fraction[idx] = np.minimum(area / (wf * hf), 1.0)
    count[area <= 0.0] = 0
    vertices[idx] = count
    k = uv.shape[1]
    polygon[idx, :k] = c + uv[..., :1] * u + uv[..., 1:] * v
    return FixedShade(fraction, polygon, vertices)
