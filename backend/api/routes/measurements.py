"""``/api/v1/sites/{site_id}/measurements``: field-logger ingestion and read-back.

POST (a plain route; the work is :func:`backend.measurements.ingest.ingest`) checks the
site's write token, then reads the body — ``{"readings": [...]}`` (JSON), emonCMS-style
rows ``[[unix_s, array, voltage_v, current_a, power_w], ...]`` or ``text/csv`` with a
header row, plain or ``Content-Encoding: gzip`` (:func:`backend.api.strict.read_body`) —
and answers :class:`~backend.api.schemas.measurements.IngestResult` once the writer has
committed the batch. GET answers a range raw (when it holds no more than ``max_points``
readings) or downsampled into buckets with min/mean/max, as JSON, CSV or line protocol.
"""

from __future__ import annotations

import csv
import io
import itertools
import logging
from collections.abc import Iterable, Iterator
from typing import Annotated, Any, Literal

import numpy as np
import orjson
from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import Response, StreamingResponse
from starlette.routing import compile_path

from backend.api import strict
from backend.api.deps import (
    ContextDep,
    anonymous_read_route,
    check_site_token,
    site_or_404,
    site_range,
)
from backend.api.schemas.measurements import IngestResult, MeasurementsRead, ingest_request_body
from backend.context import ServiceContext
from backend.diagnosis.weather_twin import weather_twin_columns
from backend.errors import InputError
from backend.limits import metered, metered_iter
from backend.measurements import ingest
from backend.measurements.export import influx_lines
from backend.measurements.parse import IngestError, Limits, body_error
from backend.measurements.queries import (
    QUANTITIES,
    bucket_grid,
    bucket_pages,
    count_rows,
    downsample,
    iso_utc,
    raw_pages,
    raw_rows,
    sensor_columns,
)
from backend.storage.tables import SOURCE_CODES

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/api/v1/sites", tags=["measurements"])

_JSON = "application/json"
#: Readings (or buckets) a streamed CSV or line-protocol export reads and holds at once
#: (≈ 10 MB).
EXPORT_PAGE_ROWS = 20_000
#: The one path of the resource; POST is logger ingest, whose body the route reads itself.
_PATH = "/{site_id}/measurements"
#: Requests :class:`backend.api.strict.StrictBodies` leaves to the ingest route (it checks
#: the token first, then reads, decodes and checks the body itself).
INGEST_PATH = compile_path(router.prefix + _PATH)[0]

_INGEST_DOC = (
    "`Authorization: Bearer <site write token>`, checked before the body is read. Answers "
    "once the readings are committed; a reading whose (array, ts) is already stored counts "
    "as a duplicate; everything up to `stored_through` (the batch's latest reading) is then "
    "stored, so a logger that buffered offline resumes after it. A batch is validated whole: "
    "every problem is listed (up to 10 per field and 50 in all, the rest counted) naming the "
    "row and the field, and nothing of the batch is stored. Bodies: JSON `{\"readings\": "
    "[...]}`, emonCMS-style rows `[[unix_s, array, voltage_v, current_a, power_w], ...]`, or "
    "CSV with a header row; unknown fields, keys given twice and CSV numbers other than plain "
    "decimals are 422s. `Content-Encoding: gzip` is decoded (at most "
    "HELIOTWIN_MAX_UPLOAD_BYTES once decompressed); other encodings are 415.")


def _rejected(status: int, entries: list[dict[str, Any]]) -> Response:
    return Response(orjson.dumps({"detail": entries}), status_code=status, media_type=_JSON)


@router.post(
    _PATH, response_model=IngestResult, response_model_exclude_none=True,
    summary="Store readings of a site's arrays", description=_INGEST_DOC,
    operation_id="post_measurements", openapi_extra={"requestBody": ingest_request_body()},
    responses={400: {"description": "a corrupt gzip body"},
               401: {"description": "no or unknown token"},
               403: {"description": "the token is for another site"},
               404: {"description": "unknown site"}, 413: {"description": "body too large"},
               415: {"description": "not JSON or CSV, or a Content-Encoding other than gzip"},
               422: {"description": "invalid rows (each named)"},
               503: {"description": "storage unavailable; nothing stored (of a batch over "
                                     "HELIOTWIN_WRITER_MAX_GROUP_ROWS readings: the count "
                                     "the message gives), send again"}})
