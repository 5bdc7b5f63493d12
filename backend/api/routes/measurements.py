"""``/api/v1/sites/{site_id}/measurements``: field-logger ingestion and read-back.

POST takes ``{"readings": [...]}`` (JSON), emonCMS-style rows
``[[unix_s, array, voltage_v, current_a, power_w], ...]`` or ``text/csv`` with a
header row, plain or ``Content-Encoding: gzip`` (decoded by
:class:`backend.api.strict.StrictBodies`), validated in bulk by
:mod:`backend.measurements.parse` and committed by the writer before the answer
``{"accepted": N, "duplicates": M, "stored_through": ISO, "stored_through_unix_s": S}``
(a logger that buffered offline resumes after ``stored_through``). GET answers a range raw (when
it holds no more than ``max_points`` readings) or downsampled into buckets with
min/mean/max, as JSON or CSV.
"""

from __future__ import annotations

import asyncio
import csv
import io
import itertools
import logging
import re
from collections.abc import AsyncIterator, Iterator, Mapping
from concurrent.futures.process import BrokenProcessPool
from typing import Annotated, Any, Literal

import anyio
import numpy as np
import orjson
from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import Response, StreamingResponse
from starlette.datastructures import Headers
from starlette.requests import ClientDisconnect
from starlette.types import ASGIApp, Receive, Scope, Send

from backend.api.deps import ContextDep, check_site_token, site_or_404
from backend.context import ServiceContext
from backend.diagnosis.weather_twin import weather_twin_columns
from backend.measurements.export import influx_lines
from backend.measurements.fields import SENSOR_FIELDS
from backend.measurements.parse import Batch, IngestError, Limits, parse_csv_batch, parse_json_batch
from backend.measurements.queries import (
    QUANTITIES,
    count_rows,
    downsample,
    iso_utc,
    raw_rows,
    sensor_columns,
)
from backend.measurements.writer import MeasurementJob
from backend.storage.tables import SOURCE_CODES
from backend.timestamps import parse_range

logger = logging.getLogger(__name__)
router = APIRouter(prefix="/api/v1/sites", tags=["measurements"])

_JSON = "application/json"
_OFFLOAD_BYTES = 32 * 1024  # parse bigger bodies in a worker process (or thread)

def _none_of(*names: str) -> dict[str, Any]:
    return {"not": {"anyOf": [{"required": [n]} for n in names]}}


_READING: dict[str, Any] = {
    "type": "object", "required": ["ts", "array"], "additionalProperties": False,
    "oneOf": [{"required": ["voltage_v", "current_a"], **_none_of("voltage_adc", "current_adc")},
              {"required": ["voltage_adc", "current_adc"], **_none_of("voltage_v", "current_a")},
              {"required": ["power_w"], "description": "a power-only logger",
               **_none_of("voltage_v", "current_a", "voltage_adc", "current_adc")}],
    "properties": {
        "ts": {"type": "string", "format": "date-time", "minLength": 1,
               "description": "ISO 8601 with UTC offset"},
        "array": {"type": "string", "minLength": 1, "example": "tracker"},
        "voltage_v": {"type": "number"}, "current_a": {"type": "number"},
        "power_w": {"type": "number", "description": "voltage_v·current_a when absent; "
                    "alone (no voltage and current) from a power-only logger"},
        "voltage_adc": {"type": "integer",
                        "description": "raw divider ADC count (seed 000 eq. 19)"},
        "current_adc": {"type": "integer",
                        "description": "raw ACS712 ADC count (seed 000 eq. 17)"},
        **{f.name: {"type": "number", "minimum": f.low, "maximum": f.high,
                    "description": f"optional: {f.meaning}"} for f in SENSOR_FIELDS},
    },
}
_EMONCMS_ROW: dict[str, Any] = {
    "type": "array", "minItems": 4, "maxItems": 5,
    "description": "[unix_s, array, voltage_v, current_a, power_w]; power_w may be left off, "
                   "or voltage_v and current_a null for a power-only logger",
    "prefixItems": [{"type": "number", "description": "Unix time [s]"},
                    {"type": "string", "minLength": 1}, {"type": ["number", "null"]},
                    {"type": ["number", "null"]}, {"type": "number"}],
}
_POST_DOC: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": {"oneOf": [
                {"type": "object", "required": ["readings"], "additionalProperties": False,
                 "properties": {"readings": {"type": "array", "minItems": 1,
                                             "items": _READING}}},
                {"type": "array", "minItems": 1, "items": _EMONCMS_ROW,
                 "description": "emonCMS-style bulk rows"},
            ]}},
            "text/csv": {"schema": {"type": "string", "example":
                                    "ts,array,voltage_v,current_a,power_w\n"
                                    "2024-03-15T12:00:00-06:00,tracker,26.1,27.3,712.5\n"}},
        },
    },
}


