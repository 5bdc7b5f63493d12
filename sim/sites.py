"""Sites: location, climate defaults, tracker geometry and PV arrays (``sim/data/sites/*.json``).

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

from sim.array_shade import PLACEMENT_KEYS, Placement
from sim.configs import read_config
from sim.dynamics import TrackerInertia
from sim.kinematics import TrackerGeometry
from sim.motors import AxisDrive
from sim.paths import default_sites_dir, default_user_sites_dir
from sim.pv import ArrayConfig, array_config_from_dict
from sim.site_config import validate_site_config

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
    placements : dict of str to Placement
        Where the arrays that have a configured position stand
        (:class:`sim.array_shade.Placement`); with ``tracker`` and ``fixed`` placed, the
        twin computes the tracker's shade on the fixed array. Empty by default.
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
    placements: dict[str, Placement] = field(default_factory=dict)
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
            "arrays": {name: {**arr.to_dict(), **self._placement(name)}
                       for name, arr in self.arrays.items()},
            "source": self.source,
            "notes": self.notes,
        }

    def _placement(self, array: str) -> dict[str, float]:
        """The configured placement keys of ``array`` (none when it has no position)."""
        p = self.placements.get(array)
        return {} if p is None else {
            k: v for k, v in dataclasses.asdict(p).items() if v is not None}

    def to_config(self) -> dict[str, Any]:
        """The site as a config file (:class:`sim.site_config.SiteConfig`): what
        :func:`site_from_dict` reads back to an equal :class:`Site`."""
        d = self.to_dict()
        keys = ("mount", "module", "modules_in_series", "strings_in_parallel",
                "surface_tilt_deg", "surface_azimuth_deg", "temperature_model", "albedo")
        arrays = {}
        for name, arr in self.arrays.items():
            a = dataclasses.asdict(arr)
            a["surface_tilt_deg"], a["surface_azimuth_deg"] = arr.surface_tilt, arr.surface_azimuth
            arrays[name] = {**{k: a[k] for k in keys}, **self._placement(name)}
        return {**d, "arrays": arrays}


def site_from_dict(d: dict[str, Any], where: str = "site") -> Site:
    """Build a :class:`Site` from the layout of ``sim/data/sites/*.json``.

    The layout is :class:`sim.site_config.SiteConfig` (``docs/site.schema.json``);
    a ValueError names every bad field by its dotted path.
    """
    cfg = validate_site_config(d, where)
    t = cfg.tracker
    try:
        tracker = TrackerGeometry(**{k: getattr(t, k) for k in _TRACKER_KEYS})
        drives = {"azimuth": AxisDrive(**t.drives.azimuth.model_dump()),
                  "elevation": AxisDrive(**t.drives.elevation.model_dump())}
        inertia = TrackerInertia(**t.inertia.model_dump())
        arrays = {name: array_config_from_dict(name, a.model_dump(exclude=set(PLACEMENT_KEYS)))
                  for name, a in cfg.arrays.items()}
        placements = {name: Placement(**a.model_dump(include=set(PLACEMENT_KEYS)))
                      for name, a in cfg.arrays.items() if a.position_east_m is not None}
    except ValueError as exc:
        raise ValueError(f"{where}: tracker: {exc}") from None
    return Site(
        site_id=cfg.site_id,
        name=cfg.name or cfg.site_id,
        latitude=cfg.latitude_deg,
        longitude=cfg.longitude_deg,
        altitude=cfg.altitude_m,
        timezone=cfg.timezone,
        arrays=arrays,
        tracker=tracker,
        temp_air=cfg.temp_air_c,
        wind_speed=cfg.wind_speed_m_s,
        transposition_model=cfg.transposition_model,
        drives=drives,
        inertia=inertia,
        placements=placements,
        source=cfg.source,
        notes=cfg.notes,
    )


def _dirs(sites_dir: str | Path | None) -> list[Path]:
    """Where sites are looked up, first match winning: the user's folder (default
    :func:`default_user_sites_dir`), then the built-ins."""
    builtin = default_sites_dir()
    user = default_user_sites_dir() if sites_dir is None else Path(sites_dir)
    return [builtin] if user.resolve() == builtin else [user, builtin]


def site_path(site_id: str, sites_dir: str | Path | None = None) -> Path:
    """The file :func:`load_site` reads for ``site_id`` (UnknownSiteError when none)."""
    return read_config("site", site_id, _dirs(sites_dir), UnknownSiteError)[0]


def builtin_site_ids() -> set[str]:
    """Ids of the built-in sites (``sim/data/sites/``)."""
    return {p.stem for p in default_sites_dir().glob("*.json")}


def is_builtin(path: Path) -> bool:
    """Whether a site file is one of the built-in sites."""
    return path.resolve().parent == default_sites_dir()


def load_site(site_id: str, sites_dir: str | Path | None = None) -> Site:
    """Read ``<site_id>.json`` from ``sites_dir`` (a user's folder) or the built-in sites.

    ``sites_dir`` (default :func:`default_user_sites_dir`) adds to
    :func:`default_sites_dir`: a user file with the id of a built-in site replaces
    the built-in one.

    Raises
    ------
    UnknownSiteError
        No such site (the message lists the known ids).
    ValueError
        The file is malformed (the message names the field).
    """
    path, data = read_config("site", site_id, _dirs(sites_dir), UnknownSiteError)
    site = site_from_dict(data, where=str(path))
    if site.site_id != site_id:
        raise ValueError(f"{path}: site_id {site.site_id!r} does not match the file name")
    return site


def site_ids(sites_dir: str | Path | None = None) -> list[str]:
    """Ids of the built-in sites and those of ``sites_dir``, sorted."""
    return sorted({p.stem for d in _dirs(sites_dir) if d.is_dir() for p in d.glob("*.json")})


def list_sites(sites_dir: str | Path | None = None) -> list[Site]:
    """The built-in sites and those of ``sites_dir`` (which win on a shared id), by id."""
    return [load_site(site_id, sites_dir) for site_id in site_ids(sites_dir)]
