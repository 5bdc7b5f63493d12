"""``/api/v1/sites/{site_id}/energy`` and ``…/report``: energy per period, measured beside the
twin, with the tracking gain (``backend/measurements/energy.py``, ``backend/reports.py``)."""

from __future__ import annotations

from pydantic import BaseModel, Field


class ArrayEnergyRead(BaseModel):
    """One array's energy over a period."""

    measured_wh: float | None = Field(description="null: no readings in the period")
    twin_wh: float | None = Field(description="the clear-sky twin")
    twin_matched_wh: float | None = Field(description="the twin over the minutes measured")
    readings: int
    performance_ratio: float | None = Field(description="measured_wh / twin_matched_wh")
    coverage_pct: float | None = Field(description="twin_matched_wh / twin_wh [%]")
    twin_weather_wh: float | None = Field(
        None, description="with source=twin_weather: the twin under the measured sky")
    twin_covered_wh: float | None = Field(
        None, description="the twin over the minutes this array's readings cover (the energy "
                          "rule's bridging; twin_matched_wh where both loggers cover all but "
                          "1 % of their twin's energy)")
    twin_shared_wh: float | None = Field(
        None, description="the twin over the minutes both the tracker's and the fixed "
                          "array's readings cover; equal (within 1 %) to twin_covered_wh for "
                          "both arrays when the loggers read the same minutes, and only then "
                          "is there a measured gain_pct (sim.energy.same_minutes)")

class EnergyTotalsRead(BaseModel):
    """The whole range."""

    arrays: dict[str, ArrayEnergyRead]
    partial: bool | None = Field(description="an array covered under partial_below_pct")
    gain_pct: float | None = Field(description="100·(tracker/fixed − 1), measured; null when "
                                              "either is missing, the fixed array's is not "
                                              "positive or the loggers read different minutes")
    gain_note: str | None = Field(None, description="why gain_pct (and, when the loggers "
                                                    "share no minutes, twin_matched_gain_pct) "
                                                    "is null, else null")
    twin_gain_pct: float | None
    twin_matched_gain_pct: float | None = Field(
        description="the twin's gain over the minutes both loggers cover (twin_shared_wh); "
                    "null where they share none")
    twin_weather_gain_pct: float | None = None


class EnergyRowRead(EnergyTotalsRead):
    """One local hour, day or month, clipped to the range."""

    period_start: str = Field(description="ISO 8601 in the site's zone")
    period_end: str
    twin_note: str | None = Field(description="why the twin has no value, or no gain (a "
                                              "period without sun), if so")
    twin_weather_note: str | None = None


class EnergyRead(BaseModel):
    """Energy per period for every array, measured and twin, with the tracking gain."""

    site_id: str
    interval: str = Field(description="`hour`, `day` or `month`")
    timezone: str
    start: str
    end: str
    max_gap_s: int = Field(description="longest gap the energy bridges [s]")
    partial_below_pct: float
    rows: list[EnergyRowRead]
    totals: EnergyTotalsRead


class ReportRead(BaseModel):
    """Totals, daily, monthly and annual energy, gain and performance ratio of a range."""

    site_id: str
    name: str
    timezone: str
    latitude_deg: float
    longitude_deg: float
    start: str
    end: str
    arrays: list[str]
    readings_note: str | None = Field(
        description="'No readings between START and END (end exclusive)' (': the range has "
                    "not begun' for one to come) when no array has a reading in the range; "
                    "null otherwise, and for a site without arrays")
    max_gap_s: int
    partial_below_pct: float
    totals: EnergyTotalsRead
    days: list[EnergyRowRead]
    months: list[EnergyRowRead]
    years: list[EnergyRowRead]