async def post_measurements(site_id: str, request: Request) -> IngestResult | Response:
    """Store a logger's batch (JSON readings, emonCMS rows or CSV), all or nothing.

    The busiest request of the service: the token is checked here, first (before the body
    is read), rather than by dependencies (``ContextDep``, ``SiteAdminDep``): in a profile
    of single-reading requests, solving those cost as much as validating the reading.
    """
    ctx: ServiceContext = request.app.state.ctx
    await check_site_token(ctx, site_id, request.headers.get("authorization"))
    info = site_or_404(ctx, site_id)
    try:
        parse = ingest.parser_for(request.headers.get("content-type"))
        try:
            body = await strict.read_body(request, ctx.settings.server.max_upload_bytes)
        except InputError as exc:  # the transport's problems, in the shape of the others
            kind = {413: "too_large", 415: "unsupported"}.get(exc.status_code, "value_error")
            raise body_error(exc.status_code, None, kind, exc.detail) from None
        stored = await ingest.ingest(ctx.writer, parse, body, info.ingest_arrays(),
                                     Limits.from_settings(ctx.settings))
    except IngestError as exc:
        return _rejected(exc.status, exc.errors)
    except ingest.StorageUnavailable as exc:
        raise HTTPException(503, str(exc), headers={"Retry-After": "5"}) from None
    answer = IngestResult(accepted=stored.accepted, duplicates=stored.duplicates,
                          stored_through=iso_utc([stored.stored_through_s])[0],
                          stored_through_unix_s=stored.stored_through_s)
    if stored.power_only:
        answer.power_only = stored.power_only
        answer.note = (f"{stored.power_only} of {stored.readings} readings carry power_w "
                       "without voltage and current: their energy rests on the logger's "
                       "power_w alone, unchecked against voltage·current")
    return answer


def _blank_nan(col: list[Any]) -> list[Any]:
    if not col or type(col[0]) is str:
        return col
    if not np.isnan(np.asarray(col, np.float64)).any():
        return col
    return ["" if x != x else x for x in col]


def _csv_lines(header: list[str], pages: Iterable[list[list[Any]]], chunk_rows: int = 20_000
               ) -> Iterator[str]:
    """The CSV text of ``pages`` of columns, in pieces of at most ``chunk_rows`` rows (a
    year is not one string in memory); a value that is not there (NaN: a power-only
    reading's voltage) is an empty cell."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for cols in pages:
        rows = zip(*[_blank_nan(c) for c in cols], strict=True)
        while part := list(itertools.islice(rows, chunk_rows)):
            w.writerows(part)
            yield buf.getvalue()
            buf.seek(0)
            buf.truncate()
    if buf.tell():  # no rows: the header alone
        yield buf.getvalue()


def _raw_columns(rows: np.ndarray, sensors: list[str]) -> dict[str, list[Any]]:
    """The answer's columns of :func:`raw_rows` rows: ts, the quantities, ``sensors``."""
    cols: dict[str, list[Any]] = {"ts": iso_utc(rows[:, 0].astype(np.int64))}
    for j, q in enumerate(QUANTITIES):
        cols[q] = rows[:, j + 1].tolist()
    if rows.shape[1] > 4:
        cols.update(sensor_columns(rows, sensors))
    return cols


_GET_TEXT: dict[int | str, dict[str, Any]] = {200: {"content": {
    "text/csv": {"schema": {"type": "string"}},
    "text/plain": {"schema": {"type": "string", "description": (
        "format=influx: InfluxDB line protocol, measurement `heliotwin`, tags `array`, `site`, "
        "`source`, fields `voltage_v`, `current_a`, `power_w` (buckets: also `_min`, `_max`, "
        "`n`), nanosecond timestamps")},
        "example": "heliotwin,array=tracker,site=tehuantepec,source=measured voltage_v=26.1,"
                   "current_a=27.3,power_w=712.53 1710525600000000000\n"},
}}}


