"""The site config format (``sim/data/sites/*.json``): one pydantic model, the single definition.

:class:`SiteConfig` validates a site file and is the source of
``docs/site.schema.json`` (:func:`site_json_schema`; ``tests/sim/test_sites.py``
checks the shipped file is what the model generates). Every field's description
gives its unit, and where its default comes from; the defaults themselves are
read from the dataclasses that use them (:class:`sim.pv.ArrayConfig`,
:class:`sim.kinematics.TrackerGeometry`, :class:`sim.motors.AxisDrive`,
:class:`sim.dynamics.TrackerInertia`), so they are declared once.
:func:`validate_site_config` turns a validation failure into one ``ValueError``
that names every bad field by its dotted path (``arrays.fixed.surface_tilt_deg``).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import re
from typing import TYPE_CHECKING, Any, Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    create_model,
    field_validator,
)

from sim.array_shade import (
    FIXED_MOUNT_HEIGHT_M,
    MODULE_GAP_M,
    TRACKER_MOUNT_HEIGHT_M,
    module_size_m,
)
from sim.configs import CONFIG_ID
from sim.dynamics import TrackerInertia
from sim.kinematics import TrackerGeometry
from sim.motors import AxisDrive
from sim.pv import ArrayConfig, cec_module_parameters
from sim.stow import STOW_RELEASE_MAX_MIN, STOW_RELEASE_MIN, STOW_WIND_MAX_M_S

SCHEMA_ID = "https://heliotwin.example/docs/site.schema.json"
_ASSUMED_KEY = re.compile(r"^[a-z0-9_-]{1,64}(\.[a-z0-9_-]{1,64}){0,3}$")
_STRICT = ConfigDict(extra="forbid", allow_inf_nan=False)
_ARRAY = ArrayConfig(name="default")
#: The most DC losses a config's ``dc_loss_pct`` may give [%]: more is a fault to find, not
#: losses to model (the diagnosis's steady-shortfall advice stops there too)
MAX_DC_LOSS_PCT = 50.0
_GEOMETRY = TrackerGeometry()

#: AxisDrive field → (unit, what the default rests on); sim/motors.py has the reasoning.
_DRIVE_DOCS = {
    "supply_voltage_v": ("V", "motor bus; seed 000, section 2.4 (MD03 drivers at 24 V)"),
    "torque_constant_nm_a": ("N m A⁻¹", "motor k_t = k_e; assumption, a ~40 W 24 V motor"),
    "winding_resistance_ohm": ("Ω", "armature resistance; assumption"),
    "no_load_current_a": ("A", "current spinning unloaded; assumption"),
    "gear_ratio": ("-", "motor turns per output turn; assumption (worm train)"),
    "gear_efficiency": ("-", "forward gearbox efficiency in (0, 1]; assumption, single-start worm"),
    "max_output_torque_nm": ("N m", "gearbox output rating; assumption"),
    "max_output_speed_rad_s": ("rad s⁻¹", "output speed limit; the twin moves the axis no "
                               "faster than it or 0.05 (sim.tracking.DriveLimits); assumption"),
    "driver_efficiency": ("-", "H-bridge efficiency in (0, 1]; assumption"),
    "standby_power_w": ("W", "driver logic drawn all day; assumption (MD03 logic)"),
}
_INERTIA_DOCS = {
    "m1_kg": ("kg", "mass of link 1 (azimuth carriage)"),
    "m2_kg": ("kg", "mass of link 2 (elevation frame and panel)"),
    "i11_kg_m2": ("kg m²", "link 1 principal inertia along x1"),
    "i12_kg_m2": ("kg m²", "link 1 principal inertia along y1 (the azimuth axis)"),
    "i13_kg_m2": ("kg m²", "link 1 principal inertia along z1"),
    "i21_kg_m2": ("kg m²", "link 2 principal inertia along x2 (panel normal)"),
    "i22_kg_m2": ("kg m²", "link 2 principal inertia along y2"),
    "i23_kg_m2": ("kg m²", "link 2 principal inertia along z2 (the elevation axis)"),
    "cg1_m": ("m", "centre of gravity of link 1 along y1"),
    "cg2_m": ("m", "signed centre of gravity of link 2 along x2 from the elevation axis"),
    "g_m_s2": ("m s⁻²", "gravitational acceleration (seed 002, eq. 17)"),
}


def _dataclass_model(name: str, default: Any, docs: dict[str, tuple[str, str]],
                     source: str) -> type[BaseModel]:
    """A strict model whose fields and defaults are those of the dataclass ``default``."""
    fields: dict[str, Any] = {
        f.name: (float, Field(getattr(default, f.name), description=(
            f"[{docs[f.name][0]}] {docs[f.name][1]}. Default {getattr(default, f.name)} "
            f"({source}).")))
        for f in dataclasses.fields(default)}
    return create_model(name, __config__=_STRICT, **fields)


if TYPE_CHECKING:  # the classes below are built at run time from the dataclasses
    class AzimuthDrive(BaseModel): ...
    class ElevationDrive(BaseModel): ...
    class Inertia(BaseModel): ...
else:
    AzimuthDrive = _dataclass_model("AzimuthDrive", AxisDrive.azimuth_default(), _DRIVE_DOCS,
                                    "sim/motors.py AxisDrive.azimuth_default")
    ElevationDrive = _dataclass_model("ElevationDrive", AxisDrive.elevation_default(),
                                      _DRIVE_DOCS, "sim/motors.py AxisDrive.elevation_default")
    Inertia = _dataclass_model("Inertia", TrackerInertia.seed002(), _INERTIA_DOCS,
                               "seed 002, Table 1")


class Drives(BaseModel):
    """Each axis's DC motor and gearbox; a field left out keeps that axis's default."""

    model_config = _STRICT
    azimuth: AzimuthDrive = Field(default_factory=AzimuthDrive)
    elevation: ElevationDrive = Field(default_factory=ElevationDrive)


class Tracker(BaseModel):
    """Geometry and joint limits of the dual-axis tracker (seed 000 Table 2, seed 002)."""

    model_config = _STRICT
    d1_m: float = Field(_GEOMETRY.d1_m, ge=0, le=20, description=(
        f"[m] D–H offset of joint 1 along the azimuth axis. Default {_GEOMETRY.d1_m} "
        "(seed 002, section II-A: 355 mm)."))
    a2_m: float = Field(_GEOMETRY.a2_m, ge=0, le=20, description=(
        f"[m] D–H length from the elevation axis to the panel plane. Default {_GEOMETRY.a2_m} "
        "(seed 002, section II-A: 91 mm)."))
    azimuth_min_deg: float = Field(_GEOMETRY.azimuth_min_deg, ge=-720, le=720, description=(
        f"[°] lowest azimuth joint angle, clockwise from north. Default "
        f"{_GEOMETRY.azimuth_min_deg} (assumption: cable wrap of sim/kinematics.py)."))
    azimuth_max_deg: float = Field(_GEOMETRY.azimuth_max_deg, ge=-720, le=720, description=(
        f"[°] highest azimuth joint angle; may span more than 360°. Default "
        f"{_GEOMETRY.azimuth_max_deg} (assumption, sim/kinematics.py)."))
    elevation_min_deg: float = Field(_GEOMETRY.elevation_min_deg, ge=0, le=90, description=(
        f"[°] lowest elevation of the panel normal. Default {_GEOMETRY.elevation_min_deg} "
        "(assumption, sim/kinematics.py)."))
    elevation_max_deg: float = Field(_GEOMETRY.elevation_max_deg, ge=0, le=90, description=(
        f"[°] highest elevation of the panel normal. Default {_GEOMETRY.elevation_max_deg} "
        "(assumption, sim/kinematics.py)."))
    drives: Drives = Field(default_factory=Drives, description="Axis drives (sim/motors.py).")
    inertia: Inertia = Field(default_factory=Inertia,
                             description="Link masses and inertias (sim/dynamics.py).")
    # wind stow (sim/stow.py): only on runs whose weather has a wind speed
    stow_wind_speed_m_s: float | None = Field(None, gt=0, le=STOW_WIND_MAX_M_S, description=(
        "[m s⁻¹] the tracker stows flat (panel horizontal, the night stow's pose) while the "
        "weather's wind_speed exceeds this (a mean or a gust, as the weather file gives it); "
        "only runs on weather with a wind speed. Default none: it never stows for wind."))
    stow_release_min: float | None = Field(None, ge=0, le=STOW_RELEASE_MAX_MIN,
                                           validate_default=True,
                                           description=(
        "[min] after a stow the tracker tracks again once the wind has stayed at or below "
        f"stow_wind_speed_m_s this long. Default {STOW_RELEASE_MIN:g} (assumption, "
        "sim/stow.py). Only with stow_wind_speed_m_s."))

    @field_validator("stow_release_min")
    @classmethod
    def _stow_release(cls, value: float | None, info: ValidationInfo) -> float | None:
        if value is not None and info.data.get("stow_wind_speed_m_s") is None:
            raise ValueError("only used with stow_wind_speed_m_s")
        return value


class Array(BaseModel):
    """One PV array: identical modules in series/parallel on one mount (sim/pv.py)."""

    model_config = _STRICT
    mount: Literal["tracker", "fixed"] = Field(_ARRAY.mount, description=(  # type: ignore[arg-type]
        f"On the dual-axis tracker or at a fixed tilt. Default {_ARRAY.mount!r}."))
    module: str = Field(_ARRAY.module, description=(
        f"Module name in pvlib's CEC table. Default {_ARRAY.module!r} (seed 000, section 2.2)."))
    modules_in_series: int = Field(_ARRAY.modules_in_series, ge=1, le=1000, description=(
        f"[-] modules per string. Default {_ARRAY.modules_in_series} (seed 000's wiring, "
        "as read in sim/data/sites/tehuantepec.json)."))
    strings_in_parallel: int = Field(_ARRAY.strings_in_parallel, ge=1, le=1000, description=(
        f"[-] strings in parallel. Default {_ARRAY.strings_in_parallel} (seed 000: four modules "
        "per array)."))
    surface_tilt_deg: float = Field(_ARRAY.surface_tilt, ge=0, le=90, description=(
        f"[°] tilt of a fixed array from horizontal (ignored on a tracker). Default "
        f"{_ARRAY.surface_tilt}: set it (seed 000's fixed array: 16°)."))
    surface_azimuth_deg: float = Field(_ARRAY.surface_azimuth, ge=0, lt=360, description=(
        f"[°] azimuth a fixed array faces, clockwise from north. Default "
        f"{_ARRAY.surface_azimuth} (south)."))
    temperature_model: Literal["open_rack_glass_glass", "close_mount_glass_glass",
                               "open_rack_glass_polymer", "insulated_back_glass_polymer"] = Field(
        _ARRAY.temperature_model, description=(  # type: ignore[arg-type]
            "SAPM cell-temperature parameters, pvlib.temperature.TEMPERATURE_MODEL_PARAMETERS"
            f"['sapm']. Default {_ARRAY.temperature_model!r}."))
    albedo: float = Field(_ARRAY.albedo, ge=0, le=1, description=(
        f"[-] ground reflectance. Default {_ARRAY.albedo} (pvlib's default)."))
    dc_loss_pct: float = Field(_ARRAY.dc_loss_pct, ge=0, le=MAX_DC_LOSS_PCT, description=(
        "[%] the array's DC losses the model does not see: soiling, mismatch, wiring, the "
        "modules' nameplate tolerance, degradation (PVWatts' system losses: 14 % by default, "
        "inverter excluded). Its current is reduced by this share everywhere the array is "
        "modelled. Left out, a sensor's sky reads them as an underperformance every day and "
        "the fixed array's own sky reads too dim (a broken-cloud day's tracker expectation "
        "fell up to 11 %): set it from a clean, healthy week's performance ratio (1 − PR). "
        f"Default {_ARRAY.dc_loss_pct}: the ideal array."))
    inverter_limit_w: float | None = Field(None, gt=0, le=1e9, description=(
        "[W] the most power the array's inverter delivers (its AC rating where the logger "
        "reads AC power): the expected power is cut there, and the fixed array's readings "
        "at it give no sky (a clipped noon is no dim sky). A plant's DC/AC ratio of 1.1-1.4 "
        "clips a tracker on every clear day. Default none: no limit."))
    # where it stands: only for the tracker's shade on the fixed array (sim/array_shade.py)
    position_east_m: float | None = Field(None, ge=-100_000, le=100_000, description=(
        "[m] east of the site's origin (any ground point, the same for every array): a "
        "tracker's pedestal foot (its azimuth axis on the ground), a fixed array's ground "
        "point below its collector's centre. Default none: with no position on 'tracker' "
        "and 'fixed' the twin computes no mutual shading."))
    position_north_m: float | None = Field(None, ge=-100_000, le=100_000,
                                           validate_default=True, description=(
        "[m] north of the site's origin; given with position_east_m. Default none."))
    mount_height_m: float | None = Field(None, ge=0, le=100, validate_default=True,
                                         description=(
        "[m] a tracker's D–H base frame {0} (top of its pedestal) above the ground, default "
        f"{TRACKER_MOUNT_HEIGHT_M}; a fixed array's lower edge above the ground, default "
        f"{FIXED_MOUNT_HEIGHT_M} (assumptions: seed 000 gives neither). Only with a position."))
    width_m: float | None = Field(None, gt=0, le=1000, validate_default=True, description=(
        "[m] the collector's horizontal edge (a tracker's along its elevation axis). Default "
        "from the modules: landscape, ceil(sqrt(N)) across, the module's Length x Width from "
        f"pvlib's CEC table, {MODULE_GAP_M} m gaps (4 KD205GX-LP: 3.02 m); required for a "
        "module the table gives no size. Only with a position."))
    height_m: float | None = Field(None, gt=0, le=1000, validate_default=True, description=(
        "[m] the collector's other edge (up its slope). Default from the modules as width_m "
        "(4 KD205GX-LP: 2.00 m). Only with a position."))

    @field_validator("module")
    @classmethod
    def _known_module(cls, value: str) -> str:
        cec_module_parameters(value)  # ValueError: not in the table
        return value

    @field_validator("position_north_m", "mount_height_m", "width_m", "height_m")
    @classmethod
    def _placement(cls, value: float | None, info: ValidationInfo) -> float | None:
        east, north = info.data.get("position_east_m"), info.data.get("position_north_m")
        if info.field_name == "position_north_m":
            if "position_east_m" in info.data and (east is None) != (value is None):
                raise ValueError("give position_east_m and position_north_m together")
            return value
        if value is not None and (east is None or north is None):
            raise ValueError("only used with position_east_m and position_north_m")
        if (info.field_name == "height_m" and north is not None
                and (value is None) != (info.data.get("width_m") is None)):
            raise ValueError("give width_m and height_m together")
        if (info.field_name == "width_m" and north is not None and value is None
                and "module" in info.data and module_size_m(info.data["module"]) is None):
            raise ValueError(f"module {info.data['module']!r} has no size in pvlib's CEC "
                             "table: give width_m and height_m")
        return value


@functools.cache
def _iana_zone_names() -> frozenset[str]:
    """The tz database's zone names, as the ``tzdata`` package lists them."""
    return frozenset(importlib.resources.files("tzdata").joinpath("zones").read_text().split())