def _limits(ctx: Any) -> Limits:
    s = ctx.settings
    return Limits(s.max_batch_rows, s.future_tolerance_s, s.max_voltage_v, s.max_current_a,
                  s.min_current_a, s.power_tolerance_w)


def _json(data: Any, status: int = 200) -> Response:
    return Response(orjson.dumps(data), status_code=status, media_type=_JSON)


def _too_large(msg: str) -> IngestError:
    return IngestError(413, [{"loc": ["body"], "row": None, "field": None, "type": "too_large",
                              "msg": msg}])


async def _read_body(chunks: AsyncIterator[bytes], length: str | None, limit: int) -> bytes:
    if length is not None and length.isdigit() and int(length) > limit:
        raise _too_large(f"body of {length} bytes; the limit is {limit} bytes "
                         "(HELIOTWIN_MAX_UPLOAD_BYTES): split the batch")
    parts: list[bytes] = []
    size = 0
    async for chunk in chunks:
        size += len(chunk)
        if size > limit:
            raise _too_large(f"body over {limit} bytes: split the batch")
        parts.append(chunk)
    return b"".join(parts)


async def ingest(ctx: ServiceContext, site_id: str, headers: Mapping[str, str],
                 chunks: AsyncIterator[bytes]) -> tuple[int, bytes, dict[str, str]]:
    """Authorise, read, validate and store one POST; ``(status, JSON body, headers)``."""
    try:
        await check_site_token(ctx, site_id, headers.get("authorization"))
        info = site_or_404(ctx, site_id)
    except HTTPException as exc:
        return exc.status_code, orjson.dumps({"detail": exc.detail}), dict(exc.headers or {})
    ctype = headers.get("content-type", _JSON).split(";")[0].strip().lower()
    try:
        if ctype not in (_JSON, "text/csv", "application/csv", ""):
            raise IngestError(415, [{"loc": ["header", "content-type"], "row": None,
                                     "field": "content-type", "type": "unsupported",
                                     "msg": f"Content-Type {ctype!r}: send application/json "
                                            "or text/csv"}])
        body = await _read_body(chunks, headers.get("content-length"),
                                ctx.settings.max_upload_bytes)
        parse = parse_csv_batch if ctype in ("text/csv", "application/csv") else parse_json_batch
        arrays, limits = info.ingest_arrays(), _limits(ctx)
        batch: Batch | None = None
        if len(body) > _OFFLOAD_BYTES and ctx.parsers is not None:
            try:
                batch = await asyncio.get_running_loop().run_in_executor(
                    ctx.parsers, parse, body, arrays, limits)
            except BrokenProcessPool:  # a parser died (memory?): validate on threads from now
                logger.exception("parser process pool broken; validating on threads instead")
                broken, ctx.parsers = ctx.parsers, None
                if broken is not None:
                    broken.shutdown(wait=False, cancel_futures=True)
        if batch is None and len(body) > _OFFLOAD_BYTES:
            batch = await anyio.to_thread.run_sync(parse, body, arrays, limits)
        elif batch is None:
            batch = parse(body, arrays, limits)
    except IngestError as exc:
        return exc.status, orjson.dumps({"detail": exc.errors}), {}
    job = MeasurementJob(batch.array_ids, SOURCE_CODES["measured"], batch.ts_s,
                         batch.voltage_v, batch.current_a, batch.power_w, batch.sensors)
    try:
        accepted, duplicates = await asyncio.wrap_future(ctx.writer.submit(job))
    except Exception as exc:  # nothing was committed: the logger should send it again
        logger.error("storing %d readings failed: %r", len(job), exc)
        return 503, orjson.dumps({"detail": f"storage unavailable ({type(exc).__name__}); "
                                            "nothing was stored, send the batch again"}), {
            "Retry-After": "5"}
    last_s = int(batch.ts_s.max())
    answer: dict[str, Any] = {"accepted": accepted, "duplicates": duplicates,
                              "stored_through": iso_utc(np.array([last_s]))[0],
                              "stored_through_unix_s": last_s}
    power_only = batch.power_only
    if power_only:
        answer["power_only"] = power_only
        answer["note"] = (f"{power_only} of {len(batch)} readings carry power_w without voltage "
                          "and current: their energy rests on the logger's power_w alone, "
                          "unchecked against voltage·current")
    return 200, orjson.dumps(answer), {}


