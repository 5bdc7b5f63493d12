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
from sim.site_config import (
    equator_azimuth_deg,
    fixed_tilt_from_latitude_deg,
    validate_site_config,
)
from sim.stow import STOW_RELEASE_MIN, WindStow

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
    wind_stow : WindStow, optional
        The tracker's wind stow (:mod:`sim.stow`; config ``tracker.stow_wind_speed_m_s``,
        ``tracker.stow_release_min``); None, the default: it never stows for wind.
    placements : dict of str to Placement
        Where the arrays that have a configured position stand
        (:class:`sim.array_shade.Placement`); with ``tracker`` and ``fixed`` placed, the
        twin computes the tracker's shade on the fixed array. Empty by default.
    assumed : dict of str to str
        Config keys filled in from the place when the site was made (:func:`place_defaults`),
        each with the rule or default it follows.
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
    readings_stamped: str = "instant"  # sim.energy.READING_STAMPS
    drives: dict[str, AxisDrive] = field(default_factory=lambda: {
        "azimuth": AxisDrive.azimuth_default(), "elevation": AxisDrive.elevation_default()})
    inertia: TrackerInertia = field(default_factory=TrackerInertia.seed002)
    wind_stow: WindStow | None = None
    placements: dict[str, Placement] = field(default_factory=dict)
    source: str = ""
    notes: str = ""
    assumed: dict[str, str] = field(default_factory=dict)

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
            # only when set: the configs stored before the key are unchanged by it (a
            # changed config drops the site's cached twin, backend.sites.sync_sites)
            **({"readings_stamped": self.readings_stamped}
               if self.readings_stamped != "instant" else {}),
            "tracker": {
                **{k: getattr(self.tracker, k) for k in _TRACKER_KEYS},
                "drives": {axis: dataclasses.asdict(d) for axis, d in self.drives.items()},
                "inertia": dataclasses.asdict(self.inertia),
                # only when set: the configs stored before the keys are unchanged by them
                **({} if self.wind_stow is None else {
                    "stow_wind_speed_m_s": self.wind_stow.wind_speed_m_s,
                    "stow_release_min": self.wind_stow.release_min}),
            },
            "arrays": {name: {**arr.to_dict(), **self._placement(name)}
                       for name, arr in self.arrays.items()},
            "source": self.source,
            "notes": self.notes,
            # only when there is one: an unchanged site's stored config stays byte-identical
            **({"assumed": dict(self.assumed)} if self.assumed else {}),
        }

    def _placement(self, array: str) -> dict[str, float]:
        """The configured placement keys of ``array`` (none when it has no position)."""
        p = self.placements.get(array)
        return {} if p is None else {
            k: v for k, v in dataclasses.asdict(p).items() if v is not None}

    def gain_ratings_w(self, tracker: str | None = "tracker", fixed: str | None = "fixed"
                       ) -> tuple[float, float] | None:
        """The STC ratings [W] of the two arrays a tracking gain compares
        (:func:`sim.energy.gain_pct`), None unless the config holds both."""
        if tracker not in self.arrays or fixed not in self.arrays:
            return None
        return self.arrays[tracker].stc_power_w, self.arrays[fixed].stc_power_w

    def to_config(self) -> dict[str, Any]:
        """The site as a config file (:class:`sim.site_config.SiteConfig`): what
        :func:`site_from_dict` reads back to an equal :class:`Site`."""
        arrays = {name: {**arr.to_config(), **self._placement(name)}
                  for name, arr in self.arrays.items()}
        return {**self.to_dict(), "arrays": arrays}


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
        wind_stow = None if t.stow_wind_speed_m_s is None else WindStow(
            t.stow_wind_speed_m_s,
            STOW_RELEASE_MIN if t.stow_release_min is None else t.stow_release_min)
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
        readings_stamped=cfg.readings_stamped,
        drives=drives,
        inertia=inertia,
        wind_stow=wind_stow,
        placements=placements,
        source=cfg.source,
        notes=cfg.notes,
        assumed=dict(cfg.assumed),
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


