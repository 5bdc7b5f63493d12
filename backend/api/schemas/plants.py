"""``/api/v1/plants``: plants of dual-axis trackers and their position server (seed 004)."""

from __future__ import annotations

from pydantic import BaseModel, Field

from backend.api.schemas.common import SunRead


class PlantSummaryRead(BaseModel):
    """One plant in the list."""

    plant_id: str
    name: str
    trackers: int = Field(description="number of trackers")
    latitude_deg: float
    longitude_deg: float
    timezone: str


class PlantFixedRead(BaseModel):
    """The fixed reference plant's orientation."""

    surface_tilt_deg: float
    surface_azimuth_deg: float


class CollectorRead(BaseModel):
    """One tracker's collector (its modules and their electrics)."""

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


class PlantTrackerRead(BaseModel):
    """A tracker's pedestal in East-North-Up metres of the plant's origin."""

    tracker_id: int
    east_m: float
    north_m: float
    up_m: float


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
    source: str
    notes: str


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