def document_ingest(schema: dict[str, Any]) -> dict[str, Any]:
    """Add ``POST /api/v1/sites/{site_id}/measurements`` to an OpenAPI ``schema``.

    :class:`IngestFastPath` serves that request outside FastAPI's routing, so no
    route declares it; this is its one honest description (what it accepts and
    answers), merged beside the ``GET`` of the same path.
    """
    ops = schema.setdefault("paths", {}).setdefault("/api/v1/sites/{site_id}/measurements", {})
    ops["post"] = {
        "tags": ["measurements"],
        "summary": "Store readings of a site's arrays",
        "description": (
            "`Authorization: Bearer <site write token>`. Answers `{\"accepted\": N, "
            "\"duplicates\": M}` once the readings are committed; a reading whose (array, ts) "
            "is already stored counts as a duplicate; everything up to `stored_through` "
            "(the batch's latest reading) is then stored, so a logger that buffered offline "
            "resumes after it. A batch is validated whole: every problem is listed (up to "
            "10 per field and 50 in all, the rest counted) naming the row and the field, and "
            "nothing of the batch is stored. Bodies: JSON `{\"readings\": [...]}`, "
            "emonCMS-style rows `[[unix_s, array, voltage_v, current_a, power_w], ...]`, or "
            "CSV with a header row; unknown fields, keys given twice and CSV numbers other "
            "than plain decimals are 422s. `Content-Encoding: gzip` is decoded (at most "
            "HELIOTWIN_MAX_UPLOAD_BYTES once decompressed); other encodings are 415."),
        "operationId": "post_measurements",
        "parameters": [{"name": "site_id", "in": "path", "required": True,
                        "schema": {"type": "string"}}],
        **_POST_DOC,
        "responses": {
            "200": {"description": "stored", "content": {_JSON: {"schema": {
                "type": "object",
                "required": ["accepted", "duplicates", "stored_through", "stored_through_unix_s"],
                "properties": {
                    "accepted": {"type": "integer"}, "duplicates": {"type": "integer"},
                    "stored_through": {"type": "string", "format": "date-time",
                                       "description": "latest reading of the batch (UTC)"},
                    "stored_through_unix_s": {"type": "integer"},
                    "power_only": {"type": "integer", "description": (
                        "readings of the batch with power_w but no voltage and current "
                        "(present only when there are some)")},
                    "note": {"type": "string", "description": (
                        "what the energy of power-only readings rests on")}}}}}},
            **{str(c): {"description": d} for c, d in (
                (400, "a corrupt gzip body"),
                (401, "no or unknown token"), (403, "the token is for another site"),
                (404, "unknown site"), (413, "body too large"),
                (415, "not JSON or CSV, or a Content-Encoding other than gzip"),
                (422, "invalid rows (each named)"),
                (503, "storage unavailable; nothing stored, send again"))},
        },
    }
    return schema


