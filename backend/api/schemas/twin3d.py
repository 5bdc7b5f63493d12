"""``/api/v1/twin3d``: the viser 3D twin's viewers and what they replay."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class ViewerRead(BaseModel):
    """One connected site viewer (a browser tab on the viser page)."""

    viewer: str
    site_id: str
    mode: Literal["live", "playing", "scrubbing"]
    time: str | None = Field(description="the instant shown, ISO 8601")
    replay_run_id: str | None
    fixed_shaded_fraction: float | None = Field(description="tracker's shade on the fixed "
                                                            "array [0, 1]")
    tracker_shadow_m: list[list[float]] = Field(description="the tracker collector's ground "
                                                            "shadow, (east, north) [m]")


class ViewersRead(BaseModel):
    """The viser port actually bound, the default site and every connected viewer."""

    viser_port: int
    default_site: str
    viewers: list[ViewerRead]


class ReplayRead(BaseModel):
    """A run shown in the 3D twin (at its first instant)."""

    run_id: str
    site_id: str
    viewer: str | None
    viewers: int = Field(description="viewers now replaying it")
    start: str
    end: str
    pointing_error_mrad: float | None


class ReplayClearedRead(BaseModel):
    """Back to live tracking."""

    replay: None
