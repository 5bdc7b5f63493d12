"""Fit a fisheye sky camera from timestamped frames and the ephemeris.

Seed 003 assumed 3.365 px/deg and set the north offset by hand; here the
centre, the scale, the north offset and the mirror (east left or right) of a
:class:`vision.cameras.FisheyeCamera` — optionally a radial polynomial and two
tilt angles — are fitted by non-linear least squares on the pixel residuals
(``scipy.optimize.least_squares``, trust-region reflective) between the
detected sun centroids and the sun positions the caller provides from an
ephemeris (SPA). Both mirrors are fitted and the one with the lower cost is
kept. Residuals are reported in pixels and as the angle on the sky.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from vision.cameras import EAST_SIDES, PROJECTIONS, FisheyeCamera
from vision.sphere import angular_separation_deg


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


def _camera(p: NDArray[np.float64], east: str, projection: str, n_radial: int,
            tilt: bool) -> FisheyeCamera:
    radial = tuple(float(v) for v in p[4:4 + n_radial])
    tn, te = (float(p[4 + n_radial]), float(p[5 + n_radial])) if tilt else (0.0, 0.0)
    return FisheyeCamera(cx_px=float(p[0]), cy_px=float(p[1]), px_per_deg=float(abs(p[2])),
                         north_offset_deg=float(p[3]), east=east, projection=projection,
                         radial_coeffs=radial, tilt_north_deg=tn, tilt_east_deg=te)


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
    fit_tilt : also fit the two tilt angles.

    Needs at least as many frames as half the number of parameters plus one
    (four parameters → three frames).
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
    w, h = image_size
    cx0, cy0 = centre_guess_px if centre_guess_px is not None else ((w - 1) / 2, (h - 1) / 2)
    sides = EAST_SIDES if east == "auto" else (east,)

    best: tuple[float, Any, str] | None = None
    costs: dict[str, float] = {}
    for side in sides:
        k0, off0 = _initial(x, y, az, el, cx0, cy0, side, projection)
        p0 = np.concatenate([[cx0, cy0, k0, off0], np.zeros(n_radial),
                             np.zeros(2 if fit_tilt else 0)])

        def resid(p: NDArray[np.float64], side: str = side) -> NDArray[np.float64]:
            cam = _camera(p, side, projection, n_radial, fit_tilt)
            px, py = cam.sky_to_pixel(az, el)
            r = np.concatenate([px - x, py - y])
            return np.where(np.isfinite(r), r, 1e4)

        sol = least_squares(resid, p0, method="trf", x_scale="jac", max_nfev=2000)
        costs[side] = float(sol.cost)
        if best is None or sol.cost < best[0]:
            best = (float(sol.cost), sol.x, side)
    assert best is not None
    _, p, side = best
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


def calibrate_frames(
    images: Iterable[NDArray[Any]],
    azimuth_deg: ArrayLike,
    elevation_deg: ArrayLike,
    names: Sequence[str] | None = None,
    method: str = "robust",
    **fit_kwargs: Any,
) -> tuple[CalibrationResult, list[dict[str, Any]]]:
    """Detect the sun in each frame (:func:`vision.detect.detect_sun`) and fit a camera.

    ``images`` may be a generator: each frame is dropped once its sun is found,
    so a batch of large frames needs the memory of one. ``azimuth_deg``/
    ``elevation_deg`` are the ephemeris sun at each frame's time; frames with
    no sun found or the sun below the horizon are left out.
    ``fit_kwargs`` go to :func:`fit_fisheye` (``projection``, ``east``,
    ``n_radial``, ``fit_tilt``). Returns the fit and one report per frame
    (``name``, ``sun_found``, ``confidence``, ``centroid_px``, ``used`` and, for
    the used ones, ``residual_px`` and ``residual_deg``). A ValueError names the
    frames without a sun when too few are left.
    """
    from vision.detect import detect_sun

    az = np.asarray(azimuth_deg, float).ravel()
    el = np.asarray(elevation_deg, float).ravel()
    if az.size != el.size:
        raise ValueError(f"{az.size} azimuths but {el.size} elevations")
    names = list(names) if names is not None else [f"frame {i}" for i in range(az.size)]
    sizes: set[tuple[int, int]] = set()
    report: list[dict[str, Any]] = []
    use: list[int] = []
    for i, img in enumerate(images):
        if i >= az.size:
            raise ValueError(f"more frames than the {az.size} sun positions")
        sizes.add((int(img.shape[1]), int(img.shape[0])))
        if len(sizes) != 1:
            raise ValueError(f"every frame must have the same size, got {sorted(sizes)}")
        d = detect_sun(img, method=method)
        ok = d.sun_found and d.centroid_px is not None and el[i] > 0
        report.append({"name": names[i], "sun_found": d.sun_found, "confidence": d.confidence,
                       "centroid_px": list(d.centroid_px) if d.centroid_px else None,
                       "used": bool(ok)})
        if ok:
            use.append(i)
    if len(report) != az.size:
        raise ValueError(f"{len(report)} frames but {az.size} sun positions")
    n_par = 4 + int(fit_kwargs.get("n_radial", 0)) + (2 if fit_kwargs.get("fit_tilt") else 0)
    if 2 * len(use) < n_par + 2:
        missing = [str(r["name"]) for r in report if not r["used"]]
        raise ValueError(f"only {len(use)} frames have a sun found above the horizon "
                         f"(none used: {', '.join(missing) or 'none'}); {n_par} parameters "
                         f"need at least {(n_par + 3) // 2}")
    xy = np.array([report[i]["centroid_px"] for i in use], float)
    res = fit_fisheye(xy[:, 0], xy[:, 1], az[use], el[use], sizes.pop(), **fit_kwargs)
    for k, i in enumerate(use):
        report[i]["residual_px"] = float(res.residuals_px[k])
        report[i]["residual_deg"] = float(res.residuals_deg[k])
    return res, report
