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
  ``20180321061000``, ``…T093900``), read in the zone the name states or, when the name
  states none, in the place's zone (a site's own zone; UTC for a bare latitude and
  longitude). ``timestamp_source`` says where the time came from. A zone is stated by
  ``UTC`` and an offset east of UTC positive — ``UTCp1``/``UTCm3`` (``p5.5``: decimal
  hours), ``UTC+1``, ``UTC-3``, ``UTC+05:30``, ``UTC+0530``, bare ``UTC`` (+0) — or by an
  ISO 8601 suffix right after the time digits: ``Z``, ``±hh:mm``, ``±hhmm``
  (``…T180000Z``, ``…T120000+0100``; a bare ``±hh`` there is not read, it is too often a
  sequence number). A zone the reader cannot read exactly (``UTC+5:3``, ``UTC+25``,
  ``UTCp5.33``, two zones that disagree) raises :class:`NameZoneError` rather than be
  rounded: the frame then needs its time sent. So does a name with a zone-like token after
  the time that is not such an offset — an abbreviation (``CET``, ``CEST``, ``MESZ``,
  ``PST``, ``GMT``, ``GMT+1``: abbreviations are ambiguous, and ``GMT+1`` is UTC−1 in the
  tz database's ``Etc/GMT+1``) or a bare ``+hh`` right after the time digits
  (``…_100600+01``): read as UTC or the place's zone they put the sun an hour or more
  from where it was. A bare ``-hh`` there stays a sequence number.
"""

from __future__ import annotations

import datetime as dt
import re
from dataclasses import dataclass
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np

from backend.errors import InputError
from backend.vision.checks import derive_fisheye_scale

_NAME_TIME = re.compile(r"(20\d{2})(\d{2})(\d{2})[_T-]?(\d{2})(\d{2})(\d{2})")
#: ``UTC`` (not inside a word) and what follows it: a sign (``p``/``m`` or ``+``/``-``)
#: and the offset's digits (``1``, ``05:30``, ``0530``, ``5.5``), or nothing (+0)
_NAME_ZONE = re.compile(r"(?<![a-z])UTC(?:([pm+-])(\d+(?:[:.]\d+)?)|(?![pm+-]\d))"
                        r"(?![a-z0-9]|[:.]\d)", re.IGNORECASE)
_SIGNED = re.compile(r"UTC[pm+-]\d", re.IGNORECASE)
#: an ISO 8601 zone right after the time digits: ``Z``, ``±hh:mm`` or ``±hhmm``
_ISO_ZONE = re.compile(r"(Z(?![a-z]))|([+-])(\d{2}:?\d{2})(?!\d)", re.IGNORECASE)
#: zone abbreviations (tz database, and German MEZ/MESZ) seen in camera file names, alone
#: or with an offset (``GMT+1``, ``CET-1``); words such as WEST or ART are left out, as they
#: name other things. Never read: only refused, so that the frame's time is sent.
_ABBREVIATIONS = ("CET", "CEST", "MEZ", "MESZ", "WET", "EET", "EEST", "GMT", "BST", "IST",
                  "PST", "PDT", "MST", "MDT", "CST", "CDT", "EST", "EDT", "AKST", "AKDT",
                  "HST", "AEST", "AEDT", "ACST", "ACDT", "AWST", "NZST", "NZDT", "JST",
                  "KST", "MSK", "HKT", "SGT", "WIB", "BRT", "UT")
_ABBREVIATION = re.compile(r"(?<![a-z])(?:" + "|".join(_ABBREVIATIONS) + r")"
                           r"(?:[pm+-]\d+(?:[:.]\d+)?)?(?![a-z0-9])", re.IGNORECASE)
#: a bare ``+hh`` (or ``+h``) right after the time digits: a zone, but not one ISO 8601
#: spells exactly enough to be told from a number
_BARE_PLUS = re.compile(r"\+\d{1,2}(?![\d:])")
_MAX_OFFSET_MIN = 14 * 60  # the farthest zones from UTC (Kiribati, UTC+14)
_OFFSET_STEP_MIN = 15  # every zone's offset is whole hours, :30 or :45 (tz database)


class NameZoneError(ValueError):
    """A file name states a zone that cannot be read exactly: refused, never rounded."""


@dataclass(frozen=True)
class NameTime:
    """The time a file name carries: its wall clock, and the UTC offset the name states."""

    wall_time: dt.datetime  # naive: the digits of the name
    utc_offset_min: int | None  # None: the name states no zone

    @property
    def utc_offset_h(self) -> float | None:
        """The stated offset in hours (5.5 for +05:30), None when the name states none."""
        return None if self.utc_offset_min is None else self.utc_offset_min / 60

    def instant(self, zone: dt.tzinfo) -> dt.datetime:
        """The UTC instant: in the name's offset, else in ``zone``."""
        tz = zone if self.utc_offset_min is None else dt.timezone(
            dt.timedelta(minutes=self.utc_offset_min))
        return self.wall_time.replace(tzinfo=tz).astimezone(dt.UTC)

    def source(self, zone: dt.tzinfo | None = None) -> str:
        """``timestamp_source`` of a time read from the name (``zone``: the place's, that a
        name without one is read in; None: there is none, UTC)."""
        if self.utc_offset_min is None:
            if zone is None:  # a bare latitude and longitude: no zone is known
                return ("file name (no zone in the name and none known for a bare latitude "
                        "and longitude: read as UTC; give a site, a zone in the name or the "
                        "timestamp)")
            return f"file name (no zone in the name: read in the place's zone, {zone})"
        sign = "-" if self.utc_offset_min < 0 else "+"
        hours, minutes = divmod(abs(self.utc_offset_min), 60)
        return f"file name (UTC{sign}{hours:02d}:{minutes:02d}, stated in the name)"


def _offset_min(sign: str, body: str, stated: str) -> int:
    """Minutes east of UTC of a sign and ``h``/``hh``, ``hh:mm``, ``hhmm`` or decimal hours;
    :class:`NameZoneError` for anything else, or beyond ±14 h."""
    minutes: float | None = None
    if re.fullmatch(r"\d{1,2}", body):
        minutes = 60 * int(body)
    elif m := re.fullmatch(r"(\d{1,2}):(\d{2})|(\d{2})(\d{2})", body):
        h, mm = (int(g) for g in (m.groups()[:2] if m.group(1) else m.groups()[2:]))
        minutes = 60 * h + mm if mm < 60 else None
    elif re.fullmatch(r"\d{1,2}\.\d+", body):
        value = float(body) * 60
        minutes = round(value) if abs(value - round(value)) < 1e-6 else None
    if minutes is None or minutes > _MAX_OFFSET_MIN or minutes % _OFFSET_STEP_MIN:
        raise NameZoneError(f"the zone {stated!r} in the file name is not a UTC offset this "
                            f"reader can read exactly (±h, ±hh:mm, ±hhmm or decimal hours "
                            f"such as UTCp5.5; at most 14 h, in quarter hours): send the "
                            f"frame's time")
    return int(minutes) * (-1 if sign.lower() in ("m", "-") else 1)


def time_from_name(name: str) -> NameTime | None:
    """The time in a file name (``Wettermast_20160615_093900UTCp1_….jpg``), or None when it
    has none, or its digits are not a calendar time (month 13, hour 25).

    Raises :class:`NameZoneError` when the name states a zone that cannot be read exactly
    (the module docstring): a silently truncated or ignored offset would put the sun
    where it was not."""
    m = _NAME_TIME.search(name)
    if m is None:
        return None
    try:
        year, month, day, hour, minute, second = (int(g) for g in m.groups())
        wall = dt.datetime(year, month, day, hour, minute, second)
    except ValueError:
        return None
    offsets: dict[str, int] = {}
    iso = _ISO_ZONE.match(name, m.end())
    if iso is not None:
        offsets[iso.group(0)] = 0 if iso.group(1) else _offset_min(iso.group(2), iso.group(3),
                                                                   iso.group(0))
    read_at = set()
    for z in _NAME_ZONE.finditer(name):
        read_at.add(z.start())
        offsets[z.group(0)] = 0 if z.group(1) is None else _offset_min(z.group(1), z.group(2),
                                                                       z.group(0))
    for t in _SIGNED.finditer(name):  # "UTC+05:30x": a signed zone the pattern did not read
        if t.start() not in read_at:
            raise NameZoneError(f"the zone at {name[t.start():t.start() + 10]!r} in the file "
                                f"name is not a UTC offset this reader can read (±h, ±hh:mm, "
                                f"±hhmm or decimal hours such as UTCp5.5): send the frame's "
                                f"time")
    rest = name[m.end():]
    for t in _ABBREVIATION.finditer(rest):  # "…_100600_CEST": a zone by name, not read
        raise NameZoneError(f"the zone {t.group(0)!r} in the file name is an abbreviation, "
                            f"which this reader does not read (abbreviations are ambiguous; "
                            f"write the offset, e.g. UTCp1 or UTC+02:00): send the frame's "
                            f"time")
    if iso is None and (plus := _BARE_PLUS.match(name, m.end())) is not None:
        raise NameZoneError(f"the zone {plus.group(0)!r} after the time in the file name is "
                            f"not a UTC offset this reader can read (±hh:mm, ±hhmm, or "
                            f"UTCp1): send the frame's time")
    if len(set(offsets.values())) > 1:
        raise NameZoneError(f"the file name states zones that disagree "
                            f"({', '.join(offsets)}): send the frame's time")
    return NameTime(wall, next(iter(offsets.values()), None))


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
    has neither a scale nor an image circle to derive one from, and (422 naming
    ``timestamp``) when no time is given and the name's zone cannot be read exactly.
    """
    derived = None
    if camera == "fisheye" and params.get("px_per_deg") in (None, ""):
        params, derived = derive_fisheye_scale(image, params)
    timestamp, source = frame_time(filename, timestamp, zone)
    return FrameInputs(params, derived, timestamp, source)


def frame_time(filename: str, timestamp: dt.datetime | None,
               zone: dt.tzinfo | None) -> tuple[dt.datetime | None, str | None]:
    """A frame's time and its ``timestamp_source``: ``timestamp`` when given (``"given"``),
    else the time in ``filename`` (:func:`time_from_name`, read in ``zone`` when the name
    states none; None: UTC), else ``(None, None)``. The rule of :func:`frame_inputs`, also
    ``heliotwin vision calibrate``'s for images given without ``--timestamps``.

    Raises :class:`backend.errors.InputError` (422 naming ``timestamp``) when the name's
    zone cannot be read exactly."""
    if timestamp is not None:
        return timestamp, "given"
    try:
        found = time_from_name(filename)
    except NameZoneError as exc:
        raise InputError(422, f"timestamp: {exc}") from None
    if found is None:
        return None, None
    return found.instant(zone or ZoneInfo("UTC")), found.source(zone)