@router.get(_PATH, response_model=MeasurementsRead,
            **anonymous_read_route({**_GET_TEXT, 404: {}, 422: {}}))
def get_measurements(
    site_id: str,
    request: Request,
    ctx: ContextDep,
    array: Annotated[str, Query(min_length=1, max_length=64,
                                description="array name, e.g. tracker")],
    start: Annotated[str, Query(min_length=1, max_length=64,
                                description="date or ISO date-time, inclusive")],
    end: Annotated[str, Query(min_length=1, max_length=64,
                              description="date or ISO date-time, exclusive")],
    max_points: Annotated[int | None, Query(ge=1, le=1_000_000, description=(
        "more readings than this are answered as min/mean/max buckets; a JSON answer holds "
        "at most HELIOTWIN_MAX_JSON_POINTS whatever this asks"))] = None,
    source: Annotated[Literal["measured", "twin", "twin_weather"], Query(description=(
        "measured: the logger's readings; twin: the clear-sky twin; twin_weather: the twin "
        "under the sky the fixed array measured (power only, computed on request, at most "
        "31 days; the answer's sky says what it rests on)"))] = "measured",
    format: Literal["json", "csv", "influx"] | None = None,
) -> Response:
    """Readings of one array over a range: raw, or min/mean/max buckets past ``max_points``.
    Without a token the CPU time of the read (a streamed CSV or line protocol body
    included) comes out of the address's ``HELIOTWIN_ANONYMOUS_READ_CPU_S_PER_MIN``."""
    with metered():
        info, start_dt, end_dt = site_range(ctx, site_id, start, end)
        if array not in info.arrays:
            raise HTTPException(422, f"array: unknown array {array[:40]!r}; "
                                     f"this site has {', '.join(info.arrays)}")
        t0, t1 = int(start_dt.timestamp()), int(end_dt.timestamp())
        want_text = format in ("csv", "influx") or (  # streamed: no max_json_points
            format is None and "text/csv" in request.headers.get("accept", ""))
        if source == "twin":
            ctx.twin.ensure(site_id, t0, t1)
        arr = info.arrays[array]
        if source == "twin_weather":
            cols, sky = weather_twin_columns(ctx, info, array, t0, t1)  # InputError: a 4xx
            n = len(cols["ts"])
            bucket_s = 0
            if max_points is not None and n > max_points:
                cols, bucket_s = _minute_buckets(cols, max_points)
            return _answer(request, site_id, array, source, start, end, t0, t1, format, [cols],
                           bucket_s, n, sky)
        src = SOURCE_CODES[source]
        measured = src == SOURCE_CODES["measured"]
        with ctx.engine.connect() as conn:
            n, sensors = count_rows(conn, arr.array_id, src, t0, t1, info.phase_s)
            sensors = sensors if measured else []
            # a JSON answer holds at most max_json_points, max_points or not (a tester's
            # max_points=1000000 built 200,001 raw points past the setting, anonymously)
            cap = None if want_text else ctx.settings.ingest.max_json_points
            limit = max_points if cap is None else min(max_points or cap, cap)
            if max_points is None and limit is not None and n > limit:
                raise HTTPException(422, f"{n} readings in the range; pass max_points (buckets) or "
                                         "format=csv or format=influx for all of them")
            if limit is not None and n > limit and not want_text:
                b = downsample(conn, arr.array_id, src, t0, t1, limit, info.phase_s)
                return _answer(request, site_id, array, source, start, end, t0, t1, format,
                               [b.points()], b.width_s, n, None)
            if not want_text:
                rows = raw_rows(conn, arr.array_id, src, t0, t1, sensors=measured)
                return _answer(request, site_id, array, source, start, end, t0, t1, format,
                               [_raw_columns(rows, sensors)], 0, n, None)
        if limit is not None and n > limit:  # streamed buckets, page by page, as raw rows
            pages = (b.points(sensors) for b in bucket_pages(
                ctx.engine, arr.array_id, src, t0, t1, limit, info.phase_s, EXPORT_PAGE_ROWS))
            return _answer(request, site_id, array, source, start, end, t0, t1, format, pages,
                           bucket_grid(t0, t1, limit, info.phase_s)[1], n, None)
        # streamed raw: page by page after this returns, the header decided by count_rows
        pages = (_raw_columns(rows, sensors) for rows in
                 raw_pages(ctx.engine, arr.array_id, src, t0, t1, measured, EXPORT_PAGE_ROWS))
        header = ["ts", *QUANTITIES, *sensors]
        return _answer(request, site_id, array, source, start, end, t0, t1, format, pages, 0,
                       n, None, header)


