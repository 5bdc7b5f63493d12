"""Circle and sphere-cone fits to a glare's limb (Kåsa 1976 algebraic fit, RANSAC).

Used for a glare cut by the horizon, a mast or an overlay, where the arc that
is left is the only trustworthy part of the outline, and for a core that
cloud has grown on one side (:func:`contained_limb_centre`).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vision.candidates import _median
from vision.detection import CameraModel


def _circle_fit(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[float, float, float]:
    """Algebraic (Kåsa) least-squares circle fit → (cx, cy, r), by its 2×2 normal equations
    in centred coordinates (Kåsa 1976)."""
    mx, my = float(x.mean()), float(y.mean())
    u, v = x - mx, y - my
    suu, svv, suv = float(u @ u), float(v @ v), float(u @ v)
    uu, vv = u * u, v * v
    su3, sv3 = float(u @ uu), float(v @ vv)
    suvv, svuu = float(u @ vv), float(v @ uu)
    det = suu * svv - suv * suv
    if abs(det) < 1e-12:
        return mx, my, 0.0
    b1, b2 = 0.5 * (su3 + suvv), 0.5 * (sv3 + svuu)
    uc = (b1 * svv - b2 * suv) / det
    vc = (b2 * suu - b1 * suv) / det
    r = float(np.sqrt(uc * uc + vc * vc + (suu + svv) / len(x)))
    return mx + uc, my + vc, r


@lru_cache(maxsize=256)
def _triples(n: int, n_trials: int) -> NDArray[np.int64]:
    """``n_trials`` random index triples into ``n`` points (``np.random.default_rng(12345)``:
    a fixed seed, so the same for every fit with ``n`` points — cached per ``n``,
    read-only)."""
    idx = np.random.default_rng(12345).integers(0, n, size=(n_trials, 3))
    idx.flags.writeable = False
    return idx


@lru_cache(maxsize=256)
def _even_subset(n: int, m: int = 120) -> NDArray[np.intp]:
    """``np.linspace(0, n - 1, min(n, m)).astype(int)``: at most ``m`` evenly spaced indices
    (cached per ``n``; read-only)."""
    sub = np.linspace(0, n - 1, min(n, m)).astype(int)
    sub.flags.writeable = False
    return sub


def _ransac_circle(x: NDArray[np.float64], y: NDArray[np.float64], n_trials: int = 256
                   ) -> NDArray[np.bool_]:
    """Inliers of the circle through most limb points (RANSAC on point triples, fixed seed).

    The limb of a glare cut by a mast, the horizon or an overlay box is an arc
    plus straight cut edges; the arc is the largest set of points on one
    circle. The tolerance, max(1.5 px, 5 % of the radius), also keeps the
    whole of a limb that the fisheye projection has made slightly oval.
    """
    n = len(x)
    idx = _triples(n, n_trials)
    # hypotheses are scored on at most 120 evenly spaced points, the inliers on all
    sub = _even_subset(n)
    x1, y1 = x[idx[:, 0]], y[idx[:, 0]]
    x2, y2 = x[idx[:, 1]], y[idx[:, 1]]
    x3, y3 = x[idx[:, 2]], y[idx[:, 2]]
    d = 2.0 * (x1 * (y2 - y3) + x2 * (y3 - y1) + x3 * (y1 - y2))
    ok = np.abs(d) > 1e-6
    s1, s2, s3 = x1**2 + y1**2, x2**2 + y2**2, x3**2 + y3**2
    with np.errstate(divide="ignore", invalid="ignore"):
        ux = (s1 * (y2 - y3) + s2 * (y3 - y1) + s3 * (y1 - y2)) / d
        uy = (s1 * (x3 - x2) + s2 * (x1 - x3) + s3 * (x2 - x1)) / d
    r = np.hypot(x1 - ux, y1 - uy)
    # the sun's limb circle is no wider than the blob and centred inside its box
    # (this rules out a horizon or overlay edge that happens to be an arc)
    ext = max(float(np.ptp(x)), float(np.ptp(y)))
    ok &= np.isfinite(r) & (r <= 0.6 * ext + 2.0)
    ok &= (ux >= x.min()) & (ux <= x.max()) & (uy >= y.min()) & (uy <= y.max())
    if not ok.any():
        return np.ones(n, bool)
    ux, uy, r = ux[ok], uy[ok], r[ok]
    tol = np.maximum(1.5, 0.05 * r)
    xs, ys = x[sub], y[sub]
    res = np.abs(np.hypot(xs[None, :] - ux[:, None], ys[None, :] - uy[:, None]) - r[:, None])
    best = int(np.argmax((res <= tol[:, None]).sum(axis=1)))
    return np.abs(np.hypot(x - ux[best], y - uy[best]) - r[best]) <= tol[best]


_COS_45 = float(np.cos(np.radians(45.0)))
_CONTAINED_TRIALS = 96  # RANSAC triples of contained_limb_centre (a ≥ 30 % arc: P(miss) < 8 %)
_CONTAINED_REL_TOL = 0.02  # tolerance on the limb: ≥ this share of the half-angle


try:
    # np.linalg.eigh's own solver (LAPACK's dsyevd on the lower triangle), called without
    # the wrapper's per-call checks and error state, which cost 7 times the solve of a
    # 3 × 3 scatter matrix (always finite here); the same eigenvectors
    from numpy.linalg import _umath_linalg

    _eigh_lo: Any = _umath_linalg.eigh_lo
except (ImportError, AttributeError):  # pragma: no cover - a numpy without it
    _eigh_lo = None


def _eigh_vectors(s: NDArray[np.float64]) -> NDArray[np.float64]:
    """The eigenvectors (columns, ascending eigenvalues) of a symmetric float64 matrix, as
    ``np.linalg.eigh(s)[1]``."""
    if _eigh_lo is None:
        return np.linalg.eigh(s)[1]
    return np.asarray(_eigh_lo(s, signature="d->dd")[1])


def _plane_axis(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Axis of the small circle through unit vectors ``[N, 3]`` (least-squares plane normal:
    the eigenvector of the 3 × 3 scatter matrix with the least eigenvalue)."""
    m = v.sum(axis=0) / len(v)  # v.mean(axis=0), without its overhead
    d = v - m
    normal = _eigh_vectors(d.T @ d)[:, 0]
    return normal if np.dot(normal, m) > 0 else -normal


