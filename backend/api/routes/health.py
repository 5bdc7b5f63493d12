"""``/healthz`` and ``/api/v1/meta``."""

from __future__ import annotations

import dataclasses
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from fastapi import APIRouter, Request

from backend.api.deps import SettingsDep
from backend.api.schemas.service import HealthRead, MetaRead
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
    free port when the configured one is busy. ``mqtt`` is ``disabled`` (no
    ``HELIOTWIN_MQTT_URL``), ``connected`` or ``retrying``; ``mqtt_status`` adds the
    broker and the message counters.
    """
    scene = getattr(request.app.state, "scene", None)
    ctx = getattr(request.app.state, "ctx", None)
    mqtt = None if ctx is None or ctx.mqtt is None else ctx.mqtt.status()
    return {
        "mqtt": "disabled" if mqtt is None else mqtt["state"],
        "mqtt_status": mqtt,
        "version": service_version(),
        "viser_port": scene.port if scene is not None else settings.server.viser_port,
        "viser_enabled": scene is not None,
        "vision_require_token": settings.vision.require_token,
        "default_site": settings.sites.default_site,
        "energy_max_gap_s": settings.ingest.energy_max_gap_s,
        "docs_url": "/docs",
        "controllers": list(CONTROLLERS),
        "receivers": list(RECEIVERS),
        "machine_parameters": [dataclasses.asdict(p) for p in MACHINE_PARAMETERS],
    }
