"""Shapes shared by several resources."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field, Strict

#: A JSON number where a request asks for one: an integer or a float, never a boolean
#: (``true`` read as 1 moved a sweep's latitude, a tester's finding) nor a numeric string.
#: For a model that cannot be strict throughout (FastAPI validates the parsed body in
#: Python mode, where a strict tuple refuses a JSON array).
JsonNumber = Annotated[float, Strict()]


class SunRead(BaseModel):
    """The sun's position: azimuth clockwise from true north, apparent elevation [°]."""

    azimuth_deg: float | None = Field(description="clockwise from true north [°]")
    elevation_deg: float | None = Field(description="apparent (refracted) elevation [°]")


#: Media types of the non-JSON answers, for ``responses={200: ...}``.
CSV_CONTENT = {"text/csv": {"schema": {"type": "string"}}}
PNG_CONTENT = {"image/png": {"schema": {"type": "string", "format": "binary"}}}
