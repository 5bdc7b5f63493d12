"""The centre of a glare the sky has joined: vision.glare.censored_glare_centre (issue 24
item 4). Expected values: the sun's pixel the frame was drawn about, never the code."""

from __future__ import annotations

import numpy as np

from vision.detection import FovCircle
from vision.glare import censored_glare_centre


def _long_exposure(sun: tuple[float, float]) -> np.ndarray:
    """A 600² grey frame: a power-law glare (exponent 2) about ``sun`` on a sky brightening
    toward +x (a horizon) by 0.8 levels a pixel, clipped at 255 — the clipped region is
    pushed toward +x."""
    yy, xx = np.mgrid[0:600, 0:600].astype(float)
    r = np.hypot(xx - sun[0], yy - sun[1])
    sky = 150.0 + 0.8 * (xx - sun[0])
    return np.clip(sky + 120.0 * (np.maximum(r, 1.0) / 60.0) ** -2.0, 0, 255).astype(np.uint8)


def test_the_glare_not_the_clipped_region_gives_the_centre() -> None:
    frame = _long_exposure((280.0, 310.0))
    clipped = np.argwhere(frame >= 252)
    cy, cx = clipped.mean(axis=0)
    radius = float(np.sqrt(len(clipped) / np.pi))
    assert cx - 280.0 > 15.0  # the clipped region's centroid follows the brighter sky
    got = censored_glare_centre(frame, float(cx), float(cy), radius,
                                FovCircle(300.0, 300.0, 299.0))
    assert got is not None
    assert np.hypot(got[0] - 280.0, got[1] - 310.0) < 3.0
