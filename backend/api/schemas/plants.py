"""``/api/v1/plants``: plants of dual-axis trackers and their position server (seed 004)."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field

from backend.api.schemas.common import JsonNumber, SunRead
from backend.plants.sweep import (
    COLLECTOR_SIZE_PATTERN,
    FIELD_SIZE_PATTERN,
    MAX_GCRS,
    MAX_LAYOUTS,
    MAX_STRATEGIES,
)
from sim.energy import MAX_STEP_S
from sim.site_config import ALTITUDE_MAX_M, ALTITUDE_MIN_M


class PlantSummaryRead(BaseModel):
    """One plant in the list."""

    plant_id: str
    name: str
    trackers: int = Field(description="number of trackers")
    latitude_deg: float
    longitude_deg: float
    timezone: str


class PlantSkippedRead(BaseModel):
    """A plant file the service does not serve, and why."""

    file: str = Field(description="its name in the plants folder, e.g. broken.json")
    reason: str = Field(description="what is wrong with it (the field, or the JSON error)")


class PlantFixedRead(BaseModel):
    """The fixed reference plant's orientation."""

    surface_tilt_deg: float
    surface_azimuth_deg: float


class CollectorRead(BaseModel):
    """One tracker's collector (its modules and their electrics; its outline when it is a
    polygon)."""

    width_m: float
    height_m: float
    area_m2: float
    modules_across: int
    modules_high: int
    module_orientation: str
    bypass_diodes: int
    module_power_w: float
    gamma_pdc_per_c: float = Field(description="power temperature coefficient [1/°C]")
    module_name: str | None
    power_stc_w: float
    outline_m: list[tuple[float, float]] | None = Field(
        None, description="a polygon collector's [u, v] vertices [m] about the pivot "
                          "(width_m × height_m is then its bounding box); null for the "
                          "rectangle")


class PlantTrackerRead(BaseModel):
    """A tracker's pedestal in East-North-Up metres of the plant's origin."""

    tracker_id: int
    east_m: float
    north_m: float
    up_m: float


class PlantStowRead(BaseModel):
    """The plant's trackers' wind stow (the plant file's ``tracker``, a site's keys:
    sim/stow.py); a run on weather with wind lays every collector flat while it blows."""

    stow_wind_speed_m_s: float = Field(description="[m s⁻¹] they stow while the weather's "
                                                   "wind_speed exceeds this")
    stow_release_min: float = Field(description="[min] they track again once the wind has "
                                                "stayed at or below it this long")


class PlantRead(BaseModel):
    """One plant: place, collector and electrical layout, trackers in ENU metres."""

    plant_id: str
    name: str
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    timezone: str
    albedo: float
    temp_air_c: float
    wind_speed_m_s: float
    fixed: PlantFixedRead
    collector: CollectorRead
    trackers: list[PlantTrackerRead]
    tracker: PlantStowRead | None = Field(None, description="the trackers' wind stow; null: "
                                                            "they never stow for wind")
    gcr: float | None = Field(description="ground cover ratio [-]: the collectors' area over "
                                          "land_m2; null for fewer than 3 trackers")
    land_m2: float | None = Field(description="ground the plant covers [m²]: its pivots' convex "
                                              "hull grown by half the median nearest-neighbour "
                                              "distance; null for fewer than 3 trackers")
    source: str
    notes: str
    strategies: list[str] = Field(description="the strategies its collector can take: sun, "
                                              "backtrack and sky_scan; sun alone for a polygon")


class TrackerPositionRead(BaseModel):
    """One tracker's orientation, its shaded fraction and the trackers that shade it."""

    tracker_id: int
    azimuth_deg: float
    elevation_deg: float
    shaded_fraction: float | None = Field(description="[0, 1]; null with the sun down")
    shaded_by: list[int]


class PositionsRead(BaseModel):
    """Every tracker's orientation under a strategy at one instant (the position server)."""

    plant_id: str
    time: str = Field(description="ISO 8601")
    strategy: str
    sun: SunRead
    sun_up: bool
    trackers_shaded: int
    mean_shaded_fraction: float | None
    trackers: list[TrackerPositionRead]


class SkyMapRead(BaseModel):
    """Seed 004 Fig. 6: POA over the hemisphere of orientations, and where it shades."""

    plant_id: str
    time: str
    projection: str
    sky: str
    transposition_model: str
    sun: SunRead
    strategy: str
    chosen: SunRead = Field(description="the orientation the strategy picks")
    azimuth_deg: list[float] = Field(description="the grid's columns [°]")
    elevation_deg: list[float] = Field(description="the grid's rows [°]")
    poa_global_w_m2: list[list[float | None]] = Field(description="rows × columns [W m⁻²]")
    shading: list[list[bool]] = Field(description="rows × columns: would shade a collector")


