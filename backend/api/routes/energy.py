"""``/api/v1/sites/{site_id}/energy``: energy per hour, day or month, measured beside the twin.

Periods are local calendar hours/days/months of the site, clipped to
``[start, end)``. ``measured_wh`` is null for a period without readings;
``twin_wh`` comes from the twin series, computed and stored on demand for past
days (``TwinService.ensure``). ``gain_pct`` is the tracking gain
``100·(tracker/fixed − 1)`` from measured energy, null when either is missing;
``twin_gain_pct`` the same from the twin. Energy does not bridge gaps longer
than ``HELIOTWIN_ENERGY_MAX_GAP_S`` (see ``docs/service.md``).

``/api/v1/sites/{site_id}/report`` (JSON), ``report.csv`` and ``report.png`` give the
totals, daily, monthly and annual tables of a range (``backend/reports.py``).

Without a token each of these reads is charged the CPU time it took to the address's
``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN`` (``backend.api.deps.anonymous_read``).
"""

from __future__ import annotations

import asyncio
import csv
import io
import weakref
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Annotated, Any, Literal

import anyio
import orjson
from fastapi import APIRouter, Query, Request
from fastapi.responses import Response

from backend.api.deps import (
    CallerDep,
    ContextDep,
    RangeEnd,
    RangeStart,
    anonymous_read_route,
    client_address,
    site_range,
)
from backend.api.routes.health import service_version
from backend.api.schemas.common import CSV_CONTENT, PNG_CONTENT
from backend.api.schemas.energy import EnergyRead, ReportRead
from backend.diagnosis.service import ANONYMOUS_MAX_COMPUTED_DAYS, computed_days_cap
from backend.diagnosis.weather_twin import weather_twin_energy
from backend.limits import run_metered
from backend.measurements.energy import energy_rows
from backend.reports import report, report_csv, report_png

router = APIRouter(prefix="/api/v1/sites", tags=["energy"])


#: Energy and report reads served at once; more wait their turn on the event loop. Each
#: read's Python work holds the GIL, which the event loop (every logger's request) and
#: the writer need as well: 10 readers back to back on 10 threads took the GIL from them
#: ten times as often as one. bench_load (15 s runs in turn, load 2-4): writes beside 10
#: month readers p99 98 and 40 ms with one at once (75 and 115 reads/s), 165 and 174 ms
#: with two (68 and 98 reads/s): one also reads more, with less GIL hand-over.
READS_AT_ONCE = 1
_read_limiters: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, anyio.CapacityLimiter] = (
    weakref.WeakKeyDictionary())


#: Of these reads, those of one address without a token that take places in that line at
#: once; its others wait behind them, off the line. The line is served in order of
#: arrival: 16 100-year reads of one address (5 s each), within its CPU allowance, kept
#: another address's 28-day read waiting 38–130 s (a tester's finding, session 25); now
#: it waits behind at most two of them. (Not a 429: a dashboard whose user flips through
#: days has more in flight, the aborted ones still running.)
READS_IN_LINE_PER_CLIENT = 2
_lines: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop,
                                  dict[str, tuple[asyncio.Semaphore, list[int]]]] = (
    weakref.WeakKeyDictionary())


def read_limiter() -> anyio.CapacityLimiter:
    """The running event loop's limiter of :data:`READS_AT_ONCE` reads."""
    loop = asyncio.get_running_loop()
    limiter = _read_limiters.get(loop)
    if limiter is None:
        limiter = _read_limiters[loop] = anyio.CapacityLimiter(READS_AT_ONCE)
    return limiter


@asynccontextmanager
async def in_line(request: Request, caller: object) -> AsyncIterator[None]:
    """The caller's turn to join the reader's line: without a token, once fewer than
    :data:`READS_IN_LINE_PER_CLIENT` of the address's reads are in it (the address's own
    semaphore, on the event loop; dropped when none of its reads is left)."""
    if caller is not None:
        yield
        return
    lines = _lines.setdefault(asyncio.get_running_loop(), {})
    client = client_address(request)
    if client not in lines:
        lines[client] = (asyncio.Semaphore(READS_IN_LINE_PER_CLIENT), [0])
    turn, users = lines[client]
    users[0] += 1
    try:
        async with turn:
            yield
    finally:
        users[0] -= 1
        if not users[0]:
            del lines[client]


@router.get("/{site_id}/energy", response_model=EnergyRead,
            **anonymous_read_route({200: {"content": CSV_CONTENT}, 404: {}, 422: {}}))