def _ransac_cone(v: NDArray[np.float64], tol_rad: float, n_trials: int = 256,
                 rel_tol: float = 0.05, inside_penalty: float = 0.0,
                 v_sum: NDArray[np.float64] | None = None) -> NDArray[np.bool_]:
    """Inliers of the small circle on the sphere through most limb directions ``[N, 3]``.

    Three unit vectors fix a plane, hence a cone (axis, half-angle); the
    residual is the angular distance of each point from that cone, the
    tolerance max(``tol_rad``, ``rel_tol`` × half-angle). A hypothesis scores its
    inliers minus ``inside_penalty`` × the points *inside* its cone by more than
    the tolerance (:func:`contained_limb_centre`). Residuals are compared as
    cosines (no arc cosine per point and hypothesis). ``v_sum``: ``v.sum(axis=0)`` when
    the caller has it.
    """
    n = len(v)
    idx = _triples(n, n_trials)
    sub = _even_subset(n)
    a = v[idx[:, 0]]
    p, q = v[idx[:, 1]] - a, v[idx[:, 2]] - a
    nrm = np.empty_like(p)  # p × q, written out (np.cross is slow on short arrays)
    nrm[:, 0] = p[:, 1] * q[:, 2] - p[:, 2] * q[:, 1]
    nrm[:, 1] = p[:, 2] * q[:, 0] - p[:, 0] * q[:, 2]
    nrm[:, 2] = p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]
    cos_half = np.einsum("ij,ij->i", nrm, a)
    # unit normal, turned toward the points: cos(half-angle) = n · a ≥ 0
    nrm *= (np.sign(cos_half) / np.maximum(np.sqrt(np.einsum("ij,ij->i", nrm, nrm)),
                                           1e-300))[:, None]
    cos_half = np.einsum("ij,ij->i", nrm, a)
    mean_dir = (v.sum(axis=0) if v_sum is None else v_sum) / n  # v.mean(axis=0)
    mean_dir /= np.sqrt(mean_dir @ mean_dir)  # np.linalg.norm's sum, without its overhead
    # the axis must lie within the limb's spread (the sun is inside its glare), the cone
    # no wider than 45° nor 1.2 × that spread
    cos_spread = float((v @ mean_dir).min())
    spread = float(np.arccos(min(max(cos_spread, -1.0), 1.0)))
    ok = (cos_half > max(_COS_45, np.cos(min(1.2 * spread + 1e-6, np.pi)))) \
        & (nrm @ mean_dir >= cos_spread) & (cos_half < 1.0)
    if not ok.any():
        return np.ones(n, bool)
    nrm = nrm[ok]
    half = np.arccos(cos_half[ok])
    tol = np.maximum(tol_rad, rel_tol * half)
    dots = v[sub] @ nrm.T  # cos of each point's angle from each axis
    lo, hi = np.cos(half + tol)[None, :], np.cos(np.maximum(half - tol, 0.0))[None, :]
    score = ((dots >= lo) & (dots <= hi)).sum(axis=0).astype(float)
    if inside_penalty:
        score -= inside_penalty * (dots > hi).sum(axis=0)
    best = int(np.argmax(score))
    return np.abs(np.arccos(np.clip(v @ nrm[best], -1.0, 1.0)) - half[best]) <= tol[best]


