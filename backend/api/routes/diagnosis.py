"""``/api/v1/sites/{site_id}/diagnosis``: per day, the tracker against the weather-aware twin
and the faults found; ``…/pointing``: the pointing error from the tracker's encoder angles
(``backend/diagnosis``, ``docs/diagnosis.md``)."""

from __future__ import annotations

from typing import Literal

import orjson
from fastapi import APIRouter, HTTPException
from fastapi.responses import Response
from pydantic import BaseModel, Field

from backend.api.deps import CallerDep, ContextDep, RangeEnd, RangeStart, site_or_404
from backend.api.schemas.diagnosis import (
    DiagnosisDayRead,
    DiagnosisRead,
    FixedDayRead,
    PointingRead,
    TrackerDayRead,
)
from backend.diagnosis.pointing import pointing
from backend.diagnosis.service import ANONYMOUS_MAX_COMPUTED_DAYS, diagnosis
from backend.timestamps import parse_range

router = APIRouter(prefix="/api/v1/sites", tags=["diagnosis"])

MountTerm = Literal["azimuth_zero_deg", "elevation_zero_deg", "pedestal_tilt_north_deg",
                    "pedestal_tilt_east_deg", "collimation_deg", "nonperpendicularity_deg"]


class MountFaultRead(BaseModel):
    """A mount fault from the tracker camera's offsets (``backend/diagnosis/mount.py``)."""

    kind: Literal["mount_offset", "encoder_slip"] = Field(
        description="`mount_offset`: a significant term of the pointing model; "
                    "`encoder_slip`: a term that stepped from one day to the next")
    term: MountTerm = Field(description="the pointing model's term (docs/pointing-model.md)")
    value_deg: float = Field(description="`mount_offset`: the term's value; "
                                         "`encoder_slip`: the step (after − before) [°]")
    std_deg: float = Field(description="its standard error [°] (a step: both days' combined)")
    n_observations: int = Field(description="camera observations it was fitted from")
    since: str = Field(description="local date: the slip's first day, or the first day of "
                                   "the observations the offset was fitted from")
    detail: str = Field(description="the finding in words, e.g. 'pedestal yaw (azimuth "
                                    "zero) +2.00° ± 0.01° (from 380 camera observations …)'")


class MountRead(BaseModel):
    """The mount as the tracker camera measured it in the range."""

    n_observations: int = Field(description="observations of the fit of the offsets (those "
                                            "since the last slip, if any)")
    n_outliers: int
    residual_rms_mrad: float
    since: str = Field(description="local date of the first of those observations")
    faults: list[MountFaultRead] = Field(description="slips (oldest first), then offsets")


class DiagnosisTrackerDayRead(TrackerDayRead):
    """The tracker's day (null numbers on a day still to come)."""

    expected_wh: float | None  # type: ignore[assignment]
    expected_wh_low: float | None = Field(  # type: ignore[assignment]
        description="band of the sky inversion's uncertainty")
    expected_wh_high: float | None  # type: ignore[assignment]


class DiagnosisFixedDayRead(FixedDayRead):
    """The fixed array's day (null numbers on a day still to come)."""

    expected_wh: float | None  # type: ignore[assignment]


class DiagnosisDayStatusRead(DiagnosisDayRead):
    """One local day, with its status."""

    status: Literal["complete", "in_progress", "future"] = Field(
        description="`complete`: the day is over; `in_progress`: judged up to now; "
                    "`future`: it starts after now, nothing computed (its numbers null, "
                    "sky source `none`)")
    tracker: DiagnosisTrackerDayRead  # type: ignore[assignment]
    fixed: DiagnosisFixedDayRead  # type: ignore[assignment]


class DiagnosisMountRead(DiagnosisRead):
    """Per local day: sky, energy, PR, gains and faults; the mount faults from the camera."""

    days: list[DiagnosisDayStatusRead]  # type: ignore[assignment]
    mount: MountRead | None = Field(description="null: no camera observations (sun offsets "
                                                "with the encoder angles) in the range")


@router.get("/{site_id}/diagnosis", response_model=DiagnosisMountRead,
            responses={401: {}, 404: {}, 422: {}},
            openapi_extra={"security": [{}, {"bearerAuth": []}]})
def get_diagnosis(
    site_id: str,
    ctx: ContextDep,
    start: RangeStart,
    end: RangeEnd,
    caller: CallerDep,
) -> Response:
    """Per local day: sky, measured and expected energy, PR, gains and faults; a day not
    yet over (``status`` ``in_progress``) is judged on its minutes before now, a day to come
    (``future``) costs nothing. ``mount``: the mount faults from the tracker camera's sun
    offsets. Without a token a request computes at most ``ANONYMOUS_MAX_COMPUTED_DAYS``
    (31) days not cached yet (422 naming ``end``)."""
    info = site_or_404(ctx, site_id)
    try:
        t0, t1 = parse_range(start, end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    body = diagnosis(ctx, info, t0, t1, max_computed_days=None if caller is not None
                     else ANONYMOUS_MAX_COMPUTED_DAYS)
    return Response(orjson.dumps(body), media_type="application/json")


@router.get("/{site_id}/pointing", response_model=PointingRead, responses={404: {}, 422: {}})
def get_pointing(
    site_id: str,
    ctx: ContextDep,
    start: RangeStart,
    end: RangeEnd,
) -> Response:
    """The tracker's pointing error every minute the sun is up, from the encoder angles
    its logger reports (``azimuth_deg``, ``elevation_deg``): summary, per day, and the
    minutes (every k-th past ``HELIOTWIN_MAX_JSON_POINTS``, ``points_step`` = k)."""
    info = site_or_404(ctx, site_id)
    try:
        t0, t1 = parse_range(start, end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    with ctx.engine.connect() as conn:
        body = pointing(conn, info, t0, t1, ctx.settings.ingest.max_json_points)
    return Response(orjson.dumps(body), media_type="application/json")
