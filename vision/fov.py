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
    pinhole frame) has no circle.
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
    if centre_level < 20.0 or corner_dark > dark_max:
        return None
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
    off = float(scale // 2)  # thumbnail pixel i is full-res pixel i·s + s//2
    return FovCircle(cx * scale + off, cy * scale + off, 0.98 * r * scale)


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
