"""Schemas of ``/api/v1/sites/{site_id}/pointing-model`` (issue 25; docs/pointing-model.md)."""

from __future__ import annotations

from pydantic import BaseModel, Field


class PointingTermRead(BaseModel):
    """One mount term [°] and its standard error from the fit's Jacobian."""

    value: float
    std: float | None = Field(description="standard error [°] (residual variance × (JᵀJ)⁻¹)")


class CorrelationRead(BaseModel):
    """Two terms the data do not separate (|correlation| above the limit)."""

    terms: list[str]
    correlation: float


class PointingModelRead(BaseModel):
    """The tracker's mount terms fitted from the sun's offsets in its camera."""

    site_id: str
    n_observations: int = Field(description="readings with encoder angles and sun offsets")
    n_outliers: int = Field(description="observations rejected by the robust fit (glints)")
    residual_rms_mrad: float = Field(description="RMS of the inliers' residuals, both axes")
    terms: dict[str, PointingTermRead] = Field(
        description="azimuth_zero_deg, elevation_zero_deg, pedestal_tilt_north_deg, "
                    "pedestal_tilt_east_deg, and collimation_deg / nonperpendicularity_deg "
                    "where the data's sky coverage separates them")
    identifiable: list[str] = Field(description="terms no other term correlates with beyond "
                                                "the limit and whose standard error is at "
                                                "most 0.5 mrad (determined by the data)")
    correlated: list[CorrelationRead]


class PointingCoverageRead(BaseModel):
    """Whether a range can be fitted, without fitting it: the observations it holds."""

    site_id: str
    has_tracker: bool = Field(description="whether the site has a tracker array to fit; "
                                          "false: a camera site or fixed arrays only")
    n_observations: int = Field(description="the tracker's measured readings in the range "
                                            "with both encoder angles and both sun offsets")
    min_observations: int = Field(description="the fewest the fit takes (10); fewer: "
                                              "GET …/pointing-model answers 422")


class PointingCommandRead(BaseModel):
    """Encoder angles that put the real optical axis on the sun at ``time``."""

    azimuth_deg: float = Field(description="encoder azimuth to command [°], [0, 360)")
    elevation_deg: float = Field(description="encoder elevation to command [°]")
    sun_azimuth_deg: float = Field(description="the sun's azimuth at time (SPA) [°]")
    sun_elevation_deg: float = Field(description="the sun's apparent elevation (SPA) [°]")
    pointing_std_mrad: float | None = Field(description=(
        "standard error of where the command puts the optical axis, relative to the sun "
        "[mrad], from the terms' covariance (null for a singular fit): large where the "
        "range's sky does not determine the model at this sun"))


class PointingPointsRead(BaseModel):
    """Observations behind the fit (every ``stride``-th, at most 2,000), column by column:
    the offsets measured (before the model) and the residuals (after it)."""

    n_total: int = Field(description="observations in the range (the fit's n_observations)")
    stride: int = Field(description="every stride-th observation is listed")
    ts: list[str] = Field(description="times, ISO 8601 UTC")
    azimuth_deg: list[float] = Field(description="encoder azimuth [°]")
    elevation_deg: list[float] = Field(description="encoder elevation [°]")
    sun_offset_x_mrad: list[float] = Field(description="offset measured, x [mrad]")
    sun_offset_y_mrad: list[float] = Field(description="offset measured, y [mrad]")
    residual_x_mrad: list[float] = Field(
        description="measured − the model's predicted offset, x [mrad]: what a command under "
                    "the model still misses")
    residual_y_mrad: list[float] = Field(description="likewise, y [mrad]")
    outlier: list[bool] = Field(description="rejected by the robust fit (a glint)")


class PointingModelPointsRead(PointingModelRead):
    """The mount terms and the observations' residuals before and after the model."""

    points: PointingPointsRead


class PointingObservationRead(BaseModel):
    """A tracker-camera frame's observation, as stored: a reading of the tracker array."""

    site_id: str
    array: str = Field(description="the site's tracker array")
    ts: str = Field(description="the frame's time, ISO 8601 UTC")
    azimuth_deg: float = Field(description="encoder azimuth as stored [°], [0, 360)")
    elevation_deg: float = Field(description="encoder elevation [°]")
    sun_offset_x_mrad: float = Field(description="the sun's offset toward increasing azimuth")
    sun_offset_y_mrad: float = Field(description="the sun's offset toward increasing "
                                                 "elevation")
    confidence: float = Field(description="the detector's calibrated probability that the "
                                          "blob is the sun")
    centroid_px: list[float] = Field(description="the sun's centroid [x, y] in the frame [px]")
    warnings: list[str] = Field(default_factory=list,
                                description="plain-language doubts about the frame (a field "
                                            "of view not given that the sun's disc belies)")