async def get_energy(
    site_id: str,
    request: Request,
    ctx: ContextDep,
    start: RangeStart,
    end: RangeEnd,
    caller: CallerDep,
    interval: Literal["hour", "day", "month"] = "day",
    format: Literal["json", "csv"] = "json",
    source: Annotated[Literal["twin_weather"] | None, Query(description=(
        "twin_weather: also the energy of the twin under the sky the fixed array measured "
        "(twin_weather_wh, twin_weather_gain_pct), beside measured and the clear-sky twin; "
        f"without a token at most {ANONYMOUS_MAX_COMPUTED_DAYS} days not diagnosed yet "
        "(422 naming end)"
    ))] = None,
) -> Response:
    """Energy per period for every array, measured and twin, with the tracking gain.
    ``source=twin_weather`` diagnoses the days it needs: without a token, as the
    diagnosis, at most ``ANONYMOUS_MAX_COMPUTED_DAYS`` (31) not cached yet."""
    async with in_line(request, caller):
        return await anyio.to_thread.run_sync(
            run_metered, _energy, site_id, ctx, start, end, interval, format, source,
            computed_days_cap(caller), limiter=read_limiter())


def _energy(site_id: str, ctx: ContextDep, start: str, end: str, interval: str, format: str,
            source: str | None, max_computed_days: int | None) -> Response:
    info, t0, t1 = site_range(ctx, site_id, start, end)
    data = energy_rows(ctx, info, t0, t1, interval)
    if source == "twin_weather":
        weather_twin_energy(ctx, info, data, max_computed_days)
    if format == "csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        names = list(info.arrays)
        keys: tuple[str, ...] = ("measured_wh", "twin_wh", "twin_matched_wh", "coverage_pct")
        if source == "twin_weather":
            keys += ("twin_weather_wh",)
        w.writerow(["period_start", "period_end", *[f"{n}_{k}" for n in names for k in keys],
                    "gain_pct", "twin_gain_pct", "twin_matched_gain_pct", "partial",
                    "gain_note", "twin_note"])
        for r in data["rows"]:
            w.writerow([r["period_start"], r["period_end"],
                        *[r["arrays"][n][k] for n in names for k in keys],
                        r["gain_pct"], r["twin_gain_pct"], r["twin_matched_gain_pct"],
                        r["partial"], r["gain_note"], r["twin_note"]])
        return Response(buf.getvalue(), media_type="text/csv", headers={
            "Content-Disposition": f'attachment; filename="{site_id}_energy_{interval}.csv"'})
    return Response(orjson.dumps(data), media_type="application/json")


_RANGE = {
    "start": Query(description="date (site midnight) or ISO date-time, inclusive"),
    "end": Query(description="date or ISO date-time, exclusive"),
}


async def _report(request: Request, caller: object, ctx: ContextDep, site_id: str, start: str,
                  end: str, shape: Callable[[dict[str, Any]], Any] = lambda rep: rep) -> Any:
    """``shape`` of the report of a range, on AnyIO's pool under :func:`read_limiter`."""
    def work() -> Any:
        info, t0, t1 = site_range(ctx, site_id, start, end)
        return shape(report(ctx, info, t0, t1))

    async with in_line(request, caller):
        return await anyio.to_thread.run_sync(run_metered, work, limiter=read_limiter())


@router.get("/{site_id}/report", response_model=ReportRead,
            **anonymous_read_route({404: {}, 422: {}}))
async def get_report(site_id: str, request: Request, caller: CallerDep, ctx: ContextDep,
                     start: Annotated[str, _RANGE["start"]],
                     end: Annotated[str, _RANGE["end"]]) -> Response:
    """Totals, daily, monthly and annual energy, gain and performance ratio of a range."""
    body = await _report(request, caller, ctx, site_id, start, end, orjson.dumps)
    return Response(body, media_type="application/json")


@router.get("/{site_id}/report.csv", response_class=Response, **anonymous_read_route(
    {200: {"content": CSV_CONTENT, "description": "the report as CSV"}, 404: {}, 422: {}}))
async def get_report_csv(site_id: str, request: Request, caller: CallerDep, ctx: ContextDep,
                         start: Annotated[str, _RANGE["start"]],
                         end: Annotated[str, _RANGE["end"]]) -> Response:
    """The report as one CSV table: day, month, year and total rows, units in the names."""
    name, body = await _report(request, caller, ctx, site_id, start, end, lambda rep: (
        f"{site_id}_report_{rep['start'][:10]}_{rep['end'][:10]}.csv", report_csv(rep)))
    return Response(body, media_type="text/csv",
                    headers={"Content-Disposition": f'attachment; filename="{name}"'})


@router.get("/{site_id}/report.png", response_class=Response, **anonymous_read_route(
    {200: {"content": PNG_CONTENT, "description": "an A4 PNG page"}, 404: {}, 422: {}}))
async def get_report_png(site_id: str, request: Request, caller: CallerDep, ctx: ContextDep,
                         start: Annotated[str, _RANGE["start"]],
                         end: Annotated[str, _RANGE["end"]]) -> Response:
    """A one-page A4 PNG report of the range (matplotlib), for a paper or a logbook."""
    name, body = await _report(request, caller, ctx, site_id, start, end, lambda rep: (
        f"{site_id}_report_{rep['start'][:10]}_{rep['end'][:10]}.png",
        report_png(rep, service_version())))
    return Response(body, media_type="image/png",
                    headers={"Content-Disposition": f'inline; filename="{name}"'})
