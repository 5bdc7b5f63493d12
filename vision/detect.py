"""Find the sun in a camera frame: a robust detector and the seeds' own pipelines.

Three named methods, all returning a :class:`SunDetection`:

* ``"robust"`` (default, :func:`detect_robust`) — field-of-view mask (the
  fisheye's image circle, found from the frame), a threshold that adapts to
  the frame's brightest level and background, connected components (grouped
  when a mast splits a glare) scored by circularity — after opening away
  streaks such as blooming or smear — glare isotropy and fall-off, and size;
  rejection of lens-flare ghosts (on the line through the optical centre,
  opposite the sun); a sub-pixel centre: the intensity-weighted centroid of a
  complete (point-symmetric) blob, a RANSAC + least-squares fit to the
  saturated limb of a cut one (in the camera's angle space when a camera
  model is given), so that a 20–50 k px glare clipped by the horizon, a mast
  or an overlay is not pulled off centre as the whole blob's centroid would
  be. ``confidence`` (0–1) says how sun-like the winner is and how clearly it
  beats the runner-up; ``sun_found`` is ``confidence >= min_confidence``.
* ``"seed000_hsv"`` (:func:`detect_seed000`) — seed 000's Table 3: BGR→HSV,
  15×15 box blur, ``inRange`` ±(30, 30, 30) around the sun's colour,
  dilate ×2, erode ×2, centroid of the largest object.
* ``"seed003_gray240"`` (:func:`detect_seed003`) — seed 003 eqs. 5–8: grey
  as the mean of R, G, B, threshold 240, centroid of the binary image.

The seeds' methods have no notion of confidence: theirs is 1 whenever their
mask is non-empty. Pixel coordinates are ``(x, y)`` = (column, row), origin at
the top-left pixel's centre. OpenCV does the image work.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.cameras import FisheyeCamera

METHODS: tuple[str, ...] = ("robust", "seed000_hsv", "seed003_gray240")

_SMALL_AREA_PX = 30  # below: intensity-weighted centroid only; above: also a limb fit
_MAX_CANDIDATES = 12
_SCORED = 4  # candidates whose glare is examined
_CORE_MAX_RADIUS_PX = 64.0  # above: the core's opening runs on a shrunk mask


class CameraModel(Protocol):
    """Anything with a pixel → unit-direction map and its inverse (vision.cameras)."""

    def pixel_to_direction(self, x_px: Any, y_px: Any) -> NDArray[np.float64]: ...

    def direction_to_pixel(self, direction: Any) -> tuple[Any, Any]: ...


@dataclass(frozen=True)
class FovCircle:
    """The usable image circle of a fisheye frame [px]."""

    cx_px: float
    cy_px: float
    radius_px: float


@dataclass(frozen=True)
class SunDetection:
    """Result of one detection; ``centroid_px`` is None when no sun was found."""

    sun_found: bool
    confidence: float
    centroid_px: tuple[float, float] | None
    method: str
    radius_px: float = 0.0
    area_px: int = 0
    threshold: float = 0.0
    n_candidates: int = 0
    ghosts_rejected: int = 0
    fov: FovCircle | None = None


# --------------------------------------------------------------------------- helpers


def to_gray(image: NDArray[Any]) -> NDArray[np.uint8]:
    """8-bit grey (ITU-R BT.601 luma, cv2.cvtColor) from a BGR, BGRA or grey frame."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        if img.dtype == np.uint16:
            img = (img >> 8).astype(np.uint8)
        elif np.issubdtype(img.dtype, np.floating):
            img = np.clip(img * (255.0 if img.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
        else:
            raise ValueError(f"unsupported image dtype {img.dtype}")
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return np.asarray(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), dtype=np.uint8)
    if img.ndim == 3 and img.shape[2] == 4:
        return np.asarray(cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY), dtype=np.uint8)
    if img.ndim == 3 and img.shape[2] == 1:
        return img[:, :, 0]
    raise ValueError(f"image must be H×W, H×W×3 or H×W×4, got shape {img.shape}")