def check_iana_zone(name: str) -> str:
    """``name`` if it names a zone of the IANA tz database (``Europe/Berlin``, ``Etc/GMT+5``,
    ``UTC``), else ValueError. A machine's zoneinfo folder also answers ``localtime`` (a
    link to its own zone: a site's days would move with the machine); the ``tzdata``
    package's list is the database's names. The one rule of sites, plants and sweeps."""
    if name not in _iana_zone_names():
        raise ValueError(f"{name!r} is not an IANA time zone (e.g. Europe/Berlin, Etc/GMT+5)")
    try:
        ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValueError(f"{name!r} is not an IANA time zone this machine can read") from None
    return name


def fixed_tilt_from_latitude_deg(latitude_deg: float) -> float:
    """Tilt [°] of a fixed array for the most yearly energy, from the latitude alone.

    C. R. Landau's rule of thumb (solarpaneltilt.com, "Optimum tilt of solar panels"),
    as GSEE implements it (``gsee.pv.optimal_tilt``; Pfenninger & Staffell, Energy 114
    (2016) 1251–1265, doi:10.1016/j.energy.2016.08.060): 0.87 |φ| up to |φ| = 25°,
    0.76 |φ| + 3.1° up to 50°, and 40° beyond (where the rule was not fitted). Facing
    the equator (:func:`equator_azimuth_deg`). The one rule of a site's fixed arrays
    (:func:`sim.sites.place_defaults`) and a plant's fixed comparison plant
    (:func:`sim.plant.layout.plant_from_dict`). A rule, not a site survey: a site's config
    marks it as assumed.
    """
    lat = abs(float(latitude_deg))
    if lat <= 25.0:
        return round(0.87 * lat, 1)
    if lat <= 50.0:
        return round(0.76 * lat + 3.1, 1)
    return 40.0


