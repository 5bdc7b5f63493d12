"""Fit a fisheye sky camera from timestamped frames and the ephemeris.

Seed 003 assumed 3.365 px/deg and set the north offset by hand; here the
centre, the scale, the north offset and the mirror (east left or right) of a
:class:`vision.cameras.FisheyeCamera` — optionally a radial polynomial and two
tilt angles — are fitted by non-linear least squares on the pixel residuals
(``scipy.optimize.least_squares``, trust-region reflective, with the camera model's
analytic Jacobian :meth:`vision.cameras.FisheyeCamera.sky_to_pixel_jacobian`) between the
detected sun centroids and the sun positions the caller provides from an
ephemeris (SPA). Both mirrors are fitted and the one with the lower cost is
kept. Residuals are reported in pixels and as the angle on the sky.

:func:`self_calibrate` needs nothing but the frames, their times' sun positions
and the image size — no centre, scale, rotation or mirror — after SuMo (Blum et
al., "Geometric calibration of all-sky cameras using sun and moon positions",
Solar Energy 2025, doi:10.1016/j.solener.2025.113476): detect the sun in each
frame, reject the frames whose sun disagrees with the consensus (RANSAC over
three-frame samples, MSAC scoring; Fischler & Bolles 1981, Torr & Zisserman
2000), fit the camera to the rest, search each frame again where the fitted
model and the ephemeris put the sun (the detector's ephemeris-guided path) and
fit again. The equidistant model comes first; a radial polynomial term is kept
only where it lowers the leave-one-out error on the sky by more than one standard
error (the frames the data hold, not the fit's own residual, decide), and with
``projection="auto"`` another lens projection by the same rule (:func:`choose_projection`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from itertools import combinations
from math import comb
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from vision.cameras import EAST_SIDES, PROJECTIONS, FisheyeCamera
from vision.confidence import AGREES_DEG
from vision.sphere import angular_separation_deg, enu_from_sky


@dataclass(frozen=True)
class CalibrationResult:
    """A fitted camera and how well it explains the frames."""

    camera: FisheyeCamera
    residuals_px: NDArray[np.float64]
    residuals_deg: NDArray[np.float64]
    n_frames: int
    cost_other_mirror: float | None = None
    fitted: tuple[str, ...] = field(default_factory=tuple)

    @property
    def rms_px(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_px**2)))

    @property
    def rms_deg(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_deg**2)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary with units in the names."""
        return {
            "camera": self.camera.to_dict(),
            "n_frames": self.n_frames,
            "fitted": list(self.fitted),
            "rms_px": self.rms_px,
            "max_px": float(np.max(self.residuals_px)),
            "rms_deg": self.rms_deg,
            "max_deg": float(np.max(self.residuals_deg)),
            "residuals_px": [float(v) for v in self.residuals_px],
            "residuals_deg": [float(v) for v in self.residuals_deg],
        }


#: two sun directions closer than this [°] are one point to a fit: its outlier tolerance
#: (:data:`OUTLIER_DEG`) lets a frame lie anywhere within it, so frames there add no
#: geometry (the sun moves 1° in about four minutes)
DISTINCT_DEG = 1.0
#: distinct sun directions a fit needs: six equations for the four base parameters
MIN_DIRECTIONS = 3


def direction_groups(azimuth_deg: ArrayLike, elevation_deg: ArrayLike,
                     min_separation_deg: float = DISTINCT_DEG) -> NDArray[np.intp]:
    """A group number per sun position: positions within ``min_separation_deg`` of a group's
    first position share its number (greedy, in order).

    Frames of the same sun direction (a frame sent twice, times a few seconds apart, one
    time given to several frames) constrain a fit no more than one of them does; the fits
    count groups, not frames, and hold a whole group out together.
    """
    az = np.asarray(azimuth_deg, float).ravel()
    el = np.asarray(elevation_deg, float).ravel()
    groups = np.full(az.size, -1, np.intp)
    firsts: list[int] = []
    for i in range(az.size):
        if firsts:
            f = np.array(firsts)
            sep = angular_separation_deg(az[f], el[f], az[i], el[i])
            near = np.flatnonzero(np.asarray(sep) <= min_separation_deg)
            if near.size:
                groups[i] = groups[f[near[0]]]
                continue
        groups[i] = len(firsts)
        firsts.append(i)
    return groups


def n_directions(azimuth_deg: ArrayLike, elevation_deg: ArrayLike) -> int:
    """How many distinct sun directions (:func:`direction_groups`) the positions hold."""
    g = direction_groups(azimuth_deg, elevation_deg)
    return int(g.max()) + 1 if g.size else 0


def _too_few(n_dirs: int, n_par: int) -> bool:
    """Fewer distinct directions than ``n_par`` parameters need (two equations each, two
    to spare: four parameters need three)."""
    return 2 * n_dirs < n_par + 2


#: the largest tilt [°] a fit with ``fit_tilt`` may give, about each axis: an all-sky camera
#: looks up (the model's "small tilt"). Unbounded, one day's suns leave the tilt and the
#: centre trading along a shallow valley, and with a radial term the solver followed it to
#: a camera looking at the horizon (a tester's 3°-tilted equisolid camera: 78–85°, its centre
#: 18° from its image circle's, refused as times in a wrong zone). A fit ending at the bound
#: is one the frames cannot determine (``backend.vision.checks.check_tilt``).
MAX_TILT_DEG = 10.0
_MIRROR_NFEV = 100  # evaluations each mirror gets before the better one is solved on


def _camera(p: NDArray[np.float64], east: str, projection: str, n_radial: int,
            tilt: bool) -> FisheyeCamera:
    radial = tuple(float(v) for v in p[4:4 + n_radial])
    tn, te = (float(p[4 + n_radial]), float(p[5 + n_radial])) if tilt else (0.0, 0.0)
    return FisheyeCamera(cx_px=float(p[0]), cy_px=float(p[1]), px_per_deg=float(abs(p[2])),
                         north_offset_deg=float(p[3]), east=east, projection=projection,
                         radial_coeffs=radial, tilt_north_deg=tn, tilt_east_deg=te)