class StrategyEnergyRead(BaseModel):
    """A strategy's plant energy over the day (``fixed``: only ``plant_energy_wh``)."""

    plant_energy_wh: float
    plant_energy_area_model_wh: float | None = None
    plant_energy_unshaded_wh: float | None = None
    shading_loss_area_pct: float | None = None
    shading_loss_electrical_pct: float | None = None
    fraction_of_daylight_any_shaded: float | None = None
    fixed_energy_wh: float | None = None


class PlantDayRead(BaseModel):
    """A clear-sky day: each tracker's shade under sun tracking, every strategy's energy."""

    plant_id: str
    date: str
    step_s: float
    sky: str
    tracker_ids: list[int]
    times: list[str] = Field(description="the daylight instants of `shaded_fraction`'s rows")
    shaded_fraction: list[list[float]] = Field(description="times × trackers [0, 1]")
    strategies: dict[str, StrategyEnergyRead]


class PlantWeatherCreate(BaseModel):
    """The form fields of ``POST /api/v1/plants/{plant_id}/weather`` besides the weather
    file (``file``, ``force``, ``weather_stamped``, ``weather_timezone``: the twin's)."""

    model_config = ConfigDict(allow_inf_nan=False, extra="forbid")

    start: str = Field(min_length=1, max_length=64,
                       description="YYYY-MM-DD (the plant's midnight) or ISO 8601 with offset")
    end: str = Field(min_length=1, max_length=64, description="exclusive")
    step_s: float = Field(60.0, gt=0, le=MAX_STEP_S, description="time step [s], at most an "
                          "hour (sim.energy.MAX_STEP_S); default 60, as the CLI's")
    strategy: str = Field("sun", description="sun, backtrack or sky_scan")


class PlantWeatherRunRead(BaseModel):
    """A plant run on a weather file: ``heliotwin plant simulate --json``'s summary
    (``sim.plant.simulate.PlantResult.summary``, docs/plants.md)."""

    plant_id: str
    trackers: int
    start: str
    end: str
    step_s: float
    strategy: str
    sky: str = Field(description="weather")
    daylight_steps: int
    fraction_of_daylight_any_shaded: float | None
    dni_weighted_shaded_fraction: float | None
    mean_shaded_fraction: float | None
    plant_energy_wh: float = Field(description="the strategy's plant energy, bypass-diode "
                                               "model [Wh]")
    plant_energy_area_model_wh: float
    plant_energy_unshaded_wh: float
    shading_loss_area_pct: float | None
    shading_loss_electrical_pct: float | None
    fixed_energy_wh: float = Field(description="the fixed plant of the same collectors [Wh]")
    gain_vs_fixed_pct: float | None
    plant_peak_w: float
    poa_insolation_wh_m2: float
    stow_wind_speed_m_s: float | None = Field(None, description=(
        "the plant's wind-stow threshold (tracker.stow_wind_speed_m_s); absent: it never "
        "stows"))
    stow_min: int | None = Field(None, description=(
        "daylight minutes the wind held the plant flat (sim.stow); null when the weather has "
        "no wind (a distant station's is dropped); absent as stow_wind_speed_m_s"))
    stow_loss_wh: float | None = Field(None, description=(
        "the plant's energy in the strategy's orientation minus flat in those minutes "
        "(bypass-diode model; negative on a cloudy spell) [Wh]; null as stow_min"))
    weather_station: dict[str, Any] = Field(description=(
        "the file's station and its distance_km from the plant (measured weather: its "
        "span), as backend.twin.scenario.check_station describes it"))
    weather_shift_min: float | None = Field(description=(
        "the shift [min] that best aligns the file's GHI with the clear sky at the plant "
        "(> 0: the file runs late); null without a sunny day to fit"))
    weather_warning: str | None = Field(description="words when weather_shift_min is 15 "
                                                    "min or more: the file's times misread")


