"""``/api/v1/sites/{site_id}/measurements``: a logger's readings in, stored readings out.

The request models (:class:`ReadingIn`, :class:`ReadingsIn`, :data:`EmoncmsRow`) document
the ingest body in OpenAPI (:func:`ingest_request_body`); the body itself is validated in
bulk by :mod:`backend.measurements.parse`, whose fields they mirror
(``tests/backend/test_measurements_api.py`` checks that both name the same fields).
"""

from __future__ import annotations

from typing import Any

from pydantic import AwareDatetime, BaseModel, ConfigDict, Field, TypeAdapter, create_model

from backend.measurements.fields import SENSOR_FIELDS


def _none_of(*names: str) -> dict[str, Any]:
    return {"not": {"anyOf": [{"required": [n]} for n in names]}}


class _ReadingBase(BaseModel):
    """One reading of one array: volts and amperes, raw ADC counts, or power alone."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"oneOf": [
        {"required": ["voltage_v", "current_a"], **_none_of("voltage_adc", "current_adc")},
        {"required": ["voltage_adc", "current_adc"], **_none_of("voltage_v", "current_a")},
        {"required": ["power_w"], "description": "a power-only logger",
         **_none_of("voltage_v", "current_a", "voltage_adc", "current_adc")},
    ]})

    ts: AwareDatetime = Field(description="ISO 8601 with a UTC offset; a naive time is a 422")
    array: str = Field(min_length=1, examples=["tracker"])
    voltage_v: float | None = None
    current_a: float | None = None
    power_w: float | None = Field(default=None, description=(
        "voltage_v·current_a when absent; alone (no voltage and current) from a power-only "
        "logger"))
    voltage_adc: int | None = Field(default=None,
                                    description="raw divider ADC count (seed 000 eq. 19)")
    current_adc: int | None = Field(default=None,
                                    description="raw ACS712 ADC count (seed 000 eq. 17)")


#: A reading with the optional sensor fields of :data:`SENSOR_FIELDS` (one list of them).
ReadingIn: type[BaseModel] = create_model(
    "ReadingIn", __base__=_ReadingBase, __doc__=_ReadingBase.__doc__,
    **{f.name: (float | None, Field(default=None, ge=f.low, le=f.high,
                                    description=f"optional: {f.meaning}"))
       for f in SENSOR_FIELDS},  # type: ignore[call-overload]
)


class ReadingsIn(BaseModel):
    """The JSON body: ``{"readings": [...]}``."""

    model_config = ConfigDict(extra="forbid")

    readings: list[ReadingIn] = Field(min_length=1)  # type: ignore[valid-type]


#: emonCMS-style bulk row ``[unix_s, array, voltage_v, current_a(, power_w)]``; voltage and
#: current null for a power-only logger.
EmoncmsRow = (tuple[float, str, float | None, float | None]
              | tuple[float, str, float | None, float | None, float])

CSV_EXAMPLE = ("ts,array,voltage_v,current_a,power_w\n"
               "2024-03-15T12:00:00-06:00,tracker,26.1,27.3,712.5\n")


def _inline(schema: dict[str, Any]) -> dict[str, Any]:
    """A pydantic JSON schema with its ``$defs`` written in place of their ``$ref`` (a
    request body given by ``openapi_extra`` has no components of its own to point into)."""
    defs = schema.pop("$defs", {})

    def walk(node: Any) -> Any:
        if isinstance(node, dict):
            ref = node.get("$ref", "")
            if ref.startswith("#/$defs/"):
                rest = {k: v for k, v in node.items() if k != "$ref"}
                return walk({**defs[ref.removeprefix("#/$defs/")], **rest})
            return {k: walk(v) for k, v in node.items()}
        if isinstance(node, list):
            return [walk(v) for v in node]
        return node

    return walk(schema)  # type: ignore[no-any-return]


def ingest_request_body() -> dict[str, Any]:
    """The OpenAPI ``requestBody`` of the ingest POST: JSON (readings or emonCMS rows) or CSV."""
    rows = TypeAdapter(list[EmoncmsRow]).json_schema()
    rows.update(minItems=1, description="emonCMS-style bulk rows [unix_s, array, voltage_v, "
                                        "current_a, power_w]; power_w may be left off")
    json_body = {"oneOf": [_inline(ReadingsIn.model_json_schema()), _inline(rows)]}
    return {"required": True, "content": {
        "application/json": {"schema": json_body},
        "text/csv": {"schema": {"type": "string", "example": CSV_EXAMPLE,
                                "description": "a header row naming the same fields"}},
    }}


class IngestResult(BaseModel):
    """What a stored batch did. The whole batch is stored, up to ``stored_through`` (its
    own latest reading, not the site's): a logger sending its buffer oldest first resumes
    after it."""

    accepted: int = Field(description="readings stored now")
    duplicates: int = Field(description="readings whose (array, ts) was already stored")
    stored_through: str = Field(json_schema_extra={"format": "date-time"},
                                description="this batch's latest reading (UTC), not the site's")
    stored_through_unix_s: int
    power_only: int | None = Field(default=None, description=(
        "readings with power_w but no voltage and current (present only when there are some)"))
    note: str | None = Field(default=None,
                             description="what the energy of power-only readings rests on")


class PointRead(BaseModel):
    """A stored reading (``bucket_s`` 0), or a bucket's mean with min/max and count.

    A value no reading had (a power-only logger's voltage) is null; sensor fields appear
    when some reading of the range carried them.
    """

    model_config = ConfigDict(extra="allow")

    ts: str = Field(description="ISO 8601 UTC: the reading's time or the bucket's start")
    voltage_v: float | None
    current_a: float | None
    power_w: float | None
    n: int | None = Field(default=None, description="buckets: readings (minutes) in the bucket")


class MeasurementsRead(BaseModel):
    """Readings of one array over ``[start, end)``: raw, or min/mean/max buckets."""

    site_id: str
    array: str
    source: str = Field(description="`measured`, `twin` or `twin_weather`")
    start: str = Field(description="ISO 8601 UTC, inclusive")
    end: str = Field(description="ISO 8601 UTC, exclusive")
    bucket_s: int = Field(description="0: readings as stored; else the bucket width [s]")
    count: int = Field(description="readings in the range")
    points: list[PointRead]
    sky: dict[str, Any] | None = Field(
        None, description="source=twin_weather: the measured sky the twin rests on")
