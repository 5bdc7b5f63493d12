"""``/healthz`` and ``/api/v1/meta``."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field


class HealthRead(BaseModel):
    """Liveness."""

    status: Literal["ok"]


class MachineParameterRead(BaseModel):
    """One machine parameter of a twin scenario (``backend/twin/parameters.py``)."""

    name: str = Field(description="the field of POST /api/v1/simulations, unit in the name")
    default: float
    minimum: float | None
    maximum: float | None
    help: str


class MetaRead(BaseModel):
    """What the dashboard needs to know about this service."""

    mqtt: str = Field(description="`disabled`, `connected` or `retrying`")
    mqtt_status: dict[str, Any] | None = Field(
        description="the broker and the message counters; null without HELIOTWIN_MQTT_URL")
    version: str
    viser_port: int = Field(description="the port the 3D scene really listens on")
    viser_public_port: int = Field(description=(
        "the port browsers reach the 3D scene on, at the dashboard's host name: "
        "HELIOTWIN_VISER_PUBLIC_PORT, else viser_port"))
    viser_enabled: bool
    vision_require_token: bool
    read_require_token: bool = Field(
        description="reads of the sites' data need a token (HELIOTWIN_READ_REQUIRE_TOKEN): "
                    "the dashboard asks for one before it reads")
    default_site: str
    energy_max_gap_s: int = Field(description="longest gap energy bridges [s]")
    docs_url: str
    controllers: list[str]
    receivers: list[str]
    machine_parameters: list[MachineParameterRead]