def _pixel_jacobian(p: NDArray[np.float64], cam: FisheyeCamera, az: NDArray[np.float64],
                    el: NDArray[np.float64], tilt: bool) -> NDArray[np.float64]:
    """The Jacobian of :func:`fit_fisheye`'s residuals ``(x…, y…)`` on the parameters ``p`` of
    :func:`_camera` (``cam``): :meth:`FisheyeCamera.sky_to_pixel_jacobian`, the scale's
    column signed as ``_camera`` takes ``|p[2]|``, zero where the pixel is undefined (the
    residual is a constant there)."""
    J = cam.sky_to_pixel_jacobian(az, el, tilt).reshape(-1, p.size)
    J[:, 2] *= np.sign(p[2])
    return np.where(np.all(np.isfinite(J), axis=1, keepdims=True), J, 0.0)


def _initial(x: NDArray[np.float64], y: NDArray[np.float64], az: NDArray[np.float64],
             el: NDArray[np.float64], cx: float, cy: float, east: str, projection: str
             ) -> tuple[float, float]:
    """Scale and north offset from the frames, given a centre guess."""
    r = np.hypot(x - cx, y - cy)
    unit = FisheyeCamera(cx, cy, 1.0, projection=projection)
    r_unit = unit.radius_px(np.radians(90.0 - el))
    ok = r_unit > 1e-6
    k = float(np.median(r[ok] / r_unit[ok])) if np.any(ok) else 1.0
    phi = np.degrees(np.arctan2(x - cx, -(y - cy)))
    off = phi + az if east == "left" else phi - az
    off_rad = np.radians(off)
    mean = float(np.degrees(np.arctan2(np.mean(np.sin(off_rad)), np.mean(np.cos(off_rad)))))
    return max(k, 1e-3), mean % 360.0


def fit_fisheye(
    x_px: ArrayLike,
    y_px: ArrayLike,
    azimuth_deg: ArrayLike,
    elevation_deg: ArrayLike,
    image_size: tuple[int, int],
    projection: str = "equidistant",
    east: str = "auto",
    n_radial: int = 0,
    fit_tilt: bool = False,
    centre_guess_px: tuple[float, float] | None = None,
    max_nfev: int = 2000,
) -> CalibrationResult:
    """Fit a :class:`FisheyeCamera` to sun centroids and their ephemeris positions.

    Parameters
    ----------
    x_px, y_px : detected sun centroids (column, row) [px].
    azimuth_deg, elevation_deg : the sun's position at each frame's time [°]
        (azimuth clockwise from north; apparent elevation from SPA).
    image_size : ``(width_px, height_px)``, for the starting centre.
    projection : one of :data:`vision.cameras.PROJECTIONS`.
    east : ``"left"``, ``"right"`` or ``"auto"`` (fit both, keep the better).
    n_radial : number of radial polynomial terms (0–2) to fit.
    fit_tilt : also fit the two tilt angles, each within ±:data:`MAX_TILT_DEG`.
    centre_guess_px : where the solver starts the centre (default the image centre).
    max_nfev : evaluations allowed to each mirror's solve.

    Needs at least as many distinct sun directions (:func:`direction_groups`) as half
    the number of parameters plus one (four parameters → three): copies of one direction
    add no equations, and a fit to fewer would leave a residual of zero and mean nothing.
    """
    x, y = np.asarray(x_px, float).ravel(), np.asarray(y_px, float).ravel()
    az, el = np.asarray(azimuth_deg, float).ravel(), np.asarray(elevation_deg, float).ravel()
    if not (x.size == y.size == az.size == el.size):
        raise ValueError("x_px, y_px, azimuth_deg and elevation_deg must have the same length")
    if projection not in PROJECTIONS:
        raise ValueError(f"projection must be one of {PROJECTIONS}, got {projection!r}")
    if east not in (*EAST_SIDES, "auto"):
        raise ValueError(f"east must be 'left', 'right' or 'auto', got {east!r}")
    if not 0 <= n_radial <= 2:
        raise ValueError("n_radial must be 0, 1 or 2")
    if np.any(~np.isfinite(x) | ~np.isfinite(y) | ~np.isfinite(az) | ~np.isfinite(el)):
        raise ValueError("non-finite centroid or sun position")
    if np.any(el <= 0):
        raise ValueError("every frame needs the sun above the horizon (elevation_deg > 0)")
    n_par = 4 + n_radial + (2 if fit_tilt else 0)
    if 2 * x.size < n_par + 2:
        raise ValueError(f"{x.size} frames are too few to fit {n_par} parameters")
    n_dirs = n_directions(az, el)
    if _too_few(n_dirs, n_par):
        raise ValueError(f"{x.size} frames hold only {n_dirs} distinct sun directions (more "
                         f"than {DISTINCT_DEG:g}° apart), too few to fit {n_par} parameters")
    w, h = image_size
    cx0, cy0 = centre_guess_px if centre_guess_px is not None else ((w - 1) / 2, (h - 1) / 2)
    sides = EAST_SIDES if east == "auto" else (east,)

    def resid_of(side: str) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
        def resid(p: NDArray[np.float64]) -> NDArray[np.float64]:
            cam = _camera(p, side, projection, n_radial, fit_tilt)
            px, py = cam.sky_to_pixel(az, el)
            r = np.concatenate([px - x, py - y])
            return np.where(np.isfinite(r), r, 1e4)
        return resid

    def jac_of(side: str) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
        def jac(p: NDArray[np.float64]) -> NDArray[np.float64]:
            return _pixel_jacobian(p, _camera(p, side, projection, n_radial, fit_tilt), az, el,
                                   fit_tilt)
        return jac

    # with both mirrors: each solved for at most _MIRROR_NFEV evaluations, the better one
    # then to convergence (the wrong mirror's solve would grind to its limit)
    first = min(max_nfev, _MIRROR_NFEV) if len(sides) > 1 else max_nfev
    n_p = 4 + n_radial + (2 if fit_tilt else 0)
    lo, hi = np.full(n_p, -np.inf), np.full(n_p, np.inf)
    if fit_tilt:
        lo[-2:], hi[-2:] = -MAX_TILT_DEG, MAX_TILT_DEG
    best: tuple[float, Any, str] | None = None
    costs: dict[str, float] = {}
    for side in sides:
        k0, off0 = _initial(x, y, az, el, cx0, cy0, side, projection)
        p0 = np.concatenate([[cx0, cy0, k0, off0], np.zeros(n_radial),
                             np.zeros(2 if fit_tilt else 0)])
        sol = least_squares(resid_of(side), p0, jac=jac_of(side), method="trf", x_scale="jac",
                            max_nfev=first, bounds=(lo, hi))
        costs[side] = float(sol.cost)
        if best is None or sol.cost < best[0]:
            best = (float(sol.cost), sol, side)
    assert best is not None
    _, sol, side = best
    if sol.status == 0 and first < max_nfev:  # stopped at the evaluation limit: go on
        sol = least_squares(resid_of(side), sol.x, jac=jac_of(side), method="trf",
                            x_scale="jac", max_nfev=max_nfev - first, bounds=(lo, hi))
        costs[side] = float(sol.cost)
    p = sol.x
    cam = _camera(p, side, projection, n_radial, fit_tilt)
    px, py = cam.sky_to_pixel(az, el)
    res_px = np.hypot(px - x, py - y)
    daz, d_el = cam.pixel_to_sky(x, y)
    res_deg = angular_separation_deg(az, el, daz, d_el)
    other = [c for s, c in costs.items() if s != side]
    fitted = ["cx_px", "cy_px", "px_per_deg", "north_offset_deg", "east" if east == "auto" else ""]
    fitted += [f"radial_c{i + 2}" for i in range(n_radial)]
    fitted += ["tilt_north_deg", "tilt_east_deg"] if fit_tilt else []
    return CalibrationResult(cam, res_px, np.asarray(res_deg, float), int(x.size),
                             other[0] if other else None, tuple(f for f in fitted if f))


