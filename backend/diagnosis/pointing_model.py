"""The tracker's pointing model fitted from its stored camera offsets (issue 25, items 2–3).

Reads the tracker array's measured readings in a range that carry the encoder angles
(``azimuth_deg``, ``elevation_deg``) and the sun's offset in the tracker camera
(``sun_offset_x_mrad``, ``sun_offset_y_mrad``; ``backend/measurements/fields.py``),
and fits the mount terms with :func:`sim.pointing_model.fit_pointing_model` (SPA's
apparent sun with the site's pressure and air temperature, as
:mod:`backend.diagnosis.pointing`); the fit's residuals per observation for the
dashboard's Pointing page (:func:`residual_points`). A tracker-camera frame becomes an
observation by :func:`frame_offsets` (item 1b: the sun found by
:func:`vision.analyse.analyse_frame` in the tracker's pinhole camera, its pixel turned
into the offsets by :func:`offsets_from_pixel_mrad`). Definitions of the frames,
offsets and terms: ``docs/pointing-model.md``.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import threading
from collections import OrderedDict
from typing import Any

import numpy as np
import pandas as pd
from pvlib import atmosphere
from sqlalchemy import Connection, text

from backend.errors import InputError
from backend.measurements.buckets import ROLLUP_WIDTH_S
from backend.measurements.fields import SENSOR_NAMES
from backend.measurements.queries import iso_utc, raw_rows
from backend.sites import ArrayInfo, SiteInfo
from sim.pointing_model import (
    CORE_TERMS,
    MIN_OBSERVATIONS,
    PointingFit,
    command_angles,
    fit_pointing_model,
    pointing_std_mrad,
    predict_offsets_mrad,
)
from sim.sun import solar_position
from vision.analyse import analyse_frame, disc_scale_warning
from vision.cameras import PinholeCamera

#: The readings' fields an observation must carry: the encoder angles and both sun offsets.
OBSERVED = ("azimuth_deg", "elevation_deg", "sun_offset_x_mrad", "sun_offset_y_mrad")
#: Their columns of :func:`raw_rows` (ts, V, I, P, then the sensors).
_COLS = tuple(4 + SENSOR_NAMES.index(n) for n in OBSERVED)


#: Fits by the digest of the observations they were made from (and the site's place and
#: refraction): a fit is a pure function of them, so a repeated range — every command
#: of a day under one model — reads the rows again but does not refit; a new or changed
#: reading changes the digest. Bounded, oldest out.
_CACHE: OrderedDict[tuple[Any, ...], PointingFit] = OrderedDict()
_CACHE_SIZE = 32
_CACHE_LOCK = threading.Lock()


class TooFewObservations(ValueError):
    """The range holds too few readings with sun offsets for a fit (a 422 at the API)."""


def refraction_of(info: SiteInfo) -> tuple[float, float]:
    """The site's pressure [Pa] and air temperature [°C] for SPA's refraction."""
    return float(atmosphere.alt2pres(info.site.altitude)), float(info.site.temp_air)


#: The longest range one request fits [days]: a year of minute observations and then some
#: (the fit of a year's ~200,000 observations takes seconds; an anonymous read is bounded).
MAX_DAYS = 400


def _tracker(info: SiteInfo, t0: dt.datetime, t1: dt.datetime) -> ArrayInfo | None:
    """The site's tracker array (None: it has none) for a range of at most
    :data:`MAX_DAYS` days (422 beyond)."""
    if t1 - t0 > dt.timedelta(days=MAX_DAYS):
        raise InputError(422, f"end: the range spans over {MAX_DAYS} days; ask for less")
    return info.array_of_kind("tracker")


def observations(conn: Connection, info: SiteInfo, t0: dt.datetime, t1: dt.datetime
                 ) -> np.ndarray:
    """The tracker's readings in ``[t0, t1)`` that carry the encoder angles and both sun
    offsets (the other readings dropped), as raw rows; at most :data:`MAX_DAYS` days."""
    tracker = _tracker(info, t0, t1)
    if tracker is None:
        raise TooFewObservations(f"site {info.site_id!r} has no tracker array")
    rows = raw_rows(conn, tracker.array_id, 0, int(t0.timestamp()), int(t1.timestamp()),
                    sensors=True)
    return rows[np.isfinite(rows[:, _COLS]).all(axis=1)] if rows.size else rows


def count_observations(conn: Connection, info: SiteInfo, t0: dt.datetime, t1: dt.datetime
                       ) -> int | None:
    """How many of the tracker's measured readings in ``[t0, t1)`` :func:`observations` would
    return (encoder angles and both sun offsets), counted by the database without reading
    them; None without a tracker array. The dashboard asks this before a fit, so a range
    without camera offsets is an empty state, not a failed request."""
    tracker = _tracker(info, t0, t1)
    if tracker is None:
        return None
    carried = " AND ".join(f"{name} IS NOT NULL" for name in OBSERVED)
    return int(conn.execute(text(
        "SELECT count(*) FROM measurements WHERE array_id = :a AND source = 0 "
        f"AND ts_s >= :t0 AND ts_s < :t1 AND {carried}"),
        {"a": tracker.array_id, "t0": int(t0.timestamp()), "t1": int(t1.timestamp())}
    ).scalar_one())


#: Fits by their range and what the writer's hourly rollups say of the range's readings
#: (:func:`range_key`), so that a command under a cached fit reads no observations: a
#: year's rows take seconds to read, the rollups' sums over its 8,760 hours a millisecond.
_RANGE_FITS: OrderedDict[tuple[Any, ...], PointingFit] = OrderedDict()


def range_key(conn: Connection, info: SiteInfo, t0: dt.datetime, t1: dt.datetime
              ) -> tuple[Any, ...] | None:
    """What fixes the fit of ``[t0, t1)`` without reading its observations: the site's place
    and refraction, the tracker array, the range, and the count, power sum and last time of
    its measured readings by the hourly rollups (the writer updates them in the transaction
    that stores a reading, a reading is never changed in place, and deleting readings drops
    their rollups); whole hours around the range, so a reading next to it also counts. None
    without a tracker array."""
    tracker = info.array_of_kind("tracker")
    if tracker is None:
        return None
    a, b = int(t0.timestamp()), int(t1.timestamp())
    width = ROLLUP_WIDTH_S
    marker = conn.execute(text(
        "SELECT count(*), coalesce(sum(n), 0), coalesce(max(last_ts_s), 0), "
        "coalesce(sum(sum_power_w), 0) FROM measurement_rollups WHERE array_id = :a AND "
        "source = 0 AND bucket_s >= :b0 AND bucket_s < :b1"),
        {"a": tracker.array_id, "b0": a // width * width, "b1": b}).one()
    s = info.site
    return (info.site_id, tracker.array_id, s.latitude, s.longitude, s.altitude,
            *refraction_of(info), a, b, *marker)


def cached_range_fit(key: tuple[Any, ...] | None) -> PointingFit | None:
    """The fit remembered under :func:`range_key`'s ``key`` (None if none)."""
    if key is None:
        return None
    with _CACHE_LOCK:
        return _RANGE_FITS.get(key)