class SweepCreate(BaseModel):
    """A plant-design sweep (issue 26): every layout × GCR × strategy, over a range.

    A place and a collector (``latitude_deg``, ``longitude_deg``, ``collector_m`` or
    ``collector_polygon_m``) for regular fields, or ``plant_id`` for an existing plant
    scaled in spacing. ``start`` and ``end``: a bare date is midnight UTC (the plant's zone
    with ``plant_id``), or ``timezone``'s.
    """

    model_config = ConfigDict(extra="forbid")

    layouts: list[str] | None = Field(None, min_length=1, max_length=MAX_LAYOUTS,
                                      description="square, diagonal, hexagonal_n_s, "
                                                  "hexagonal_e_w, custom; default square "
                                                  "(refused with plant_id)")
    gcr: Annotated[list[JsonNumber], Field(min_length=1, max_length=MAX_GCRS)] | Annotated[
        str, Field(min_length=1, max_length=200)] = Field(
        description="ground cover ratios: a list, or the CLI's text (its rule, "
                    "backend.plants.sweep.parse_gcr) — \"0.15,0.25\" or a range "
                    f"\"START:STOP:STEP\" (STOP included); at most {MAX_GCRS} values")
    strategies: list[str] = Field(["sun"], min_length=1, max_length=MAX_STRATEGIES,
                                  description="sun, backtrack, sky_scan")
    collector_m: str | None = Field(None, pattern=COLLECTOR_SIZE_PATTERN,
                                    description="collector WIDTHxHEIGHT [m], e.g. 12x5")
    collector_polygon_m: list[tuple[JsonNumber, JsonNumber]] | None = Field(
        None, min_length=3, max_length=256,
        description="any collector outline instead of collector_m: [u, v] vertices [m] about "
                    "the pivot in the collector plane (u right, v up when facing it); "
                    "strategy sun only")
    latitude_deg: JsonNumber | None = Field(None, ge=-90, le=90)
    longitude_deg: JsonNumber | None = Field(None, ge=-180, le=180)
    altitude_m: JsonNumber | None = Field(None, ge=ALTITUDE_MIN_M, le=ALTITUDE_MAX_M,
                                          description="default 0 (refused with plant_id)")
    plant_id: str | None = Field(None, max_length=100)
    timezone: str | None = Field(
        None, max_length=64,
        description="IANA zone of the local days at a latitude/longitude (the dates, the "
                    "shade chart's day); default UTC; with plant_id the plant's own")
    field_size: str | None = Field(None, pattern=FIELD_SIZE_PATTERN,
                                   description="ROWSxCOLUMNS of the regular field; default "
                                               "5x5 (refused with plant_id)")
    aspect_ratio: JsonNumber | None = Field(None, gt=0, le=10, description="layout custom")
    offset: JsonNumber | None = Field(None, ge=-0.5, lt=0.5, description="layout custom")
    rotation_deg: JsonNumber | None = Field(None, ge=0, lt=180, description="layout custom")
    slope_azimuth_deg: JsonNumber | None = Field(None, ge=0, lt=360,
                                                 description="default 0 (refused with plant_id)")
    slope_tilt_deg: JsonNumber | None = Field(None, ge=0, lt=45,
                                              description="default 0, level (refused with "
                                                            "plant_id)")
    start: str = Field(description="YYYY-MM-DD or ISO 8601 with offset")
    end: str = Field(description="exclusive")
    step_s: JsonNumber = Field(3600.0, ge=60, le=MAX_STEP_S,
                               description="time step [s], at most an hour (sim.energy.MAX_STEP_S)")



class SweepRowRead(BaseModel):
    """One case of a sweep."""

    layout: str
    gcr: float
    strategy: str
    interior_beam_shaded_pct: float | None = Field(
        description="interior collector: Σ shaded fraction × DNI / Σ DNI over daylight [%]")
    field_beam_shaded_pct: float | None = Field(description="the same, field average [%]")
    energy_kwh_per_collector: float = Field(
        description="the finite field's average per collector, bypass-diode model (most of a "
                    "5x5 field's collectors are on its edge)")
    interior_energy_kwh: float = Field(
        description="the interior collector's: what a large plant's collectors get")
    energy_mwh_per_ha: float = Field(description="the field average's, over its land")
    interior_energy_mwh_per_ha: float = Field(description="the interior collector's, over "
                                                          "its land")
    land_m2_per_collector: float
    collectors: int
    shading_loss_electrical_pct: float | None


class SweepResultRead(BaseModel):
    """A finished sweep: where it ran and its rows (sorted by layout, strategy, GCR)."""

    engine: str = Field(description="dask or in-process")
    scheduler: str | None
    workers: int
    worker_processes: int
    sky_computations: int = Field(description="the range's sky was computed this many times "
                                              "(at most once per worker)")
    cases: int
    wall_s: float
    compute_s: float
    rows: list[SweepRowRead]


class SweepAcceptedRead(BaseModel):
    """A queued sweep: poll ``GET /api/v1/plants/sweeps/{sweep_id}``."""

    sweep_id: str
    status: str
    progress: float = Field(description="0…1")
    cases: int


class SweepRunRead(BaseModel):
    """A sweep's status, progress and, when done, its result (a cancelled one's: the cases
    finished before it)."""

    sweep_id: str
    status: str = Field(description="queued, running, done or failed")
    progress: float = Field(description="cases done / cases")
    cases_done: int
    cases: int
    params: dict[str, Any]
    result: SweepResultRead | None
    error: str | None


class SweepShadeRead(BaseModel):
    """One case's field through a clear-sky day."""

    layout: str
    gcr: float
    strategy: str
    date: str
    step_s: float
    interior_index: int
    positions_m: list[list[float]] = Field(description="pivots (east, north) [m]")
    times: list[str] = Field(description="daylight steps, ISO 8601 UTC")
    sun_azimuth_deg: list[float]
    sun_elevation_deg: list[float] = Field(description="apparent (refracted)")
    interior_shaded_fraction: list[float]
    field_mean_shaded_fraction: list[float]
    shaded_fraction: list[list[float]] = Field(description="times × collectors [0, 1]")
