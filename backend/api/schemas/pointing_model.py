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
                                                "the limit")
    correlated: list[CorrelationRead]


class PointingCommandRead(BaseModel):
    """Encoder angles that put the real optical axis on the sun at ``time``."""

    azimuth_deg: float = Field(description="encoder azimuth to command [°], [0, 360)")
    elevation_deg: float = Field(description="encoder elevation to command [°]")
    sun_azimuth_deg: float = Field(description="the sun's azimuth at time (SPA) [°]")
    sun_elevation_deg: float = Field(description="the sun's apparent elevation (SPA) [°]")
