"""Directions on the sky sphere: the one set of functions every package uses.

A sky direction is (azimuth, elevation) in degrees — azimuth clockwise from true
north (pvlib's convention), elevation above the horizon — or an ENU unit vector
(east, north, up). ``sim`` (sun vectors, pointing errors) and ``vision``
(camera models, error metrics) both call these; no other copy exists.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

SUN_RADIUS_DEG = 0.2665
"""The solar disc's mean apparent radius [°]: half of its 0.533° diameter (0.524–0.542° over
the year, with the Earth's distance). The renderers draw it (``vision.synth``,
``vision.skyrender``), the detector refuses a core smaller than it
(``vision.confidence.smaller_than_the_disc``)."""


def enu_from_sky(azimuth_deg: ArrayLike, elevation_deg: ArrayLike) -> FloatArray:
    """Unit vectors ``[..., 3]`` (east, north, up) from azimuth/elevation [°]."""
    az = np.radians(np.asarray(azimuth_deg, dtype=float))
    el = np.radians(np.asarray(elevation_deg, dtype=float))
    cos_el = np.cos(el)
    out = np.empty(np.broadcast_shapes(az.shape, el.shape) + (3,))  # np.stack's, cheaper
    out[..., 0] = cos_el * np.sin(az)
    out[..., 1] = cos_el * np.cos(az)
    out[..., 2] = np.sin(el)
    return out


def sky_from_enu(v: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Azimuth (clockwise from north, [0, 360)) and elevation [°] of ENU vectors."""
    v = np.asarray(v, dtype=float)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    n = np.sqrt(x * x + y * y + z * z)  # the components added: a sum along a last axis of 3
    # is ~20x slower (sim.plant.shading.sum_columns), np.linalg.norm slower still
    az = np.degrees(np.arctan2(x, y)) % 360.0
    el = np.degrees(np.arcsin(np.minimum(np.maximum(z / n, -1.0), 1.0)))
    return az, el


def angular_separation_deg(
    azimuth1_deg: ArrayLike,
    elevation1_deg: ArrayLike,
    azimuth2_deg: ArrayLike,
    elevation2_deg: ArrayLike,
) -> FloatArray:
    """Great-circle angle [°] between two sky directions (haversine form, stable near 0)."""
    a1, e1, a2, e2 = (np.radians(np.asarray(v, dtype=float)) for v in
                      (azimuth1_deg, elevation1_deg, azimuth2_deg, elevation2_deg))
    h = np.sin((e2 - e1) / 2) ** 2 + np.cos(e1) * np.cos(e2) * np.sin((a2 - a1) / 2) ** 2
    return np.degrees(2.0 * np.arcsin(np.sqrt(np.clip(h, 0.0, 1.0))))
