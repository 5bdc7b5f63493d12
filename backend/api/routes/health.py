"""``/healthz`` and ``/api/v1/meta``."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version
from typing import Any

from fastapi import APIRouter

from backend.api.deps import SettingsDep
from sim.twin import CONTROLLERS

router = APIRouter(tags=["service"])


def service_version() -> str:
    """The installed package version."""
    try:
        return version("heliotwin")
    except PackageNotFoundError:
        return "0+unknown"


@router.get("/healthz")
def healthz() -> dict[str, str]:
    """Liveness: the service answers."""
    return {"status": "ok"}


@router.get("/api/v1/meta")
def meta(settings: SettingsDep) -> dict[str, Any]:
    """What the dashboard needs to know about this service."""
    return {
        "version": service_version(),
        "viser_port": settings.viser_port,
        "viser_enabled": settings.viser,
        "vision_require_token": settings.vision_require_token,
        "default_site": settings.default_site,
        "energy_max_gap_s": settings.energy_max_gap_s,
        "docs_url": "/docs",
        "controllers": list(CONTROLLERS),
    }
