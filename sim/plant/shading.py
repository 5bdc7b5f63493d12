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
is computed exactly (inclusion–exclusion, or the grid of the rectangles' edges).

Which pairs to look at. |P| < a² + b² (the diagonal D) is needed for an
overlap, and |P| ≥ |d⊥|, the distance of d from the sun ray, whatever the
orientation. The sky is cut into bins of 1° in azimuth × 0.5° in elevation; a
pair is a candidate in a bin when some sun direction inside it can have
|d⊥| < D (the bin's centre with its angular radius as margin). For collectors
facing the sun (n = s) the test is the exact one, |d·u| < a and |d·v| < b, with
a margin of |d| times the bin's largest change of u and v. Only the candidates
of each step's bin are computed exactly; the table is built for the bins the
steps fall in, and a :class:`BinTable` keeps it for the next call (a long run
in chunks of time meets the same bins every day).

Times where the sun is below the horizon give NaN fractions. A collector whose
front faces away from the sun (s·n ≤ 0) receives no beam and counts as unshaded.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.kinematics import panel_axes
from sim.plant.layout import polygon_area
from vision.sphere import enu_from_sky, sky_from_enu

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_EPS_AREA_M2 = 1e-9
_IE_MAX = 8  # inclusion–exclusion up to this many rectangles, edge grid beyond
_BIN_AZ_DEG, _BIN_EL_DEG = 1.0, 0.5
_FACING_COS = 1 - 1e-12  # n·s above this: the collectors face the sun
_CHUNK = 200_000  # candidates computed at once (bounded memory, temporaries in cache)
_BIN_BLOCK = 128  # sun bins of the candidate table computed at once (in cache)


def collector_axes(azimuth: ArrayLike, elevation: ArrayLike) -> tuple[FloatArray, ...]:
    """Collector normal n and in-plane unit vectors u, v in ENU (seed 004 eqs. 4–6).

    The panel frame of :func:`sim.kinematics.panel_axes` — the frame the twin
    (:func:`sim.array_shade.tracker_panel_frames`) and the 3D scene pose a collector
    with — in seed 004's names.

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
        v = n × u in the plane pointing up-slope (eq. 6: the collector's height),
        so that (u, v, n) is right-handed and v grows from the collector's lower
        edge to its upper edge (the strings of :class:`sim.plant.layout.Collector`,
        bottom to top).
    """
    u, v, n = panel_axes(azimuth, elevation)
    return n, u, v


def pair_vectors(positions: ArrayLike) -> tuple[IntArray, IntArray, FloatArray]:
    """Unordered pairs i < j of a layout and their offsets d = p_j − p_i [m], shape (P, 3)."""
    p = np.asarray(positions, dtype=float)
    ii, jj = np.triu_indices(len(p), 1)
    return ii.astype(np.int64), jj.astype(np.int64), p[jj] - p[ii]


#: How a step's orientation is known to the bin test (:func:`pair_candidates`).
GENERIC, FACING, FIXED = 0, 1, 2


def _bin_table(d: FloatArray, az_c: FloatArray, el_c: FloatArray, mode: IntArray,
               width: float, height: float, normal: FloatArray | None) -> NDArray[np.bool_]:
    """Candidate pairs ``(B, P)`` of sun bins centred on (az_c, el_c) [°] (module docstring).

    ``mode`` per bin: any orientation (|d⊥| < D); facing the sun (|d·u| < a,
    |d·v| < b, u and v move by at most 2 h_a + h_e in the bin); or the constant
    orientation ``normal`` = (n, u, v): (du, dv) at the bin's centre, which move
    by at most |d·n|·ρ/(s·n)²_min (the gradient of (s·u)/(s·n) is ≤ 1/(s·n)²).

    The |d⊥| test needs no trigonometry per bin: with α the angle between the sun
    and the line of d, |d⊥| = |d| sin α can drop below D somewhere in the bin
    exactly when α < ρ + arcsin(min(1, D/|d|)) =: α_max, a bound of the pair alone,
    i.e. when |s·d| > |d| cos α_max (every α passes when α_max ≥ 90°). Bins are
    done in blocks, so that the (bins × pairs) temporaries stay in cache.
    """
    h_a, h_e = np.radians(_BIN_AZ_DEG / 2), np.radians(_BIN_EL_DEG / 2)
    rho = h_a + h_e                   # angular radius of a bin (parallel, then meridian)
    length = np.sqrt(np.einsum("pk,pk->p", d, d))
    diag = np.hypot(width, height)
    alpha_max = rho + np.arcsin(np.minimum(1.0, diag / length))
    min_dot = np.where(alpha_max < np.pi / 2, length * np.cos(alpha_max), -1.0)   # (P,)
    slack = 1.5e-6                    # facing: n within arccos(_FACING_COS) of s
    lim_u = width + length * (h_a + slack)
    lim_v = height + length * (2 * h_a + h_e + 2 * slack)
    if normal is not None:
        n, u, v = normal
        dn, du0, dv0 = d @ n, d @ u, d @ v                              # (P,)
    ok = np.empty((len(az_c), len(d)), dtype=bool)
    for b0 in range(0, len(az_c), _BIN_BLOCK):
        blk = slice(b0, b0 + _BIN_BLOCK)
        s_c = enu_from_sky(az_c[blk], el_c[blk])
        out = np.abs(s_c @ d.T) > min_dot                               # |d⊥| < D
        f = np.nonzero(mode[blk] == FACING)[0]
        if len(f):
            _, u_f, v_f = collector_axes(az_c[blk][f], el_c[blk][f])
            out[f] &= (np.abs(u_f @ d.T) < lim_u) & (np.abs(v_f @ d.T) < lim_v)
        f = np.nonzero(mode[blk] == FIXED)[0]
        if len(f) and normal is not None:
            sn = s_c[f] @ n
            lower = sn - rho
            bounded = lower > 0
            with np.errstate(divide="ignore", invalid="ignore"):
                ru, rv = (s_c[f] @ u) / sn, (s_c[f] @ v) / sn
                margin = np.abs(dn)[None, :] * (rho / lower**2)[:, None]
            near = (np.abs(du0[None, :] - ru[:, None] * dn[None, :]) < width + margin) \
                & (np.abs(dv0[None, :] - rv[:, None] * dn[None, :]) < height + margin)
            out[f] &= near | ~bounded[:, None]
            out[f[sn + rho <= 0]] = False   # the sun behind the collectors in the whole bin
        ok[blk] = out
    return ok


@dataclass
class _BinRows:
    """Candidate pairs of the bins built so far, for one layout, size and orientation:
    bin ``key[b]`` (sorted) holds ``pairs[start[b]:start[b] + count[b]]``."""

    key: IntArray
    start: IntArray
    count: IntArray
    pairs: IntArray


class BinTable:
    """The candidate pairs of every sun bin built so far (:func:`pair_candidates`).

    A run split into chunks of time (:func:`sim.plant.simulate.simulate_plant`)
    meets the same sun bins again every day; with one ``BinTable`` passed to every
    chunk each bin's candidates are worked out once. A bin keeps the indices of
    its candidate pairs (a few per cent of all pairs), per layout, collector size
    and constant orientation, so one table serves several orientation series
    (the tracking plant and the fixed plant).
    """

    def __init__(self) -> None:
        self._rows: dict[bytes, _BinRows] = {}

    def lookup(self, key: IntArray, d: FloatArray, az_c: FloatArray, el_c: FloatArray,
               mode: IntArray, width: float, height: float, normal: FloatArray | None
               ) -> tuple[IntArray, IntArray, IntArray]:
        """Candidates of the bins ``key`` (sorted, unique; centres ``az_c``, ``el_c`` [°],
        ``mode`` as :func:`_bin_table`), building the bins not kept yet.

        Returns ``start``, ``count`` (per bin) and ``pairs``: bin b's candidate pair
        indices are ``pairs[start[b]:start[b] + count[b]]``, increasing.
        """
        tag = b"".join([d.tobytes(), np.array([width, height]).tobytes(),
                        b"" if normal is None else np.asarray(normal, dtype=float).tobytes()])
        empty = np.zeros(0, dtype=np.int64)
        rows = self._rows.get(tag) or _BinRows(empty, empty, empty, empty)
        pos = np.searchsorted(rows.key, key)
        new = pos >= len(rows.key)
        new[~new] = rows.key[pos[~new]] != key[~new]
        if new.any():
            b_of, q_of = np.nonzero(_bin_table(d, az_c[new], el_c[new], mode[new], width,
                                               height, normal))           # sorted by bin
            count = np.bincount(b_of, minlength=int(new.sum()))
            start = len(rows.pairs) + np.cumsum(count) - count
            order = np.argsort(np.concatenate([rows.key, key[new]]), kind="stable")
            rows = _BinRows(np.concatenate([rows.key, key[new]])[order],
                            np.concatenate([rows.start, start])[order],
                            np.concatenate([rows.count, count])[order],
                            np.concatenate([rows.pairs, q_of.astype(np.int64)]))
            self._rows[tag] = rows
            pos = np.searchsorted(rows.key, key)
        return rows.start[pos], rows.count[pos], rows.pairs


def pair_candidates(d: FloatArray, sun: FloatArray, mode: IntArray, width: float,
                height: float, normal: FloatArray | None = None,
                table: BinTable | None = None) -> tuple[IntArray, IntArray]:
    """(step, unordered pair) that may shade, from the table of the steps' sun bins.

    ``d`` from :func:`pair_vectors`; ``sun`` (T, 3) unit vectors; ``mode`` (T,)
    GENERIC (any orientation), FACING (collectors on the sun) or FIXED (the
    constant orientation ``normal`` = stacked n, u, v); ``table`` keeps the bins'
    candidates for the next call. Returns (step, pair index), sorted by step.

    Steps with the sun above the layout's bound are dropped first: no pair can
    overlap when |d|·sin(elevation − steepest pair slope) ≥ D, and facing the
    sun |dv| ≥ sin(elevation − slope)·√(|d|² − a²) must stay below b.
    """
    if not len(d):                           # one collector: no pair to shade
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    n_az = int(round(360 / _BIN_AZ_DEG))
    d2 = np.einsum("pk,pk->p", d, d)
    slope = float(np.max(np.abs(np.arcsin(np.clip(d[:, 2] / np.sqrt(d2), -1, 1)))))
    d_min = float(np.sqrt(d2.min()))
    ratio = np.hypot(width, height) / d_min
    el_max = np.arcsin(ratio) + slope if ratio < 1 else np.pi
    el_facing = (np.arcsin(min(1.0, height / np.sqrt(d_min**2 - width**2))) + slope
                 if d_min > width else np.pi)
    el_rad = np.arcsin(np.clip(sun[:, 2], -1, 1))
    low = np.nonzero(el_rad < np.where(mode == FACING, min(el_facing, el_max), el_max))[0]
    sun, mode = sun[low], mode[low]
    az, el = sky_from_enu(sun)
    ka = np.minimum((az / _BIN_AZ_DEG).astype(np.int64), n_az - 1)
    ke = np.floor((el + 90.0) / _BIN_EL_DEG).astype(np.int64)
    key = (ke * n_az + ka) * 3 + mode
    ukey, inv = np.unique(key, return_inverse=True)
    ub = ukey // 3
    start, count, pairs = (table if table is not None else BinTable()).lookup(
        ukey, d, ((ub % n_az) + 0.5) * _BIN_AZ_DEG, ((ub // n_az) + 0.5) * _BIN_EL_DEG - 90.0,
        ukey % 3, width, height, normal)
    count, start = count[inv], start[inv]                                 # per step
    steps = np.repeat(low.astype(np.int64), count)
    first = np.repeat(start - np.cumsum(count) + count, count)
    return steps, pairs[first + np.arange(len(steps), dtype=np.int64)]


def candidate_pairs(positions: ArrayLike, sun_enu: ArrayLike,
                    diagonal: float) -> tuple[IntArray, IntArray, IntArray]:
    """Pairs (step, i, j) where collector j may shade collector i, whatever the orientation.

    Keeps the pairs whose sun bin allows |d⊥| < diagonal (d = p_j − p_i, d⊥ its
    part perpendicular to the sun vector; module docstring) and d·s > −diagonal
    (j not behind i as seen from the sun); every other pair is certainly unshaded.

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
    s = np.asarray(sun_enu, dtype=float).reshape(-1, 3)
    ii, jj, d = pair_vectors(positions)
    empty = np.zeros(0, dtype=np.int64)
    if not len(d) or not len(s):
        return empty, empty, empty
    # the bin test with a square collector of the same diagonal is the |d⊥| test alone
    t, q = pair_candidates(d, s, np.full(len(s), GENERIC), diagonal, 0.0)
    ds = np.einsum("mk,mk->m", s[t], d[q])
    fwd, bwd = ds > -diagonal, ds < diagonal
    t_all = np.concatenate([t[fwd], t[bwd]])
    i_all = np.concatenate([ii[q[fwd]], jj[q[bwd]]])
    j_all = np.concatenate([jj[q[fwd]], ii[q[bwd]]])
    order = np.lexsort((j_all, i_all, t_all))
    return t_all[order], i_all[order], j_all[order]


def _direct_pairs(positions: FloatArray, sun: FloatArray, surface_az: FloatArray,
                  surface_el: FloatArray, bounds: tuple[float, float, float, float],
                  table: BinTable | None = None
                  ) -> tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]:
    """Shading pairs for a common orientation per step: (step, i, j), the rectangle
    (u0, u1, v0, v1) where the two collectors' bounding boxes ``bounds`` overlap on i (the
    shade itself for a rectangle), and the shift (du, dv) of j's projection on i's plane.

    With d = p_j − p_i: λ = (d·n)/(s·n) and (du, dv) = (d·u − λ s·u, d·v − λ s·v);
    the reverse direction is (−du, −dv) with −λ, and the direction with λ > 0
    is the one that can shade. Only each step's candidate pairs are computed.
    """
    u_lo, u_hi, v_lo, v_hi = bounds
    width, height = u_hi - u_lo, v_hi - v_lo
    ii, jj, d = pair_vectors(positions)
    empty_i = np.zeros(0, dtype=np.int64)
    if not len(d) or not len(sun):
        return empty_i, empty_i, empty_i, np.zeros((0, 4)), np.zeros((0, 2))
    constant = bool(np.all(surface_az == surface_az[0]) and np.all(surface_el == surface_el[0]))
    if constant:                            # one orientation: its axes once, broadcast
        axes = collector_axes(surface_az[:1], surface_el[:1])
        n, u, v = (np.broadcast_to(a, sun.shape) for a in axes)
    else:
        n, u, v = collector_axes(surface_az, surface_el)
    sn = np.einsum("tk,tk->t", sun, n)
    mode = np.where(sn > _FACING_COS, FACING, FIXED if constant else GENERIC)
    t_c, q_c = pair_candidates(d, sun, mode, width, height,
                               np.stack([n[0], u[0], v[0]]) if constant else None, table)
    with np.errstate(divide="ignore", invalid="ignore"):
        ru = np.where(sn > 0, np.einsum("tk,tk->t", sun, u) / sn, np.nan)
        rv = np.where(sn > 0, np.einsum("tk,tk->t", sun, v) / sn, np.nan)
    # (d·n, du, dv) = W d per step, W's rows n, u − (s·u/s·n) n, v − (s·v/s·n) n:
    # one 3 × 3 gather per candidate (NaN rows where s·n ≤ 0: never a hit), laid out
    # component-major so that the gathers and the products run over contiguous rows
    w = np.ascontiguousarray(np.stack([n, u - ru[:, None] * n, v - rv[:, None] * n]
                                      ).transpose(0, 2, 1))                  # (3, 3, T)
    d_t = np.ascontiguousarray(d.T)                                          # (3, P)
    out: list[list[NDArray[np.generic]]] = [[], [], [], [], []]
    for m0 in range(0, len(t_c), _CHUNK):
        t, q = t_c[m0:m0 + _CHUNK], q_c[m0:m0 + _CHUNK]
        dn, du, dv = np.einsum("jkm,km->jm", np.take(w, t, axis=2), np.take(d_t, q, axis=1))
        # dn = λ·(s·n): its sign says whether j shades i or i shades j
        hit = (np.abs(du) < width) & (np.abs(dv) < height) & (dn != 0)
        fwd = dn[hit] > 0                     # j (at +d) is in front of i's plane: j shades i
        sign = np.where(fwd, 1.0, -1.0)
        out[0].append(t[hit])
        out[1].append(np.where(fwd, ii[q[hit]], jj[q[hit]]))
        out[2].append(np.where(fwd, jj[q[hit]], ii[q[hit]]))
        out[3].append(du[hit] * sign)
        out[4].append(dv[hit] * sign)
    if not out[0]:
        return empty_i, empty_i, empty_i, np.zeros((0, 4)), np.zeros((0, 2))
    t_all, i_all, j_all, du_all, dv_all = (np.concatenate(x) for x in out)
    u0, u1 = np.maximum(u_lo, du_all + u_lo), np.minimum(u_hi, du_all + u_hi)
    v0, v1 = np.maximum(v_lo, dv_all + v_lo), np.minimum(v_hi, dv_all + v_hi)
    keep = np.flatnonzero(((u1 - u0) * (v1 - v0) > _EPS_AREA_M2) & (u1 > u0) & (v1 > v0))
    # filtered column by column (1-D gathers; numpy's row gathers of (M, 4) are slow)
    return (t_all[keep], i_all[keep], j_all[keep],
            np.stack([u0[keep], u1[keep], v0[keep], v1[keep]], axis=-1),
            np.stack([du_all[keep], dv_all[keep]], axis=-1))


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
    return band_union_areas(r, np.array([-np.inf, np.inf]))[:, 0]


def band_union_areas(rects: ArrayLike, v_edges: ArrayLike) -> FloatArray:
    """Exact area of the union of rectangles inside each band v_edges[b] ≤ v < v_edges[b+1].

    Parameters
    ----------
    rects : array_like, shape (G, K, 4)
        (u0, u1, v0, v1); empty slots have u1 ≤ u0 or v1 ≤ v0.
    v_edges : array_like, shape (B + 1,)
        Increasing band edges (e.g. a collector's strings).

    Returns
    -------
    numpy.ndarray, shape (G, B)

        Inclusion–exclusion (subsets whose intersection is empty everywhere are not
        followed) up to eight rectangles per group, the grid of their edges beyond.
    """
    r = np.asarray(rects, dtype=float)
    edges = np.asarray(v_edges, dtype=float)
    valid = (r[..., 1] > r[..., 0]) & (r[..., 3] > r[..., 2])
    # bucket the groups by the slot of their last non-empty rectangle; empty rectangles
    # before it add nothing to any union formula
    last = np.where(valid.any(axis=1), r.shape[1] - np.argmax(valid[:, ::-1], axis=1), 0)
    return _union_by_count(last, lambda g, k: np.take(r, g, axis=0)[:, :k], edges)


def _union_by_count(count: IntArray, rects_of: Callable[[IntArray, int], FloatArray],
                    edges: FloatArray) -> FloatArray:
    """:func:`band_union_areas` of groups bucketed by ``count`` ``(G,)``, the number of
    rectangles that matter in each: ``rects_of(g, k)`` gives groups g's first k ``(len(g),
    k, 4)`` (np.take: numpy's fast row gather). :func:`plant_shade` calls it with its rows
    by group, without reading them back from the padded ``(G, K, 4)``."""
    out = np.zeros((len(count), len(edges) - 1))
    for k in np.flatnonzero(np.bincount(count, minlength=1)[1:]) + 1:  # non-empty buckets
        g = np.flatnonzero(count == k)
        rk = rects_of(g, int(k))
        out[g] = (_union_inclusion_exclusion(rk, edges) if k <= _IE_MAX else _union_grid(
            rk, (rk[..., 1] > rk[..., 0]) & (rk[..., 3] > rk[..., 2]), edges))
    return out


def sum_columns(a: FloatArray) -> FloatArray:
    """``a.sum(axis=1)`` of a ``(G, B)`` array of a few columns, added left to right (numpy's
    order for fewer than 8): its reduction along a short last axis is ~20× slower."""
    if a.shape[1] >= 8:                      # numpy sums pairwise from 8 on: its own order
        return np.asarray(a.sum(axis=1), dtype=float)
    out = a[:, 0].copy()
    for b in range(1, a.shape[1]):
        out += a[:, b]
    return out


def _band_areas(u0: FloatArray, u1: FloatArray, v0: FloatArray, v1: FloatArray,
                edges: FloatArray) -> FloatArray:
    """Area of non-empty rectangles (G,) inside each band → ``(G, B)``, band by band
    (1-D passes: broadcasting against the few bands ran 2.5× slower)."""
    width = u1 - u0
    out = np.empty((len(u0), len(edges) - 1))
    for b in range(len(edges) - 1):
        out[:, b] = width * np.maximum(np.minimum(v1, edges[b + 1]) - np.maximum(v0, edges[b]),
                                       0.0)
    return out


def _union_inclusion_exclusion(r: FloatArray, edges: FloatArray) -> FloatArray:
    """Union area per band of few rectangles per group: Σ over subsets (−1)^(|S|+1) |∩S|.

    Depth-first over subsets; a branch is dropped for the groups where the
    intersection so far is empty (every superset's is too). The terms are summed per
    group at the end (bincount, in the order they were found), not scattered into the
    result at every subset.
    """
    g_all, k = r.shape[:2]
    coords = np.ascontiguousarray(r.transpose(2, 1, 0))             # (4, K, G)
    rows: list[IntArray] = []
    terms: list[FloatArray] = []

    def follow(idx: IntArray | None, cur: tuple[FloatArray, ...] | None, first: int,
               sign: float) -> None:
        """Subsets that add rectangles ``first`` … to ``cur`` on groups ``idx`` (None: all
        groups; ``cur`` None: the empty subset)."""
        for m in range(first, k):
            c = coords[:, m] if idx is None else coords[:, m, idx]
            if cur is None:
                u0, u1, v0, v1 = c
            else:
                u0, u1 = np.maximum(cur[0], c[0]), np.minimum(cur[1], c[1])
                v0, v1 = np.maximum(cur[2], c[2]), np.minimum(cur[3], c[3])
            live = (u1 > u0) & (v1 > v0)
            if live.all():
                sub, nxt = idx, (u0, u1, v0, v1)
            else:
                keep = np.flatnonzero(live)
                if not len(keep):
                    continue
                sub = keep if idx is None else idx[keep]
                nxt = (u0[keep], u1[keep], v0[keep], v1[keep])
            rows.append(np.arange(g_all) if sub is None else sub)
            terms.append(sign * _band_areas(*nxt, edges))
            if m + 1 < k:
                follow(sub, nxt, m + 1, -sign)

    follow(None, None, 0, 1.0)
    if len(rows) == 1 and len(rows[0]) == g_all:    # one rectangle each: its own areas
        return terms[0]
    out = np.zeros((g_all, len(edges) - 1))
    if rows:
        at, term = np.concatenate(rows), np.concatenate(terms)
        for b in range(out.shape[1]):
            out[:, b] = np.bincount(at, term[:, b], minlength=g_all)
    return out


def _union_grid(r: FloatArray, valid: NDArray[np.bool_], edges: FloatArray) -> FloatArray:
    """Union area per band of rectangles ``(G, K, 4)`` (``valid`` the non-empty ones) on their
    edge grid (band edges added, so that no cell crosses one)."""
    g = len(r)
    inner = edges[np.isfinite(edges)]
    xs = np.sort(r[..., :2].reshape(g, -1), axis=1)                  # (G, 2K)
    ys = np.sort(np.concatenate([r[..., 2:].reshape(g, -1),
                                 np.broadcast_to(inner, (g, len(inner)))], axis=1), axis=1)
    cx = (xs[:, 1:] + xs[:, :-1]) / 2
    cy = (ys[:, 1:] + ys[:, :-1]) / 2
    dx = np.diff(xs, axis=1)
    dy = np.diff(ys, axis=1)
    inx = (cx[:, :, None] > r[:, None, :, 0]) & (cx[:, :, None] < r[:, None, :, 1]) \
        & valid[:, None, :]                                         # (G, X, K)
    iny = (cy[:, :, None] > r[:, None, :, 2]) & (cy[:, :, None] < r[:, None, :, 3])
    covered = np.einsum("gxk,gyk->gxy", inx.astype(np.float64), iny.astype(np.float64)) > 0
    col = np.einsum("gxy,gx->gy", covered.astype(np.float64), dx) * dy   # (G, Y)
    band = np.searchsorted(edges, cy, side="right") - 1                   # (G, Y)
    out = np.zeros((g, len(edges) - 1))
    for b in range(len(edges) - 1):
        out[:, b] = np.where(band == b, col, 0.0).sum(axis=1)
    return out


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
    group_band_area : numpy.ndarray, shape (G, B + 1), optional
        Shaded area [m²] of each collector between consecutive ``band_edges`` (below
        the first, between them, above the last): the strings' shaded areas that
        :func:`sim.plant.electrical.beam_factors` needs, from the same union.
    band_edges : numpy.ndarray, shape (B,), optional
        Increasing v [m] that cut the collector into those bands.
    outline : numpy.ndarray, shape (V, 2), optional
        A polygon collector's vertices (u, v) [m] (None: the rectangle). Then
        ``group_rects`` holds where the two collectors' bounding boxes overlap (a rectangle
        that contains that neighbour's shade), ``group_offsets`` the shift (du, dv) [m] of
        each shading neighbour's outline on the collector, and ``group_shade`` the shaded
        part of the collector (shapely polygons, one per group).
    """

    fraction: FloatArray
    group_step: IntArray
    group_tracker: IntArray
    group_rects: FloatArray
    group_by: IntArray
    group_band_area: FloatArray | None = None
    band_edges: FloatArray | None = None
    outline: FloatArray | None = None
    group_offsets: FloatArray | None = None
    group_shade: NDArray[np.object_] | None = None

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


def polygon_shade(outline: FloatArray, offsets: FloatArray, used: NDArray[np.bool_]
                  ) -> NDArray[np.object_]:
    """The shaded part of a polygon collector P per group: P ∩ ∪_k (P + offsets[g, k]) over
    the ``used`` slots, as shapely polygons ``(G,)`` — exact polygon clipping (GEOS),
    convex or not. ``offsets`` ``(G, K, 2)`` [m]."""
    import shapely

    own = shapely.Polygon(outline)
    slots = np.full(used.shape, None, dtype=object)
    slots[used] = shapely.polygons(outline[None] + offsets[used][:, None, :])
    return np.asarray(shapely.intersection(shapely.union_all(slots, axis=1), own), dtype=object)


def polygon_band_areas(shade: NDArray[np.object_], bounds: tuple[float, float, float, float],
                       band_edges: FloatArray) -> FloatArray:
    """Area [m²] of each shaded polygon ``(G,)`` between consecutive ``band_edges`` in v
    (±inf allowed) → ``(G, B)``: one rectangle clip per band (GEOS ``clip_by_rect``)."""
    import shapely

    u_lo, u_hi, v_lo, v_hi = bounds
    edges = np.clip(band_edges, v_lo - 1.0, v_hi + 1.0)
    out = np.empty((len(shade), len(edges) - 1))
    for b in range(len(edges) - 1):
        out[:, b] = shapely.area(shapely.clip_by_rect(shade, u_lo - 1.0, edges[b], u_hi + 1.0,
                                                      edges[b + 1]))
    return out


@functools.lru_cache(maxsize=16)
def _overlap_region(outline: tuple[tuple[float, float], ...]) -> Any:
    """The shifts t for which a polygon P and P + t overlap with positive area: the interior
    of the Minkowski difference P ⊕ (−P), the union over pairs of P's triangles (Ti, Tj) of
    the convex hulls of their vertex differences (P itself when convex: one hull). Prepared
    for many point tests."""
    import shapely

    own = shapely.Polygon(outline)
    if own.convex_hull.area - own.area <= _EPS_AREA_M2:
        pieces = [np.asarray(outline, dtype=float)]
    else:
        tri = shapely.get_parts(shapely.constrained_delaunay_triangles(own))
        pieces = [np.asarray(t.exterior.coords)[:3] for t in tri]
    verts = np.stack(pieces)                                   # (pieces, vertices, 2)
    diff = (verts[:, None, :, None, :] - verts[None, :, None, :, :]).reshape(
        len(verts) ** 2, -1, 2)
    region = shapely.union_all(shapely.convex_hull(shapely.multipoints(diff)))
    shapely.prepare(region)
    return region


def _polygon_pairs(outline: FloatArray, offsets: FloatArray) -> NDArray[np.bool_]:
    """Which (du, dv) shifts ``(M, 2)`` make a polygon overlap its own translate with
    positive area: the shift inside :func:`_overlap_region` (exact, a point test each; the
    bounding boxes' overlap only bounds it)."""
    import shapely

    region = _overlap_region(tuple(map(tuple, np.asarray(outline, dtype=float).tolist())))
    return np.asarray(shapely.contains_properly(region, shapely.points(offsets)), dtype=bool)


def _put_rows(out: FloatArray, at: IntArray, rows: FloatArray) -> None:
    """``out[at] = rows`` for 2-D float arrays, each row copied whole (as one opaque item):
    numpy's fancy assignment of rows goes element by element, twice as slow here."""
    item = f"V{out.shape[1] * out.itemsize}"
    np.put(out.view(item).reshape(-1), at, np.ascontiguousarray(rows, dtype=out.dtype)
           .view(item).reshape(-1))


def plant_shade(positions: ArrayLike, solar_azimuth: ArrayLike, solar_elevation: ArrayLike,
                surface_azimuth: ArrayLike, surface_elevation: ArrayLike, width: float,
                height: float, band_edges: ArrayLike = (),
                table: BinTable | None = None, outline: ArrayLike | None = None) -> PlantShade:
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
    band_edges : array_like, shape (B,), optional
        Increasing v [m] across the collector (e.g. ``Collector.string_boundaries()``):
        the shaded area of every band between them is kept
        (``PlantShade.group_band_area``); the fraction is their sum, so the bands
        cost one union, not two.
    table : BinTable, optional
        Keeps the sun bins' candidate pairs for the next call (a run in chunks).
    outline : array_like, shape (V, 2), optional
        A polygon collector's vertices (u, v) [m] about the pivot
        (:attr:`sim.plant.layout.Collector.outline`); ``width`` and ``height`` are then
        its bounding box's. The pairs come from the bounding boxes as for a rectangle;
        each shade is the exact polygon clip of :func:`polygon_shade` (shapely), slower
        than the rectangles' unions.

    Returns
    -------
    PlantShade
    """
    poly = None if outline is None else np.asarray(outline, dtype=float)
    if poly is None:
        bounds = (-width / 2, width / 2, -height / 2, height / 2)
    else:
        bounds = (float(poly[:, 0].min()), float(poly[:, 0].max()),
                  float(poly[:, 1].min()), float(poly[:, 1].max()))
        width, height = bounds[1] - bounds[0], bounds[3] - bounds[2]
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
    t, i, j, rects, offsets = _direct_pairs(p, sun[upi], saz[upi], sel[upi], bounds, table)
    if poly is not None:
        hit = _polygon_pairs(poly, offsets)
        t, i, j, rects, offsets = t[hit], i[hit], j[hit], rects[hit], offsets[hit]
    key = upi[t] * n + i
    by_pair = key * n + j
    if np.any(by_pair[1:] < by_pair[:-1]):          # by step already, often by (i, j) too
        order = np.argsort(by_pair, kind="stable")
        key, j = key[order], j[order]
        rects, offsets = np.take(rects, order, axis=0), np.take(offsets, order, axis=0)
    start = np.flatnonzero(np.diff(key, prepend=-1))  # each group's first row (key ≥ 0)
    gkey, count = key[start], np.diff(start, append=len(key))
    kmax = int(count.max()) if len(count) else 1
    # row r of group g goes to slot r − start[g], at g·kmax + slot of the flattened padding
    flat = np.arange(len(key)) + np.repeat(np.arange(len(gkey)) * kmax - start, count)
    g_rects = np.zeros((len(gkey), kmax, 4))
    g_by = np.full((len(gkey), kmax), -1, dtype=np.int64)
    _put_rows(g_rects.reshape(-1, 4), flat, rects)
    g_by.reshape(-1)[flat] = j
    cuts = np.asarray(band_edges, dtype=float).reshape(-1)
    edges = np.concatenate([[-np.inf], cuts, [np.inf]])
    g_step, g_tracker = gkey // n, gkey % n
    if poly is None:
        band_area = _union_by_count(count, lambda g, k: np.take(
            rects, (start[g, None] + np.arange(k)).reshape(-1), axis=0).reshape(-1, k, 4), edges)
        fraction.reshape(-1)[gkey] = np.minimum(sum_columns(band_area) / (width * height), 1.0)
        return PlantShade(fraction, g_step.astype(np.int64), g_tracker.astype(np.int64),
                          g_rects, g_by, band_area, cuts)
    import shapely

    g_offsets = np.zeros((len(gkey), kmax, 2))
    _put_rows(g_offsets.reshape(-1, 2), flat, offsets)
    g_shade = polygon_shade(poly, g_offsets, g_by >= 0)
    band_area = (polygon_band_areas(g_shade, bounds, edges) if len(cuts)
                 else np.asarray(shapely.area(g_shade), dtype=float)[:, None])
    # the outline's area whichever way round its vertices go (check_outline makes them
    # counter-clockwise; a caller of this function may not have)
    fraction[g_step, g_tracker] = np.minimum(band_area.sum(axis=1) / abs(polygon_area(poly)),
                                             1.0)
    return PlantShade(fraction, g_step.astype(np.int64), g_tracker.astype(np.int64),
                      g_rects, g_by, band_area, cuts, poly, g_offsets, g_shade)


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