def _small(gray: NDArray[np.uint8]) -> tuple[NDArray[np.uint8], int]:
    """A ~96 px thumbnail by plain subsampling (every s-th pixel, centred): cheap, and
    enough for the frame's statistics and its image circle."""
    h, w = gray.shape
    s = max(1, min(h, w) // 96)
    if s == 1:
        return gray, 1
    return np.ascontiguousarray(gray[s // 2::s, s // 2::s]), s


def _median_u8(a: NDArray[np.uint8], mask: NDArray[np.uint8] | None = None) -> float:
    """Median of 8-bit values (under ``mask``) from their histogram (cv2.calcHist)."""
    hist = cv2.calcHist([np.ascontiguousarray(a)], [0], mask, [256], [0, 256]).ravel()
    total = hist.sum()
    if total <= 0:
        return 0.0
    return float(np.searchsorted(np.cumsum(hist), 0.5 * total))


def estimate_fov(gray: NDArray[np.uint8], small: NDArray[np.uint8] | None = None,
                 scale: int = 1) -> FovCircle | None:
    """The fisheye image circle: the bright disc surrounded by dark corners, or None.

    A frame whose four corners are not dark (a pinhole frame) has no circle.
    Works on a ~96 px thumbnail; the circle is the minimum enclosing circle of
    the largest bright region, shrunk by 2 %.
    """
    if small is None:
        small, scale = _small(gray)
    h, w = small.shape
    ph, pw = max(2, h // 12), max(2, w // 12)
    corners = [small[:ph, :pw], small[:ph, -pw:], small[-ph:, :pw], small[-ph:, -pw:]]
    means = sorted(cv2.mean(c)[0] for c in corners)
    corner_level = 0.5 * (means[1] + means[2])  # the median of four
    centre_level = _median_u8(small[h // 3: 2 * h // 3, w // 3: 2 * w // 3])
    if centre_level < 20.0 or corner_level > max(35.0, 0.25 * centre_level):
        return None
    level = corner_level + 0.3 * (centre_level - corner_level)
    binary = (small > level).astype(np.uint8)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return None
    big = max(contours, key=cv2.contourArea)
    if cv2.contourArea(big) < 0.2 * h * w:
        return None
    (cx, cy), r = cv2.minEnclosingCircle(big)
    off = float(scale // 2)  # thumbnail pixel i is full-res pixel i·s + s//2
    return FovCircle(cx * scale + off, cy * scale + off, 0.98 * r * scale)


def _fov_mask(shape: tuple[int, int], fov: FovCircle) -> NDArray[np.uint8]:
    mask = np.zeros(shape, np.uint8)
    cv2.circle(mask, (int(round(fov.cx_px)), int(round(fov.cy_px))), int(fov.radius_px), 255, -1)
    return mask


_RING_COS = np.cos(np.linspace(0.0, 2 * np.pi, 24, endpoint=False))
_RING_SIN = np.sin(np.linspace(0.0, 2 * np.pi, 24, endpoint=False))


def _ring_values(gray: NDArray[np.uint8], cx: float, cy: float, radius: float,
                 fov: FovCircle | None) -> NDArray[np.float64]:
    """Grey values at 24 points of a circle (nearest pixel), those inside the frame/FOV."""
    xs = cx + radius * _RING_COS
    ys = cy + radius * _RING_SIN
    h, w = gray.shape
    ok = (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    if fov is not None:
        ok &= (xs - fov.cx_px) ** 2 + (ys - fov.cy_px) ** 2 < fov.radius_px**2
    return gray[(ys[ok] + 0.5).astype(np.intp), (xs[ok] + 0.5).astype(np.intp)].astype(float)


def _clamp(v: float, lo: float, hi: float) -> float:
    return float(min(max(v, lo), hi))


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


def _ransac_circle(x: NDArray[np.float64], y: NDArray[np.float64], n_trials: int = 256
                   ) -> NDArray[np.bool_]:
    """Inliers of the circle through most limb points (RANSAC on point triples, fixed seed).

    The limb of a glare cut by a mast, the horizon or an overlay box is an arc
    plus straight cut edges; the arc is the largest set of points on one
    circle. The tolerance, max(1.5 px, 5 % of the radius), also keeps the
    whole of a limb that the fisheye projection has made slightly oval.
    """
    n = len(x)
    rng = np.random.default_rng(12345)
    idx = rng.integers(0, n, size=(n_trials, 3))
    # hypotheses are scored on at most 120 evenly spaced points, the inliers on all
    sub = np.linspace(0, n - 1, min(n, 120)).astype(int)
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
    if not np.any(ok):
        return np.ones(n, bool)
    ux, uy, r = ux[ok], uy[ok], r[ok]
    tol = np.maximum(1.5, 0.05 * r)
    xs, ys = x[sub], y[sub]
    res = np.abs(np.hypot(xs[None, :] - ux[:, None], ys[None, :] - uy[:, None]) - r[:, None])
    best = int(np.argmax((res <= tol[:, None]).sum(axis=1)))
    return np.abs(np.hypot(x - ux[best], y - uy[best]) - r[best]) <= tol[best]


def _plane_axis(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Axis of the small circle through unit vectors ``[N, 3]`` (least-squares plane normal)."""
    m = v.mean(axis=0)
    _, _, vt = np.linalg.svd(v - m, full_matrices=False)
    return vt[2] if np.dot(vt[2], m) > 0 else -vt[2]


def _ransac_cone(v: NDArray[np.float64], tol_rad: float, n_trials: int = 256
                 ) -> NDArray[np.bool_]:
    """Inliers of the small circle on the sphere through most limb directions ``[N, 3]``.

    Three unit vectors fix a plane, hence a cone (axis, half-angle); the
    residual is the angular distance of each point from that cone.
    """
    n = len(v)
    rng = np.random.default_rng(12345)
    idx = rng.integers(0, n, size=(n_trials, 3))
    sub = np.linspace(0, n - 1, min(n, 120)).astype(int)
    a, b, c = v[idx[:, 0]], v[idx[:, 1]], v[idx[:, 2]]
    nrm = np.cross(b - a, c - a)
    length = np.linalg.norm(nrm, axis=1)
    ok = length > 1e-12
    if not np.any(ok):
        return np.ones(n, bool)
    nrm = nrm[ok] / length[ok, None]
    nrm *= np.sign(np.sum(nrm * a[ok], axis=1))[:, None]
    half = np.arccos(np.clip(np.sum(nrm * a[ok], axis=1), -1.0, 1.0))
    mean_dir = v.mean(axis=0)
    ok2 = (half < np.radians(45.0)) & (nrm @ mean_dir > 0)
    # the axis must lie within the limb's spread (the sun is inside its glare)
    spread = float(np.max(np.arccos(np.clip(v @ (mean_dir / np.linalg.norm(mean_dir)), -1, 1))))
    axis_off = np.arccos(np.clip(nrm @ (mean_dir / np.linalg.norm(mean_dir)), -1.0, 1.0))
    ok2 &= (axis_off <= spread) & (half <= 1.2 * spread + 1e-6)
    if not np.any(ok2):
        return np.ones(n, bool)
    nrm, half = nrm[ok2], half[ok2]
    res = np.abs(np.arccos(np.clip(v[sub] @ nrm.T, -1.0, 1.0)) - half[None, :])
    tol = np.maximum(tol_rad, 0.05 * half)
    best = int(np.argmax((res <= tol[None, :]).sum(axis=0)))
    return np.abs(np.arccos(np.clip(v @ nrm[best], -1.0, 1.0)) - half[best]) <= tol[best]


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
                axis = _plane_axis(v[keep])
                for _ in range(3):  # re-select inliers among all points around the fit
                    ang = np.arccos(np.clip(v @ axis, -1.0, 1.0))
                    half = float(np.median(ang[keep]))
                    new = np.abs(ang - half) <= max(tol, 0.05 * half)
                    if new.sum() < 6 or np.array_equal(new, keep):
                        break
                    keep = new
                    axis = _plane_axis(v[keep])
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


def _weighted_centroid(gray: NDArray[np.uint8], cx: float, cy: float, radius: float,
                       level: float) -> tuple[float, float] | None:
    """Intensity-weighted centroid of ``gray − level`` (clipped at 0) in a disc window."""
    h, w = gray.shape
    x0, y0 = max(0, int(cx - radius)), max(0, int(cy - radius))
    x1, y1 = min(w, int(cx + radius) + 2), min(h, int(cy + radius) + 2)
    if x1 <= x0 or y1 <= y0:
        return None
    win = gray[y0:y1, x0:x1].astype(np.float32) - np.float32(level)
    np.maximum(win, 0, out=win)
    disc = np.zeros(win.shape, np.float32)
    cv2.circle(disc, (int(round((cx - x0) * 16)), int(round((cy - y0) * 16))),
               int(round(radius * 16)), 1.0, -1, cv2.LINE_8, 4)  # 1/16 px centre
    m = cv2.moments(win * disc, False)
    if m["m00"] <= 0:
        return None
    return x0 + m["m10"] / m["m00"], y0 + m["m01"] / m["m00"]


# --------------------------------------------------------------------------- robust


@dataclass
class _Candidate:
    """A cluster of bright components (a glare cut by a mast stays one candidate)."""

    labels: list[int]
    area: int
    x: int
    y: int
    w: int
    h: int
    cx: float
    cy: float
    score: float = 0.0
    ghost: bool = False
    ox: int = 0  # where the label image (a region of interest) starts in the frame
    oy: int = 0

    core: NDArray[np.uint8] | None = None  # set by _core(): the disc without its streaks

    def mask(self, labels: NDArray[Any]) -> NDArray[np.uint8]:
        if self.core is not None:
            return self.core
        y0, x0 = self.y - self.oy, self.x - self.ox
        roi = labels[y0:y0 + self.h, x0:x0 + self.w]
        if len(self.labels) == 1:
            return (roi == self.labels[0]).astype(np.uint8)
        return np.isin(roi, self.labels).astype(np.uint8)


def _clusters(stats: NDArray[Any], cents: NDArray[Any], order: NDArray[np.int64],
              ox: int = 0, oy: int = 0) -> list[_Candidate]:
    """Group components whose boxes lie within a quarter radius (+3 px) of each other."""
    items = [int(i) for i in order]
    parent = {i: i for i in items}

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for ai, a in enumerate(items):
        xa, ya, wa, ha, aa = stats[a]
        for b in items[ai + 1:]:
            xb, yb, wb, hb, ab = stats[b]
            gap_x = max(xb - (xa + wa), xa - (xb + wb), 0)
            gap_y = max(yb - (ya + ha), ya - (yb + hb), 0)
            reach = 3.0 + 0.25 * np.sqrt(max(aa, ab) / np.pi)
            if max(gap_x, gap_y) <= reach:
                parent[root(b)] = root(a)
    groups: dict[int, list[int]] = {}
    for i in items:
        groups.setdefault(root(i), []).append(i)
    out = []
    for members in groups.values():
        st = stats[members]
        area = int(st[:, 4].sum())
        x0, y0 = int(st[:, 0].min()), int(st[:, 1].min())
        x1, y1 = int((st[:, 0] + st[:, 2]).max()), int((st[:, 1] + st[:, 3]).max())
        cx = float((cents[members, 0] * st[:, 4]).sum() / area)
        cy = float((cents[members, 1] * st[:, 4]).sum() / area)
        out.append(_Candidate(members, area, x0, y0, x1 - x0, y1 - y0, cx, cy, ox=ox, oy=oy))
    return out


def _shape(c: _Candidate, labels: NDArray[Any]) -> float:
    """Circularity 0–1 from the cluster's second moments.

    ``aspect = √(λ2/λ1)`` and ``fill = A / (4π√(λ1 λ2))`` (1 for a filled disc);
    thin spikes (a flare streak, blooming) barely move them, ragged or
    elongated cloud edges do.
    """
    if c.area < 5:
        return 1.0
    m = cv2.moments(c.mask(labels), True)
    mu20, mu02, mu11 = m["mu20"] / m["m00"], m["mu02"] / m["m00"], m["mu11"] / m["m00"]
    half_tr = 0.5 * (mu20 + mu02)
    disc = np.sqrt(max(half_tr**2 - (mu20 * mu02 - mu11**2), 0.0))
    l1, l2 = half_tr + disc, max(half_tr - disc, 1e-6)
    aspect = float(np.sqrt(l2 / l1))
    fill = c.area / (4.0 * np.pi * np.sqrt(l1 * l2))
    return min(1.0, aspect / 0.75) * _clamp(fill / 0.85, 0.0, 1.0)


def _core(c: _Candidate, labels: NDArray[Any]) -> _Candidate | None:
    """The candidate's disc without the streaks attached to it (blooming, smear, a flare).

    A morphological opening with a disc of 0.6 × the largest inscribed radius
    (the distance transform's maximum) removes everything thinner than the
    core; the opened component under that maximum is the core. Returns a
    candidate restricted to it, or None when nothing was removed.
    """
    mask = c.mask(labels)
    # a zero border: a blob that fills its box (a saturated rectangle) has no zero pixel
    padded = cv2.copyMakeBorder(mask, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    dist = cv2.distanceTransform(padded, cv2.DIST_L2, 3)[1:-1, 1:-1]
    _, d_max, _, (px, py) = cv2.minMaxLoc(dist)
    if d_max < 2.0:
        return None
    # the opening's cost grows with the kernel's area: past an inscribed radius of
    # _CORE_MAX_RADIUS_PX it runs on a shrunk mask (enough to cut thin streaks)
    f = min(1.0, _CORE_MAX_RADIUS_PX / d_max)
    k = max(1, int(0.6 * d_max * f))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))
    if f < 1.0:
        small = cv2.resize(mask, None, fx=f, fy=f, interpolation=cv2.INTER_NEAREST)
        opened_small = cv2.morphologyEx(small, cv2.MORPH_OPEN, kernel)
        opened = cv2.bitwise_and(
            cv2.resize(opened_small, (mask.shape[1], mask.shape[0]),
                       interpolation=cv2.INTER_NEAREST),
            mask,
        )
    else:
        opened = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
    n, lab, stats, cents = cv2.connectedComponentsWithStats(opened, connectivity=8)
    i = int(lab[py, px])
    if n < 2 or i == 0 or stats[i, 4] >= 0.97 * c.area:
        return None
    x, y, w, h, area = (int(v) for v in stats[i])
    core = (lab[y:y + h, x:x + w] == i).astype(np.uint8)
    # only streaks count: what was removed must be thin, straight and centred on
    # the core (spikes on both sides), not the lobes of a ragged cloud highlight
    rest = mask.copy()
    rest[y:y + h, x:x + w] -= core
    m = cv2.moments(rest, True)
    if m["m00"] <= 0:
        return None
    mu20, mu02, mu11 = m["mu20"] / m["m00"], m["mu02"] / m["m00"], m["mu11"] / m["m00"]
    half_tr = 0.5 * (mu20 + mu02)
    disc = np.sqrt(max(half_tr**2 - (mu20 * mu02 - mu11**2), 0.0))
    aspect = np.sqrt(max(half_tr - disc, 0.0) / max(half_tr + disc, 1e-9))
    off = np.hypot(m["m10"] / m["m00"] - cents[i, 0], m["m01"] / m["m00"] - cents[i, 1])
    if aspect > 0.35 or off > max(2.0, 0.5 * d_max):
        return None
    return _Candidate(c.labels, area, c.x + x, c.y + y, w, h, c.x + float(cents[i, 0]),
                      c.y + float(cents[i, 1]), ox=c.ox, oy=c.oy, core=core)


def _prior(c: _Candidate, labels: NDArray[Any], diam: float) -> tuple[float, float]:
    """``(shape term, size term)`` of the score: cheap, so computed for every candidate.

    A candidate that is not a clean disc is narrowed to its core
    (:func:`_core`) when the core is the cleaner disc: a sun with blooming or
    smear along its columns is a disc with spikes.
    """
    raw = _shape(c, labels)
    if raw < 0.95 and c.area >= 30:
        core = _core(c, labels)
        if core is not None:
            core_shape = _shape(core, labels)
            if core_shape > raw:
                c.area, c.x, c.y, c.w, c.h = core.area, core.x, core.y, core.w, core.h
                c.cx, c.cy, c.core = core.cx, core.cy, core.core
                raw = core_shape
    shape = _clamp((raw - 0.45) / 0.4, 0.0, 1.0)
    min_area = max(4.0, np.pi * (0.0025 * diam) ** 2)
    return shape, _clamp(c.area / min_area, 0.25, 1.0)


def _score(c: _Candidate, gray: NDArray[np.uint8], shape: float, size: float, peak: float,
           bg: float, fov: FovCircle | None, diam: float) -> float:
    """Sun-likeness 0–1 of one bright cluster.

    ``shape²`` (a sun's saturated core is a clean disc; cloud highlights are
    ragged) × glare evidence × a size prior (radius ≥ ~0.25 % of the
    diameter). The glare evidence is the larger of (a) an isotropic glare that
    falls off outward — three rings at 1.6 R, 2.5 R and 4 R whose
    inter-quartile spread is small and whose medians decline by ≥ 15 % of the
    frame's contrast — and (b) a sharp drop right outside the disc to no less
    than the sky's level (a clear-sky sun next to a cloud; not white text on a
    dark overlay box). A bright cloud highlight passes neither.
    """
    r_eq = np.sqrt(c.area / np.pi)
    contrast = max(peak - bg, 1.0)
    iso = 1.0
    medians = []
    for rad in (1.6 * r_eq + 2.0, 2.5 * r_eq + 3.0, max(4.0 * r_eq, 0.03 * diam)):
        v = _ring_values(gray, c.cx, c.cy, rad, fov)
        if v.size < 8:
            iso *= 0.5
            medians.append(np.nan)
            continue
        v.sort()
        n = v.size
        q25, med, q75 = v[n // 4], v[n // 2], v[(3 * n) // 4]
        medians.append(float(med))
        iso *= _clamp(1.0 - ((q75 - q25) / contrast - 0.06) / 0.25, 0.0, 1.0)
    m1, _, m3 = medians
    falloff = (m1 - m3) / contrast if np.isfinite(m1) and np.isfinite(m3) else 0.0
    iso_glare = iso ** (1.0 / 3.0) * _clamp((falloff - 0.05) / 0.15, 0.0, 1.0)
    drop = (peak - m1) / contrast if np.isfinite(m1) else 0.0
    sharp = _clamp((drop - 0.3) / 0.3, 0.0, 1.0)
    if np.isfinite(m1) and m1 < bg - 0.15 * contrast:
        sharp = 0.0  # ringed by something darker than the sky: white text on a dark box
    glare = max(iso_glare, sharp)
    return float(shape**2 * (0.25 + 0.75 * glare) * size)


def _mark_ghosts(cands: list[_Candidate], centre: tuple[float, float]) -> int:
    """Flag clusters on the line through the optical centre, opposite a larger one."""
    n = 0
    ox, oy = centre
    for a in cands:
        for b in cands:
            if a is b or b.ghost or a.ghost or b.area >= a.area:
                continue
            va = np.array([a.cx - ox, a.cy - oy])
            vb = np.array([b.cx - ox, b.cy - oy])
            na, nb = np.linalg.norm(va), np.linalg.norm(vb)
            if na < 3 or nb < 3:
                continue
            if float(va @ vb / (na * nb)) < -np.cos(np.radians(6.0)):
                b.ghost = True
                n += 1
    return n


def detect_robust(image: NDArray[Any], camera: CameraModel | None = None,
                  fov: FovCircle | None = None, auto_fov: bool = True,
                  min_confidence: float = 0.5) -> SunDetection:
    """The robust detector (see the module docstring).

    ``camera`` (optional) lets the limb fit work in angle space; ``fov``
    overrides the image circle found from the frame (``auto_fov=False`` to
    use the whole frame).
    """
    gray = to_gray(image)
    h, w = gray.shape
    small, scale = _small(gray)
    if fov is None and auto_fov:
        fov = estimate_fov(gray, small, scale)
    if fov is not None:
        work = cv2.bitwise_and(gray, _fov_mask(gray.shape, fov))
        sm = _fov_mask(small.shape, FovCircle((fov.cx_px - scale // 2) / scale,
                                              (fov.cy_px - scale // 2) / scale,
                                              fov.radius_px / scale))
        bg = _median_u8(small, sm) if np.any(sm) else _median_u8(small)
        diam = 2.0 * fov.radius_px
        centre = (fov.cx_px, fov.cy_px)
    else:
        work = gray
        bg = _median_u8(small)
        diam = float(min(h, w))
        centre = ((w - 1) / 2.0, (h - 1) / 2.0)
    peak = float(cv2.minMaxLoc(work)[1])
    contrast = peak - bg
    none = SunDetection(False, 0.0, None, "robust", fov=fov)
    if contrast < 20.0:
        return none
    thr = peak - max(3.0, 0.04 * contrast)
    binary = cv2.threshold(work, thr - 0.5, 255, cv2.THRESH_BINARY)[1]
    # components only inside the bright pixels' bounding box (most frames: a small box)
    ox, oy, bw, bh = cv2.boundingRect(binary)
    if bw == 0 or bh == 0:
        return none
    n, labels, stats, cents = cv2.connectedComponentsWithStats(
        binary[oy:oy + bh, ox:ox + bw], connectivity=8)
    if n < 2:
        return none
    stats[:, 0] += ox
    stats[:, 1] += oy
    cents = cents + (ox, oy)
    order = np.argsort(-stats[1:, cv2.CC_STAT_AREA])[:_MAX_CANDIDATES] + 1
    # ghosts first, per component, so that a ghost next to the sun (the sun near the
    # optical centre) is not merged into the sun's cluster
    singles = [_Candidate([int(i)], int(stats[i, 4]), int(stats[i, 0]), int(stats[i, 1]),
                          int(stats[i, 2]), int(stats[i, 3]), float(cents[i, 0]),
                          float(cents[i, 1])) for i in order]
    ghosts = _mark_ghosts(singles, centre)
    real = np.array([c.labels[0] for c in singles if not c.ghost], dtype=np.int64)
    cands = _clusters(stats, cents, real, ox, oy)
    priors = {id(c): _prior(c, labels, diam) for c in cands}
    # the glare rings are the costly part: only for the best few by shape and size
    ranked = sorted(priors, key=lambda k: -priors[k][0] ** 2 * priors[k][1])[:_SCORED]
    for c in cands:
        if id(c) in ranked:
            c.score = _score(c, gray, *priors[id(c)], peak, bg, fov, diam)
    cands.sort(key=lambda c: -c.score)
    best = cands[0]
    runner = cands[1].score if len(cands) > 1 else 0.0
    strength = _clamp(contrast / 60.0, 0.0, 1.0)
    confidence = best.score * strength * (1.0 - 0.5 * runner / max(best.score, 1e-9))
    found = confidence >= min_confidence
    fallback = None
    if camera is None and fov is not None:
        # no model given: an equidistant 180° lens spanning the image circle
        fallback = FisheyeCamera(fov.cx_px, fov.cy_px, fov.radius_px / 0.98 / 90.0)
    cx, cy, radius = (_refine(gray, labels, best, peak, bg, camera, fallback) if found
                      else (0.0, 0.0, 0.0))
    return SunDetection(
        sun_found=found,
        confidence=round(float(confidence), 4),
        centroid_px=(cx, cy) if found else None,
        method="robust",
        radius_px=radius,
        area_px=best.area,
        threshold=float(thr),
        n_candidates=len(cands),
        ghosts_rejected=ghosts,
        fov=fov,
    )


def _symmetry(mask: NDArray[np.uint8]) -> float:
    """Overlap (IoU) of a blob with itself turned 180° about its centroid: ~1 for a disc,
    an oval, or a disc with spikes on both sides; low for a disc cut by a box or the
    horizon."""
    m = cv2.moments(mask, True)
    if m["m00"] <= 0:
        return 0.0
    mx, my = m["m10"] / m["m00"], m["m01"] / m["m00"]
    h, w = mask.shape
    turn = np.array([[-1.0, 0.0, 2.0 * mx], [0.0, -1.0, 2.0 * my]])
    rot = cv2.warpAffine(mask, turn, (w, h), flags=cv2.INTER_NEAREST)
    inter = cv2.countNonZero(cv2.bitwise_and(mask, rot))
    union = cv2.countNonZero(cv2.bitwise_or(mask, rot))
    return inter / union if union else 0.0


def _refine(gray: NDArray[np.uint8], labels: NDArray[Any], c: _Candidate, peak: float,
            bg: float, camera: CameraModel | None, fallback: CameraModel | None = None
            ) -> tuple[float, float, float]:
    """Sub-pixel centre of the winning cluster → (x, y, radius_px).

    A complete blob — point-symmetric about its centroid (:func:`_symmetry`
    ≥ 0.9): a disc, an oval, a disc with blooming or flare spikes on both
    sides — gets the intensity-weighted centroid of a disc window above 80 %
    of the way from the local background to the peak. A blob cut by the
    horizon, a mast or an overlay, or merged with a cloud on one side, gets
    the limb fit (:func:`_robust_limb_centre`): on the sphere of ``camera``
    when one is given, else in the image — or on the sphere of ``fallback``
    (an approximate lens model) when that puts more of the limb on one circle.
    """
    r_eq = float(np.sqrt(c.area / np.pi))
    pad = max(3.0, 0.5 * r_eq + 2.0)
    ring = _ring_values(gray, c.cx, c.cy, r_eq + pad + 1.0, None)
    local_bg = float(np.median(ring)) if ring.size else bg
    level = local_bg + 0.8 * (peak - local_bg)
    got = _weighted_centroid(gray, c.cx, c.cy, r_eq + pad, level)
    wx, wy = got if got is not None else (c.cx, c.cy)
    if c.area < _SMALL_AREA_PX:
        return float(wx), float(wy), r_eq
    mask = c.mask(labels)
    if _symmetry(mask) >= 0.9:
        return float(wx), float(wy), r_eq
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    pts = np.vstack(contours).reshape(-1, 2).astype(float)
    if len(pts) < 8:
        return float(wx), float(wy), r_eq
    pts[:, 0] += c.x
    pts[:, 1] += c.y
    if camera is not None:
        cx, cy, r, _ = _robust_limb_centre(pts, camera)
        return cx, cy, r
    ix, iy, ir, inliers = _robust_limb_centre(pts, None)
    if fallback is not None and inliers < 0.6:
        sx, sy, sr, s_in = _robust_limb_centre(pts, fallback)
        if s_in > inliers:
            return sx, sy, sr
    return ix, iy, ir


# --------------------------------------------------------------------------- seeds


def detect_seed000(image: NDArray[Any], tolerance: tuple[int, int, int] = (30, 30, 30)
                   ) -> SunDetection:
    """Seed 000's pipeline (Acosta-Banda et al. 2025, Table 3, lines 43–49).

    HSV conversion, 15×15 box blur, ``inRange`` ± ``tolerance`` around the
    operator's picked colour — here the blurred frame's colour at its brightest
    V (the sun, where the operator clicked) — then dilate ×2 and erode ×2
    (3×3; the paper leaves the elements unstated) and the centroid (moments)
    of the largest object. The listing's V bounds read ``pixel[1] ∓ V``; we
    take that as a misprint for ``pixel[2]``.
    """
    img = np.asarray(image)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    hsv = cv2.cvtColor(img[:, :, :3], cv2.COLOR_BGR2HSV)
    blur = cv2.blur(hsv, (15, 15))
    v = blur[:, :, 2]
    _, _, _, (mx, my) = cv2.minMaxLoc(v)
    ref = blur[my, mx].astype(int)
    tol = np.array(tolerance)
    lo = np.clip(ref - tol, 0, 255)
    hi = np.clip(ref + tol, 0, 255)
    lo[0], hi[0] = max(0, ref[0] - tol[0]), min(180, ref[0] + tol[0])
    mask = cv2.inRange(blur, lo.astype(np.uint8), hi.astype(np.uint8))
    k = np.ones((3, 3), np.uint8)
    mask = cv2.erode(cv2.dilate(mask, k, iterations=2), k, iterations=2)
    n, _, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n < 2:
        return SunDetection(False, 0.0, None, "seed000_hsv")
    i = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return SunDetection(True, 1.0, (float(cents[i, 0]), float(cents[i, 1])), "seed000_hsv",
                        area_px=int(stats[i, 4]), n_candidates=n - 1)


def detect_seed003(image: NDArray[Any], threshold: int = 240) -> SunDetection:
    """Seed 003's pipeline (Garcia-Gil & Ramirez 2019, eqs. 5–8).

    Grey = mean of the three channels (eq. 5), binary = grey > 240 (eq. 6),
    centroid of all white pixels (eqs. 7–8).
    """
    img = np.asarray(image)
    if img.ndim == 3:
        s = cv2.transform(img[:, :, :3], np.full((1, 3), 1.0 / 3.0))
        gray = np.asarray(s)
    else:
        gray = img
    binary = cv2.threshold(gray, threshold, 1, cv2.THRESH_BINARY)[1]
    m = cv2.moments(binary, True)
    if m["m00"] == 0:
        return SunDetection(False, 0.0, None, "seed003_gray240", threshold=float(threshold))
    return SunDetection(True, 1.0, (m["m10"] / m["m00"], m["m01"] / m["m00"]),
                        "seed003_gray240", area_px=int(m["m00"]), threshold=float(threshold))


_DISPATCH: dict[str, Callable[..., SunDetection]] = {
    "robust": detect_robust,
    "seed000_hsv": detect_seed000,
    "seed003_gray240": detect_seed003,
}


def detect_sun(image: NDArray[Any], method: str = "robust", camera: CameraModel | None = None,
               **kwargs: Any) -> SunDetection:
    """Run one of :data:`METHODS` on a BGR (or grey) frame."""
    if method not in _DISPATCH:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if method == "robust":
        return detect_robust(image, camera=camera, **kwargs)
    return _DISPATCH[method](image, **kwargs)


def threshold_moments(gray: NDArray[np.uint8], threshold: int = 240) -> tuple[float, float] | None:
    """The bare kernel the benchmark compares against: threshold + image moments."""
    m = cv2.moments(cv2.threshold(gray, threshold, 1, cv2.THRESH_BINARY)[1], True)
    if m["m00"] == 0:
        return None
    return m["m10"] / m["m00"], m["m01"] / m["m00"]
