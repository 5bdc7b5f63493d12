"""Sites: location, climate defaults, tracker geometry and PV arrays (``data/sites/*.json``).

A site file uses units in its keys (``latitude_deg``, ``altitude_m``,
``temp_air_c``, ``surface_tilt_deg`` …); the :class:`Site` dataclass holds the
same values under pvlib glossary names. The built-in ``tehuantepec`` is seed
000's prototype (see ``../shared/reference/sites.json``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from sim.configs import read_config
from sim.dynamics import TrackerInertia
from sim.kinematics import TrackerGeometry
from sim.motors import AxisDrive
from sim.pv import ArrayConfig, array_config_from_dict

_TRACKER_KEYS = (
    "d1_m",
    "a2_m",
    "azimuth_min_deg",
    "azimuth_max_deg",
    "elevation_min_deg",
    "elevation_max_deg",
)


class UnknownSiteError(ValueError):
    """No site file with that id."""


def default_sites_dir() -> Path:
    """The repository's ``data/sites/`` (found relative to this package)."""
    return Path(__file__).resolve().parent.parent / "data" / "sites"


@dataclass(frozen=True)
class Site:
    """A site with a dual-axis tracker and its arrays.

    Parameters
    ----------
    site_id, name : str
    latitude, longitude : float
        [°], north and east positive.
    altitude : float
        [m] above sea level.
    timezone : str
        IANA zone for local display and bare dates.
    arrays : dict of str to ArrayConfig
        Usually ``"tracker"`` and ``"fixed"``.
    tracker : TrackerGeometry
    temp_air : float
        Air temperature used with clear-sky runs [°C].
    wind_speed : float
        Wind speed used with clear-sky runs [m s⁻¹].
    transposition_model : str
        ``"haydavies"`` (default), ``"perez"`` or ``"isotropic"``.
    drives : dict of str to AxisDrive
        ``"azimuth"`` and ``"elevation"``: each axis's DC motor and gearbox
        (:mod:`sim.motors`; the config's ``tracker.drives.<axis>`` overrides the
        defaults field by field, units in the names).
    inertia : TrackerInertia
        The two links' masses, inertias and centres of gravity (seed 002,
        Table 1 by default; the config's ``tracker.inertia`` overrides).
    """

    site_id: str
    name: str
    latitude: float
    longitude: float
    altitude: float
    timezone: str
    arrays: dict[str, ArrayConfig]
    tracker: TrackerGeometry = field(default_factory=TrackerGeometry)
    temp_air: float = 25.0
    wind_speed: float = 1.0
    transposition_model: str = "haydavies"
    drives: dict[str, AxisDrive] = field(default_factory=lambda: {
        "azimuth": AxisDrive.azimuth_default(), "elevation": AxisDrive.elevation_default()})
    inertia: TrackerInertia = field(default_factory=TrackerInertia.seed002)
    source: str = ""
    notes: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description with units in the keys."""
        return {
            "site_id": self.site_id,
            "name": self.name,
            "latitude_deg": self.latitude,
            "longitude_deg": self.longitude,
            "altitude_m": self.altitude,
            "timezone": self.timezone,
            "temp_air_c": self.temp_air,
            "wind_speed_m_s": self.wind_speed,
            "transposition_model": self.transposition_model,
            "tracker": {
                **{k: getattr(self.tracker, k) for k in _TRACKER_KEYS},
                "drives": {axis: dataclasses.asdict(d) for axis, d in self.drives.items()},
                "inertia": dataclasses.asdict(self.inertia),
            },
            "arrays": {name: arr.to_dict() for name, arr in self.arrays.items()},
            "source": self.source,
            "notes": self.notes,
        }


def site_from_dict(d: dict[str, Any], where: str = "site") -> Site:
    """Build a :class:`Site` from the layout of ``data/sites/*.json``; ValueError names the key."""
    try:
        site_id = str(d["site_id"])
        lat = float(d["latitude_deg"])
        lon = float(d["longitude_deg"])
        tz = str(d["timezone"])
    except KeyError as exc:
        raise ValueError(f"{where}: missing key {exc.args[0]!r}") from None
    if not -90 <= lat <= 90:
        raise ValueError(f"{where}: latitude_deg {lat} outside [-90, 90]")
    if not -180 <= lon <= 180:
        raise ValueError(f"{where}: longitude_deg {lon} outside [-180, 180]")
    try:
        ZoneInfo(tz)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValueError(f"{where}: timezone {tz!r} is not an IANA time zone") from None
    tracker_d = dict(d.get("tracker", {}))
    drives = _drives_from_dict(tracker_d.pop("drives", {}), where)
    inertia = _overrides(TrackerInertia.seed002(), tracker_d.pop("inertia", {}),
                         f"{where}: tracker.inertia")
    unknown = sorted(set(tracker_d) - set(_TRACKER_KEYS))
    if unknown:
        raise ValueError(f"{where}: tracker has unknown keys {unknown}")
    arrays = {
        name: array_config_from_dict(name, cfg) for name, cfg in (d.get("arrays") or {}).items()
    }
    return Site(
        site_id=site_id,
        name=str(d.get("name", site_id)),
        latitude=lat,
        longitude=lon,
        altitude=float(d.get("altitude_m", 0.0)),
        timezone=tz,
        arrays=arrays,
        tracker=TrackerGeometry(**{k: float(v) for k, v in tracker_d.items()}),
        temp_air=float(d.get("temp_air_c", 25.0)),
        wind_speed=float(d.get("wind_speed_m_s", 1.0)),
        transposition_model=str(d.get("transposition_model", "haydavies")),
        drives=drives,
        inertia=inertia,
        source=str(d.get("source", "")),
        notes=str(d.get("notes", "")),
    )


def _overrides(default: Any, values: Any, where: str) -> Any:
    """``default`` (a frozen dataclass) with the fields of ``values`` replaced; unknown or
    non-numeric fields and the dataclass's own checks are a ValueError naming them."""
    if not isinstance(values, dict):
        raise ValueError(f"{where}: must be an object of field: value")
    names = {f.name for f in dataclasses.fields(default)}
    unknown = sorted(set(values) - names)
    if unknown:
        raise ValueError(f"{where}: unknown keys {unknown}; known: {sorted(names)}")
    try:
        return dataclasses.replace(default, **{k: float(v) for k, v in values.items()})
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def _drives_from_dict(values: Any, where: str) -> dict[str, AxisDrive]:
    defaults = {"azimuth": AxisDrive.azimuth_default(), "elevation": AxisDrive.elevation_default()}
    if not isinstance(values, dict) or set(values) - set(defaults):
        raise ValueError(f"{where}: tracker.drives must be an object with 'azimuth' and/or "
                         "'elevation'")
    return {axis: _overrides(d, values.get(axis, {}), f"{where}: tracker.drives.{axis}")
            for axis, d in defaults.items()}


def load_site(site_id: str, sites_dir: str | Path | None = None) -> Site:
    """Read ``<sites_dir>/<site_id>.json`` (default: :func:`default_sites_dir`).

    Raises
    ------
    UnknownSiteError
        No such site (the message lists the known ids).
    ValueError
        The file is malformed (the message names the key).
    """
    directory = Path(sites_dir) if sites_dir is not None else default_sites_dir()
    path, data = read_config("site", site_id, directory, UnknownSiteError)
    site = site_from_dict(data, where=str(path))
    if site.site_id != site_id:
        raise ValueError(f"{path}: site_id {site.site_id!r} does not match the file name")
    return site


def list_sites(sites_dir: str | Path | None = None) -> list[Site]:
    """All sites in ``sites_dir`` (default: :func:`default_sites_dir`), sorted by id."""
    directory = Path(sites_dir) if sites_dir is not None else default_sites_dir()
    return [load_site(p.stem, directory) for p in sorted(directory.glob("*.json"))]