def _answer(request: Request, site_id: str, array: str, source: str, start: str, end: str,
            t0: int, t1: int, format: str | None, pages: Iterable[dict[str, list[Any]]],
            bucket_s: int, n: int, sky: dict[str, Any] | None, header: list[str] | None = None
            ) -> Response:
    """A measurements answer as JSON, CSV or line protocol from ``pages`` of columns: one
    page, or for CSV and line protocol an iterator of them made as the body is sent, whose
    column names ``header`` gives."""
    want_csv = format == "csv" or (format is None and "text/csv" in
                                   request.headers.get("accept", ""))
    if format == "influx":
        lines = itertools.chain.from_iterable(influx_lines(site_id, array, source, cols)
                                              for cols in pages)
        return StreamingResponse(metered_iter(lines), media_type="text/plain; charset=utf-8")
    if want_csv:
        if header is None:  # the first page's columns, every page's
            pages = iter(pages)
            first = next(pages)
            header = list(first)
            pages = itertools.chain([first], pages)
        name = f"{site_id}_{array}_{source}_{start}_{end}.csv".replace(":", "")
        text = _csv_lines(header, (list(cols.values()) for cols in pages))
        return StreamingResponse(metered_iter(text), media_type="text/csv",
                                 headers={"Content-Disposition": f'attachment; filename="{name}"'})
    (cols,) = pages
    keys = list(cols)
    points = [dict(zip(keys, vals, strict=True)) for vals in zip(*cols.values(), strict=True)]
    body: dict[str, Any] = {
        "site_id": site_id, "array": array, "source": source,
        "start": iso_utc(np.array([t0]))[0], "end": iso_utc(np.array([t1]))[0],
        "bucket_s": bucket_s, "count": n, "points": points}
    if sky is not None:
        body["sky"] = sky
    return Response(orjson.dumps(body), media_type=_JSON)


def _minute_buckets(cols: dict[str, list[Any]], max_points: int
                    ) -> tuple[dict[str, list[Any]], int]:
    """Minute columns of the weather-aware twin in at most ``max_points`` buckets of whole
    minutes from the first: mean/min/max power, ``n`` minutes, ``sky_valid`` share."""
    n = len(cols["ts"])
    k = -(-n // max_points)
    p = np.array(cols["power_w"], np.float64)
    valid = np.array(cols["sky_valid"], np.float64)
    first = np.arange(0, n, k)
    counts = np.diff(np.append(first, n))
    out: dict[str, list[Any]] = {
        "ts": [cols["ts"][i] for i in first.tolist()], "n": counts.tolist(),
        "voltage_v": [None] * first.size, "current_a": [None] * first.size,
        "power_w": (np.add.reduceat(p, first) / counts).tolist(),
        "power_w_min": np.minimum.reduceat(p, first).tolist(),
        "power_w_max": np.maximum.reduceat(p, first).tolist(),
        "sky_valid": (np.add.reduceat(valid, first) / counts).tolist(),
    }
    return out, 60 * k