class IngestFastPath:
    """ASGI middleware serving ``POST /api/v1/sites/{site_id}/measurements`` directly.

    Field loggers send this request more than all others together; FastAPI's
    routing and dependency solving cost more per request than validating and
    storing a reading, so the middleware hands it straight to :func:`ingest` —
    the only code path for it; :func:`document_ingest` describes it in OpenAPI.
    Everything else passes through untouched.
    """

    _PATH = re.compile(r"^/api/v1/sites/([^/]+)/measurements$")

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        match = (self._PATH.match(scope["path"])
                 if scope["type"] == "http" and scope["method"] == "POST" else None)
        if match is None:
            await self.app(scope, receive, send)
            return
        headers = Headers(scope=scope)  # what ``Request.headers`` gives the route

        async def chunks() -> AsyncIterator[bytes]:
            more = True
            while more:
                message = await receive()
                if message["type"] == "http.disconnect":
                    raise ClientDisconnect
                more = message.get("more_body", False)
                yield message.get("body", b"")

        try:
            status, body, extra = await ingest(scope["app"].state.ctx, match.group(1), headers,
                                               chunks())
        except ClientDisconnect:  # the logger hung up mid-body: nothing stored, no answer
            return
        out = [(b"content-type", b"application/json"),
               (b"content-length", str(len(body)).encode())]
        out += [(k.lower().encode(), v.encode()) for k, v in extra.items()]
        await send({"type": "http.response.start", "status": status, "headers": out})
        await send({"type": "http.response.body", "body": body})


def _range(info: Any, start: str, end: str) -> tuple[int, int]:
    try:
        t0, t1 = parse_range(start, end, info.zone)
    except ValueError as exc:
        raise HTTPException(422, str(exc)) from None
    return int(t0.timestamp()), int(t1.timestamp())


def _blank_nan(col: list[Any]) -> list[Any]:
    if not col or type(col[0]) is str:
        return col
    if not np.isnan(np.asarray(col, np.float64)).any():
        return col
    return ["" if x != x else x for x in col]


def _csv_lines(header: list[str], cols: list[list[Any]], chunk_rows: int = 20_000
               ) -> Iterator[str]:
    """The CSV text in pieces of ``chunk_rows`` rows (a year is not one string in memory);
    a value that is not there (NaN: a power-only reading's voltage) is an empty cell."""
    cols = [_blank_nan(c) for c in cols]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    rows = zip(*cols, strict=True)
    while part := list(itertools.islice(rows, chunk_rows)):
        w.writerows(part)
        yield buf.getvalue()
        buf.seek(0)
        buf.truncate()
    if buf.tell():  # no rows: the header alone
        yield buf.getvalue()


_GET_TEXT: dict[int | str, dict[str, Any]] = {200: {"content": {
    "text/csv": {"schema": {"type": "string"}},
    "text/plain": {"schema": {"type": "string", "description": (
        "format=influx: InfluxDB line protocol, measurement `heliotwin`, tags `array`, `site`, "
        "`source`, fields `voltage_v`, `current_a`, `power_w` (buckets: also `_min`, `_max`, "
        "`n`), nanosecond timestamps")},
        "example": "heliotwin,array=tracker,site=tehuantepec,source=measured voltage_v=26.1,"
                   "current_a=27.3,power_w=712.53 1710525600000000000\n"},
}}}


