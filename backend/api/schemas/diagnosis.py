"""``/api/v1/sites/{site_id}/diagnosis`` and ``…/pointing`` (``backend/diagnosis``,
``docs/diagnosis.md``)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field

from backend.diagnosis.faults import GHI_UNCERTAINTY, INVERSION_UNCERTAINTY, FaultKind


class DaySkyRead(BaseModel):
    """What the day's sky rests on."""

    clearness_index: float | None = Field(description="measured over clear-sky POA in daylight")
    source: str = Field(description="`sensor`, `fixed_array` or `clear_sky`")
    sensor: str | None = Field(description="the sensor reading used (`poa_irradiance_w_m2`, "
                                           "`ghi_w_m2`) or null")
    valid_minutes_pct: float = Field(description="daylight minutes with a usable sky [%]")
    beam_unseen_expected_pct: float | None = Field(
        None, description="share of the expected tracker energy [%] from minutes the sky "
                          "instrument did not see the sun's beam in: the sun behind or grazing "
                          "the fixed plane (summer dawns and dusks), low for a horizontal "
                          "pyranometer, or a gap in its readings. There the beam is the one "
                          "the seen minutes make likely and the band widens by that guess "
                          "(docs/diagnosis.md, \"Any site\"); null on a clear-sky day (no "
                          "instrument)")


BAND = ("lower edge of the expected energy's band [Wh]: the two sky decompositions' spread "
        f"widened by the sky instrument's uncertainty, {100 * INVERSION_UNCERTAINTY:g} % from the "
        f"fixed plane, {100 * GHI_UNCERTAINTY:g} % from a GHI pyranometer alone")


VOLTAGE_RATIO = ("the measured voltage over the twin's at the array's maximum power point, "
                 "power-weighted over the day's valid minutes with a voltage reading "
                 "(faults.electrical_ratios); null without an hour of them or on a day not "
                 "whole")
CURRENT_RATIO = ("the measured power's ratio over `voltage_ratio`: where a loss lies, in the "
                 "current (a string down, soiling, an even cover) or the voltage (substrings "
                 "bypassed, the inverter off its maximum power point)")


class TrackerDayRead(BaseModel):
    """The tracker's day: measured against the weather-aware twin."""

    measured_wh: float | None
    expected_wh: float
    expected_wh_low: float = Field(description=BAND)
    expected_wh_high: float
    performance_ratio: float | None
    voltage_ratio: float | None = Field(None, description=VOLTAGE_RATIO)
    current_ratio: float | None = Field(None, description=CURRENT_RATIO)


class FixedDayRead(BaseModel):
    """The fixed array's day (it is the sky sensor)."""

    measured_wh: float | None
    expected_wh: float
    performance_ratio: float | None
    iec_performance_ratio: float | None = Field(
        None, description="IEC 61724-1's performance ratio, model-free: the array's final "
                          "yield (energy over its STC rating) over the reference yield (the "
                          "POA sensor in its plane, over 1000 W m⁻²), on the minutes both read "
                          "validly, no temperature correction; null on a day whose sky is not "
                          "a POA sensor's, or not whole")
    voltage_ratio: float | None = Field(None, description=VOLTAGE_RATIO)
    current_ratio: float | None = Field(None, description=CURRENT_RATIO)


class FaultRead(BaseModel):
    """A named fault signature (``backend/diagnosis/faults.py``)."""

    kind: FaultKind
    array: Literal["tracker", "fixed"] = Field(
        "tracker", description="the array it is found on: `fixed` for "
                               "`fixed_underperformance`, `tracker` for the others")
    title: str = Field(description="the kind in words, e.g. `tracker stuck`: what the "
                                   "dashboard and the alerts say")
    confidence: float = Field(description="[0, 1]")
    since: str = Field(description="the first day of its run of days (local date)")
    since_time: str | None = Field(
        None, description="`stuck`: the minute the tracker stopped on the run's first day, "
                          "where it tracked before (ISO 8601 with the site's offset, to a "
                          "few minutes); null when it was stuck all that day, and for the "
                          "other kinds")
    magnitude: float = Field(description="in `unit`")
    unit: str
    detail: str
    shortfall_wh: float | None = Field(
        None, description="`underperformance` (`fixed_underperformance`): the day's measured "
                          "tracker (fixed array) energy short of "
                          "the expected one [Wh] (`magnitude` the same in % of expected); "
                          "null for the other kinds")

class ShapeUntestedRead(BaseModel):
    """Why a day was not tested for shape faults (``faults.shape_untested``)."""

    readings: float = Field(description="independent tracker readings under the sun (a slow "
                                        "logger's counted by their spacing)")
    needed: int = Field(description="what the shape fits need: 10 per fitted parameter")
    detail: str


