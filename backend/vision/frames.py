"""What a sky frame brings beyond its pixels: the time written in its file name, and the
fisheye scale its image circle implies. One rule for every caller.

:func:`frame_inputs` is what ``heliotwin vision detect`` (``backend/cli/vision.py``) and
``POST /api/v1/vision/sun`` (``backend/api/routes/vision.py``) apply to a frame before
detection, so a file gives the same answer through either; the dashboard asks
``GET /api/v1/vision/frame-times`` (:func:`time_from_name`) for the times it shows
beside each file instead of reading names itself.

- A fisheye sent without ``px_per_deg`` gets the scale of its image circle
  (:func:`backend.vision.checks.derive_fisheye_scale`, ``camera_derived`` in the answer).
- A frame sent without a time gets the time its file name carries (``20160615_093900``,
  ``20180321061000``, ``…T093900``), read in the zone the name states (``UTCp1``,
  ``UTC+1``, ``UTCm3``, ``UTC-3``: whole hours east of UTC positive) or, when the name
  states none, in the place's zone (a site's own zone; UTC for a bare latitude and
  longitude). ``timestamp_source`` says where the time came from.
"""

from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np

from backend.vision.checks import derive_fisheye_scale

_NAME_TIME = re.compile(r"(20\d{2})(\d{2})(\d{2})[_T-]?(\d{2})(\d{2})(\d{2})")
_NAME_ZONE = re.compile(r"UTC([pm+-])(\d{1,2})(?!\d)", re.IGNORECASE)


@dataclass(frozen=True)
class NameTime:
    """The time a file name carries: its wall clock, and the UTC offset the name states."""

    wall_time: dt.datetime  # naive: the digits of the name
    utc_offset_h: int | None  # None: the name states no zone

    def instant(self, zone: dt.tzinfo) -> dt.datetime:
        """The UTC instant: in the name's offset, else in ``zone``."""
        tz = zone if self.utc_offset_h is None else dt.timezone(
            dt.timedelta(hours=self.utc_offset_h))
        return self.wall_time.replace(tzinfo=tz).astimezone(dt.UTC)

    def source(self) -> str:
        """``timestamp_source`` of a time read from the name."""
        if self.utc_offset_h is None:
            return "file name (no zone in the name: read in the place's zone)"
        return f"file name (UTC{self.utc_offset_h:+d} h, stated in the name)"


def time_from_name(name: str) -> NameTime | None:
    """The time in a file name (``Wettermast_20160615_093900UTCp1_….jpg``), or None when it
    has none, or its digits are not a calendar time (month 13, hour 25)."""
    m = _NAME_TIME.search(name)
    if m is None:
        return None
    try:
        year, month, day, hour, minute, second = (int(g) for g in m.groups())
        wall = dt.datetime(year, month, day, hour, minute, second)
    except ValueError:
        return None
    z = _NAME_ZONE.search(name)
    offset = None
    if z is not None and int(z.group(2)) <= 14:
        offset = (-1 if z.group(1).lower() in ("m", "-") else 1) * int(z.group(2))
    return NameTime(wall, offset)


@dataclass(frozen=True)
class FrameInputs:
    """A frame's camera parameters and time, completed by :func:`frame_inputs`."""

    params: dict[str, object]
    camera_derived: dict[str, Any] | None
    timestamp: dt.datetime | None
    timestamp_source: str | None  # "given", "file name (…)", or None: no time


def frame_inputs(image: np.ndarray, filename: str, camera: str | None,
                 params: dict[str, object], timestamp: dt.datetime | None,
                 zone: dt.tzinfo | None) -> FrameInputs:
    """Complete a frame's parameters the one way the CLI and the service do.

    Parameters
    ----------
    image : the decoded frame (only read for a fisheye without ``px_per_deg``).
    filename : the file's name (its time is used when ``timestamp`` is None).
    camera : ``"fisheye"``, ``"pinhole"``, or None (a stored calibration: nothing to derive).
    params : the camera parameters given (``px_per_deg``, ``projection``, ``cx_px`` …).
    timestamp : the time given, tz-aware; None to read it from ``filename``.
    zone : the place's zone, for a name without a zone (None: UTC).

    Raises :class:`backend.errors.InputError` (422 naming ``px_per_deg``) when a fisheye
    has neither a scale nor an image circle to derive one from.
    """
    derived = None
    if camera == "fisheye" and params.get("px_per_deg") in (None, ""):
        params, derived = derive_fisheye_scale(image, params)
    source = None if timestamp is None else "given"
    if timestamp is None:
        found = time_from_name(filename)
        if found is not None:
            timestamp = found.instant(zone or ZoneInfo("UTC"))
            source = found.source()
    return FrameInputs(params, derived, timestamp, source)