def equator_azimuth_deg(latitude_deg: float) -> float:
    """Azimuth [°, clockwise from north] facing the equator: 180° (south) on the equator and
    north of it, 0° (north) south of it — where a fixed array faces and a tracker's azimuth
    range is centred when a config does not say (a site's arrays, a plant's fixed
    comparison plant: a southern plant's had faced the pole)."""
    return 180.0 if latitude_deg >= 0 else 0.0


#: The heights [m] a place may have (the Dead Sea shore to above any plant): a site's, a
#: plant file's and a sweep's ``altitude_m`` (a sweep at 99,999 m had run, its energy negative).
ALTITUDE_MIN_M, ALTITUDE_MAX_M = -500.0, 9000.0


#: A clock (a weather file's UTC offset, a site's zone in standard time) this far from its
#: place's mean solar time (longitude / 15° h⁻¹) [h] is most likely a mistake: a sign slip
#: (Alice Springs' +9.5 written −9.5) or another place's zone (Europe/Berlin at 133.9° E put
#: the clear-sky noon at 04:08). Real zones stray up to about 3 h (western China, Spain).
MAX_CLOCK_OFF_LONGITUDE_H = 3.0


def clock_off_longitude(offset_h: float, longitude_deg: float, what: str) -> str | None:
    """A sentence when ``offset_h`` (a UTC offset [h]) is more than
    :data:`MAX_CLOCK_OFF_LONGITUDE_H` from ``longitude_deg`` / 15, naming both numbers
    (``what`` names the clock); None otherwise. The difference is taken across the date
    line (Samoa's +13 h at 171.8° W is 0.5 h off, not 24.5 h). UTC itself (0 h) is named as
    a likely cause: weather written in UTC far from Greenwich (an EPW at Delhi)."""
    solar_h = longitude_deg / 15.0
    off_h = (offset_h - solar_h + 12.0) % 24.0 - 12.0
    if abs(off_h) <= MAX_CLOCK_OFF_LONGITUDE_H:
        return None
    noon_min = round((12.0 + off_h) % 24.0 * 60.0)
    return (f"{what} UTC{offset_h:+g} h is {abs(off_h):.1f} h from the longitude's "
            f"{longitude_deg:.1f}° / 15 = {solar_h:+.1f} h (more than "
            f"{MAX_CLOCK_OFF_LONGITUDE_H:g} h): the sun would culminate near "
            f"{noon_min // 60:02d}:{noon_min % 60:02d} on its clock — a sign slip, "
            + ("another place's zone, or a file written in UTC?" if offset_h == 0
               else "or another place's zone?"))


