"""The result types every detector returns, and the camera protocol they accept."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray


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
    reason: str | None = None  # why not, on every "no sun" answer
    distance_from_ephemeris_px: float | None = None  # when a prediction was given
    features: dict[str, float] = field(default_factory=dict)  # the confidence's inputs
    candidate_px: tuple[float, float] | None = None  # the winning region's centroid, found or not