# --------------------------------------------------------------------------- self-calibration

#: detection passes of :func:`self_calibrate` (blind, then ephemeris-guided): each frame is
#: decoded this many times, what a caller's cost bound counts
CALIBRATION_PASSES = 2
#: a frame whose sun lies farther than this from the consensus model is an outlier [°]: the
#: detector's own tolerance of agreement with an ephemeris (vision.confidence.AGREES_DEG)
OUTLIER_DEG = AGREES_DEG
_RANSAC_SAMPLE = 3  # frames per sample: six equations for the four base parameters
#: samples drawn (all of them when there are fewer triples): with 30 % of the frames
#: outliers, 20 draws all miss a clean triple with probability (1 − 0.7³)²⁰ < 0.001
_RANSAC_TRIALS = 20


def sky_residuals_deg(camera: FisheyeCamera, x_px: ArrayLike, y_px: ArrayLike,
                      azimuth_deg: ArrayLike, elevation_deg: ArrayLike) -> NDArray[np.float64]:
    """Angle on the sky [°] between the direction a camera gives each pixel and the sun.

    The angle through the centre of the camera's sphere, so a frame near the
    horizon of a fisheye counts as much as one near the zenith (pixel residuals
    do not: the px/° of a projection varies).
    """
    v = camera.pixel_to_direction(x_px, y_px)
    s = enu_from_sky(azimuth_deg, elevation_deg)
    out = np.degrees(np.arccos(np.clip(np.sum(v * s, axis=-1), -1.0, 1.0)))
    return np.where(np.isfinite(out), out, 180.0)


@dataclass(frozen=True)
class RobustFit:
    """:func:`robust_fit`: the fit on the inliers and every frame's residual to it."""

    result: CalibrationResult
    inlier: NDArray[np.bool_]
    residuals_deg: NDArray[np.float64]
    residuals_px: NDArray[np.float64]