#: Config keys a site's place decides: a new site takes them from its place
#: (:func:`place_defaults`), never from the site it was copied from.
CLIMATE_KEYS = ("temp_air_c", "wind_speed_m_s")
FIXED_SURFACE_KEYS = ("surface_tilt_deg", "surface_azimuth_deg")
#: The tracker's azimuth joint range: its span is the machine's (cable wrap), its centre
#: the place's (:func:`tracker_azimuth_range_deg`).
TRACKER_PLACE_KEYS = ("azimuth_min_deg", "azimuth_max_deg")
_AZIMUTH_JOINT_BOUND_DEG = 720.0  # the site format's limit (sim.site_config.Tracker)


def tracker_azimuth_range_deg(latitude_deg: float,
                              span_deg: float | None = None) -> tuple[float, float]:
    """Azimuth joint limits [°] of a tracker at ``latitude_deg``: ``span_deg`` (default
    :class:`sim.kinematics.TrackerGeometry`'s 540°) centred on the equator-facing direction
    (180° north of the equator, 0° south of it), within the format's ±720°.

    The twin sweeps each day around the side of its noon sun
    (:func:`sim.control.noon_reference_azimuth`). On a day whose noon sun is on the
    equator side the sun stays within ±180° of it; in the tropics, on a day whose noon sun
    is on the pole side, within ±90° of the pole. 540° centred on the equator side holds
    both, so no day's sun path needs an unwind while the sun is up; under a midnight sun
    the one unwind per day falls at the lowest sun, towards the pole. A range centred on
    the wrong side (a northern tracker copied south) unwinds in the afternoon.
    """
    geometry = TrackerGeometry()
    span = (geometry.azimuth_max_deg - geometry.azimuth_min_deg
            if span_deg is None else float(span_deg))
    centre = equator_azimuth_deg(latitude_deg)
    return (max(centre - span / 2.0, -_AZIMUTH_JOINT_BOUND_DEG),
            min(centre + span / 2.0, _AZIMUTH_JOINT_BOUND_DEG))


def altitude_at_m(latitude_deg: float, longitude_deg: float) -> float:
    """The ground's height at a place [m]: ``pvlib.location.lookup_altitude`` (the terrain
    table pvlib ships, no network), clipped to the site format's −500…9,000 m."""
    from pvlib.location import lookup_altitude

    return float(min(max(lookup_altitude(latitude_deg, longitude_deg), -500.0), 9000.0))


