"""Stored sun detections and fisheye calibrations: their reads and writes.

The tables are declared in ``backend.storage.tables`` with the rest of the
schema (Alembic revision ``0002_vision``). Frame times are integer Unix milliseconds
(``ts_ms``, UTC; NULL when the frame came without a time), like the core's
integer keys: unambiguous and identical on SQLite and PostgreSQL.

Writes (:func:`insert_detection`, :func:`insert_calibration`) take a
``Connection`` and are meant to run inside the service's one writer
(``Writer.call``); reads take a ``Connection`` or ``Session``.
"""

from __future__ import annotations

import datetime as dt
import json
from typing import Any

from sqlalchemy import delete, insert, select
from sqlalchemy.engine import Connection
from sqlalchemy.orm import Session

from backend.storage.tables import VisionCalibration, VisionDetection, utcnow
from backend.vision.checks import error_warnings

_DETECTION_COLUMNS = [c.name for c in VisionDetection.__table__.columns]
_CALIBRATION_COLUMNS = [c.name for c in VisionCalibration.__table__.columns]


def _iso(ts_ms: int | None) -> str | None:
    if ts_ms is None:
        return None
    return dt.datetime.fromtimestamp(ts_ms / 1000.0, dt.UTC).isoformat().replace("+00:00", "Z")


def _created(value: dt.datetime) -> str:
    if value.tzinfo is None:  # SQLite hands back naive UTC
        value = value.replace(tzinfo=dt.UTC)
    return value.astimezone(dt.UTC).isoformat().replace("+00:00", "Z")


def insert_detection(conn: Connection, row: dict[str, Any]) -> int:
    """Store one detection (keys = column names, ``id``/``created_at`` optional) → its id."""
    values = {k: row.get(k) for k in _DETECTION_COLUMNS if k != "id"}
    values["created_at"] = row.get("created_at") or utcnow()
    result = conn.execute(insert(VisionDetection).values(**values))
    return int(result.inserted_primary_key[0])  # type: ignore[index]


def insert_calibration(conn: Connection, row: dict[str, Any]) -> int:
    """Store one calibration (``radial_coeffs`` and ``frames`` as Python lists) → its id."""
    values = {k: row.get(k) for k in _CALIBRATION_COLUMNS
              if k not in ("id", "radial_coeffs_json", "frames_json")}
    values["created_at"] = row.get("created_at") or utcnow()
    values["name"] = row.get("name") or ""
    values["radial_coeffs_json"] = json.dumps(list(row.get("radial_coeffs") or []))
    values["frames_json"] = json.dumps(row.get("frames") or [])
    result = conn.execute(insert(VisionCalibration).values(**values))
    return int(result.inserted_primary_key[0])  # type: ignore[index]


def detection_to_dict(r: Any) -> dict[str, Any]:
    """A stored detection in the shape of the ``POST /api/v1/vision/sun`` answer."""
    out: dict[str, Any] = {
        "detection_id": r.id,
        "timestamp": _iso(r.ts_ms),
        "created_at": _created(r.created_at),
        "site_id": r.site_id,
        "latitude_deg": r.latitude_deg,
        "longitude_deg": r.longitude_deg,
        "camera": r.camera,
        "calibration_id": r.calibration_id,
        "method": r.method,
        "image_size_px": [r.image_width_px, r.image_height_px],
        "sun_found": bool(r.sun_found),
        "confidence": r.confidence,
        "centroid_px": (None if r.centroid_x_px is None
                        else [r.centroid_x_px, r.centroid_y_px]),
    }
    if r.camera == "fisheye":
        out["azimuth_deg"] = r.azimuth_deg
        out["elevation_deg"] = r.elevation_deg
    else:
        out["pointing_error_deg"] = (None if r.pointing_error_horizontal_deg is None else
                                     [r.pointing_error_horizontal_deg,
                                      r.pointing_error_vertical_deg])
        out["pointing_error_mrad"] = r.pointing_error_mrad
    if r.ephemeris_azimuth_deg is not None:
        out["ephemeris"] = {"azimuth_deg": r.ephemeris_azimuth_deg,
                            "elevation_deg": r.ephemeris_elevation_deg}
    if r.error_deg is not None:
        out["error"] = {"separation_deg": r.error_deg}
    out["warnings"] = error_warnings(out, None)
    return out