def remember_range_fit(key: tuple[Any, ...] | None, fit: PointingFit) -> None:
    """Remember ``fit`` under ``key`` (bounded as the digest cache, oldest out)."""
    if key is None:
        return
    with _CACHE_LOCK:
        _RANGE_FITS[key] = fit
        while len(_RANGE_FITS) > _CACHE_SIZE:
            _RANGE_FITS.popitem(last=False)


def fit_site(rows: np.ndarray, info: SiteInfo) -> PointingFit:
    """Fit the site's tracker to :func:`observations`' rows; :class:`TooFewObservations`
    when there are too few."""
    if rows.shape[0] < MIN_OBSERVATIONS:
        raise TooFewObservations(
            f"{rows.shape[0]} observations with sun offsets (sun_offset_x_mrad, "
            f"sun_offset_y_mrad and the encoder angles) in the range; the fit needs at least "
            f"{MIN_OBSERVATIONS}")
    s = info.site
    pressure, temperature = refraction_of(info)
    obs = np.ascontiguousarray(rows[:, (0, *_COLS)])
    key = (s.latitude, s.longitude, s.altitude, pressure, temperature,
           hashlib.blake2b(obs.tobytes(), digest_size=16).digest())
    with _CACHE_LOCK:
        cached = _CACHE.get(key)
    if cached is not None:
        return cached
    times = pd.DatetimeIndex(pd.to_datetime(obs[:, 0], unit="s", utc=True))
    fit = fit_pointing_model(times, obs[:, 1], obs[:, 2], obs[:, 3], obs[:, 4], s.latitude,
                             s.longitude, s.altitude, pressure, temperature)
    with _CACHE_LOCK:
        _CACHE[key] = fit
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return fit


