"""``/api/v1/sites``: sites with their arrays, logger calibration and live status."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from backend.api.schemas.common import SunRead


class CalibrationRead(BaseModel):
    """Logger calibration of one array (seed 000, eqs. 16–19)."""

    adc_bits: int = Field(description="ADC resolution [bit]")
    adc_vref_v: float = Field(description="ADC reference voltage [V]")
    current_zero_v: float = Field(description="ACS712 output at 0 A [V] (eq. 16)")
    current_sensitivity_mv_per_a: float = Field(description="ACS712 sensitivity [mV/A]")
    divider_ratio: float = Field(description="(R1+R2+R3)/Rx of the divider (eq. 19)")


class ArrayRead(BaseModel):
    """One PV array of a site (``sim.pv.ArrayConfig.to_dict`` and its placement).

    ``surface_*`` only for a fixed mount; the placement keys only when configured.
    """

    name: str
    kind: str = Field(description="`tracker` or `fixed`: its role in the comparison")
    mount: str
    module: str = Field(description="CEC module name")
    modules: int
    modules_in_series: int
    strings_in_parallel: int
    wiring: str
    stc_power_w: float
    temperature_model: str
    albedo: float
    dc_loss_pct: float | None = Field(None, description="[%] DC losses, when set (else 0)")
    inverter_limit_w: float | None = Field(None, description="[W] the inverter's limit, when "
                                                             "set (else none)")
    surface_tilt_deg: float | None = None
    surface_azimuth_deg: float | None = None
    position_east_m: float | None = None
    position_north_m: float | None = None
    mount_height_m: float | None = None
    width_m: float | None = None
    height_m: float | None = None
    calibration: CalibrationRead


class DriveRead(BaseModel):
    """One axis's gear motor (``sim.dynamics``)."""

    gear_ratio: float
    gear_efficiency: float
    driver_efficiency: float
    torque_constant_nm_a: float
    winding_resistance_ohm: float
    no_load_current_a: float
    supply_voltage_v: float
    max_output_speed_rad_s: float
    max_output_torque_nm: float
    standby_power_w: float


class InertiaRead(BaseModel):
    """Masses and inertias of the two links (seed 002, Table 1)."""

    m1_kg: float
    m2_kg: float
    cg1_m: float
    cg2_m: float
    i11_kg_m2: float
    i12_kg_m2: float
    i13_kg_m2: float
    i21_kg_m2: float
    i22_kg_m2: float
    i23_kg_m2: float
    g_m_s2: float


class TrackerGeometryRead(BaseModel):
    """The tracker's D–H lengths, joint limits, drives and inertia (seeds 000, 002)."""

    d1_m: float
    a2_m: float
    azimuth_min_deg: float
    azimuth_max_deg: float
    elevation_min_deg: float
    elevation_max_deg: float
    drives: dict[str, DriveRead] = Field(description="`azimuth` and `elevation`")
    inertia: InertiaRead
    stow_wind_speed_m_s: float | None = Field(None, description=(
        "wind speed above which the tracker stows flat (sim.stow); absent: it never stows"))
    stow_release_min: float | None = Field(None, description=(
        "minutes of calm after which a stowed tracker tracks again; with the threshold"))


class SiteRead(BaseModel):
    """A site with its arrays and where its config lives."""

    site_id: str
    name: str
    latitude_deg: float
    longitude_deg: float
    altitude_m: float
    timezone: str
    temp_air_c: float
    wind_speed_m_s: float
    transposition_model: str
    readings_stamped: str = Field("instant", description=(
        "what the loggers' timestamps mark: 'instant', 'interval_end' or 'interval_start'"))
    tracker: TrackerGeometryRead
    arrays: dict[str, ArrayRead]
    source: str
    notes: str
    assumed: dict[str, str] = Field(default_factory=dict, description=(
        "config keys (dotted paths) filled in from the place when the site was made, each "
        "with its rule or default (sim.sites.place_defaults); absent: none"))
    has_twin: bool = Field(False, description=(
        "whether the twin simulates the site, and so the diagnosis, its energies and the "
        "sky from its fixed array exist: arrays named 'tracker' and 'fixed' so mounted "
        "(sim.twin.has_twin_arrays); false: a camera site or other arrays"))
    origin: Literal["builtin", "user", "unknown"] = Field(
        description="a built-in file, or the user's folder (which wins)")
    overrides_builtin: bool


class SiteWrittenRead(SiteRead):
    """A site created (201) or edited (200) by ``PUT``."""

    created: bool
    twin_readings_dropped: int = Field(description="cached twin readings dropped, to be "
                                                   "simulated again")
    written_by: str = Field(description="`admin`, or the site id whose token wrote it")
    warnings: list[str] = Field(default_factory=list, description=(
        "what looks wrong but was written: a timezone whose standard time is more than 3 h "
        "from the longitude / 15 (sim.site_config.site_zone_warning)"))


class ArrayStatusRead(BaseModel):
    """One array's tile: its last reading, its twin now and today's energy."""

    kind: str
    last_ts: str | None = Field(description="UTC, ISO 8601; null: never reported")
    power_w: float | None
    voltage_v: float | None
    current_a: float | None
    age_s: float | None = Field(description="age of the last reading [s]: the service's "
                                            "clock minus its stamp; negative when the "
                                            "logger's clock runs ahead (readings up to the "
                                            "ingest's future tolerance are taken)")
    silent_s: float | None = Field(
        None, description="the part of age_s that counts as the logger's silence [s]: its "
                          "daylight seconds while the alerts count silence in daylight only "
                          "(HELIOTWIN_ALERT_SILENT_DAYLIGHT_ONLY, the default), else age_s; "
                          "a logger quiet since sunset is not late (null: never reported)")
    logger: Literal["never", "reporting", "stale"] = Field(
        description="stale: silent_s is past fresh_s (the logger_silent alert's count)")
    fresh_s: int | None = Field(
        None, description="this logger's last reading is stale past this age [s]: 2.5 of its "
                          "own cadence, from the site's fresh_s up to the energy rule's gap "
                          "(null: never reported)")
    twin_power_w: float | None
    energy_today_wh: float | None
    twin_energy_today_wh: float | None


class TrackerJointsRead(BaseModel):
    """The twin tracker's joint angles now [°]."""

    azimuth_joint_deg: float | None
    elevation_joint_deg: float | None


class SiteStatusRead(BaseModel):
    """The overview tiles: sun and tracker now, last readings, twin power, today's energy."""

    site_id: str
    time: str = Field(description="now in the site's zone, ISO 8601")
    time_utc: str
    timezone: str
    sun: SunRead
    tracker: TrackerJointsRead
    twin_minute: str = Field(description="the twin minute sampled (UTC)")
    arrays: dict[str, ArrayStatusRead]
    gain_today_pct: float | None
    twin_gain_today_pct: float | None
    twin_matched_gain_today_pct: float | None
    partial_today: bool | None
    fresh_s: int = Field(description="the least age [s] at which a last reading is stale; "
                                     "each array's own fresh_s follows its cadence")


class JsonSchemaRead(BaseModel):
    """A JSON Schema document (draft 2020-12), as ``docs/site.schema.json``."""

    model_config = ConfigDict(extra="allow")