def _refit_cone(v: NDArray[np.float64], keep: NDArray[np.bool_], tol_rad: float,
                rel_tol: float) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Plane fit to the inliers, then inliers re-selected among all points around the fit
    (at most three times) → (axis, inliers)."""
    axis = _plane_axis(v[keep])
    for _ in range(3):
        ang = np.arccos(np.clip(v @ axis, -1.0, 1.0))
        half = _median(ang[keep])
        new = np.abs(ang - half) <= max(tol_rad, rel_tol * half)
        if new.sum() < 6 or np.array_equal(new, keep):
            break
        keep = new
        axis = _plane_axis(v[keep])
    return axis, keep


def contained_limb_centre(pts: NDArray[np.float64], camera: CameraModel, tol_px: float = 0.7,
                          n_trials: int = _CONTAINED_TRIALS
                          ) -> tuple[float, float, float] | None:
    """The sun's centre from the limb of its saturated core when cloud has grown the core
    on one side: the small circle on the sphere (a cone about the sun's direction) that
    passes through most limb points ``[N, 2]`` while leaving (almost) none *inside* it.

    Why: thin cloud near the sun adds light (forward scattering) to part of the glare, so
    the saturated region there reaches farther out, while it never hides the clear-sky
    core — on a cloud-free arc the limb is the clear-sky circle, on the cloudy side it
    bulges outward. A plain RANSAC circle (Fischler & Bolles 1981, CACM 24:381) may pick
    the bulge; scoring each hypothesis by its inliers minus three times the limb points
    lying inside it (the clear-sky disc is contained in the core) picks the clear arc.
    The cone is fitted on the camera's sphere (a wide glare is an oval in a fisheye
    image); its axis is the normal of the least-squares plane through the inliers. Tolerance:
    max(``tol_px`` / px-per-radian, 2 % of the half-angle); ``n_trials`` RANSAC triples.
    Returns
    ``(x, y, inlier_fraction)``, or None with too few usable points.
    """
    x, y = pts[:, 0], pts[:, 1]
    v_all = camera.pixel_to_direction(x, y)
    fin = np.isfinite(v_all).all(axis=1)
    n_fin = int(np.count_nonzero(fin))
    if n_fin < 12:
        return None
    if n_fin < fin.size:
        v, x, y = v_all[fin], x[fin], y[fin]
    else:
        v = v_all
    # the angular size of a pixel here: the points' spread on the sphere over that in pixels
    v_sum = v.sum(axis=0)
    mean_dir = v_sum / n_fin  # v.mean(axis=0)
    cos_spread = float((v @ mean_dir).min()) / float(np.sqrt(mean_dir @ mean_dir))
    spread = float(np.arccos(min(1.0, cos_spread)))
    ext = max(float(x.max() - x.min()), float(y.max() - y.min()))
    tol = tol_px * spread / max(0.5 * ext, 1.0)
    keep = _ransac_cone(v, tol, n_trials=n_trials, rel_tol=_CONTAINED_REL_TOL,
                        inside_penalty=3.0, v_sum=v_sum)
    if keep.sum() < 6:
        return None
    axis = _plane_axis(v[keep])
    px, py = camera.direction_to_pixel(axis)
    if not (np.isfinite(px) and np.isfinite(py)):
        return None
    return float(px), float(py), int(np.count_nonzero(keep)) / keep.size


def _robust_limb_centre(pts: NDArray[np.float64], camera: CameraModel | None
                        ) -> tuple[float, float, float, float]:
    """Centre of the limb points ``[N, 2]``: RANSAC inliers, then a trimmed least-squares fit.

    Without a camera: a circle in the image. With one: the limb, mapped to unit
    vectors, is a small circle on the sphere (a fisheye draws it as an oval
    near the horizon); RANSAC finds the cone through most of it, a plane is
    fitted to the inliers (trimmed on their angular residual) and its normal —
    the glare's axis — is projected back. Returns
    ``(x, y, radius_px, inlier_fraction)``.
    """
    x, y = pts[:, 0], pts[:, 1]
    if camera is not None:
        v_all = camera.pixel_to_direction(x, y)
        fin = np.all(np.isfinite(v_all), axis=1)
        if fin.sum() >= 12:
            v = v_all[fin]
            r_px = 0.25 * (np.ptp(x[fin]) + np.ptp(y[fin]))
            centre_dir = v.mean(axis=0) / np.linalg.norm(v.mean(axis=0))
            ang_r = float(np.median(np.arccos(np.clip(v @ centre_dir, -1, 1))))
            tol = 1.5 * ang_r / max(r_px, 1.0)
            keep = _ransac_cone(v, tol)
            if keep.sum() >= 6:
                axis, keep = _refit_cone(v, keep, tol, 0.05)
                px, py = camera.direction_to_pixel(axis)
                if np.isfinite(px) and np.isfinite(py):
                    return float(px), float(py), float(r_px), float(keep.mean())
    cx, cy, r = _circle_fit(x, y)
    if np.all(np.abs(np.hypot(x - cx, y - cy) - r) <= max(1.5, 0.05 * r)):
        return cx, cy, r, 1.0  # a clean limb: no outliers to hunt
    keep = _ransac_circle(x, y) if len(x) >= 12 else np.ones(len(x), bool)
    if keep.sum() < 6:
        keep = np.ones(len(x), bool)
    cx, cy, r = _circle_fit(x[keep], y[keep])
    for _ in range(3):  # re-select inliers among all points around the fit
        res = np.abs(np.hypot(x - cx, y - cy) - r)
        new = res <= max(1.5, 0.05 * r)
        if new.sum() < 6 or np.array_equal(new, keep):
            break
        keep = new
        cx, cy, r = _circle_fit(x[keep], y[keep])
    return cx, cy, r, float(keep.mean())
