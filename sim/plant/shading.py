"""Inter-shading of a plant of dual-axis trackers (seed 004 §2.1), vectorised over time.

Seed 004 (Fernández-Ahumada et al., Sensors 2021, 21, 726, §2.1, Fig. 1–2) decides
with a Boolean whether an orientation (γ, α) of the collectors causes
inter-shading at a sun position, from the collector size a × b, the tracker
positions, the sun vector s (eq. 1), the collector normal n (eq. 4) and the
in-plane unit vectors u (horizontal, eq. 5) and v (eq. 6). This module computes
that Boolean and, beyond the seed, the shaded *fraction* of every collector.

Geometry (collectors parallel: every tracker has the same orientation at a
time step, as seed 004's position server sends one orientation to all). A
point X of collector i is shaded by collector j when the ray X + λ s (λ > 0)
hits j. With d = p_j − p_i, λ = (d·n)/(s·n) and j's rectangle, projected along
s onto i's plane, is i's rectangle shifted by the in-plane coordinates of
P = d − λ s: (P·u, P·v). The shade is the intersection of two axis-aligned
rectangles in (u, v); the shade of several neighbours is their union, whose area
is computed exactly on the grid of the rectangles' edges.

A necessary condition that does not depend on the orientation prunes the
neighbour pairs first: the shifted rectangle can only overlap when |P| is
below the collector's diagonal, and |P| ≥ |d⊥|, the distance of d from the
sun ray (P and d differ by a multiple of s).

Times where the sun is below the horizon give NaN fractions. A collector whose
front faces away from the sun (s·n ≤ 0) receives no beam and counts as unshaded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.sphere import enu_from_sky

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_CHUNK = 20_000
_EPS_AREA_M2 = 1e-9
_IE_MAX = 4  # inclusion–exclusion up to this many rectangles, edge grid beyond


def collector_axes(azimuth: ArrayLike, elevation: ArrayLike) -> tuple[FloatArray, ...]:
    """Collector normal n and in-plane unit vectors u, v in ENU (seed 004 eqs. 4–6).

    Parameters
    ----------
    azimuth : array_like
        Azimuth of the collector normal [°], clockwise from north.
    elevation : array_like
        Elevation of the collector normal above the horizon [°] (seed 004's α;
        surface tilt = 90° − elevation).

    Returns
    -------
    n, u, v : numpy.ndarray, shape (..., 3)
        n the normal (eq. 4), u horizontal in the plane (eq. 5: the collector's
        width, pointing to the right when facing the collector's front),
        v = u × n in the plane pointing up-slope (eq. 6: the collector's height).
    """
    az = np.radians(np.asarray(azimuth, dtype=float))
    n = enu_from_sky(azimuth, elevation)
    u = np.stack([-np.cos(az), np.sin(az), np.zeros_like(az)], axis=-1)
    v = np.cross(u, n)
    return n, u, v


def candidate_pairs(positions: ArrayLike, sun_enu: ArrayLike,
                    diagonal: float) -> tuple[IntArray, IntArray, IntArray]:
    """Pairs (step, i, j) where collector j may shade collector i, whatever the orientation.

    Keeps the pairs with |d⊥| < diagonal (d = p_j − p_i, d⊥ its part
    perpendicular to the sun vector) and d·s > −diagonal (j not behind i as
    seen from the sun); every other pair is certainly unshaded (module docstring).

    Parameters
    ----------
    positions : array_like, shape (N, 3)
        Pivot positions, ENU [m].
    sun_enu : array_like, shape (T, 3)
        Unit vectors towards the sun.
    diagonal : float
        Collector diagonal [m].

    Returns
    -------
    step, i, j : numpy.ndarray of int
        Indices of the candidate pairs, sorted by step then i.
    """
    p = np.asarray(positions, dtype=float)
    s = np.asarray(sun_enu, dtype=float).reshape(-1, 3)
    n = len(p)
    ii, jj = np.triu_indices(n, 1)
    d = p[jj] - p[ii]                                   # (P, 3), i < j
    d2 = np.einsum("pk,pk->p", d, d)
    thr = d2 - diagonal**2
    empty = np.zeros(0, dtype=np.int64)
    if not len(d):
        return empty, empty, empty
    # |d⊥| ≥ |d| sin(angle(d, s)) ≥ |d| sin(elevation − steepest offset): skip high suns
    slope = float(np.max(np.abs(np.arcsin(np.clip(d[:, 2] / np.sqrt(d2), -1, 1)))))
    ratio = diagonal / float(np.sqrt(d2.min()))
    el_max = np.arcsin(min(1.0, ratio)) + slope if ratio < 1 else np.pi
    steps = np.nonzero(np.arcsin(np.clip(s[:, 2], -1, 1)) < el_max)[0]
    out_t, out_i, out_j = [], [], []
    for k0 in range(0, len(steps), _CHUNK):
        st = steps[k0:k0 + _CHUNK]
        ds = s[st] @ d.T                                # (T, P)
        near = (ds * ds > thr) | (thr < 0)              # |d⊥| < diagonal, both directions
        fwd = near & (ds > -diagonal)                   # j may shade i
        bwd = near & (ds < diagonal)                    # i may shade j
        t, q = np.nonzero(fwd)
        out_t.append(st[t])
        out_i.append(ii[q])
        out_j.append(jj[q])
        t, q = np.nonzero(bwd)
        out_t.append(st[t])
        out_i.append(jj[q])
        out_j.append(ii[q])
    if not out_t:
        return empty, empty, empty
    t_all = np.concatenate(out_t).astype(np.int64)
    i_all = np.concatenate(out_i).astype(np.int64)
    j_all = np.concatenate(out_j).astype(np.int64)
    order = np.lexsort((j_all, i_all, t_all))
    return t_all[order], i_all[order], j_all[order]


def _direct_pairs(positions: FloatArray, sun: FloatArray, surface_az: FloatArray,
                  surface_el: FloatArray, width: float, height: float
                  ) -> tuple[IntArray, IntArray, IntArray, FloatArray]:
    """Shading pairs and their rectangles for a common orientation, all pairs at once.

    With d = p_j − p_i: λ = (d·n)/(s·n) and (du, dv) = (d·u − λ s·u, d·v − λ s·v)
    are linear in d, so three products (steps × 3)·(3 × pairs) give them for every
    unordered pair; the reverse direction is (−du, −dv) with −λ, and the
    direction with λ > 0 is the one that can shade. Only steps with the sun
    below the layout's bound (see :func:`candidate_pairs`; tighter for collectors
    facing the sun) are looked at.
    """
    n_tr = len(positions)
    ii, jj = np.triu_indices(n_tr, 1)
    d64 = positions[jj] - positions[ii]
    empty_i = np.zeros(0, dtype=np.int64)
    if not len(d64):
        return empty_i, empty_i, empty_i, np.zeros((0, 4))
    d2 = np.einsum("pk,pk->p", d64, d64)
    slope = float(np.max(np.abs(np.arcsin(np.clip(d64[:, 2] / np.sqrt(d2), -1, 1)))))
    ratio = np.hypot(width, height) / float(np.sqrt(d2.min()))
    el_max = np.arcsin(ratio) + slope if ratio < 1 else np.pi
    # facing the sun, |dv| = sin(elevation)·|d·ĥ| ≥ sin(elevation)·√(|d|² − a²): tighter
    d_min = float(np.sqrt(d2.min()))
    el_facing = (np.arcsin(min(1.0, height / np.sqrt(d_min**2 - width**2))) + slope
                 if d_min > width else np.pi)
    facing = np.einsum("tk,tk->t", sun, enu_from_sky(surface_az, surface_el)) > 1 - 1e-12
    sun_el = np.arcsin(np.clip(sun[:, 2], -1, 1))
    steps = np.nonzero(sun_el < np.where(facing, min(el_facing, el_max), el_max))[0]
    d = d64.T.astype(np.float32)                                    # (3, P)
    n, u, v = collector_axes(surface_az[steps], surface_el[steps])
    s = sun[steps]
    sn = np.einsum("tk,tk->t", s, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        ru = np.where(sn > 0, np.einsum("tk,tk->t", s, u) / sn, np.nan)
        rv = np.where(sn > 0, np.einsum("tk,tk->t", s, v) / sn, np.nan)
    out: list[list[NDArray[np.generic]]] = [[], [], [], [], []]
    for k0 in range(0, len(steps), _CHUNK):
        sl = slice(k0, k0 + _CHUNK)
        dn = n[sl].astype(np.float32) @ d                           # λ·(s·n)
        du = u[sl].astype(np.float32) @ d - ru[sl, None].astype(np.float32) * dn
        dv = v[sl].astype(np.float32) @ d - rv[sl, None].astype(np.float32) * dn
        # float32 screen with a margin; the survivors are recomputed in float64
        hit = (np.abs(du) < width + 1e-3) & (np.abs(dv) < height + 1e-3) & (dn != 0)
        t, q = np.nonzero(hit)
        tt = k0 + t
        dq = d64[q]
        lam_sign = np.einsum("mk,mk->m", dq, n[tt])
        fwd = lam_sign > 0                    # j (at +d) is in front of i's plane: j shades i
        dq = dq * np.where(fwd, 1.0, -1.0)[:, None]
        lam = np.einsum("mk,mk->m", dq, n[tt]) / sn[tt]
        proj = dq - lam[:, None] * s[tt]
        out[0].append(steps[tt])
        out[1].append(np.where(fwd, ii[q], jj[q]))
        out[2].append(np.where(fwd, jj[q], ii[q]))
        out[3].append(np.einsum("mk,mk->m", proj, u[tt]))
        out[4].append(np.einsum("mk,mk->m", proj, v[tt]))
    if not out[0]:
        return empty_i, empty_i, empty_i, np.zeros((0, 4))
    t_all, i_all, j_all, du_all, dv_all = (np.concatenate(x) for x in out)
    a2, b2 = width / 2, height / 2
    rects = np.stack([np.maximum(-a2, du_all - a2), np.minimum(a2, du_all + a2),
                      np.maximum(-b2, dv_all - b2), np.minimum(b2, dv_all + b2)], axis=-1)
    keep = ((rects[:, 1] - rects[:, 0]) * (rects[:, 3] - rects[:, 2]) > _EPS_AREA_M2) \
        & (rects[:, 1] > rects[:, 0]) & (rects[:, 3] > rects[:, 2])
    order = np.lexsort((j_all[keep], i_all[keep], t_all[keep]))
    return (t_all[keep][order].astype(np.int64), i_all[keep][order].astype(np.int64),
            j_all[keep][order].astype(np.int64), rects[keep][order])


def pair_shade_rects(positions: ArrayLike, sun_enu: ArrayLike, normal_az: ArrayLike,
                     normal_el: ArrayLike, width: float, height: float, step: IntArray,
                     i: IntArray, j: IntArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Shade of collector j on collector i as a rectangle in i's (u, v) coordinates.

    Parameters
    ----------
    positions : array_like, shape (N, 3)
        Pivot positions, ENU [m].
    sun_enu : array_like, shape (T, 3)
        Sun unit vectors.
    normal_az, normal_el : array_like, shape (T,)
        Common collector orientation at each step [°].
    width, height : float
        Collector size [m].
    step, i, j : numpy.ndarray of int
        The pairs (from :func:`candidate_pairs`).

    Returns
    -------
    rects : numpy.ndarray, shape (M, 4)
        (u0, u1, v0, v1) [m] of the shaded part of i, collector centred on (0, 0).
    shading : numpy.ndarray of bool, shape (M,)
        True where the shade has positive area.
    """
    p = np.asarray(positions, dtype=float)
    s = np.asarray(sun_enu, dtype=float).reshape(-1, 3)[step]
    n, u, v = collector_axes(np.asarray(normal_az, dtype=float).reshape(-1)[step],
                             np.asarray(normal_el, dtype=float).reshape(-1)[step])
    d = p[j] - p[i]
    sn = np.einsum("mk,mk->m", s, n)
    dn = np.einsum("mk,mk->m", d, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = dn / sn
    proj = d - lam[:, None] * s
    du = np.einsum("mk,mk->m", proj, u)
    dv = np.einsum("mk,mk->m", proj, v)
    a2, b2 = width / 2, height / 2
    u0 = np.maximum(-a2, du - a2)
    u1 = np.minimum(a2, du + a2)
    v0 = np.maximum(-b2, dv - b2)
    v1 = np.minimum(b2, dv + b2)
    shading = (sn > 0) & (lam > 0) & ((u1 - u0) * (v1 - v0) > _EPS_AREA_M2) \
        & (u1 > u0) & (v1 > v0)
    return np.stack([u0, u1, v0, v1], axis=-1), shading


def union_area(rects: ArrayLike, clip: ArrayLike | None = None) -> FloatArray:
    """Exact area [m²] of the union of axis-aligned rectangles, per group.

    Parameters
    ----------
    rects : array_like, shape (G, K, 4)
        (u0, u1, v0, v1); empty slots have u1 ≤ u0 or v1 ≤ v0.
    clip : array_like, shape (4,) or (G, 4), optional
        Count only the part inside this rectangle.

    Returns
    -------
    numpy.ndarray, shape (G,)
    """
    r = np.array(rects, dtype=float)
    if clip is not None:
        c = np.broadcast_to(np.asarray(clip, dtype=float), (r.shape[0], 4))[:, None, :]
        r[..., 0] = np.maximum(r[..., 0], c[..., 0])
        r[..., 1] = np.minimum(r[..., 1], c[..., 1])
        r[..., 2] = np.maximum(r[..., 2], c[..., 2])
        r[..., 3] = np.minimum(r[..., 3], c[..., 3])
    valid = (r[..., 1] > r[..., 0]) & (r[..., 3] > r[..., 2])
    # bucket the groups by the slot of their last non-empty rectangle; empty rectangles
    # before it add nothing to either union formula
    last = np.where(valid.any(axis=1), r.shape[1] - np.argmax(valid[:, ::-1], axis=1), 0)
    out = np.zeros(len(r))
    for k in np.unique(last):
        if k == 0:
            continue
        g = np.nonzero(last == k)[0]
        sub = r[g, :k]
        out[g] = (_union_inclusion_exclusion(sub) if k <= _IE_MAX
                  else _union_grid(sub, valid[g, :k]))
    return out


def _union_grid(r: FloatArray, valid: NDArray[np.bool_]) -> FloatArray:
    """Union area of rectangles ``(G, K, 4)`` (``valid`` the non-empty ones) on their edge grid."""
    xs = np.sort(r[..., :2].reshape(len(r), -1), axis=1)       # (G, 2K)
    ys = np.sort(r[..., 2:].reshape(len(r), -1), axis=1)
    cx = (xs[:, 1:] + xs[:, :-1]) / 2                           # (G, 2K−1)
    cy = (ys[:, 1:] + ys[:, :-1]) / 2
    dx = np.diff(xs, axis=1)
    dy = np.diff(ys, axis=1)
    inx = (cx[:, :, None] > r[:, None, :, 0]) & (cx[:, :, None] < r[:, None, :, 1]) \
        & valid[:, None, :]                                     # (G, X, K)
    iny = (cy[:, :, None] > r[:, None, :, 2]) & (cy[:, :, None] < r[:, None, :, 3])
    covered = np.einsum("gxk,gyk->gxy", inx.astype(np.float64), iny.astype(np.float64)) > 0
    return np.einsum("gxy,gx,gy->g", covered.astype(np.float64), dx, dy)


def _union_inclusion_exclusion(r: FloatArray) -> FloatArray:
    """Union area of few rectangles per group: Σ over subsets (−1)^(|S|+1) |∩S|."""
    k = r.shape[1]
    total = np.zeros(len(r))
    for mask in range(1, 1 << k):
        members = [m for m in range(k) if mask >> m & 1]
        sub = r[:, members]
        w = np.clip(sub[..., 1].min(axis=1) - sub[..., 0].max(axis=1), 0.0, None)
        h = np.clip(sub[..., 3].min(axis=1) - sub[..., 2].max(axis=1), 0.0, None)
        total += (1.0 if len(members) % 2 else -1.0) * w * h
    return total


@dataclass(frozen=True)
class PlantShade:
    """Shade on every collector at every step (common orientation per step).

    Attributes
    ----------
    fraction : numpy.ndarray, shape (T, N)
        Shaded fraction of each collector's area [-]; NaN with the sun down.
    group_step, group_tracker : numpy.ndarray of int, shape (G,)
        The (step, tracker) of each shaded collector.
    group_rects : numpy.ndarray, shape (G, K, 4)
        The shade rectangles (u0, u1, v0, v1) [m] on that collector (padded with empties).
    group_by : numpy.ndarray of int, shape (G, K)
        Index of the shading tracker of each rectangle (−1 for padding).
    """

    fraction: FloatArray
    group_step: IntArray
    group_tracker: IntArray
    group_rects: FloatArray
    group_by: IntArray

    @property
    def shaded(self) -> NDArray[np.bool_]:
        """Seed 004's Boolean per collector and step: some of it is shaded."""
        return np.nan_to_num(self.fraction) > 0

    def shaded_by(self, step: int, tracker: int) -> list[int]:
        """Indices of the trackers that shade ``tracker`` at ``step``."""
        g = np.nonzero((self.group_step == step) & (self.group_tracker == tracker))[0]
        if not len(g):
            return []
        return sorted(int(b) for b in self.group_by[g[0]] if b >= 0)


def plant_shade(positions: ArrayLike, solar_azimuth: ArrayLike, solar_elevation: ArrayLike,
                surface_azimuth: ArrayLike, surface_elevation: ArrayLike, width: float,
                height: float) -> PlantShade:
    """Shaded fraction of every collector of a plant at every step (seed 004 §2.1 geometry).

    Parameters
    ----------
    positions : array_like, shape (N, 3)
        Pivot positions, ENU [m] (collectors centred on them).
    solar_azimuth, solar_elevation : array_like, shape (T,)
        Sun direction [°] (azimuth clockwise from north). Use the apparent
        elevation: the shade follows the refracted ray.
    surface_azimuth, surface_elevation : array_like, shape (T,)
        The collectors' common orientation: azimuth and elevation of the normal [°].
        For sun tracking pass the sun's own angles.
    width, height : float
        Collector size [m] (seed 004: a, b).

    Returns
    -------
    PlantShade
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"positions must have shape (N, 3), got {p.shape}")
    az = np.atleast_1d(np.asarray(solar_azimuth, dtype=float))
    el = np.atleast_1d(np.asarray(solar_elevation, dtype=float))
    saz = np.broadcast_to(np.asarray(surface_azimuth, dtype=float), az.shape)
    sel = np.broadcast_to(np.asarray(surface_elevation, dtype=float), az.shape)
    if el.shape != az.shape:
        raise ValueError("solar_azimuth and solar_elevation must have the same shape")
    n_t, n = len(az), len(p)
    fraction = np.zeros((n_t, n))
    up = el > 0
    fraction[~up] = np.nan
    sun = enu_from_sky(az, el)
    upi = np.nonzero(up)[0]
    t, i, j, rects = _direct_pairs(p, sun[upi], saz[upi], sel[upi], width, height)
    t = upi[t]
    key = t * n + i
    order = np.argsort(key, kind="stable")
    key, j, rects = key[order], j[order], rects[order]
    gkey, start, count = np.unique(key, return_index=True, return_counts=True)
    kmax = int(count.max()) if len(count) else 1
    g_rects = np.zeros((len(gkey), kmax, 4))
    g_by = np.full((len(gkey), kmax), -1, dtype=np.int64)
    slot = np.arange(len(key)) - np.repeat(start, count)
    gidx = np.repeat(np.arange(len(gkey)), count)
    g_rects[gidx, slot] = rects
    g_by[gidx, slot] = j
    area = np.zeros(len(gkey))
    for k in np.unique(count):
        sel_g = count == k
        area[sel_g] = union_area(g_rects[sel_g, :k])
    g_step, g_tracker = gkey // n, gkey % n
    fraction[g_step, g_tracker] = np.minimum(area / (width * height), 1.0)
    return PlantShade(fraction, g_step.astype(np.int64), g_tracker.astype(np.int64),
                      g_rects, g_by)


def shades_anyone(positions: ArrayLike, solar_azimuth: ArrayLike, solar_elevation: ArrayLike,
                  surface_azimuth: ArrayLike, surface_elevation: ArrayLike, width: float,
                  height: float) -> NDArray[np.bool_]:
    """Seed 004's Boolean for the whole plant: does this orientation shade any collector?

    Same arguments as :func:`plant_shade`, all broadcast to one shape ``(M,)``
    (e.g. one sun position against a grid of candidate orientations). False
    with the sun down.
    """
    p = np.asarray(positions, dtype=float)
    arrs = np.broadcast_arrays(*(np.atleast_1d(np.asarray(x, dtype=float)) for x in
                                 (solar_azimuth, solar_elevation, surface_azimuth,
                                  surface_elevation)))
    az, el, saz, sel = (a.reshape(-1) for a in arrs)
    out = np.zeros(len(az), dtype=bool)
    up = np.nonzero(el > 0)[0]
    if not len(up):
        return out
    sun = enu_from_sky(az[up], el[up])
    t, i, j = candidate_pairs(p, sun, float(np.hypot(width, height)))
    _, shading = pair_shade_rects(p, sun, saz[up], sel[up], width, height, t, i, j)
    out[up[np.unique(t[shading])]] = True
    return out
