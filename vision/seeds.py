"""The seeds' own sun-finding pipelines, kept as named methods for comparison."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.detection import SunDetection

_KERNEL_3X3 = np.ones((3, 3), np.uint8)  #: seed 000's dilate/erode element


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
    # the bounds in plain ints: np.clip on three values cost more than the frame's
    # morphology (the closed loop detects a frame every daylight second)
    ref = [int(c) for c in blur[my, mx]]
    top = (180, 255, 255)  # OpenCV's 8-bit hue runs 0…180
    lo = np.array([max(0, r - t) for r, t in zip(ref, tolerance, strict=True)], np.uint8)
    hi = np.array([min(m, r + t) for r, t, m in zip(ref, tolerance, top, strict=True)],
                  np.uint8)
    mask = cv2.inRange(blur, lo, hi)
    mask = cv2.erode(cv2.dilate(mask, _KERNEL_3X3, iterations=2), _KERNEL_3X3, iterations=2)
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



def threshold_moments(gray: NDArray[np.uint8], threshold: int = 240) -> tuple[float, float] | None:
    """The bare kernel the benchmark compares against: threshold + image moments."""
    m = cv2.moments(cv2.threshold(gray, threshold, 1, cv2.THRESH_BINARY)[1], True)
    if m["m00"] == 0:
        return None
    return m["m10"] / m["m00"], m["m01"] / m["m00"]