def model_body(info: SiteInfo, fit: PointingFit) -> dict[str, Any]:
    """The ``GET …/pointing-model`` answer: terms with standard errors, what the data separate."""
    def finite(v: float | None) -> float | None:  # a singular fit's NaN is JSON null
        return v if v is not None and np.isfinite(v) else None

    terms = {t: {"value": getattr(fit.model, t), "std": finite(fit.std.get(t))}
             for t in (*CORE_TERMS, *(t for t in fit.fitted_terms if t not in CORE_TERMS))}
    return {"site_id": info.site_id, "n_observations": fit.n_observations,
            "n_outliers": fit.n_outliers, "residual_rms_mrad": fit.residual_rms_mrad,
            "terms": terms, "identifiable": list(fit.identifiable),
            "correlated": [{"terms": [a, b], "correlation": r} for a, b, r in fit.correlated]}


def command(info: SiteInfo, fit: PointingFit, when: dt.datetime) -> dict[str, float | None]:
    """Encoder angles to command at ``when`` so the real optical axis points at the sun, and
    how far that may miss it (:func:`sim.pointing_model.pointing_std_mrad`; None when the
    fit has no finite covariance)."""
    s = info.site
    pressure, temperature = refraction_of(info)
    sun = solar_position(pd.DatetimeIndex([when]), s.latitude, s.longitude, s.altitude,
                         pressure, temperature)
    saz, sel = sun["azimuth"].to_numpy(), sun["apparent_elevation"].to_numpy()
    az, el = command_angles(fit.model, saz, sel)
    std = float(pointing_std_mrad(fit, saz, sel, az, el)[0])
    return {"azimuth_deg": float(np.mod(az[0], 360.0)), "elevation_deg": float(el[0]),
            "sun_azimuth_deg": float(saz[0]), "sun_elevation_deg": float(sel[0]),
            "pointing_std_mrad": std if np.isfinite(std) else None}


#: The most observations :func:`residual_points` returns (evenly spaced over the range).
MAX_POINTS = 2000