class DiagnosisDayRead(BaseModel):
    """One local day."""

    date: str = Field(description="local date, YYYY-MM-DD")
    complete: bool = Field(description="false: the day is not over; judged up to now")
    partial: bool = Field(description="true: the day is not over, the range asked for "
                                      "covers only part of it, or an array's readings "
                                      "cover under 99 % of its expected energy (a logger "
                                      "that began or stopped that day, a dropout): its "
                                      "measured gain is not the whole day's")
    sky: DaySkyRead
    tracker: TrackerDayRead
    fixed: FixedDayRead
    gain_measured_pct: float | None = Field(
        description="the measured tracking gain [%], over the minutes both loggers' readings "
                    "cover; null when they cover different minutes, one has no reading or "
                    "the fixed array measured no energy")
    gain_expected_pct: float | None = Field(
        description="the twin's tracking gain under the day's sky [%]: over the same minutes "
                    "as gain_measured_pct where there is one (a gap in both loggers leaves "
                    "its minutes out of both), else over the whole day")
    faults: list[FaultRead]
    shape_untested: ShapeUntestedRead | None = Field(
        None, description="the day's tracker readings under the sun were too few for the "
                          "shape fits (stuck, clock offset, azimuth offset): none of them was "
                          "tested; null when they were enough")


class DiagnosisRead(BaseModel):
    """Per local day: sky, measured and expected energy, PR, gains and faults."""

    site_id: str
    timezone: str
    start: str
    end: str
    days: list[DiagnosisDayRead]


class PointingStatsRead(BaseModel):
    """Statistics of the angle between the panel normal and the sun [°]."""

    rms_deg: float
    median_deg: float
    p95_deg: float
    max_deg: float


class PointingSummaryRead(PointingStatsRead):
    """Over the whole range, with the mean signed errors and the cosine loss."""

    mean_azimuth_error_deg: float
    mean_elevation_error_deg: float
    mean_cos_loss_pct: float


class PointingDayRead(PointingStatsRead):
    """One local day."""

    date: str
    minutes: int


class PointingPointRead(BaseModel):
    """One minute: encoder angles, the sun, the error and its components [°]."""

    ts: str
    azimuth_deg: float
    elevation_deg: float
    sun_azimuth_deg: float
    sun_elevation_deg: float
    error_deg: float
    azimuth_error_deg: float
    elevation_error_deg: float


class PointingRead(BaseModel):
    """The tracker's pointing error from its logger's encoder angles."""

    site_id: str
    array: str | None = Field(description="the tracker array; null when the site has none")
    start: str
    end: str
    minutes: int = Field(description="readings with both angles and the sun up (one a minute "
                                     "for a 1-minute logger; the name is kept for the contract)")
    summary: PointingSummaryRead | None
    days: list[PointingDayRead]
    points: list[PointingPointRead]
    points_step: int = Field(description="every k-th reading is in `points`")


MountTerm = Literal["azimuth_zero_deg", "elevation_zero_deg", "pedestal_tilt_north_deg",
                    "pedestal_tilt_east_deg", "collimation_deg", "nonperpendicularity_deg"]


class MountFaultRead(BaseModel):
    """A mount fault from the tracker camera's offsets (``backend/diagnosis/mount.py``)."""

    kind: Literal["mount_offset", "encoder_slip"] = Field(
        description="`mount_offset`: a significant term of the pointing model; "
                    "`encoder_slip`: a term that stepped from one day to the next")
    term: MountTerm = Field(description="the pointing model's term (docs/pointing-model.md)")
    value_deg: float = Field(description="`mount_offset`: the term's value; "
                                         "`encoder_slip`: the step (after − before) [°]")
    std_deg: float = Field(description="its standard error [°] (a step: both days' combined)")
    n_observations: int = Field(description="camera observations it was fitted from")
    since: str = Field(description="local date: the slip's first day, or the first day of "
                                   "the observations the offset was fitted from")
    detail: str = Field(description="the finding in words, e.g. 'pedestal yaw (azimuth "
                                    "zero) +2.00° ± 0.01° (from 380 camera observations …)'")


class MountRead(BaseModel):
    """The mount as the tracker camera measured it in the range."""

    n_observations: int = Field(description="observations of the fit of the offsets (those "
                                            "since the last slip, if any)")
    n_outliers: int
    residual_rms_mrad: float
    since: str = Field(description="local date of the first of those observations")
    faults: list[MountFaultRead] = Field(description="slips (oldest first), then offsets")
    undetermined: list[str] = Field(description=(
        "terms the observations do not determine (standard error over 0.5 mrad, as from "
        "minutes of sky): neither named as a fault nor cleared"))


class DiagnosisTrackerDayRead(TrackerDayRead):
    """The tracker's day (null numbers on a day still to come)."""

    expected_wh: float | None  # type: ignore[assignment]
    expected_wh_low: float | None = Field(description=BAND)  # type: ignore[assignment]
    expected_wh_high: float | None  # type: ignore[assignment]


class DiagnosisFixedDayRead(FixedDayRead):
    """The fixed array's day (null numbers on a day still to come)."""

    expected_wh: float | None  # type: ignore[assignment]


class DiagnosisDayStatusRead(DiagnosisDayRead):
    """One local day, with its status."""

    status: Literal["complete", "in_progress", "future"] = Field(
        description="`complete`: the day is over; `in_progress`: judged up to now; "
                    "`future`: it starts after now, nothing computed (its numbers null, "
                    "sky source `none`)")
    tracker: DiagnosisTrackerDayRead  # type: ignore[assignment]
    fixed: DiagnosisFixedDayRead  # type: ignore[assignment]


class DiagnosisMountRead(DiagnosisRead):
    """Per local day: sky, energy, PR, gains and faults; the mount faults from the camera."""

    days: list[DiagnosisDayStatusRead]  # type: ignore[assignment]
    mount: MountRead | None = Field(description="null: no camera observations (sun offsets "
                                                "with the encoder angles) in the range")