def _residuals_all(cam: FisheyeCamera, x: NDArray[np.float64], y: NDArray[np.float64],
                   az: NDArray[np.float64], el: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    px, py = cam.sky_to_pixel(az, el)
    res_px = np.hypot(px - x, py - y)
    return sky_residuals_deg(cam, x, y, az, el), np.where(np.isfinite(res_px), res_px, np.inf)


def robust_fit(x_px: ArrayLike, y_px: ArrayLike, azimuth_deg: ArrayLike,
               elevation_deg: ArrayLike, image_size: tuple[int, int],
               outlier_deg: float = OUTLIER_DEG, seed: int = 0, **fit_kwargs: Any) -> RobustFit:
    """:func:`fit_fisheye` with the outlying frames left out.

    RANSAC (Fischler & Bolles 1981) over samples of three frames, each fitted
    with the four base parameters (centre, scale, north offset; both mirrors),
    scored by MSAC (Torr & Zisserman 2000: the sum of the squared sky residuals
    [°], each capped at ``outlier_deg``²); the best sample's inliers (within
    ``outlier_deg``) are fitted with the full model (``fit_kwargs``), and the
    inliers of that fit are fitted again until the set no longer changes (at
    most five times; the refits keep the first one's mirror). A sample's solve stops
    after 60 evaluations (a degenerate triple only has to lose). Every triple is tried
    when there are at most :data:`_RANSAC_TRIALS`; otherwise that many random ones
    (``seed``); a sample of fewer than three distinct sun directions is no sample.
    Frames count by distinct sun direction (:func:`direction_groups`). Returns the fit
    and every frame's residual to it, inlier or not.
    """
    x, y = np.asarray(x_px, float).ravel(), np.asarray(y_px, float).ravel()
    az, el = np.asarray(azimuth_deg, float).ravel(), np.asarray(elevation_deg, float).ravel()
    n = x.size
    if not (n == y.size == az.size == el.size):
        raise ValueError("x_px, y_px, azimuth_deg and elevation_deg must have the same length")
    if not outlier_deg > 0:
        raise ValueError(f"outlier_deg must be positive, got {outlier_deg}")
    n_par = 4 + int(fit_kwargs.get("n_radial", 0)) + (2 if fit_kwargs.get("fit_tilt") else 0)
    groups = direction_groups(az, el)

    def too_few(use: NDArray[np.bool_]) -> bool:
        return _too_few(np.unique(groups[use]).size, n_par)

    if too_few(np.ones(n, bool)):
        raise ValueError(f"{n} frames holding {np.unique(groups).size} distinct sun directions "
                         f"are too few to fit {n_par} parameters")
    base = {k: v for k, v in fit_kwargs.items() if k in ("projection", "east",
                                                          "centre_guess_px")}
    inlier = np.ones(n, bool)
    if n > _RANSAC_SAMPLE + 1:
        if comb(n, _RANSAC_SAMPLE) <= _RANSAC_TRIALS:
            samples = [np.array(c) for c in combinations(range(n), _RANSAC_SAMPLE)]
        else:
            rng = np.random.default_rng(seed)
            samples = [np.sort(rng.choice(n, _RANSAC_SAMPLE, replace=False))
                       for _ in range(_RANSAC_TRIALS)]
        best = np.inf
        for s in samples:
            try:
                cand = fit_fisheye(x[s], y[s], az[s], el[s], image_size, max_nfev=60,
                                   **base).camera
            except ValueError:
                continue
            r = sky_residuals_deg(cand, x, y, az, el)
            score = float(np.sum(np.minimum(r, outlier_deg) ** 2))
            if score < best:
                best, inlier = score, r <= outlier_deg
        if too_few(inlier):
            inlier = np.ones(n, bool)  # no consensus: everything, and say so in the residuals
    first: CalibrationResult | None = None
    for _ in range(5):
        fitted_on = inlier
        use = np.flatnonzero(fitted_on)
        # the first fit tries both mirrors (unless one is given); the refits keep its mirror
        kw = fit_kwargs if first is None else {**fit_kwargs, "east": first.camera.east}
        res = fit_fisheye(x[use], y[use], az[use], el[use], image_size, **kw)
        if first is None:
            first = res
        r_deg, r_px = _residuals_all(res.camera, x, y, az, el)
        inlier = r_deg <= outlier_deg
        if np.array_equal(inlier, fitted_on) or too_few(inlier):
            break
    assert first is not None
    if res is not first:  # what the first fit decided (the mirror) stays said
        res = replace(res, cost_other_mirror=first.cost_other_mirror, fitted=first.fitted)
    return RobustFit(res, fitted_on, r_deg, r_px)


#: Evaluations a held-out fit of :func:`leave_one_out_deg` gets (:func:`fit_fisheye`'s
#: ``max_nfev``; its own default 2,000). Of the 1,526 held-out fits of the calibration tests,
#: 99 % converged within 44; only fits the frames cannot determine went on — two radial terms
#: on a few directions, held out tens of degrees off: on the Wettermast frames an hour late
#: 1,141 and 1,142, and 16 to the 2,000: that calibration took 10.3 s of CPU to be refused,
#: 4.7 s now (the service's, decoding included, by hand). Stopped here, such a fit's held-out
#: residual is what it is then, large either way, and its model is not chosen: the service's
#: calibrations of the Wolf and Wettermast frames (right, reversed and late times) are
#: unchanged but for one such model's held-out RMS on every third Wolf frame, 36.57° → 36.74°
#: (session 33, by hand).
LOO_MAX_NFEV = 300


def leave_one_out_deg(x_px: ArrayLike, y_px: ArrayLike, azimuth_deg: ArrayLike,
                      elevation_deg: ArrayLike, image_size: tuple[int, int],
                      **fit_kwargs: Any) -> NDArray[np.float64]:
    """Each frame's sky residual [°] to the camera fitted on all the others (held out), each
    fit given :data:`LOO_MAX_NFEV` evaluations unless ``fit_kwargs`` say otherwise.

    The frames of the held-out frame's sun direction (:func:`direction_groups`) are held
    out with it: a copy left in the fit would predict the frame from itself.
    """
    fit_kwargs = {"max_nfev": LOO_MAX_NFEV, **fit_kwargs}
    x, y = np.asarray(x_px, float).ravel(), np.asarray(y_px, float).ravel()
    az, el = np.asarray(azimuth_deg, float).ravel(), np.asarray(elevation_deg, float).ravel()
    groups = direction_groups(az, el)
    out = np.empty(x.size)
    for i in range(x.size):
        keep = groups != groups[i]
        cam = fit_fisheye(x[keep], y[keep], az[keep], el[keep], image_size,
                          **fit_kwargs).camera
        out[i] = sky_residuals_deg(cam, x[i:i + 1], y[i:i + 1], az[i:i + 1], el[i:i + 1])[0]
    return out


def choose_radial(x_px: ArrayLike, y_px: ArrayLike, azimuth_deg: ArrayLike,
                  elevation_deg: ArrayLike, image_size: tuple[int, int],
                  max_terms: int = 2, eligible: Sequence[int] | None = None,
                  held_out: dict[int, NDArray[np.float64]] | None = None,
                  **fit_kwargs: Any) -> tuple[int, list[dict[str, Any]]]:
    """How many radial polynomial terms the frames support (0: the plain projection).

    Each model (0 … ``max_terms`` terms) is scored by its leave-one-out mean squared
    error on the sky; the one kept is the simplest within one standard error of the
    best (the one-standard-error rule, Hastie, Tibshirani & Friedman, *The Elements of
    Statistical Learning*, 2nd ed., §7.10): a term must lower the held-out error by more
    than the frames can tell apart from noise. ``eligible`` (default: every model tried)
    are the models the choice is made among; the others are scored for the report only.
    Returns the number of terms and, for each tried, ``n_radial`` and ``loo_rms_deg``;
    ``held_out`` (a dict given) receives each model's held-out residuals [°], so that the
    caller does not fit them again. A model needs distinct sun directions enough for a
    leave-one-out fit with one to spare (:func:`radial_terms_possible`).
    """
    x = np.asarray(x_px, float).ravel()
    n_dirs = n_directions(azimuth_deg, elevation_deg)
    tried: list[dict[str, Any]] = []
    mse: dict[int, float] = {}
    se: dict[int, float] = {}
    for k in range(radial_terms_possible(n_dirs, bool(fit_kwargs.get("fit_tilt")), max_terms)):
        loo = leave_one_out_deg(x, y_px, azimuth_deg, elevation_deg, image_size,
                                n_radial=k, **fit_kwargs)
        if held_out is not None:
            held_out[k] = loo
        sq = loo ** 2
        mse[k] = float(np.mean(sq))
        se[k] = float(np.std(sq, ddof=1) / np.sqrt(sq.size))
        tried.append({"n_radial": k, "loo_rms_deg": float(np.sqrt(mse[k]))})
    among = [k for k in mse if eligible is None or k in eligible]
    if not among:
        return min(eligible or [0]), tried
    return _one_standard_error(among, mse, se), tried


def _one_standard_error(order: Sequence[Any], mse: dict[Any, float],
                        se: dict[Any, float]) -> Any:
    """The first model of ``order`` whose leave-one-out mean squared error is within one
    standard error of the best's (Hastie, Tibshirani & Friedman §7.10): ``order`` runs from
    the model kept unless the frames show another to be better."""
    best = min(order, key=lambda k: mse[k])
    return next(k for k in order if mse[k] <= mse[best] + se[best])


#: ``projection`` of :func:`calibrate_positions` / :func:`self_calibrate` that lets the frames
#: choose the lens's projection (:func:`choose_projection`)
PROJECTION_FROM_FRAMES = "auto"


def choose_projection(x_px: ArrayLike, y_px: ArrayLike, azimuth_deg: ArrayLike,
                      elevation_deg: ArrayLike, image_size: tuple[int, int],
                      equidistant_loo_deg: NDArray[np.float64] | None = None,
                      equidistant_terms: int = 0, **fit_kwargs: Any
                      ) -> tuple[str, list[dict[str, Any]]]:
    """The lens projection the frames support, among :data:`vision.cameras.PROJECTIONS`.

    Each other projection, without radial terms (four parameters), is scored by its
    leave-one-out mean squared error on the sky against equidistant with the radial terms
    the frames chose for it (``equidistant_loo_deg`` on the same frames, its
    ``equidistant_terms``; without it, equidistant's plain model); equidistant is kept unless
    another is better by more than one standard error (:func:`_one_standard_error`, the
    order of ``PROJECTIONS``). An equisolid lens's frames at Cape Town (suns 6–32° up)
    fitted as equidistant with the radial terms the frames chose left 0.45° held out where
    the equisolid model left 0.135° (a tester's renderer); on Wolf's hand labels a plain
    stereographic model beat the plain equidistant one on 12 frames but not equidistant with
    its radial term, which held out better (0.306° against 0.347°). Returns the projection
    and, for each, ``projection``, ``n_radial`` and ``loo_rms_deg``.
    """
    mse: dict[str, float] = {}
    se: dict[str, float] = {}
    tried: list[dict[str, Any]] = []
    for p in PROJECTIONS:
        terms = equidistant_terms if p == "equidistant" and equidistant_loo_deg is not None \
            else 0
        sq = (equidistant_loo_deg if p == "equidistant" and equidistant_loo_deg is not None
              else leave_one_out_deg(x_px, y_px, azimuth_deg, elevation_deg, image_size,
                                     **{**fit_kwargs, "projection": p, "n_radial": 0})) ** 2
        mse[p] = float(np.mean(sq))
        se[p] = float(np.std(sq, ddof=1) / np.sqrt(sq.size))
        tried.append({"projection": p, "n_radial": terms,
                      "loo_rms_deg": float(np.sqrt(mse[p]))})
    return _one_standard_error(list(PROJECTIONS), mse, se), tried


def radial_terms_possible(n_dirs: int, fit_tilt: bool = False, max_terms: int = 2) -> int:
    """How many radial models (0, 1, … terms) ``n_dirs`` distinct sun directions can be
    checked on by leaving each out: the held-out fit needs two equations to spare."""
    return sum(1 for k in range(max_terms + 1)
               if 2 * (n_dirs - 1) >= 4 + k + (2 if fit_tilt else 0) + 4)


@dataclass(frozen=True)
class PositionFit:
    """:func:`calibrate_positions`: the robust fit, the radial terms tried and the
    leave-one-out residual [°] of each inlier (empty when too few)."""

    fit: RobustFit
    model_selection: list[dict[str, Any]]
    loo_deg: NDArray[np.float64]


def consensus_fits(x_px: ArrayLike, y_px: ArrayLike, azimuth_deg: ArrayLike,
                   elevation_deg: ArrayLike, image_size: tuple[int, int],
                   n_radial: int | None = None, outlier_deg: float = OUTLIER_DEG,
                   **fit_kwargs: Any) -> tuple[dict[int, RobustFit], list[int]]:
    """:func:`robust_fit` of each radial model, each deciding its own outliers, and the
    models that explain the most distinct sun directions within ``outlier_deg`` — the
    same frames as the simplest of them (so they can be compared on those frames).

    ``n_radial`` given: that model alone. ``None``: every model the frames can check by
    leaving each out (:func:`radial_terms_possible`), at least the plain projection.
    RANSAC's consensus is the base model's, its refits the full model's (:func:`robust_fit`),
    so a lens the plain projection describes badly (a stereographic lens fitted as
    equidistant leaves its low suns more than :data:`OUTLIER_DEG` off) is not refused for
    the plain model's outliers when a radial term explains them. A model explains a frame
    when the frame is in its fitted set and within ``outlier_deg`` of it (a fit that found
    no consensus fits every frame and explains only those it lies near).
    """
    az, el = np.asarray(azimuth_deg, float).ravel(), np.asarray(elevation_deg, float).ravel()
    groups = direction_groups(az, el)
    models = ([n_radial] if n_radial is not None else
              range(max(1, radial_terms_possible(int(groups.max()) + 1,
                                                 bool(fit_kwargs.get("fit_tilt"))))))
    fits = {k: robust_fit(x_px, y_px, az, el, image_size, outlier_deg, n_radial=k,
                          **fit_kwargs) for k in models}
    explained = {k: np.unique(groups[f.inlier & (f.residuals_deg <= outlier_deg)]).size
                 for k, f in fits.items()}
    first = next(k for k in fits if explained[k] == max(explained.values()))
    return fits, [k for k in fits if np.array_equal(fits[k].inlier, fits[first].inlier)]


def calibrate_positions(x_px: ArrayLike, y_px: ArrayLike, azimuth_deg: ArrayLike,
                        elevation_deg: ArrayLike, image_size: tuple[int, int],
                        projection: str = "equidistant", east: str = "auto",
                        n_radial: int | None = None, fit_tilt: bool = False,
                        outlier_deg: float = OUTLIER_DEG,
                        centre_guess_px: tuple[float, float] | None = None) -> PositionFit:
    """The fit of :func:`self_calibrate` on sun positions already found, and each inlier
    held out in turn.

    The models of :func:`consensus_fits` that explain the most frames (the same frames)
    compete by :func:`choose_radial`'s one-standard-error rule on those frames;
    ``model_selection`` (``n_radial=None`` only) reports every model's leave-one-out RMS on
    those same frames, the stored fit's, and how many frames its own robust fit explains
    (``n_inliers``). ``projection="auto"``: the projection too (:func:`choose_projection`;
    its rows without ``n_inliers``).
    """
    x, y = np.asarray(x_px, float).ravel(), np.asarray(y_px, float).ravel()
    az, el = np.asarray(azimuth_deg, float).ravel(), np.asarray(elevation_deg, float).ravel()
    if projection == PROJECTION_FROM_FRAMES:
        return _positions_any_projection(x, y, az, el, image_size, east, n_radial, fit_tilt,
                                         outlier_deg, centre_guess_px)
    fixed: dict[str, Any] = {"projection": projection, "east": east, "fit_tilt": fit_tilt}
    fits, best = consensus_fits(x, y, az, el, image_size, n_radial, outlier_deg,
                                centre_guess_px=centre_guess_px, **fixed)
    inl = fits[best[0]].inlier
    # the mirror is the consensus's; held-out fits start from its centre (each mirror's
    # solve costs as much again, and the wrong one's grinds to its limit)
    cam = fits[best[0]].result.camera
    known = {**fixed, "east": cam.east, "centre_guess_px": (cam.cx_px, cam.cy_px)}
    selection: list[dict[str, Any]] = []
    held: dict[int, NDArray[np.float64]] = {}  # the models' held-out residuals, fitted once
    k = best[0]
    if n_radial is None:
        k, selection = choose_radial(x[inl], y[inl], az[inl], el[inl], image_size,
                                     max_terms=max(fits), eligible=best, held_out=held,
                                     **known)
        for row in selection:
            f = fits[row["n_radial"]]
            row["n_inliers"] = int(np.sum(f.inlier & (f.residuals_deg <= outlier_deg)))
    rf = fits[k]
    n_par = 4 + k + (2 if fit_tilt else 0)
    loo = held[k] if k in held else (
        leave_one_out_deg(x[inl], y[inl], az[inl], el[inl], image_size,
                          **{**known, "n_radial": k})
        if not _too_few(n_directions(az[inl], el[inl]) - 1, n_par) else np.empty(0))
    return PositionFit(rf, [{"projection": projection, **row} for row in selection], loo)


def _positions_any_projection(x: NDArray[np.float64], y: NDArray[np.float64],
                              az: NDArray[np.float64], el: NDArray[np.float64],
                              image_size: tuple[int, int], east: str, n_radial: int | None,
                              fit_tilt: bool, outlier_deg: float,
                              centre_guess_px: tuple[float, float] | None) -> PositionFit:
    """:func:`calibrate_positions` with the projection chosen by :func:`choose_projection` on
    the equidistant fit's inliers (its consensus decides the frames, its mirror and centre
    start the held-out fits); ``model_selection`` lists every projection tried, then the
    chosen one's radial terms."""
    def positions(p: str) -> PositionFit:
        return calibrate_positions(x, y, az, el, image_size, p, east, n_radial, fit_tilt,
                                   outlier_deg, centre_guess_px)

    base = positions("equidistant")
    inl, cam = base.fit.inlier, base.fit.result.camera
    if _too_few(n_directions(az[inl], el[inl]) - 1, 4 + (2 if fit_tilt else 0)):
        return base  # too few frames to hold one out: the equidistant model
    chosen, tried = choose_projection(x[inl], y[inl], az[inl], el[inl], image_size,
                                      base.loo_deg if base.loo_deg.size else None,
                                      len(cam.radial_coeffs), east=cam.east,
                                      fit_tilt=fit_tilt, centre_guess_px=(cam.cx_px, cam.cy_px))
    pf = base if chosen == "equidistant" else positions(chosen)
    rows = [r for r in tried if r["projection"] != chosen] + (pf.model_selection or [
        r for r in tried if r["projection"] == chosen])  # the chosen one's radial models
    return replace(pf, model_selection=rows)


#: the least detection scatter assumed per image axis [°, in the fitted scale]: the fit's
#: own residual understates it when the frames are few or lie on a short arc (three frames
#: leave two degrees of freedom). The least any real series in the repository shows:
#: Wettermast's six frames, 0.11° RMS in-sample, 0.095° per axis over the fit's 12 − 4
#: degrees of freedom (Wolf's twelve: 0.26° per axis; docs/vision-calibration.md)
DETECTION_FLOOR_DEG = 0.1
#: the sky over which :func:`sky_uncertainty_deg` looks: directions this high or higher [°]
SKY_MIN_ELEVATION_DEG = 10.0


def _parameters(cam: FisheyeCamera, tilt: bool) -> NDArray[np.float64]:
    """The parameter vector of :func:`_camera` for a camera (its inverse)."""
    return np.array([cam.cx_px, cam.cy_px, cam.px_per_deg, cam.north_offset_deg,
                     *cam.radial_coeffs,
                     *((cam.tilt_north_deg, cam.tilt_east_deg) if tilt else ())], float)


def sky_uncertainty_deg(fit: CalibrationResult, azimuth_deg: ArrayLike,
                        elevation_deg: ArrayLike, image_size: tuple[int, int],
                        floor_deg: float = DETECTION_FLOOR_DEG,
                        min_elevation_deg: float = SKY_MIN_ELEVATION_DEG) -> float:
    """The largest 1-σ error [°] of the direction the fitted camera gives a pixel, over
    the sky it sees (directions ``min_elevation_deg`` or higher, every 10° of azimuth and
    5° of elevation, whose pixel lies in the frame).

    How well the frames constrain the camera away from their own suns: the fitted
    parameters' covariance ``C = σ² (JᵀJ)⁻¹`` at the solution (``J`` the Jacobian of the
    sun pixels on the parameters — the fit's own, analytic — one row pair per distinct sun
    direction of ``azimuth_deg``/``elevation_deg``, the fit's inliers; σ the fit's residual
    per image axis over its degrees of freedom, not below ``floor_deg`` in the fitted scale),
    propagated to first order to each pixel's direction ``d``: ``Σ_d = G C Gᵀ``,
    ``G = ∂d/∂p``, and its 1-σ angle ``√trace Σ_d`` (Hartley & Zisserman, *Multiple View
    Geometry*, 2nd ed., §5.2: backward and forward propagation of covariance). Frames
    on a short arc fit to a few hundredths of a degree and leave the camera free to turn
    about them: this grows where their residual does not. Infinite when the parameters
    are not all determined. It holds where the model holds: it cannot see a lens term the
    model lacks, so below the lowest sun fitted (where the radial law is extrapolated)
    it says nothing — :func:`self_calibrate` computes it from that sun up
    (:func:`sky_band_deg`).
    """
    az, el = np.asarray(azimuth_deg, float).ravel(), np.asarray(elevation_deg, float).ravel()
    _, first = np.unique(direction_groups(az, el), return_index=True)
    az, el = az[first], el[first]
    cam = fit.camera
    tilt = "tilt_north_deg" in fit.fitted
    p0 = _parameters(cam, tilt)
    n_radial = len(cam.radial_coeffs)

    def jacobian(f: Callable[[FisheyeCamera], NDArray[np.float64]]) -> NDArray[np.float64]:
        """A central difference: the pixels' direction, the inverse of the fit's model
        (through :meth:`FisheyeCamera.theta_rad`'s Newton steps), has no analytic one here."""
        cols = []
        for j in range(p0.size):
            h = 1e-4 * max(1.0, abs(p0[j])) if j != 3 else 1e-3  # the north offset [°]
            step = np.zeros_like(p0)
            step[j] = h
            hi = f(_camera(p0 + step, cam.east, cam.projection, n_radial, tilt))
            lo = f(_camera(p0 - step, cam.east, cam.projection, n_radial, tilt))
            cols.append((hi - lo).ravel() / (2 * h))
        return np.stack(cols, axis=-1)

    J = _pixel_jacobian(p0, cam, az, el, tilt)
    dof = 2 * fit.n_frames - p0.size
    sigma_px = float(np.sqrt(np.sum(fit.residuals_px**2) / dof)) if dof > 0 else 0.0
    sigma_px = max(sigma_px, floor_deg * cam.px_per_deg)
    try:
        cov = sigma_px**2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return float("inf")
    grid_az, grid_el = np.meshgrid(np.arange(0.0, 360.0, 10.0),
                                   np.arange(min_elevation_deg, 90.0, 5.0))
    gx, gy = cam.sky_to_pixel(np.append(grid_az.ravel(), 0.0), np.append(grid_el.ravel(), 90.0))
    w, h = image_size
    seen = np.isfinite(gx) & np.isfinite(gy) & (gx >= 0) & (gx <= w - 1) & (gy >= 0) & (gy <= h - 1)
    G = jacobian(lambda c: c.pixel_to_direction(gx[seen], gy[seen])).reshape(-1, 3, p0.size)
    var = np.einsum("mip,pq,miq->m", G, cov, G)  # trace of G C Gᵀ per direction
    worst = float(np.degrees(np.sqrt(np.max(var)))) if var.size else float("inf")
    return worst if np.isfinite(worst) and np.all(np.diag(cov) >= 0) else float("inf")


def sky_band_deg(elevation_deg: ArrayLike) -> float:
    """The lowest elevation [°] a calibration's :func:`sky_uncertainty_deg` is computed
    from: its lowest fitted sun's (``elevation_deg``, the inliers'), but not below
    :data:`SKY_MIN_ELEVATION_DEG`. Between that sun's circle and the zenith (the fitted
    centre) the frames measure the radial law; below it the law is extrapolated, and its
    error there is not the parameters' covariance but the lens terms the model lacks: a
    tester's tilted equisolid 190° camera fitted on suns 34–60° up claimed 0.19° from 10°
    up while its true error was 6.0° RMS, 7.8° worst at 5–15° up."""
    return max(SKY_MIN_ELEVATION_DEG, float(np.min(np.asarray(elevation_deg, float))))


@dataclass(frozen=True)
class SelfCalibration:
    """:func:`self_calibrate`'s answer.

    ``fit`` is the camera fitted on the inlier frames; ``frames`` one report per
    frame; ``loo_deg`` the leave-one-out residual of each inlier (in ``fit``'s
    order; empty when too few frames); ``model_selection`` the radial terms tried;
    ``image_size_px`` the size the frames decode to (orientation applied), the size
    the camera is valid for; ``fitted_elevation_deg`` the lowest and highest elevation of
    the inlier suns; ``sky_uncertainty_deg`` how well the frames fix the camera over the
    sky from the lowest of them up (:func:`sky_uncertainty_deg`, :func:`sky_band_deg`).
    """

    fit: CalibrationResult
    frames: list[dict[str, Any]]
    loo_deg: NDArray[np.float64]
    model_selection: list[dict[str, Any]]
    image_size_px: tuple[int, int]  # (width, height) of the decoded frames
    sky_uncertainty_deg: float  # :func:`sky_uncertainty_deg` of ``fit``, from sky_band_deg up
    fitted_elevation_deg: tuple[float, float]  # (lowest, highest) inlier sun [°]

    @property
    def n_outliers(self) -> int:
        return sum(1 for f in self.frames if f.get("outlier"))

    @property
    def loo_rms_deg(self) -> float | None:
        return float(np.sqrt(np.mean(self.loo_deg**2))) if self.loo_deg.size else None


#: a fit leaving an RMS above this on the sky [°] is refused: it is the radius of the
#: ephemeris-guided search around the predicted sun (``vision.detect._SEARCH_DEG``), so a
#: camera that misplaces its own frames' suns by more cannot even guide that search
MAX_RMS_DEG = 8.0


class CalibrationFailed(ValueError):
    """A fit that explains its frames too badly to be a calibration (:data:`MAX_RMS_DEG`);
    ``frames`` holds each frame's report with its residual."""

    def __init__(self, message: str, frames: list[dict[str, Any]]) -> None:
        super().__init__(message)
        self.frames = frames


def _detect_all(load: Callable[[int], NDArray[Any]], n: int, method: str,
                camera: FisheyeCamera | None, az: NDArray[np.float64],
                el: NDArray[np.float64]) -> tuple[list[Any], tuple[int, int]]:
    from vision.detect import detect_sun

    out: list[Any] = []
    sizes: set[tuple[int, int]] = set()
    for i in range(n):
        img = load(i)
        sizes.add((int(img.shape[1]), int(img.shape[0])))
        if len(sizes) != 1:
            raise ValueError(f"every frame must have the same size, got {sorted(sizes)}")
        if camera is None or el[i] <= 0 or method != "robust":
            out.append(detect_sun(img, method=method))
        else:
            px, py = camera.sky_to_pixel(az[i], el[i])
            out.append(detect_sun(img, method=method, camera=camera,
                                  expected_px=(float(px), float(py))))
        del img
    return out, sizes.pop()


def self_calibrate(load: Callable[[int], NDArray[Any]], azimuth_deg: ArrayLike,
                   elevation_deg: ArrayLike, names: Sequence[str] | None = None,
                   method: str = "robust", projection: str = "equidistant",
                   east: str = "auto", n_radial: int | None = None, fit_tilt: bool = False,
                   outlier_deg: float = OUTLIER_DEG, guided: bool = True) -> SelfCalibration:
    """Fit a fisheye camera from frames, their sun positions and nothing else (SuMo-style).

    ``load(i)`` decodes frame ``i`` (called once per pass, so a batch of large
    frames needs the memory of one); ``azimuth_deg``/``elevation_deg`` are the
    ephemeris sun at each frame's time. Steps (the module docstring): blind
    detection (:func:`vision.detect.detect_sun`), :func:`robust_fit` of the four
    base parameters, then — with ``guided`` and the ``robust`` method — each
    frame searched again around the sun the fitted model predicts, and the model
    fitted again; ``n_radial=None`` lets :func:`choose_radial` decide the radial
    terms, ``projection="auto"`` (:data:`PROJECTION_FROM_FRAMES`) :func:`choose_projection`
    the projection. Each frame's report: ``name``, ``sun_found``, ``confidence``,
    ``centroid_px``, ``search`` (``blind`` or ``ephemeris-guided``), ``used``,
    ``outlier`` and, when a sun was found above the horizon, ``residual_px`` and
    ``residual_deg`` to the final model. A ValueError says why when too few
    distinct sun directions (:func:`direction_groups`: frames of one direction count
    once) are given or left with a sun found; :class:`CalibrationFailed` (a ValueError)
    when the fit's RMS on the sky exceeds :data:`MAX_RMS_DEG`, with every frame's
    residual.
    """
    az = np.asarray(azimuth_deg, float).ravel()
    el = np.asarray(elevation_deg, float).ravel()
    if az.size != el.size:
        raise ValueError(f"{az.size} azimuths but {el.size} elevations")
    n = az.size
    names = list(names) if names is not None else [f"frame {i}" for i in range(n)]
    if n_radial is not None and not 0 <= n_radial <= 2:
        raise ValueError("n_radial must be 0, 1, 2 or None (chosen from the frames)")
    fixed: dict[str, Any] = {"projection": projection, "east": east, "fit_tilt": fit_tilt}
    # the first fit only guides the second search: equidistant where the frames choose
    guide = {**fixed, "projection": "equidistant" if projection == PROJECTION_FROM_FRAMES
             else projection}
    up = el > 0
    given = n_directions(az[up], el[up])
    if given < MIN_DIRECTIONS:
        raise ValueError(f"the {n} frames' times put the sun above the horizon in only "
                         f"{given} distinct direction{'' if given == 1 else 's'} (more than "
                         f"{DISTINCT_DEG:g}° apart; "
                         f"frames of one direction count once); a calibration needs at "
                         f"least {MIN_DIRECTIONS}")

    def found(dets: list[Any], k: int
              ) -> tuple[NDArray[np.intp], NDArray[np.float64], tuple[float, float] | None]:
        """The frames with a sun above the horizon, its pixels, the image circle's centre."""
        use = np.array([i for i, d in enumerate(dets)
                        if d.sun_found and d.centroid_px is not None and el[i] > 0], int)
        n_par = 4 + k + (2 if fit_tilt else 0)
        dirs = n_directions(az[use], el[use])
        if _too_few(dirs, n_par):
            missing = [names[i] for i in range(n) if i not in set(use.tolist())]
            raise ValueError(f"only {use.size} frames have a sun found above the horizon, in "
                             f"{dirs} distinct direction{'' if dirs == 1 else 's'} (none in: "
                             f"{', '.join(missing) or 'none'}); {n_par} parameters need at "
                             f"least {(n_par + 3) // 2} directions")
        xy = np.array([dets[i].centroid_px for i in use], float)
        fov = next((d.fov for d in dets if getattr(d, "fov", None) is not None), None)
        return use, xy, (fov.cx_px, fov.cy_px) if fov is not None else None

    dets, size = _detect_all(load, n, method, None, az, el)
    search = ["blind"] * n
    if guided and method == "robust":
        # the first fit only guides the second search: the simplest model explaining the
        # most frames (a model that misplaces the low suns would guide the search there)
        use, xy, guess = found(dets, n_radial or 0)
        fits, best = consensus_fits(xy[:, 0], xy[:, 1], az[use], el[use], size, n_radial,
                                    outlier_deg, centre_guess_px=guess, **guide)
        again, _ = _detect_all(load, n, method, fits[best[0]].result.camera, az, el)
        # keep the guided answer where it found a sun; a refusal keeps the blind one
        for i, d in enumerate(again):
            if d.sun_found and d.centroid_px is not None:
                dets[i], search[i] = d, "ephemeris-guided"
    use, xy, guess = found(dets, n_radial or 0)
    pf = calibrate_positions(xy[:, 0], xy[:, 1], az[use], el[use], size, n_radial=n_radial,
                             outlier_deg=outlier_deg, centre_guess_px=guess, **fixed)
    rf = pf.fit
    at = {int(i): j for j, i in enumerate(use)}
    report: list[dict[str, Any]] = []
    for i, d in enumerate(dets):
        j = at.get(i)
        r: dict[str, Any] = {
            "name": names[i], "sun_found": bool(d.sun_found), "confidence": float(d.confidence),
            "centroid_px": list(d.centroid_px) if d.centroid_px else None,
            "search": search[i], "used": bool(j is not None and rf.inlier[j]),
            "outlier": bool(j is not None and not rf.inlier[j])}
        if j is not None:
            r["residual_px"] = float(rf.residuals_px[j])
            r["residual_deg"] = float(rf.residuals_deg[j])
        report.append(r)
    if rf.result.rms_deg > MAX_RMS_DEG:
        worst = sorted((r for r in report if "residual_deg" in r),
                       key=lambda r: -r["residual_deg"])
        listed = ", ".join(f"{r['name']} {r['residual_deg']:.1f}°" for r in worst)
        raise CalibrationFailed(
            f"no camera explains these frames: the best fit leaves {rf.result.rms_deg:.1f}° "
            f"RMS on the sky (worst {rf.result.residuals_deg.max():.1f}°), more than the "
            f"{MAX_RMS_DEG:g}° within which detection searches around a calibration's "
            f"prediction; check the frames' times (their zone) and the place. Residuals: "
            f"{listed}", report)
    inl = use[rf.inlier]
    return SelfCalibration(rf.result, report, pf.loo_deg, pf.model_selection, size,
                           sky_uncertainty_deg(rf.result, az[inl], el[inl], size,
                                               min_elevation_deg=sky_band_deg(el[inl])),
                           (float(el[inl].min()), float(el[inl].max())))