def residual_points(rows: np.ndarray, info: SiteInfo, fit: PointingFit,
                    max_points: int = MAX_POINTS) -> dict[str, Any]:
    """The observations behind ``fit`` with the model's residuals, for the dashboard.

    Every ``stride``-th of :func:`observations`' rows (``stride`` = ⌈n / max_points⌉, so
    at most ``max_points``): the time (UTC), the encoder angles, the offsets measured
    (before the model: the pointing error of the mount as it is) and the residuals
    ``residual_*_mrad`` = measured − :func:`sim.pointing_model.predict_offsets_mrad`
    (after the model: what a command under the model still misses, to first order),
    and whether the fit rejected the observation as an outlier.
    """
    n = int(rows.shape[0])
    stride = max(1, -(-n // max(max_points, 1)))
    pick = np.arange(0, n, stride)
    obs = rows[pick][:, (0, *_COLS)]
    s = info.site
    pressure, temperature = refraction_of(info)
    sun = solar_position(pd.DatetimeIndex(pd.to_datetime(obs[:, 0], unit="s", utc=True)),
                         s.latitude, s.longitude, s.altitude, pressure, temperature)
    px, py = predict_offsets_mrad(fit.model, sun["azimuth"].to_numpy(),
                                  sun["apparent_elevation"].to_numpy(), obs[:, 1], obs[:, 2])
    rx, ry = obs[:, 3] - px, obs[:, 4] - py
    return {"n_total": n, "stride": stride, "ts": iso_utc(obs[:, 0].astype(np.int64)),
            "azimuth_deg": obs[:, 1].tolist(), "elevation_deg": obs[:, 2].tolist(),
            "sun_offset_x_mrad": obs[:, 3].tolist(), "sun_offset_y_mrad": obs[:, 4].tolist(),
            "residual_x_mrad": rx.tolist(), "residual_y_mrad": ry.tolist(),
            "outlier": fit.outlier[pick].tolist()}


def offsets_from_pixel_mrad(camera: PinholeCamera, x_px: float, y_px: float
                            ) -> tuple[float, float]:
    """The sun's offsets [mrad] (``sun_offset_x_mrad``, ``sun_offset_y_mrad``) of a sun
    seen at pixel ``(x_px, y_px)`` of the tracker's pinhole camera.

    Issue 25's definition (``docs/pointing-model.md``): x = 1000·atan2(s·h, s·n),
    y = 1000·atan2(s·u, s·n), s the sun's direction in the camera frame
    (:meth:`vision.cameras.PinholeCamera.pixel_to_direction`: right, up, forward) and
    (n, h, u) the camera's axes: n the direction of its reference pixel (the optical
    centre unless seed 001's fixed reference pixel is given) at angles (a, e) =
    :meth:`~vision.cameras.PinholeCamera.pixel_angles_deg` — n = (sin a cos e, sin e,
    cos a cos e), h = (cos a, 0, −sin a) toward the right (increasing azimuth), u =
    (−sin a sin e, cos e, −cos a sin e) up (increasing elevation), the joint frame's
    formulas with (a, e) for (az, el). With the reference at the centre, x = atan(X/Z)
    and y = atan(Y/Z): the vertical offset is not the elevation-like angle
    atan2(Y, √(X² + Z²)) of :meth:`~vision.cameras.PinholeCamera.pointing_error`.
    """
    d = camera.pixel_to_direction(x_px, y_px)
    a, e = (np.radians(float(v)) for v in camera.pixel_angles_deg(*camera.reference_px))
    n = np.array([np.sin(a) * np.cos(e), np.sin(e), np.cos(a) * np.cos(e)])
    h = np.array([np.cos(a), 0.0, -np.sin(a)])
    u = np.array([-np.sin(a) * np.sin(e), np.cos(e), -np.cos(a) * np.sin(e)])
    dn = float(d @ n)
    return 1000.0 * float(np.arctan2(d @ h, dn)), 1000.0 * float(np.arctan2(d @ u, dn))


def frame_offsets(image: np.ndarray, camera: PinholeCamera, fov_given: bool = True
                  ) -> dict[str, Any]:
    """Find the sun in a tracker-camera frame (:func:`vision.analyse.analyse_frame`, the
    robust detector) and give its offsets: ``sun_offset_x_mrad``, ``sun_offset_y_mrad``,
    ``confidence`` (the detector's calibrated probability), ``centroid_px`` and ``warnings``:
    with ``fov_given`` false (the default 67° used), one naming ``fov_deg`` when the sun's
    disc is drawn at another scale (:func:`vision.analyse.disc_scale_warning`).

    No sun found (overcast, the sun outside the frame, a glare without a disc) is a 422
    on ``file`` with the detector's reason: nothing is observed.
    """
    found = analyse_frame(image, camera, "robust")
    if not found["sun_found"] or found["centroid_px"] is None:
        raise InputError(422, f"file: no sun found in the frame ({found['reason']}); "
                              "nothing was stored")
    x, y = found["centroid_px"]
    ox, oy = offsets_from_pixel_mrad(camera, x, y)
    warning = None if fov_given else disc_scale_warning(image, (x, y), camera)
    return {"sun_offset_x_mrad": ox, "sun_offset_y_mrad": oy,
            "confidence": float(found["confidence"]), "centroid_px": [float(x), float(y)],
            "warnings": [] if warning is None else [warning]}
