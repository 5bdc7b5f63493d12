"""Where a plant's trackers point: ``sun``, ``backtrack``, ``sky_scan`` (seed 004 §2).

One interface, :func:`orientations`: from the sun and the weather at each step,
the common orientation (azimuth and elevation of the collector normal) that seed
004's position server would send to every tracker.

- ``sun`` — astronomical tracking: the normal on the (refracted) sun.
- ``backtrack`` — where pointing at the sun shades a collector, search the
  orientations that shade nobody (seed 004's Boolean, :mod:`sim.plant.shading`)
  for the one of maximum plane-of-array irradiance, not merely the closest to
  the sun: for normal azimuths within ±45° of the sun's (3° steps, then 0.5°, 0.05°
  and 0.005° about the best) the lowest shade-free elevation at or above the sun's comes
  in closed form (:func:`lowest_free_elevation`: each pair shades on one
  interval of elevations), and the flat orientation is added; the shade-free candidate
  of highest POA wins (those at 90° are checked: on sloped ground flat shades). Where
  none is shade-free, the sky-scan grid's best; where nothing is, the sun's (its shade
  shows in the result). Where the sun orientation shades nobody, it is kept.
- ``sky_scan`` — seed 004's device (§2, Fig. 6): a scan of a hemispheric grid of
  orientations (5° in elevation, 10° in azimuth, plus the zenith, the sun and the
  backtracking candidates) with the shaded region excluded; the orientation of
  maximum POA, which under an overcast sky is near horizontal.

POA is pvlib's Perez (1990) anisotropic sky through :func:`sim.sky.poa_irradiance`.
Night steps (sun at or below the horizon) give the flat stow (elevation 90°,
azimuth 180°).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.plant.layout import Collector, Plant
from sim.plant.shading import GENERIC, IntArray, collector_axes, pair_candidates, pair_vectors
from sim.sky import poa_irradiance
from vision.sphere import enu_from_sky

FloatArray = NDArray[np.float64]
STRATEGIES = ("sun", "backtrack", "sky_scan")
STOW_AZIMUTH, STOW_ELEVATION = 180.0, 90.0

_BT_AZ_OFFSETS = np.arange(-45.0, 45.1, 3.0)
# backtracking's refinements about the best azimuth so far: (half-width, step) [°], each grid
# on the multiples of its step, not offsets from the sun: a grid that moved with the sun served
# an optimum standing still as a zig-zag of its step (3x3 plant, 21 Dec: 114 reversals of the
# azimuth, 57 of the elevation, in a day at 1 min; 10 and 7 with these, docs/plants.md)
_BT_LEVELS = ((2.5, 0.5), (0.3, 0.05), (0.03, 0.005))
_SCAN_EL = np.arange(0.0, 86.0, 5.0)
_SCAN_AZ = np.arange(0.0, 360.0, 10.0)
# (pair, candidate) rows computed at once: 1,000,000 peaked at 181 MB (a Peñarroya sky_scan
# day at 300 s), 100,000 at 24 MB in the same CPU time (0.52-0.55 s, measured before
# shade_free made its products per step)
_CAND_BLOCK = 100_000


def scan_grid() -> tuple[FloatArray, FloatArray]:
    """The sky-scan grid: normal azimuths and elevations [°] (flattened, zenith last)."""
    az, el = np.meshgrid(_SCAN_AZ, _SCAN_EL)
    return np.append(az.ravel(), 180.0), np.append(el.ravel(), 90.0)


def _dot3(a: FloatArray, b: FloatArray) -> FloatArray:
    """The dot product of vectors stored component-first (``a[0..2]``, broadcasting), their
    components added left to right, as numpy sums three."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def shade_free(plant: Plant, solar_azimuth: ArrayLike, solar_elevation: ArrayLike,
               cand_azimuth: ArrayLike, cand_elevation: ArrayLike) -> NDArray[np.bool_]:
    """Seed 004's Boolean, negated, for C candidate orientations at each of T steps.

    Parameters
    ----------
    plant : Plant
    solar_azimuth, solar_elevation : array_like, shape (T,)
        Sun direction [°].
    cand_azimuth, cand_elevation : array_like, shape (T, C)
        Candidate common orientations of the collector normals [°].

    Returns
    -------
    numpy.ndarray of bool, shape (T, C)
        True where that orientation shades no collector (always True with the sun down).
    """
    az = np.atleast_1d(np.asarray(solar_azimuth, dtype=float))
    el = np.atleast_1d(np.asarray(solar_elevation, dtype=float))
    caz = np.asarray(cand_azimuth, dtype=float).reshape(len(az), -1)
    cel = np.asarray(cand_elevation, dtype=float).reshape(len(az), -1)
    ok = np.ones(caz.shape, dtype=bool)
    up = np.nonzero(el > 0)[0]
    if not len(up):
        return ok
    sun = enu_from_sky(az, el)
    c = plant.collector
    _, _, d = pair_vectors(plant.positions)
    t, q = pair_candidates(d, sun[up], np.full(len(up), GENERIC), c.width, c.height)
    t = up[t]
    steps, t_local = np.unique(t, return_inverse=True)
    # the sun's and the candidates' frames are per step: the products that need no pair
    # are made once per step, and each (S, C) component is its own array, so that a pair
    # row gathers plain 2-D arrays (a sum along a last axis of 3 is ~20× slower than
    # adding its components, sim.plant.shading.sum_columns)
    n, u, v = (np.moveaxis(x, -1, 0).copy() for x in collector_axes(caz[steps], cel[steps]))
    s = sun[steps].T[:, :, None]                                    # (3, S, 1)
    sn = _dot3(n, s)                                                # (S, C)
    with np.errstate(divide="ignore", invalid="ignore"):
        su_sn, sv_sn = _dot3(u, s) / sn, _dot3(v, s) / sn
    lit = sn > 0
    rows = max(1, _CAND_BLOCK // caz.shape[1])
    for m0 in range(0, len(t), rows):
        tm, tl = t[m0:m0 + rows], t_local[m0:m0 + rows]
        dm = d[q[m0:m0 + rows]].T[:, :, None]                       # (3, M, 1)
        dn = _dot3(dm, n[:, tl])                                    # (M, C)
        du = _dot3(dm, u[:, tl]) - su_sn[tl] * dn
        dv = _dot3(dm, v[:, tl]) - sv_sn[tl] * dn
        # either direction of the pair: i shaded by j (dn > 0) or j by i (dn < 0)
        shade = lit[tl] & (dn != 0) & (np.abs(du) < c.width - 1e-9) \
            & (np.abs(dv) < c.height - 1e-9)
        r, k = np.nonzero(shade)
        ok[tm[r], k] = False
    return ok


def lowest_free_elevation(plant: Plant, solar_azimuth: ArrayLike, solar_elevation: ArrayLike,
                          cand_azimuth: ArrayLike, from_elevation: ArrayLike) -> FloatArray:
    """Lowest normal elevation ≥ ``from_elevation`` that shades nobody, per candidate azimuth.

    Closed form (seed 004 §2.1 geometry, collectors parallel). With n(α) = cos α h
    + sin α z for the normal azimuth γ (h horizontal towards γ), u = z × h and
    v = u × n = sin α h − cos α z (down the slope here; the collector's own frame,
    :func:`sim.kinematics.panel_axes`, takes −v, up the slope — only |m·v| enters
    below, so the sign does not matter), and m = d × s for a pair offset d, the shade
    offsets times s·n are du (s·n) = m·v and dv (s·n) = −m·u. A pair shades exactly where

        |m·u| < b (s·n)   and   |m·v(α)| < a (s·n),

    three conditions p cos α + q sin α = R cos(α − φ) > c ≥ 0 on α, each an arc
    |α − φ| < arccos(c/R) ≤ 90° (φ = atan2(q, p) ∈ (−180°, 180°], so shifts by
    ±360° cannot reach [0°, 90°]); their intersection with [0°, 90°] is one open
    interval per pair. Walking up from
    ``from_elevation`` over the intervals that contain the current elevation
    gives the lowest shade-free one; where the walk passes 90° the answer is 90°, which
    shades nobody on level ground but may on a slope (the caller checks it).

    Parameters
    ----------
    plant : Plant
    solar_azimuth, solar_elevation : array_like, shape (T,)
        Sun direction [°].
    cand_azimuth : array_like, shape (T, C)
        Normal azimuths [°].
    from_elevation : array_like, shape (T,)
        Start of the search [°] (the sun's elevation for backtracking).

    Returns
    -------
    numpy.ndarray, shape (T, C)
        [°].
    """
    az = np.atleast_1d(np.asarray(solar_azimuth, dtype=float))
    el = np.atleast_1d(np.asarray(solar_elevation, dtype=float))
    caz = np.asarray(cand_azimuth, dtype=float).reshape(len(az), -1)
    n_c = caz.shape[1]
    alpha = np.repeat(np.radians(np.clip(np.asarray(from_elevation, dtype=float), 0, 90))
                      .reshape(-1, 1), n_c, axis=1).ravel()
    up = np.nonzero(el > 0)[0]
    if not len(up):
        return np.degrees(alpha).reshape(len(az), n_c)
    sun = enu_from_sky(az, el)
    col = plant.collector
    _, _, d = pair_vectors(plant.positions)
    t, q = pair_candidates(d, sun[up], np.full(len(up), GENERIC), col.width, col.height)
    t = up[t]
    m = np.cross(d[q], sun[t])                                         # (M, 3)
    g = np.radians(caz)
    sg, cg = np.sin(g), np.cos(g)                                      # (T, C)
    sh = sun[:, 0, None] * sg + sun[:, 1, None] * cg                   # s·h
    sz = np.broadcast_to(sun[:, 2, None], sh.shape)
    r_b, phi_b = np.hypot(sh, sz), np.arctan2(sz, sh)                  # s·n = r_b cos(α − φ_b)
    a_m, b_m = col.width, col.height
    start = alpha.reshape(-1, n_c)
    rows = max(1, _CAND_BLOCK // n_c)
    edges = np.unique(np.append(np.searchsorted(t, t[::rows]), len(t)))  # whole steps
    for m0, m1 in zip(edges[:-1], edges[1:], strict=True):
        tm, mm = t[m0:m1], m[m0:m1]
        me, mn, mz = mm[:, 0, None], mm[:, 1, None], mm[:, 2, None]
        sgt, cgt, sht, szt = sg[tm], cg[tm], sh[tm], sz[tm]
        mu = np.abs(mn * sgt - me * cgt)                               # |m·u|, u = z × h
        mh = me * sgt + mn * cgt                                       # m·h
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.arccos(np.minimum(mu / (b_m * r_b[tm]), 1.0))       # |m·u| < b s·n
        lo = np.maximum(phi_b[tm] - w, 0.0)
        hi = np.where(w > 0, np.minimum(phi_b[tm] + w, np.pi / 2), 0.0)
        for pp, qq in ((a_m * sht + mz, a_m * szt - mh), (a_m * sht - mz, a_m * szt + mh)):
            phi = np.arctan2(qq, pp)                                   # |m·v| < a s·n, halves
            lo = np.maximum(lo, phi - np.pi / 2)
            hi = np.where((pp == 0) & (qq == 0), 0.0, np.minimum(hi, phi + np.pi / 2))
        r, k = np.nonzero(hi > np.maximum(lo, start[tm]))
        _walk_up(alpha, tm[r] * n_c + k, lo[r, k], hi[r, k])
    return np.degrees(np.minimum(alpha, np.pi / 2)).reshape(len(az), n_c)


def _walk_up(alpha: FloatArray, grp: IntArray, lo: FloatArray, hi: FloatArray) -> None:
    """Move each ``alpha[grp]`` up past the open intervals (lo, hi) of its group.

    Each round lifts alpha to the highest hi of the intervals that contain it;
    intervals wholly below alpha can no longer matter and are dropped. It ends
    when alpha is in no interval (at most one round per interval of a group).
    """
    while len(grp):
        a = alpha[grp]
        inside = (lo < a) & (a < hi)
        if not inside.any():
            return
        np.maximum.at(alpha, grp[inside], hi[inside] + 1e-9)
        keep = hi > alpha[grp]
        grp, lo, hi = grp[keep], lo[keep], hi[keep]


def _poa(plant: Plant, cand_az: FloatArray, cand_el: FloatArray, sky: dict[str, FloatArray],
         steps: NDArray[np.int64]) -> FloatArray:
    """Perez POA global [W m⁻²] of candidates ``(len(steps), C)`` at the given steps."""
    shape = cand_az.shape
    rep = lambda k: np.repeat(sky[k][steps], shape[1])  # noqa: E731
    out = poa_irradiance(90.0 - cand_el.ravel(), cand_az.ravel() % 360.0,
                         rep("apparent_zenith"), rep("solar_azimuth"), rep("dni"), rep("ghi"),
                         rep("dhi"), rep("dni_extra"), rep("airmass_relative"),
                         albedo=plant.albedo, model="perez")
    return out["poa_global"].reshape(shape)


def _backtrack_candidates(plant: Plant, sky: dict[str, FloatArray],
                          steps: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
    """Candidates ``(S, C)``: the lowest shade-free elevation on a 3° azimuth fan (±45° about
    the sun), refined about the best azimuth so far at 0.5°, 0.05° and 0.005°
    (:data:`_BT_LEVELS`), plus flat. The optimum found is then continuous in time wherever the
    optimum is (a 0.05° step in azimuth still moved the elevation 0.35° along a steep shade
    boundary). Those below 90° are shade-free by construction; those at 90° (flat, or a fan
    azimuth whose shade reaches the zenith) are not on sloped ground: :func:`_pick` checks
    every candidate."""
    az0 = sky["solar_azimuth"][steps]
    el0 = sky["apparent_elevation"][steps]
    rows = np.arange(len(steps))
    caz = [(az0[:, None] + _BT_AZ_OFFSETS[None, :]) % 360.0]
    cel = [lowest_free_elevation(plant, az0, el0, caz[0], el0)]
    poa = _poa(plant, caz[0], cel[0], sky, steps)
    for half, step in _BT_LEVELS:
        k = np.argmax(poa, axis=1)
        best_az, best_poa = caz[-1][rows, k], poa[rows, k]
        grid = np.arange(-half, half + step / 2, step)
        raz = (np.round(best_az / step)[:, None] * step + grid[None, :]) % 360.0
        rel = lowest_free_elevation(plant, az0, el0, raz, el0)
        caz.append(np.concatenate([best_az[:, None], raz], axis=1))
        cel.append(np.concatenate([cel[-1][rows, k][:, None], rel], axis=1))
        poa = np.concatenate([best_poa[:, None], _poa(plant, raz, rel, sky, steps)], axis=1)
    caz.append(np.full((len(steps), 1), STOW_AZIMUTH))
    cel.append(np.full((len(steps), 1), 90.0))
    return np.concatenate(caz, axis=1), np.concatenate(cel, axis=1)


def _pick(plant: Plant, caz: FloatArray, cel: FloatArray, sky: dict[str, FloatArray],
          steps: NDArray[np.int64], known_free: NDArray[np.bool_] | None = None
          ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """The shade-free candidate of highest Perez POA at each step (candidates ``(S, C)``),
    and whether one was shade-free (where none is, the first candidate is returned: the
    caller decides). ``known_free``: candidates known to be shade-free; the others are
    tested (:func:`shade_free`; all of them without it)."""
    poa = _poa(plant, caz, cel, sky, steps)
    saz, sel = sky["solar_azimuth"][steps], sky["apparent_elevation"][steps]
    if known_free is None:
        free = shade_free(plant, saz, sel, caz, cel)
    else:
        free = known_free.copy()
        r, c = np.nonzero(~known_free)
        free[r, c] = shade_free(plant, saz[r], sel[r], caz[r, c, None], cel[r, c, None])[:, 0]
    k = np.argmax(np.where(free, poa, -np.inf), axis=1)
    rows = np.arange(len(steps))
    found = np.any(free, axis=1)
    return caz[rows, k], cel[rows, k], found


def _grid(n: int) -> tuple[FloatArray, FloatArray]:
    """The sky-scan grid as candidates of ``n`` steps ``(n, C)``."""
    gaz, gel = scan_grid()
    return np.broadcast_to(gaz, (n, len(gaz))), np.broadcast_to(gel, (n, len(gel)))


def _backtrack(plant: Plant, sky: dict[str, FloatArray], steps: NDArray[np.int64]
               ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """Backtracking at ``steps`` (where the sun's orientation shades): the shade-free one of
    :func:`_backtrack_candidates` of highest POA; where none is shade-free (sloped ground:
    flat shades there), the sky-scan grid's. The third array is False where neither holds a
    shade-free orientation."""
    caz, cel = _backtrack_candidates(plant, sky, steps)
    a, e, found = _pick(plant, caz, cel, sky, steps, known_free=cel < 90.0)
    lost = np.nonzero(~found)[0]
    if len(lost):
        a[lost], e[lost], found[lost] = _pick(plant, *_grid(len(lost)), sky, steps[lost])
    return a, e, found


def strategies_for(collector: Collector) -> tuple[str, ...]:
    """The strategies a collector can take: all of :data:`STRATEGIES` for the rectangle;
    ``sun`` alone for a polygon, since ``backtrack`` and ``sky_scan`` (and the sky map)
    decide "shades nobody" by the rectangle's closed form (:func:`lowest_free_elevation`,
    :func:`shade_free`), which would answer for the polygon's bounding box."""
    return tuple(STRATEGIES) if collector.is_rectangle else ("sun",)


def check_strategy_collector(strategy: str, plant: Plant) -> None:
    """``ValueError`` naming the strategy when ``plant``'s collector cannot take it
    (:func:`strategies_for`)."""
    if strategy not in strategies_for(plant.collector):
        raise ValueError(f"strategy {strategy!r} needs a rectangular collector (its shade-free "
                         "test is the rectangle's closed form); a polygon collector takes "
                         "strategy 'sun'")


def orientations(strategy: str, plant: Plant, sky: dict[str, FloatArray]
                 ) -> tuple[FloatArray, FloatArray]:
    """Common collector orientation at each step for a strategy.

    Parameters
    ----------
    strategy : {"sun", "backtrack", "sky_scan"}
    plant : Plant
    sky : dict of numpy.ndarray, each shape (T,)
        ``solar_azimuth``, ``apparent_elevation``, ``apparent_zenith`` [°];
        ``dni``, ``ghi``, ``dhi``, ``dni_extra`` [W m⁻²]; ``airmass_relative`` [-].

    Returns
    -------
    surface_azimuth, surface_elevation : numpy.ndarray, shape (T,)
        Azimuth (clockwise from north) and elevation of the collector normal [°].
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"strategy must be one of {', '.join(STRATEGIES)}; got {strategy!r}")
    az = np.asarray(sky["solar_azimuth"], dtype=float)
    el = np.asarray(sky["apparent_elevation"], dtype=float)
    up = el > 0
    saz = np.where(up, az, STOW_AZIMUTH)
    sel = np.where(up, el, STOW_ELEVATION)
    if strategy == "sun":
        return saz, sel
    check_strategy_collector(strategy, plant)
    free_sun = shade_free(plant, az, el, saz[:, None], sel[:, None])[:, 0]
    # where no orientation searched is shade-free, the sun's stays (its shade is then in the
    # result: the positions' trackers_shaded, a run's shading loss)
    if strategy == "backtrack":
        steps = np.nonzero(up & ~free_sun)[0]
        if len(steps):
            a, e, found = _backtrack(plant, sky, steps)
            saz[steps[found]], sel[steps[found]] = a[found], e[found]
        return saz, sel
    steps = np.nonzero(up)[0]
    for s0 in range(0, len(steps), 2000):
        st = steps[s0:s0 + 2000]
        gaz, gel = _grid(len(st))
        caz = np.concatenate([gaz, saz[st, None]], axis=1)
        cel = np.concatenate([gel, sel[st, None]], axis=1)
        a, e, found = _pick(plant, caz, cel, sky, st)
        k = np.nonzero(~free_sun[st])[0]
        if len(k):
            bz, be, bt_found = _backtrack(plant, sky, st[k])
            p_grid = _poa(plant, a[k, None], e[k, None], sky, st[k])[:, 0]
            p_bt = _poa(plant, bz[:, None], be[:, None], sky, st[k])[:, 0]
            better = bt_found & (~found[k] | (p_bt > p_grid))
            a[k[better]], e[k[better]] = bz[better], be[better]
            found[k[better]] = True
        saz[st[found]], sel[st[found]] = a[found], e[found]
    return saz, sel


def sky_map(plant: Plant, sky: dict[str, FloatArray], step: int = 0, resolution_deg: float = 2.0
            ) -> dict[str, FloatArray]:
    """The hemispheric POA map at one step, as seed 004 Fig. 6 (before projection).

    Parameters
    ----------
    plant : Plant
    sky : dict
        As for :func:`orientations`.
    step : int
        Which step of ``sky`` to map.
    resolution_deg : float
        Grid spacing in azimuth and elevation [°].

    Returns
    -------
    dict
        ``azimuth`` (A,), ``elevation`` (E,) [°]; ``poa_global`` (E, A) [W m⁻²];
        ``shading`` (E, A) bool (seed 004's Boolean: that orientation shades a collector).
    """
    if not 0.25 <= resolution_deg <= 15:
        raise ValueError(f"resolution_deg must be in [0.25, 15], got {resolution_deg}")
    az = np.arange(0.0, 360.0, resolution_deg)
    el = np.arange(0.0, 90.0 + 1e-9, resolution_deg)
    gaz, gel = np.meshgrid(az, el)
    st = np.array([step], dtype=np.int64)
    poa = _poa(plant, gaz.reshape(1, -1), gel.reshape(1, -1), sky, st).reshape(gaz.shape)
    free = shade_free(plant, sky["solar_azimuth"][st], sky["apparent_elevation"][st],
                      gaz.reshape(1, -1), gel.reshape(1, -1)).reshape(gaz.shape)
    return {"azimuth": az, "elevation": el, "poa_global": poa, "shading": ~free}
