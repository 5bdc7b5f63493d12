"""Shapes shared by several resources."""

from __future__ import annotations

from pydantic import BaseModel, Field


class SunRead(BaseModel):
    """The sun's position: azimuth clockwise from true north, apparent elevation [°]."""

    azimuth_deg: float | None = Field(description="clockwise from true north [°]")
    elevation_deg: float | None = Field(description="apparent (refracted) elevation [°]")


#: Media types of the non-JSON answers, for ``responses={200: ...}``.
CSV_CONTENT = {"text/csv": {"schema": {"type": "string"}}}
PNG_CONTENT = {"image/png": {"schema": {"type": "string", "format": "binary"}}}