def place_defaults(config: dict[str, Any], climate: dict[str, float] | None = None,
                   climate_source: str = "",
                   azimuth_span_deg: float | None = None) -> dict[str, Any]:
    """``config`` with what its place decides filled in where it is left out, each marked.

    A fixed array without ``surface_tilt_deg`` gets :func:`fixed_tilt_from_latitude_deg`,
    without ``surface_azimuth_deg`` the equator (180° north of it, 0° south); a site with a
    tracker array whose ``tracker`` gives neither of :data:`TRACKER_PLACE_KEYS` gets
    :func:`tracker_azimuth_range_deg` (``azimuth_span_deg`` wide, default 540°); a config
    without ``altitude_m`` the ground's height there (:func:`altitude_at_m`), a config
    without ``temp_air_c``/``wind_speed_m_s`` gets ``climate``'s values (a weather file's
    annual means, named by ``climate_source``) or the defaults the site format states
    (:class:`sim.site_config.SiteConfig`). Each filled key is listed in ``assumed`` with
    its rule; a key the config gives is left alone. A config without a numeric
    ``latitude_deg``, or whose ``assumed`` is not an object, is returned unchanged (its
    validation names the field).
    """
    from sim.site_config import Array, SiteConfig

    lat = config.get("latitude_deg")
    marks = config.get("assumed") or {}
    if not isinstance(lat, int | float) or isinstance(lat, bool) or not isinstance(marks, dict):
        return config
    out = {**config}
    assumed = dict(marks)
    lon = config.get("longitude_deg")
    if ("altitude_m" not in out and isinstance(lon, int | float) and not isinstance(lon, bool)
            and -90 <= lat <= 90 and -180 <= lon <= 180):  # else validation names it
        # 0 m had been taken silently: 13 % of a clear day's energy at La Paz (3,640 m)
        out["altitude_m"] = altitude_at_m(lat, lon)
        assumed["altitude_m"] = (f"pvlib.location.lookup_altitude at ({lat:g}°, {lon:g}°): "
                                 "a terrain grid of about 2 km (ships with pvlib): set the "
                                 "site's own height")
    for key in CLIMATE_KEYS:
        if key in out:
            continue
        if climate is not None and key in climate:
            out[key], assumed[key] = climate[key], f"annual mean of {climate_source}"
        else:
            out[key] = SiteConfig.model_fields[key].default
            assumed[key] = (f"the site format's default {out[key]:g} (sim/site_config.py), "
                            "no weather file given: set the site's own value")
    arrays = out.get("arrays")
    if isinstance(arrays, dict):
        out["arrays"] = arrays = {**arrays}
        default_mount = Array.model_fields["mount"].default
        for name, arr in arrays.items():
            if not isinstance(arr, dict) or arr.get("mount", default_mount) != "fixed":
                continue
            arrays[name] = arr = {**arr}
            if "surface_tilt_deg" not in arr:
                arr["surface_tilt_deg"] = fixed_tilt_from_latitude_deg(lat)
                assumed[f"arrays.{name}.surface_tilt_deg"] = (
                    f"from latitude {lat:g}°: Landau's rule as GSEE's optimal_tilt "
                    "(sim.sites.fixed_tilt_from_latitude_deg)")
            if "surface_azimuth_deg" not in arr:
                arr["surface_azimuth_deg"] = equator_azimuth_deg(lat)
                assumed[f"arrays.{name}.surface_azimuth_deg"] = "facing the equator"
        tracker = out.get("tracker", {})
        has_tracker = any(isinstance(a, dict) and a.get("mount", default_mount) == "tracker"
                          for a in arrays.values())
        if (has_tracker and isinstance(tracker, dict)
                and not any(k in tracker for k in TRACKER_PLACE_KEYS)):
            lo, hi = tracker_azimuth_range_deg(lat, azimuth_span_deg)
            out["tracker"] = {**tracker, "azimuth_min_deg": lo, "azimuth_max_deg": hi}
            # beyond a polar circle the midnight sun goes round the whole sky each day: no
            # finite range follows it, the tracker unwinds once a day (a tester's finding)
            unwind = ("every day's sun path without an unwind in daylight" if abs(lat) < 66.5
                      else "under the midnight sun, which goes round the sky each day, one "
                           "unwind a day at its lowest")
            why = (f"{hi - lo:g}° of azimuth centred on the equator side "
                   f"({'south' if lat >= 0 else 'north'}) at latitude {lat:g}°: {unwind} "
                   "(sim.sites.tracker_azimuth_range_deg)")
            for key in TRACKER_PLACE_KEYS:
                assumed[f"tracker.{key}"] = why
    if assumed:
        out["assumed"] = assumed
    return out


def relocated_config(template: dict[str, Any], place: dict[str, Any],
                     climate: dict[str, float] | None = None,
                     climate_source: str = "") -> dict[str, Any]:
    """A config at a new place from ``template`` (a site's :meth:`Site.to_config`): its
    tracker and arrays kept, what its place decided (:data:`CLIMATE_KEYS`, fixed arrays'
    :data:`FIXED_SURFACE_KEYS`, the tracker's :data:`TRACKER_PLACE_KEYS`, its ``assumed``
    marks) dropped and taken from the new place (:func:`place_defaults`; the tracker keeps
    its azimuth span, centred anew); ``place`` sets ``site_id``, ``latitude_deg`` … ."""
    out = {k: v for k, v in template.items()
           if k not in (*CLIMATE_KEYS, "altitude_m", "assumed")}
    out["arrays"] = {name: ({k: v for k, v in arr.items() if k not in FIXED_SURFACE_KEYS}
                            if arr.get("mount") == "fixed" else dict(arr))
                     for name, arr in template.get("arrays", {}).items()}
    tracker = template.get("tracker", {})
    span = None
    if all(k in tracker for k in TRACKER_PLACE_KEYS):
        span = float(tracker["azimuth_max_deg"]) - float(tracker["azimuth_min_deg"])
    out["tracker"] = {k: v for k, v in tracker.items() if k not in TRACKER_PLACE_KEYS}
    return place_defaults({**out, **place}, climate, climate_source, azimuth_span_deg=span)
