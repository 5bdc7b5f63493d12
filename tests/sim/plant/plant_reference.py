"""Independent references for the plant tests: twoaxistracking and brute-force ray sampling.

Neither uses :mod:`sim.plant.shading`: twoaxistracking (pvlib's project for two-axis
tracker fields) intersects shapely polygons per tracker and step; the sampler casts a
ray towards the sun from points on each collector and tests it against every
neighbour's rectangle.
"""

from __future__ import annotations

import numpy as np
import pandas as pd


def twoaxistracking_fractions(positions, solar_azimuth, solar_elevation, width, height):
    """Shaded fraction (T, N) of sun-pointing collectors from ``twoaxistracking``."""
    from shapely import geometry
    from twoaxistracking.shading import shaded_fraction

    geom = geometry.box(-width / 2, -height / 2, width / 2, height / 2)
    spacing = float(np.hypot(width, height))  # at least the diagonal, or neighbours are skipped
    p = np.asarray(positions, dtype=float)
    out = np.full((len(solar_azimuth), len(p)), np.nan)
    for i in range(len(p)):
        d = np.delete(p - p[i], i, axis=0)
        dist = np.hypot(d[:, 0], d[:, 1])
        raz = np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 360.0
        slope = np.degrees(np.arctan2(d[:, 2], dist))
        for k, (az, el) in enumerate(zip(solar_azimuth, solar_elevation, strict=True)):
            out[k, i] = shaded_fraction(el, az, geom, geom, spacing, dist, raz, slope)
    return out


def _axes(az_deg, el_deg):
    az, el = np.radians(az_deg), np.radians(el_deg)
    n = np.array([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    u = np.array([-np.cos(az), np.sin(az), 0.0])
    return n, u, np.cross(u, n)


def sampled_fractions(positions, sun_az, sun_el, normal_az, normal_el, width, height,
                      samples=(121, 51)):
    """Shaded fraction (N,) at one instant by ray casting from a grid of points per collector.

    Each collector is a ``width × height`` rectangle centred on its pivot with normal
    (normal_az, normal_el); a point is shaded when the ray towards the sun meets
    another collector's rectangle.
    """
    p = np.asarray(positions, dtype=float)
    n, u, v = _axes(normal_az, normal_el)
    s = np.array([np.cos(np.radians(sun_el)) * np.sin(np.radians(sun_az)),
                  np.cos(np.radians(sun_el)) * np.cos(np.radians(sun_az)),
                  np.sin(np.radians(sun_el))])
    a = (np.arange(samples[0]) + 0.5) / samples[0] * width - width / 2
    b = (np.arange(samples[1]) + 0.5) / samples[1] * height - height / 2
    aa, bb = (x.ravel() for x in np.meshgrid(a, b))
    out = np.zeros(len(p))
    for i in range(len(p)):
        pts = p[i] + aa[:, None] * u + bb[:, None] * v          # (S, 3)
        hit = np.zeros(len(pts), dtype=bool)
        for j in range(len(p)):
            if j == i:
                continue
            lam = ((p[j] - pts) @ n) / (s @ n)                  # ray to j's plane
            q = pts + lam[:, None] * s - p[j]
            hit |= (lam > 0) & (np.abs(q @ u) < width / 2) & (np.abs(q @ v) < height / 2)
        out[i] = hit.mean()
    return out


def utc_from_true_solar_time(day: str, hours: float, longitude: float) -> pd.Timestamp:
    """UTC instant of a true-solar-time clock reading (Spencer 1971 equation of time, pvlib)."""
    from pvlib.solarposition import equation_of_time_spencer71

    d = pd.Timestamp(day, tz="UTC")
    eot_min = float(equation_of_time_spencer71(d.day_of_year))
    return d + pd.Timedelta(hours=hours - longitude / 15.0) - pd.Timedelta(minutes=eot_min)


def shapely_shades_anyone(positions, sun_az, sun_el, normal_az, normal_el, width, height):
    """Does a common orientation shade any collector? Shapely polygons, every ordered pair.

    Each neighbour's four corners are projected along the sun ray onto a
    collector's plane (only when in front of it) and intersected with that
    collector's rectangle; a shade of more than 1e-9 m² counts.
    """
    import shapely

    p = np.asarray(positions, dtype=float)
    n, u, v = _axes(normal_az, normal_el)
    s = np.array([np.cos(np.radians(sun_el)) * np.sin(np.radians(sun_az)),
                  np.cos(np.radians(sun_el)) * np.cos(np.radians(sun_az)),
                  np.sin(np.radians(sun_el))])
    if s @ n <= 0:
        return False
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [width / 2, height / 2]
    own = shapely.box(-width / 2, -height / 2, width / 2, height / 2)
    ii, jj = np.nonzero(~np.eye(len(p), dtype=bool))
    d = p[jj] - p[ii]                                           # centre of j seen from i
    pts = d[:, None, :] + corners[None, :, 0, None] * u + corners[None, :, 1, None] * v
    lam = -(pts @ n) / (s @ n)                                  # move along s onto i's plane
    front = (d @ n) / (s @ n) > 0                               # j between i and the sun
    proj = pts + lam[..., None] * s
    poly = shapely.polygons(np.stack([proj @ u, proj @ v], axis=-1))
    area = shapely.area(shapely.intersection(poly, own))
    return bool(np.any(front & (area > 1e-9)))
