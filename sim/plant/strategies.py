"""Where a plant's trackers point: ``sun``, ``backtrack``, ``sky_scan`` (seed 004 §2).

One interface, :func:`orientations`: from the sun and the weather at each step,
the common orientation (azimuth and elevation of the collector normal) that seed
004's position server would send to every tracker.

- ``sun`` — astronomical tracking: the normal on the (refracted) sun.
- ``backtrack`` — where pointing at the sun shades a collector, search the
  orientations that shade nobody (seed 004's Boolean, :mod:`sim.plant.shading`)
  for the one of maximum plane-of-array irradiance, not merely the closest to
  the sun: for normal azimuths within ±45° of the sun's (5° steps) the lowest
  shade-free elevation is found by bisection (0.02°), and the flat orientation
  is added; the candidate of highest POA wins. Where the sun orientation shades
  nobody, it is kept.
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

from sim.plant.layout import Plant
from sim.plant.shading import candidate_pairs, collector_axes
from sim.sky import poa_irradiance
from vision.sphere import enu_from_sky

FloatArray = NDArray[np.float64]
STRATEGIES = ("sun", "backtrack", "sky_scan")
STOW_AZIMUTH, STOW_ELEVATION = 180.0, 90.0

_BT_AZ_OFFSETS = np.arange(-45.0, 45.1, 3.0)
_BT_REFINE = np.arange(-2.5, 2.6, 0.5)
_BT_ITER = 12
_SCAN_EL = np.arange(0.0, 86.0, 5.0)
_SCAN_AZ = np.arange(0.0, 360.0, 10.0)
_PAIR_CHUNK = 4000


def scan_grid() -> tuple[FloatArray, FloatArray]:
    """The sky-scan grid: normal azimuths and elevations [°] (flattened, zenith last)."""
    az, el = np.meshgrid(_SCAN_AZ, _SCAN_EL)
    return np.append(az.ravel(), 180.0), np.append(el.ravel(), 90.0)


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
    t, i, j = candidate_pairs(plant.positions, sun[up], c.diagonal)
    t = up[t]
    d_all = plant.positions[j] - plant.positions[i]
    a_eps, b_eps = c.width - 1e-9, c.height - 1e-9
    for m0 in range(0, len(t), _PAIR_CHUNK):
        tm = t[m0:m0 + _PAIR_CHUNK]
        d = d_all[m0:m0 + _PAIR_CHUNK][:, None, :]
        n, u, v = collector_axes(caz[tm], cel[tm])                  # (M, C, 3)
        s = sun[tm][:, None, :]
        sn = np.sum(s * n, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.sum(d * n, axis=-1) / sn
        proj = d - lam[..., None] * s
        shade = (sn > 0) & (lam > 0) & (np.abs(np.sum(proj * u, axis=-1)) < a_eps) \
            & (np.abs(np.sum(proj * v, axis=-1)) < b_eps)
        rows, cols = np.nonzero(shade)
        ok[tm[rows], cols] = False
    return ok


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


def _lowest_free(plant: Plant, sky: dict[str, FloatArray], steps: NDArray[np.int64],
                 caz: FloatArray) -> FloatArray:
    """Lowest shade-free normal elevation above the sun's for each candidate azimuth (bisection).

    The upper end (flat, 90°) shades nobody on level ground; where the shade-free
    set is not an interval, the bisection still ends on a shade-free elevation.
    """
    az0 = sky["solar_azimuth"][steps]
    el0 = sky["apparent_elevation"][steps]
    lo = np.repeat(el0[:, None], caz.shape[1], axis=1)
    hi = np.full_like(lo, 90.0)
    for _ in range(_BT_ITER):
        mid = (lo + hi) / 2
        free = shade_free(plant, az0, el0, caz, mid)
        hi = np.where(free, mid, hi)
        lo = np.where(free, lo, mid)
    return hi


def _backtrack_candidates(plant: Plant, sky: dict[str, FloatArray],
                          steps: NDArray[np.int64]) -> tuple[FloatArray, FloatArray]:
    """Shade-free candidates ``(S, C)``: the lowest shade-free elevation on a 3° azimuth fan
    (±45° about the sun), refined at 0.5° about the best of the fan, plus flat."""
    az0 = sky["solar_azimuth"][steps]
    caz = (az0[:, None] + _BT_AZ_OFFSETS[None, :]) % 360.0
    hi = _lowest_free(plant, sky, steps, caz)
    a, _ = _best(plant, caz, hi, sky, steps, check=False)
    raz = (a[:, None] + _BT_REFINE[None, :]) % 360.0
    rel = _lowest_free(plant, sky, steps, raz)
    caz = np.concatenate([caz, raz], axis=1)
    hi = np.concatenate([hi, rel], axis=1)
    caz = np.concatenate([caz, np.full((len(steps), 1), STOW_AZIMUTH)], axis=1)
    cel = np.concatenate([hi, np.full((len(steps), 1), 90.0)], axis=1)
    return caz, cel


def _best(plant: Plant, caz: FloatArray, cel: FloatArray, sky: dict[str, FloatArray],
          steps: NDArray[np.int64], check: bool) -> tuple[FloatArray, FloatArray]:
    poa = _poa(plant, caz, cel, sky, steps)
    if check:
        free = shade_free(plant, sky["solar_azimuth"][steps], sky["apparent_elevation"][steps],
                          caz, cel)
        poa = np.where(free, poa, -np.inf)
    k = np.argmax(poa, axis=1)
    rows = np.arange(len(steps))
    return caz[rows, k], cel[rows, k]


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
    free_sun = shade_free(plant, az, el, saz[:, None], sel[:, None])[:, 0]
    if strategy == "backtrack":
        steps = np.nonzero(up & ~free_sun)[0]
        if len(steps):
            caz, cel = _backtrack_candidates(plant, sky, steps)
            saz[steps], sel[steps] = _best(plant, caz, cel, sky, steps, check=False)
        return saz, sel
    steps = np.nonzero(up)[0]
    gaz, gel = scan_grid()
    for s0 in range(0, len(steps), 2000):
        st = steps[s0:s0 + 2000]
        caz = np.broadcast_to(gaz, (len(st), len(gaz)))
        cel = np.broadcast_to(gel, (len(st), len(gel)))
        sun_ok = free_sun[st]
        extra_az, extra_el = saz[st, None], sel[st, None]
        shaded = st[~sun_ok]
        caz = np.concatenate([caz, extra_az], axis=1)
        cel = np.concatenate([cel, extra_el], axis=1)
        a, e = _best(plant, caz, cel, sky, st, check=True)
        if len(shaded):
            baz, bel = _backtrack_candidates(plant, sky, shaded)
            bz, be = _best(plant, baz, bel, sky, shaded, check=False)
            k = np.nonzero(~sun_ok)[0]
            p_grid = _poa(plant, a[k, None], e[k, None], sky, shaded)[:, 0]
            p_bt = _poa(plant, bz[:, None], be[:, None], sky, shaded)[:, 0]
            better = p_bt > p_grid
            a[k[better]], e[k[better]] = bz[better], be[better]
        saz[st], sel[st] = a, e
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
