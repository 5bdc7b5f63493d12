"""``/api/v1/simulations``: twin scenario summaries, background runs and their series."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

#: A run's life: queued → running → done | failed (a cancelled run is failed, error
#: ``cancelled``).
RunStatus = Literal["queued", "running", "done", "failed"]


class SimulationAcceptedRead(BaseModel):
    """A background run accepted (202): poll ``GET /api/v1/simulations/{run_id}``."""

    run_id: str
    status: RunStatus
    progress: float = Field(description="0…1")
    estimated_run_s: float | None = Field(
        None, description="expected worker time of the run (backend/twin/cost.py) [s]")
    estimated_wait_s: float | None = Field(
        None, description="expected time before it starts, behind the queue's order [s]")
    queue_position: int | None = Field(None, description="0: the next run to start")


class SimulationEstimateRead(BaseModel):
    """What a run would cost and when it would start if asked now (nothing is queued)."""

    site_id: str
    controller: str
    steps: int
    estimated_run_s: float = Field(description="expected worker time of the run [s]")
    estimated_wait_s: float = Field(description="expected time before it would start [s]")
    runs_ahead: int = Field(description="runs running or queued that would go before it")
    anonymous_run_max_s: float | None = Field(
        description="without a token: the most one run may take [s]; null with a token")
    anonymous_hour_left_s: float | None = Field(
        description="without a token: the worker time this address may still ask this hour "
                    "[s]; null with a token")
    allowed: bool = Field(description="whether the run would be accepted now")
    reason: str | None = Field(description="why not, naming the limit")


class DisturbancesRead(BaseModel):
    """The machine's disturbances of the run (``sim.disturbances.Disturbances``)."""

    pedestal_yaw_deg: float
    elevation_zero_deg: float
    pedestal_tilt_deg: float
    pedestal_tilt_azimuth_deg: float
    encoder_drift_mrad_per_h: float
    clock_offset_s: float
    backlash_deg: float
    gust_torque_nm: float
    camera_offset_right_deg: float
    camera_offset_up_deg: float


class SimulationDayRead(BaseModel):
    """One local calendar day of a run, by the energy rule (``sim.energy``) split at the
    site's midnights: the days add up to the run's totals."""

    date: str = Field(description="local date, YYYY-MM-DD")
    tracker_energy_wh: float
    fixed_energy_wh: float
    gain_pct: float | None
    stow_loss_wh: float | None = Field(None, description=(
        "the tracker's energy lost to wind stow that day; absent when the run has no wind "
        "stow (sim.stow)"))


class SimulationSummaryRead(BaseModel):
    """A run's summary (DESIGN.md ``heliotwin simulate``, ``sim.twin.TwinResult.summary``)."""

    run_id: str
    site_id: str
    start: str
    end: str
    step_s: float
    controller: str
    receiver: str
    sky: str
    timezone: str
    steps: int
    daylight_steps: int
    tracker_energy_wh: float
    fixed_energy_wh: float
    gain_pct: float | None
    net_gain_pct: float | None = Field(description="the gain after the actuators' energy")
    tracker_peak_w: float
    fixed_peak_w: float
    tracker_peak_time: str | None
    fixed_peak_time: str | None
    tracker_modules: int
    fixed_modules: int
    wiring: dict[str, str]
    pointing_error_rms_mrad: float | None
    pointing_error_p95_mrad: float | None
    pointing_error_max_mrad: float | None
    pointing_error_energy_weighted_rms_mrad: float | None = Field(
        None, description=(
            "RMS weighted at each step by the ideal tracker's plane-of-array irradiance "
            "(the beam alone for a CPV receiver): an error at a dim low sun barely counts"))
    pointing_error_minutes: int | None = Field(
        None, description="tracking minutes the pointing statistics cover")
    pointing_min_elevation_deg: float | None = Field(
        None, description="sun elevation above which the pointing error is defined")
    azimuth_error_rms_mrad: float | None
    elevation_error_rms_mrad: float | None
    moves: int
    actuator_energy_wh: float
    actuator_move_energy_wh: float
    actuator_standby_energy_wh: float
    actuator_moves_beyond_drive: int = Field(
        0, description="moves that ask more than their drive gives (torque over its rating, "
                       "voltage over the bus): costed as if made")
    actuator_warning: str | None = Field(
        None, description="words when actuator_moves_beyond_drive > 0: the actuator energy "
                          "is not what this machine would draw")
    pointing_loss_wh: float
    weather_shift_min: float | None = Field(
        None, description="a run on weather: the shift [min] that best aligns the file's GHI "
                          "with the clear sky at the site, the median of its sunny days "
                          "(> 0: the file runs late); null without such a day")
    weather_warning: str | None = Field(
        None, description="words when weather_shift_min is 15 min or more: the file's "
                          "times misread (weather_stamped, the zone)")
    acceptance_angle_deg: float | None = Field(description="CPV receiver only")
    spot_distance_m: float
    spot_displacement_rms_m: float | None
    spot_x_rms_m: float | None
    spot_y_rms_m: float | None
    camera_frames: int
    camera_frames_found: int
    camera_frames_used: int
    disturbances: DisturbancesRead
    days: list[SimulationDayRead]
    fixed_shade_loss_wh: float | None = Field(None, description="when the site places both "
                                                                "arrays")
    stow_wind_speed_m_s: float | None = Field(None, description=(
        "the site's wind-stow threshold (tracker.stow_wind_speed_m_s); absent: it never stows"))
    stow_min: int | None = Field(None, description=(
        "daylight minutes the wind held the tracker flat (sim.stow); null when the site "
        "stows but the run's sky has no wind speed (clear sky, or weather without one)"))
    stow_loss_wh: float | None = Field(None, description=(
        "the tracker's energy without the stow minus with it, same sky and PV model; null "
        "as stow_min"))


class SimulationRunRead(BaseModel):
    """Status, progress and, when done, the summary of a run."""

    run_id: str
    site_id: str
    status: RunStatus
    progress: float = Field(description="0…1")
    summary: SimulationSummaryRead | None
    error: str | None
    params: dict[str, Any] = Field(description="the scenario: site_id, start, end, step_s, "
                                               "controller, receiver, machine parameters "
                                               "changed, weather_station")
    estimated_run_s: float | None = Field(
        None, description="expected worker time [s] (known while the service remembers it)")
    estimated_wait_s: float | None = Field(
        None, description="queued: expected time before it starts [s]; running: 0")
    queue_position: int | None = Field(None, description="queued: 0 is the next to start")
    started_at: str | None = Field(None, description="UTC, ISO 8601; null until it starts")
    finished_at: str | None = Field(None, description="UTC, ISO 8601; null until it ends")


class SimulationSeriesRead(BaseModel):
    """A finished run's series (streamed as written), averaged into buckets when
    ``max_points`` or ``step_s`` asks, within ``start``/``end`` when given."""

    run_id: str
    bucket_s: float = Field(description="0: every step as computed")
    columns: list[str] = Field(description="the points' keys after `ts`, units in the names")
    points: list[dict[str, float | str | None]] = Field(
        description="`ts` (UTC, ISO 8601) and one number (or null) per column")
