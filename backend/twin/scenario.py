"""A twin scenario: what ``heliotwin simulate`` and ``POST /api/v1/simulations`` both run.

One table (:data:`backend.twin.parameters.MACHINE_PARAMETERS`) declares the
machine's parameters beyond site, range and step — the controller's
disturbances and the receiver — with their units, defaults and bounds; the CLI
builds its flags from it and the HTTP schema its fields, so the two never
drift apart. :func:`run_scenario` is the one call into ``sim.twin.simulate``.

Weather: a scenario may carry a typical year (TMY3, EPW, PVGIS or NSRDB, read by
:func:`sim.sky.read_typical_year`); :func:`run_scenario` lays it onto the run's
calendar at the site (:func:`sim.sky.typical_year_at_site`). :func:`check_station` is the one
rule for a station far from the site: refused unless forced. Or measured weather
(:func:`sim.sky.read_measured`): the site's own, of its own dates; a run outside them is
refused naming them (:func:`check_weather_span`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from backend.twin.parameters import DISTURBANCE_NAMES, MACHINE_PARAMETERS, RUN_PARAMETERS
from sim.control import ControlSettings
from sim.disturbances import Disturbances
from sim.energy import check_step
from sim.plant.layout import Plant
from sim.pointing_model import PointingModel
from sim.site_config import clock_off_longitude
from sim.sites import Site
from sim.sky import typical_year_at_site
from sim.twin import CONTROLLERS, RECEIVERS, TwinResult, simulate
from sim.weather_clock import weather_clock

#: A weather station farther than this from the site is refused unless forced [km]: its sun
#: rises and sets at other times and its sky is another climate's (about 1° of latitude).
MAX_STATION_DISTANCE_KM = 100.0
_EARTH_RADIUS_KM = 6371.0


class StationTooFar(ValueError):
    """The weather file's station is farther from the site than :data:`MAX_STATION_DISTANCE_KM`,
    or its UTC offset is far from its longitude's (``sim.site_config.clock_off_longitude``):
    either is run only when forced."""


def station_distance_km(station: dict[str, Any], site: Site | Plant) -> float:
    """Great-circle (haversine) distance between a weather station and a site or plant [km]."""
    p1, p2 = math.radians(station["latitude"]), math.radians(site.latitude)
    dp, dl = p2 - p1, math.radians(site.longitude - station["longitude"])
    h = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2 * _EARTH_RADIUS_KM * math.asin(min(1.0, math.sqrt(h)))


def check_station(station: dict[str, Any], site: Site | Plant, force: bool,
                  force_name: str = "force") -> dict[str, Any]:
    """The station's description with its distance to ``site`` (a twin's site or a plant;
    units in the keys); raises :class:`StationTooFar` when it is farther than
    :data:`MAX_STATION_DISTANCE_KM`, or its UTC offset more than
    ``sim.site_config.MAX_CLOCK_OFF_LONGITUDE_H`` from its longitude / 15, and not ``force``
    (the message names the flag or field ``force_name``)."""
    if station["format"] == "measured":  # of its own dates: the site's own, unless it says
        out = {k: station[k] for k in ("format", "name", "stamped", "start", "end")} | {
            "forced": bool(force)}                   # where it is from (an NSRDB year)
        if station["latitude"] is None:
            return out
        return out | _checked_distance(station, site, force, force_name)
    # a PVGIS year's clock is UTC by the format, an NSRDB year's its header's as the NSRDB
    # wrote it (UTC for a UTC download): neither is a header a person can slip
    clock = None if station["format"] in ("pvgis", "nsrdb") else clock_off_longitude(
        station["utc_offset_h"], station["longitude"], "the weather file's offset")
    if clock is not None and not force:  # Alice Springs' −9.5 for +9.5 cost 39 % of its energy
        utc = (" (a file written in UTC, its header saying so, is read right when forced)"
               if station["utc_offset_h"] == 0 else "")
        raise StationTooFar(f"{clock} Fix the file's header, or set {force_name} to run on it "
                            f"anyway{utc}")
    where = _checked_distance(station, site, force, force_name)
    return {"format": station["format"], "name": station["name"],
            **{k: where[k] for k in ("latitude_deg", "longitude_deg", "altitude_m")},
            "utc_offset_h": station["utc_offset_h"], "distance_km": where["distance_km"],
            "forced": bool(force)}


def _checked_distance(station: dict[str, Any], site: Site | Plant, force: bool,
                      force_name: str) -> dict[str, Any]:
    """The station's place and distance to ``site`` (units in the keys); a
    :class:`StationTooFar` past :data:`MAX_STATION_DISTANCE_KM` unless ``force``."""
    distance = station_distance_km(station, site)
    place = (f"site {site.site_id}" if isinstance(site, Site) else f"plant {site.plant_id}")
    if distance > MAX_STATION_DISTANCE_KM and not force:
        raise StationTooFar(
            f"the weather station {station['name'] or '?'} ({station['latitude']:.2f}, "
            f"{station['longitude']:.2f}) is {distance:.0f} km from {place} "
            f"({site.latitude:.2f}, {site.longitude:.2f}), more than "
            f"{MAX_STATION_DISTANCE_KM:.0f} km: its sky does not go with this site's sun; use "
            f"weather from nearer the site, or set {force_name} to run on it anyway")
    return {"latitude_deg": station["latitude"], "longitude_deg": station["longitude"],
            "altitude_m": station["altitude"], "distance_km": round(distance, 1)}


def check_weather_span(station: dict[str, Any] | None, start: pd.Timestamp,
                       end: pd.Timestamp) -> None:
    """Refuse a run outside the span of measured weather (``station["start"]``, ``["end"]``),
    naming both: measured weather is of its own dates (a typical year, of any year's, has
    no span)."""
    if station is None or station.get("format") != "measured":
        return
    first, last = pd.Timestamp(station["start"]), pd.Timestamp(station["end"])
    if start < first or end > last:
        zone = start.tz
        raise ValueError(f"weather: the measured weather covers {first.tz_convert(zone)} to "
                         f"{last.tz_convert(zone)}; the run {start} to {end} is not within "
                         "it — run within those dates")


def place_weather(weather: pd.DataFrame, meta: dict[str, Any], place: Site | Plant,
                  start: pd.Timestamp, end: pd.Timestamp, force: bool, force_name: str
                  ) -> tuple[pd.DataFrame, dict[str, Any], dict[str, Any]]:
    """(weather on ``[start, end)`` at ``place``, its station, its clock check) of a file read
    by :func:`sim.sky.read_typical_year` or :func:`sim.sky.read_measured` (``meta``): the
    station checked (:func:`check_station`; :class:`StationTooFar` names ``force_name``), a
    typical year laid on the range's calendar (:func:`sim.sky.typical_year_at_site`: far
    away only the state of its sky is moved), measured weather taken as it is within its
    own dates (:func:`check_weather_span`, a ValueError), and
    :func:`sim.weather_clock.weather_clock` (``weather_shift_min``, ``weather_warning``).
    The one path of a plant run on a weather file: ``heliotwin plant simulate``/``sweep``
    and ``POST /api/v1/plants/{plant_id}/weather``."""
    station = check_station(meta, place, force, force_name)
    if station["format"] == "measured":
        check_weather_span(station, start, end)
        on_range = weather
    else:
        on_range = typical_year_at_site(
            weather, meta["utc_offset_h"], start, end,
            (meta["latitude"], meta["longitude"], meta["altitude"]),
            (place.latitude, place.longitude, place.altitude))
    clock = weather_clock(on_range, place.latitude, place.longitude, place.altitude, start,
                          end, station)
    return on_range, station, clock


@dataclass(frozen=True)
class Scenario:
    """A validated twin scenario."""

    site_id: str
    start: pd.Timestamp
    end: pd.Timestamp
    step_s: float = 60.0
    controller: str = "ideal"
    receiver: str = "flat"
    machine: dict[str, float] = field(default_factory=dict)
    #: a typical year (:func:`sim.sky.read_typical_year`) instead of clear sky, and its station
    #: as :func:`check_station` describes it
    weather: pd.DataFrame | None = field(default=None, compare=False, repr=False)
    station: dict[str, Any] | None = None
    #: ``open_loop_model``'s mount terms (``sim.pointing_model.PointingModel.from_terms``:
    #: the ``terms`` of ``GET …/pointing-model`` as they come, or ``{name: degrees}``)
    pointing_model_terms: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        check_step(self.start, self.end, self.step_s)
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller: {self.controller!r} is not one of "
                             f"{', '.join(CONTROLLERS)}")
        if self.receiver not in RECEIVERS:
            raise ValueError(f"receiver: {self.receiver!r} is not one of {', '.join(RECEIVERS)}")
        known = {p.name: p for p in MACHINE_PARAMETERS}
        for name, value in self.machine.items():
            p = known.get(name)
            if p is None:
                raise ValueError(f"{name}: not a machine parameter")
            if not math.isfinite(value):  # NaN passed the bounds below and the
                raise ValueError(f"{name}: {value} is not a finite number")  # dataclass named it
            if (p.minimum is not None and value < p.minimum) or (
                    p.maximum is not None and value > p.maximum):
                raise ValueError(f"{name}: {value} is outside [{p.minimum}, {p.maximum}]")
        _check_disturbances_felt(self.controller, self.machine)
        if self.pointing_model_terms is not None:
            if self.controller != "open_loop_model":
                raise ValueError("pointing_model_terms: only the open_loop_model controller "
                                 f"uses them, not {self.controller!r}")
            try:
                PointingModel.from_terms(self.pointing_model_terms)
            except ValueError as exc:
                raise ValueError(f"pointing_model_terms: {exc}") from None
        if (self.weather is None) != (self.station is None):
            raise ValueError("weather: a typical year goes with its station")
        check_weather_span(self.station, self.start, self.end)

    def disturbances(self) -> Disturbances:
        return disturbances_of(self.machine)

    def to_dict(self) -> dict[str, Any]:
        out = {"site_id": self.site_id, "start": self.start.isoformat(),
               "end": self.end.isoformat(), "step_s": self.step_s,
               "controller": self.controller, "receiver": self.receiver, **self.machine}
        if self.station is not None:
            out["weather_station"] = self.station
        if self.pointing_model_terms is not None:
            out["pointing_model_terms"] = PointingModel.from_terms(
                self.pointing_model_terms).as_dict()
        return out

    def to_json(self) -> str:
        return json.dumps(self.to_dict())


def _check_disturbances_felt(controller: str, machine: dict[str, float]) -> None:
    """Refuse a disturbance the controller cannot feel, naming it: ``ideal`` is the
    reference — the normal exactly on the sun, no motors — and no disturbance reaches it
    (``sim.twin.simulate``, ``docs/control.md``). Run with it, a 5° pedestal yaw read
    1.6e-13 mrad RMS while the summary echoed the yaw as applied (a tester's finding); the
    same yaw costs ``open_loop_spa`` 61 mrad."""
    if controller != "ideal":
        return
    for name in DISTURBANCE_NAMES:
        if machine.get(name, 0.0) != 0.0:
            raise ValueError(f"{name}: the ideal controller feels no disturbance (it is the "
                             "reference, exactly on the sun); choose a controller that "
                             "does, e.g. open_loop_spa, closed_loop_camera or hybrid")


def run_scenario(site: Site, scenario: Scenario, weather: pd.DataFrame | None = None,
                 progress: Callable[[float], None] | None = None) -> TwinResult:
    """``sim.twin.simulate`` for ``scenario`` (the one call the CLI and the API share).

    ``weather`` (already on the run's times) wins over the scenario's typical year, which is
    laid onto the run's calendar here, or its measured weather, taken as it is. A run on
    weather says how far its irradiance runs from the sun, and warns from
    ``sim.weather_clock.WEATHER_SHIFT_WARN_MIN`` on (``weather_shift_min``, ``weather_warning``).
    """
    if (weather is None and scenario.station is not None
            and scenario.station["format"] == "measured"):
        weather = scenario.weather  # of its own dates, already on UTC instants
    if weather is None and scenario.weather is not None and scenario.station is not None:
        st = scenario.station
        weather = typical_year_at_site(
            scenario.weather, st["utc_offset_h"], scenario.start, scenario.end,
            (st["latitude_deg"], st["longitude_deg"], st["altitude_m"]),
            (site.latitude, site.longitude, site.altitude))
    defaults = {p.name: p.default for p in MACHINE_PARAMETERS}
    run = {k: scenario.machine.get(k, defaults[k]) for k in RUN_PARAMETERS}
    result = simulate(
        site, scenario.start, scenario.end, step_s=scenario.step_s,
        controller=scenario.controller, weather=weather, progress=progress,
        disturbances=scenario.disturbances(), receiver=scenario.receiver,
        acceptance_angle_deg=run["acceptance_angle_deg"],
        spot_distance_m=run["spot_distance_m"],
        settings=ControlSettings(chronological_interval_min=run["chronological_interval_min"]),
        pointing_model_terms=scenario.pointing_model_terms,
    )
    if weather is not None:  # is the file on the sun's time? (a misread stamp or zone)
        clock = weather_clock(weather, site.latitude, site.longitude, site.altitude,
                              scenario.start, scenario.end, scenario.station)
        result.weather_shift_min = clock["weather_shift_min"]
        result.weather_warning = clock["weather_warning"]
    return result


def disturbances_of(params: dict[str, Any]) -> Disturbances:
    """The disturbances of a stored run's parameters (:meth:`Scenario.to_dict`)."""
    values: dict[str, Any] = {k: float(params[k]) for k in DISTURBANCE_NAMES if k in params}
    return Disturbances(**values)