@router.get("/{site_id}/measurements", responses={**_GET_TEXT, 404: {}, 422: {}})
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
    max_points: Annotated[int | None, Query(ge=1, le=1_000_000)] = None,
    source: Annotated[Literal["measured", "twin", "twin_weather"], Query(description=(
        "measured: the logger's readings; twin: the clear-sky twin; twin_weather: the twin "
        "under the sky the fixed array measured (power only, computed on request, at most "
        "31 days; the answer's sky says what it rests on)"))] = "measured",
    format: Literal["json", "csv", "influx"] | None = None,
) -> Response:
    """Readings of one array over a range: raw, or min/mean/max buckets past ``max_points``."""
    info = site_or_404(ctx, site_id)
    if array not in info.arrays:
        raise HTTPException(422, f"array: unknown array {array[:40]!r}; "
                                 f"this site has {', '.join(info.arrays)}")
    t0, t1 = _range(info, start, end)
    want_text = format in ("csv", "influx") or (  # streamed: no max_json_points
        format is None and "text/csv" in request.headers.get("accept", ""))
    if source == "twin":
        ctx.twin.ensure(site_id, t0, t1)
    arr = info.arrays[array]
    cols: dict[str, list[Any]]
    if source == "twin_weather":
        cols, sky = weather_twin_columns(ctx, info, array, t0, t1)  # InputError: a 4xx
        n = len(cols["ts"])
        bucket_s = 0
        if max_points is not None and n > max_points:
            cols, bucket_s = _minute_buckets(cols, max_points)
        return _answer(request, site_id, array, source, start, end, t0, t1, format, cols,
                       bucket_s, n, sky)
    src = SOURCE_CODES[source]
    with ctx.engine.connect() as conn:
        n = count_rows(conn, arr.array_id, src, t0, t1, info.phase_s)
        limit = max_points if max_points is not None else (
            None if want_text else ctx.settings.max_json_points)
        if limit is not None and n > limit and max_points is None:
            raise HTTPException(422, f"{n} readings in the range; pass max_points (buckets) or "
                                     "format=csv or format=influx for all of them")
        if limit is None or n <= limit:
            rows = raw_rows(conn, arr.array_id, src, t0, t1, sensors=src == SOURCE_CODES[
                "measured"])
            bucket_s = 0
            cols = {"ts": iso_utc(rows[:, 0].astype(np.int64))}
            for j, q in enumerate(QUANTITIES):
                cols[q] = rows[:, j + 1].tolist()
            if rows.shape[1] > 4:
                cols.update(sensor_columns(rows))
        else:
            b = downsample(conn, arr.array_id, src, t0, t1, limit, info.phase_s)
            bucket_s = b.width_s
            cols = b.points()
    return _answer(request, site_id, array, source, start, end, t0, t1, format, cols,
                   bucket_s, n, None)


def _answer(request: Request, site_id: str, array: str, source: str, start: str, end: str,
            t0: int, t1: int, format: str | None, cols: dict[str, list[Any]], bucket_s: int,
            n: int, sky: dict[str, Any] | None) -> Response:
    """A measurements answer as JSON, CSV or line protocol."""
    want_csv = format == "csv" or (format is None and "text/csv" in
                                   request.headers.get("accept", ""))
    if format == "influx":
        return StreamingResponse(influx_lines(site_id, array, source, cols),
                                 media_type="text/plain; charset=utf-8")
    if want_csv:
        name = f"{site_id}_{array}_{source}_{start}_{end}.csv".replace(":", "")
        return StreamingResponse(_csv_lines(list(cols), list(cols.values())),
                                 media_type="text/csv",
                                 headers={"Content-Disposition": f'attachment; filename="{name}"'})
    keys = list(cols)
    points = [dict(zip(keys, vals, strict=True)) for vals in zip(*cols.values(), strict=True)]
    body: dict[str, Any] = {
        "site_id": site_id, "array": array, "source": source,
        "start": iso_utc(np.array([t0]))[0], "end": iso_utc(np.array([t1]))[0],
        "bucket_s": bucket_s, "count": n, "points": points}
    if sky is not None:
        body["sky"] = sky
    return _json(body)


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