def calibration_to_dict(r: Any, full: bool = True) -> dict[str, Any]:
    """A stored calibration: ``camera`` holds the parameters by their public names."""
    out: dict[str, Any] = {
        "calibration_id": r.id,
        "name": r.name,
        "created_at": _created(r.created_at),
        "site_id": r.site_id,
        "latitude_deg": r.latitude_deg,
        "longitude_deg": r.longitude_deg,
        "elevation_m": r.elevation_m,
        "projection": r.projection,
        "image_size_px": [r.image_width_px, r.image_height_px],
        "n_frames": r.n_frames,
        "rms_px": r.rms_px,
        "max_px": r.max_px,
        "rms_deg": r.rms_deg,
        "max_deg": r.max_deg,
        "camera": {
            "projection": r.projection,
            "cx_px": r.cx_px,
            "cy_px": r.cy_px,
            "px_per_deg": r.px_per_deg,
            "north_offset_deg": r.north_offset_deg,
            "east": r.east,
            "radial_coeffs": json.loads(r.radial_coeffs_json),
            "tilt_north_deg": r.tilt_north_deg,
            "tilt_east_deg": r.tilt_east_deg,
        },
    }
    if full:
        out["frames"] = json.loads(r.frames_json)
    return out


def get_calibration(db: Connection | Session, calibration_id: int) -> dict[str, Any] | None:
    """One calibration, or None."""
    row = db.execute(select(VisionCalibration.__table__)
                     .where(VisionCalibration.id == calibration_id)).first()
    return None if row is None else calibration_to_dict(row)


def list_calibrations(db: Connection | Session, limit: int = 200) -> list[dict[str, Any]]:
    """The newest calibrations first (without their per-frame lists)."""
    rows = db.execute(select(VisionCalibration.__table__)
                      .order_by(VisionCalibration.id.desc()).limit(limit)).all()
    return [calibration_to_dict(r, full=False) for r in rows]


def delete_calibration(conn: Connection, calibration_id: int) -> dict[str, int] | None:
    """Delete a calibration and the detections made with it (their angles came from a
    camera that no longer exists) → the counts, or None when there is no such calibration."""
    if conn.execute(select(VisionCalibration.id)
                    .where(VisionCalibration.id == calibration_id)).first() is None:
        return None
    n_det = conn.execute(delete(VisionDetection)
                         .where(VisionDetection.calibration_id == calibration_id)).rowcount
    conn.execute(delete(VisionCalibration).where(VisionCalibration.id == calibration_id))
    return {"calibrations_deleted": 1, "detections_deleted": int(n_det or 0)}


def delete_detections(conn: Connection, site_id: str | None, start_ms: int, end_ms: int,
                      calibration_id: int | None = None, uncalibrated: bool = False) -> int:
    """Delete the detections of a site (or of free places when ``site_id`` is None) in
    [start, end), optionally only those of one calibration or only those made with typed
    parameters (``uncalibrated``) → how many."""
    t = VisionDetection
    q = delete(t).where(t.ts_ms >= start_ms, t.ts_ms < end_ms)
    q = q.where(t.site_id.is_(None) if site_id is None else t.site_id == site_id)
    if calibration_id is not None:
        q = q.where(t.calibration_id == calibration_id)
    elif uncalibrated:
        q = q.where(t.calibration_id.is_(None))
    return int(conn.execute(q).rowcount or 0)


def list_detections(db: Connection | Session, site_id: str | None, start_ms: int | None,
                    end_ms: int | None, limit: int = 10_000) -> list[dict[str, Any]]:
    """Detections of a site (or of any place when ``site_id`` is None) in [start, end), by time."""
    t = VisionDetection.__table__
    q = select(t)
    if site_id is not None:
        q = q.where(t.c.site_id == site_id)
    if start_ms is not None:
        q = q.where(t.c.ts_ms >= start_ms)
    if end_ms is not None:
        q = q.where(t.c.ts_ms < end_ms)
    if start_ms is None and end_ms is None:
        q = q.order_by(t.c.id.desc())
    else:
        q = q.order_by(t.c.ts_ms, t.c.id)
    return [detection_to_dict(r) for r in db.execute(q.limit(limit)).all()]


__all__ = [
    "VisionCalibration",
    "VisionDetection",
    "calibration_to_dict",
    "delete_calibration",
    "delete_detections",
    "detection_to_dict",
    "get_calibration",
    "insert_calibration",
    "insert_detection",
    "list_calibrations",
    "list_detections",
]
