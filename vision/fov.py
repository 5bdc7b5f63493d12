"""Grey conversion, frame statistics and the fisheye image circle (field-of-view mask)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.detection import FovCircle


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
    # the histogram's total, counted directly (exact: whole counts below 2**24)
    total = a.size if mask is None else cv2.countNonZero(mask)
    if total <= 0:
        return 0.0
    return float(np.searchsorted(np.cumsum(hist), 0.5 * total))


def estimate_fov(gray: NDArray[np.uint8], small: NDArray[np.uint8] | None = None,
                 scale: int = 1) -> FovCircle | None:
    """The fisheye image circle: the bright disc surrounded by dark corners, or None.

    A frame whose four corners are not dark (by their mean, or on 90 % of their pixels; a
    pinhole frame) has no circle — unless they are a lifted black: at most half the centre's
    level with the frame just outside the circle at their level, a sharp rim
    (:func:`_sharp_rim`; a brighter exposure or gamma lifts the unlit corners past the dark
    level).
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
    dark_max = max(35.0, 0.25 * centre_level)
    if corner_level > dark_max:
        # or dark on 90 % of their pixels: the overlay text a station prints there (its name,
        # the time) lifts the corners' mean past the dark level on a brighter exposure; a
        # pinhole view with something dark across part of its corners (a window frame,
        # foliage) stays without a circle
        px = np.stack([c.ravel() for c in corners])
        k = (9 * px.shape[1]) // 10
        p90 = np.sort(np.partition(px, k, axis=1)[:, k])
        corner_dark = 0.5 * (float(p90[1]) + float(p90[2]))  # the median of four
    else:
        corner_dark = corner_level
    lifted = False  # the corners passed only as a lifted black behind a sharp rim
    if centre_level < 20.0:
        return None
    if corner_dark > dark_max:
        if min(corner_level, corner_dark) > _LIFTED_MAX * centre_level:
            return None
        lifted = True
    level = corner_level + 0.3 * (centre_level - corner_level)
    # small > level (an 8-bit threshold compares with ⌊level⌋: the same pixels)
    binary = cv2.threshold(small, level, 1, cv2.THRESH_BINARY)[1]
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return None
    big = max(contours, key=cv2.contourArea)
    if cv2.contourArea(big) < 0.2 * h * w:
        return None
    (cx, cy), r = cv2.minEnclosingCircle(big)
    if lifted and not _sharp_rim(small, cx, cy, r, corner_level, centre_level):
        return None
    off = float(scale // 2)  # thumbnail pixel i is full-res pixel i·s + s//2
    return FovCircle(cx * scale + off, cy * scale + off, 0.98 * r * scale)


_LIFTED_MAX = 0.5  # a lifted black: corners at most this share of the centre's level
_RIM_OUT = 1.1  # the ring just outside the image circle [× its radius]
_RIM_TOL = 0.15  # … within this share of the step from the corners' level: unlit
_RIM_IN = 0.9  # the ring just inside it [× its radius]
_RIM_LIT = 0.5  # … at least this share of the way up the step: lit to the rim
_RIM_MIN_POINTS = 8  # … read on at least this many of its 96 points inside the frame
_RIM_COS = np.cos(np.linspace(0.0, 2 * np.pi, 96, endpoint=False))
_RIM_SIN = np.sin(np.linspace(0.0, 2 * np.pi, 96, endpoint=False))


def _sharp_rim(small: NDArray[np.uint8], cx: float, cy: float, r: float, corner: float,
               centre: float) -> bool:
    """Whether the frame just outside a candidate image circle (thumbnail pixels: centre
    ``cx, cy``, radius ``r``) is at the unlit corners' level — the circle's edge a step.

    A fisheye's image circle is the shadow of its field stop (Ray 2002, *Applied
    Photographic Optics*, 3rd ed., ch. 24: the field stop bounds the image sharply): outside
    it the sensor sees nothing, whatever the tone curve. A brighter exposure or a lifted
    gamma raises that unlit level (UCEEB and Wolf at gamma 0.7: 16–19 → 36–41 grey levels,
    past the dark level of :func:`estimate_fov`), but the ring at :data:`_RIM_OUT` × the
    radius stays within :data:`_RIM_TOL` of the step from the corners' level (the real suns'
    and UCEEB's frames that reach this test at gammas 0.5 and 0.7: −0.10 to +0.08), and the
    sky inside is lit to the rim: the ring at :data:`_RIM_IN` × the radius at least
    :data:`_RIM_LIT` of the way up the step (at gamma 0.7: 0.66–1.45 on 7 frames; Wolf 09:44
    at 0.50 and, at gamma 0.5, seven Wolf frames at 0.33–0.46 stay without a circle). A
    pinhole view's vignetting falls off gradually; a
    glare filling a small crop (the tracker's region of interest, whose corners are sky)
    falls off inside its ring (0.23–0.34 of the way up; the tracker's whole frames
    0.32–0.37); and a view framed by something dark (a window frame) has its dark edges
    inside the frame's corners, not on a ring about a bright disc: the ring lies past the
    frame's corners and has too few points to read (:data:`_RIM_MIN_POINTS`)."""
    h, w = small.shape
    step = centre - corner
    for k in (_RIM_OUT, _RIM_IN):
        xs = np.rint(cx + k * r * _RIM_COS).astype(np.intp)
        ys = np.rint(cy + k * r * _RIM_SIN).astype(np.intp)
        ok = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        if int(ok.sum()) < _RIM_MIN_POINTS:
            return False
        level = (float(np.median(small[ys[ok], xs[ok]])) - corner) / step
        if (k > 1.0 and abs(level) > _RIM_TOL) or (k < 1.0 and level < _RIM_LIT):
            return False
    return True


def _fov_mask(shape: tuple[int, int], fov: FovCircle) -> NDArray[np.uint8]:
    mask = np.zeros(shape, np.uint8)
    cv2.circle(mask, (int(round(fov.cx_px)), int(round(fov.cy_px))), int(fov.radius_px), 255, -1)
    return mask


def image_circle(gray: NDArray[np.uint8]) -> tuple[FovCircle, bool] | None:
    """The lens's whole image circle (not shrunk) and whether it reaches the frame's edge.

    :func:`estimate_fov` shrinks the circle by 2 % to keep the detector off the
    dark rim; a camera whose scale is unknown wants the rim itself: the circle
    a 180° lens draws is the horizon (θ = 90°). ``clipped`` is True when the
    circle leaves the frame, so the frame's edge, not the lens, bounds what was
    measured. None when the frame has no dark corners (no circle).
    """
    fov = estimate_fov(gray)
    if fov is None:
        return None
    circle = FovCircle(fov.cx_px, fov.cy_px, fov.radius_px / 0.98)
    h, w = gray.shape[:2]
    clipped = (circle.cx_px - circle.radius_px < -0.5 or circle.cy_px - circle.radius_px < -0.5
               or circle.cx_px + circle.radius_px > w - 0.5
               or circle.cy_px + circle.radius_px > h - 0.5)
    return circle, bool(clipped)