def standard_offset_h(zone: str) -> float:
    """A zone's standard-time UTC offset [h]: the lesser of its January and July offsets
    (2024), whichever hemisphere keeps summer time."""
    import datetime as dt

    tz = ZoneInfo(zone)
    return min((dt.datetime(2024, m, 15, tzinfo=tz).utcoffset() or dt.timedelta()
                ).total_seconds() / 3600.0 for m in (1, 7))


def site_zone_warning(config: dict[str, Any]) -> str | None:
    """:func:`clock_off_longitude` of a site config's zone (in standard time), or None."""
    try:
        zone, lon = str(config["timezone"]), float(config["longitude_deg"])
        offset = standard_offset_h(zone)
    except (KeyError, TypeError, ValueError, ZoneInfoNotFoundError):
        return None
    found = clock_off_longitude(offset, lon, f"timezone {zone}")
    return None if found is None else f"timezone: {found} Check the site's timezone."


class SiteConfig(BaseModel):
    """A heliotwin site: a place, its climate defaults, a dual-axis tracker and its PV arrays.

    Keys carry their unit (``latitude_deg``, ``altitude_m``); ``sim.sites.Site``
    holds the same values under pvlib's names.
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, populate_by_name=True,
                              json_schema_extra={"$id": SCHEMA_ID})
    schema_ref: str | None = Field(None, alias="$schema",
                                   description="Optional link to this schema, for editors.")
    site_id: str = Field(pattern=CONFIG_ID.pattern, description=(
        "Id: lower-case letters, digits, '_' and '-', at most 64; the file is <site_id>.json."))
    name: str | None = Field(None, max_length=200,
                             description="Name shown on the dashboard. Default: the site_id.")
    latitude_deg: float = Field(ge=-90, le=90, description="[°] latitude, north positive.")
    longitude_deg: float = Field(ge=-180, le=180, description="[°] longitude, east positive.")
    altitude_m: float = Field(0.0, ge=ALTITUDE_MIN_M, le=ALTITUDE_MAX_M, description=(
        "[m] height above sea level (air mass, pressure). Default 0."))
    timezone: str = Field(description=(
        "IANA time zone of the site (America/Mexico_City, Etc/GMT+5): local days and display."))
    temp_air_c: float = Field(25.0, ge=-60, le=60, description=(
        "[°C] air temperature of clear-sky runs. Default 25 (assumption)."))
    wind_speed_m_s: float = Field(1.0, ge=0, le=60, description=(
        "[m s⁻¹] wind speed of clear-sky runs. Default 1 (assumption)."))
    transposition_model: Literal["haydavies", "perez", "isotropic"] = Field(
        "haydavies", description="pvlib POA transposition model. Default 'haydavies'.")
    readings_stamped: Literal["instant", "interval_end", "interval_start"] = Field(
        "instant", description=(
            "What the loggers' timestamps mark: the instant of the value, or the end or the "
            "start of the interval a value averages (a logger storing hourly means at the "
            "end of each hour: 'interval_end'). The diagnosis matches each reading to the "
            "sun at its interval's middle. Default 'instant'."))
    tracker: Tracker = Field(default_factory=Tracker,  # type: ignore[arg-type]
                             description="The dual-axis tracker.")
    arrays: dict[str, Array] = Field(default_factory=dict, description=(
        "PV arrays by name; the twin simulates a site with arrays named 'tracker' (mount "
        "'tracker') and 'fixed' (mount 'fixed'). None: a camera-only site."))
    source: str = Field("", description="Where the values come from (paper, survey, station).")
    notes: str = Field("", description="Assumptions and remarks.")
    assumed: dict[str, str] = Field(default_factory=dict, description=(
        "Keys (dotted paths, e.g. 'temp_air_c', 'arrays.fixed.surface_tilt_deg') whose values "
        "were not given for this site but filled in from its place when it was created "
        "(sim.sites.place_defaults), each with the rule or default it follows: check them. "
        "Changing such a value through PUT /api/v1/sites/{site_id} drops its mark. Default "
        "none."))

    @field_validator("timezone")
    @classmethod
    def _iana_zone(cls, value: str) -> str:
        return check_iana_zone(value)

    @field_validator("assumed")
    @classmethod
    def _assumed_keys(cls, value: dict[str, str]) -> dict[str, str]:
        bad = [k for k in value if not _ASSUMED_KEY.match(k)]
        if bad:
            raise ValueError(f"keys {bad} are not dotted config paths")
        return value

    @field_validator("arrays")
    @classmethod
    def _array_names(cls, value: dict[str, Array]) -> dict[str, Array]:
        bad = [name for name in value if not CONFIG_ID.match(name)]
        if bad:
            raise ValueError(f"array names {bad} must be lower-case letters, digits, '_' or '-'")
        placed = {name for name in ("tracker", "fixed")
                  if name in value and value[name].position_east_m is not None}
        if len(placed) == 1 and {"tracker", "fixed"} <= set(value):
            other = ({"tracker", "fixed"} - placed).pop()
            raise ValueError(f"arrays.{other}.position_east_m/position_north_m: needed as "
                             f"arrays.{placed.pop()} has a position (the tracker's shade on "
                             "the fixed array needs both)")
        return value


def _where(loc: tuple[int | str, ...]) -> str:
    return ".".join(str(p) for p in loc) or "(top level)"


def _clip(text: str, limit: int = 200) -> str:
    """``text`` cut to ``limit`` characters: a problem's key or message may echo what was
    sent (a 10 MB time zone name had come back whole in the 422)."""
    return text if len(text) <= limit else text[:limit - 1] + "…"


def _control_characters(value: Any, path: str = "") -> str | None:
    """The dotted path of the first string (key or value) holding a control character other
    than a tab or a line end (U+0000–U+001F but those, U+007F), None when there is none:
    PostgreSQL refuses a NUL in text, and a config it refused made the service unable to
    start; a note may span lines."""
    if isinstance(value, str):
        return path if any((ord(c) < 32 and c not in "\t\n\r") or ord(c) == 127
                           for c in value) else None
    items = value.items() if isinstance(value, dict) else (
        enumerate(value) if isinstance(value, list) else ())
    for key, item in items:
        here = f"{path}.{key}" if path else str(key)
        if isinstance(key, str) and _control_characters(key) is not None:
            return here
        if (found := _control_characters(item, here)) is not None:
            return found
    return None


def validate_site_config(data: Any, where: str = "site") -> SiteConfig:
    """``data`` as a :class:`SiteConfig`; ValueError naming each bad field otherwise."""
    if not isinstance(data, dict):
        raise ValueError(f"{where}: a site config must be a JSON object")
    if (path := _control_characters(data)) is not None:
        raise ValueError(f"{where}: {path}: holds a control character (a NUL, an escape…); "
                         "write it without")
    try:
        # strict throughout: `"latitude_deg": true` had moved a site to 1° (a tester's
        # finding); a number is a JSON number, an integer where a float is asked included
        return SiteConfig.model_validate(data, strict=True)
    except ValidationError as exc:
        problems = []
        for err in exc.errors()[:10]:
            msg = "unknown key (docs/site.schema.json lists the keys)" if (
                err["type"] == "extra_forbidden") else err["msg"].removeprefix("Value error, ")
            problems.append(f"{_clip(_where(err['loc']))}: {_clip(msg)}")
        raise ValueError(f"{where}: " + "; ".join(problems)) from None


def site_json_schema() -> dict[str, Any]:
    """The JSON Schema of a site file (shipped as ``docs/site.schema.json``)."""
    schema = SiteConfig.model_json_schema(by_alias=True)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}
