"""``/healthz``, ``/api/v1/meta`` and ``/api/v1/live-twin``."""

from __future__ import annotations

import dataclasses
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field

from backend.api.deps import ContextDep, SettingsDep
from backend.api.schemas.service import HealthRead, MetaRead
from backend.api.security import viser_listen_port, viser_public_port
from backend.measurements.queries import iso_utc
from backend.twin.parameters import MACHINE_PARAMETERS
from sim.twin import CONTROLLERS, RECEIVERS

router = APIRouter(tags=["service"])


def service_version() -> str:
    """The installed package version."""
    try:
        return version("heliotwin")
    except PackageNotFoundError:
        return "0+unknown"


@router.get("/healthz", response_model=HealthRead)
def healthz() -> dict[str, str]:
    """Liveness: the service answers."""
    return {"status": "ok"}


@router.get("/api/v1/meta", response_model=MetaRead)
def meta(request: Request, settings: SettingsDep) -> dict[str, Any]:
    """What the dashboard needs to know about this service.

    ``viser_port`` is the port the 3D scene really listens on: it moves to the next
    free port when the configured one is busy; ``viser_public_port`` the one a browser
    reaches it on (``HELIOTWIN_VISER_PUBLIC_PORT``, e.g. a container's published port;
    else ``viser_port``), which the dashboard frames and its CSP allows. ``mqtt`` is
    ``disabled`` (no ``HELIOTWIN_MQTT_URL``), ``connected`` or ``retrying``;
    ``mqtt_status`` adds the broker and the message counters.
    """
    scene = getattr(request.app.state, "scene", None)
    ctx = getattr(request.app.state, "ctx", None)
    mqtt = None if ctx is None or ctx.mqtt is None else ctx.mqtt.status()
    return {
        "mqtt": "disabled" if mqtt is None else mqtt["state"],
        "mqtt_status": mqtt,
        "version": service_version(),
        "viser_port": viser_listen_port(request.app),
        "viser_public_port": viser_public_port(request.app),
        "viser_enabled": scene is not None,
        "vision_require_token": settings.vision.require_token,
        "read_require_token": settings.server.read_require_token,
        "default_site": settings.sites.default_site,
        "energy_max_gap_s": settings.ingest.energy_max_gap_s,
        "docs_url": "/docs",
        "controllers": list(CONTROLLERS),
        "receivers": list(RECEIVERS),
        "machine_parameters": [dataclasses.asdict(p) for p in MACHINE_PARAMETERS],
    }


class LiveTwinRead(BaseModel):
    """Whether the live twin keeps up (``backend.twin.service.LiveClock``)."""

    enabled: bool = Field(description="the live loop runs (HELIOTWIN_LIVE_TWIN)")
    interval_s: float | None = Field(description="its tick (HELIOTWIN_LIVE_TWIN_INTERVAL_S)")
    ticks: int = Field(description="ticks finished since the service started")
    last_minute_utc: str | None = Field(description="the minute the last tick stored")
    last_done_utc: str | None = Field(description="when the last tick's readings were committed")
    lag_s: float | None = Field(description=(
        "how late the loop is [s]: of a tick still running, now minus when it was due; "
        "else the last tick's commit minus when it was due"))
    max_lag_s: float | None = Field(description="the largest lag of the last 60 ticks [s]")
    last_start_delay_s: float | None = Field(description=(
        "of the last tick: from when it was due until its step began (the live thread's "
        "wake-up: the CPU and the GIL) [s]"))
    last_step_s: float | None = Field(description=(
        "of the last tick: from when its step began until its readings were committed "
        "(the twin's minute, the writer's queue and commit) [s]"))


@router.get("/api/v1/live-twin", response_model=LiveTwinRead)
async def live_twin(ctx: ContextDep) -> dict[str, Any]:
    """The live twin loop's lag: how long after its due time each minute was stored."""
    clock = ctx.twin.clock
    if clock is None:
        return {"enabled": False, "interval_s": None, "ticks": 0, "last_minute_utc": None,
                "last_done_utc": None, "lag_s": None, "max_lag_s": None,
                "last_start_delay_s": None, "last_step_s": None}
    st = clock.status()
    return {
        "enabled": True, "interval_s": st["interval_s"], "ticks": st["ticks"],
        "last_minute_utc": None if st["last_minute_s"] is None
        else iso_utc([st["last_minute_s"]])[0],
        "last_done_utc": None if st["last_done_s"] is None
        else iso_utc([int(st["last_done_s"])])[0],
        "lag_s": st["lag_s"], "max_lag_s": st["max_lag_s"],
        "last_start_delay_s": st["last_start_delay_s"], "last_step_s": st["last_step_s"],
    }
