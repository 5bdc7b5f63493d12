"""Logger ingest as a service: one request's bytes → a validated batch → the writer → counts.

``POST /api/v1/sites/{site_id}/measurements`` (``backend/api/routes/measurements.py``)
authorises, reads and decodes the body, then calls :func:`ingest`: the body is
validated whole by :mod:`backend.measurements.parse` (JSON or CSV, chosen by its
media type) and handed to the single writer; :func:`ingest` returns only once the
writer has committed it (a batch over ``HELIOTWIN_WRITER_MAX_GROUP_ROWS`` readings: all
its pieces), so an answered batch survives a killed process.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from backend.measurements.parse import (
    Batch,
    IngestArray,
    Limits,
    body_error,
    parse_csv_batch,
    parse_json_batch,
)
from backend.measurements.writer import MeasurementJob, PartlyStored, Writer
from backend.storage.tables import SOURCE_CODES

logger = logging.getLogger(__name__)

JSON = "application/json"
CSV_TYPES = frozenset(("text/csv", "application/csv"))
#: Bodies bigger than this are validated on the parse thread: the event loop keeps
#: answering the other loggers meanwhile (a 1,000-reading batch is ~100 kB).
THREAD_FROM_BYTES = 32 * 1024
#: One thread validates the big bodies, one after another. Parsing holds the GIL almost
#: throughout, so more threads (anyio's default pool has 40) only convoy on it with the
#: event loop and the writer: a back-fill over HTTP stored 112–114k rows/s (35 % of raw
#: executemany) with the default pool and 122–134k (39–42 %) with this one thread
#: (benchmarks/bench_service.py --only backfill, same machine, 2026-12-04).
_PARSE_THREAD = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ingest-parse")

Parser = Callable[[bytes, dict[str, IngestArray], Limits], Batch]


class StorageUnavailable(Exception):
    """The writer could not commit the batch: nothing of it is stored, or of a batch
    committed in pieces the pieces before the failure (the message says how many); either
    way, send it again."""


@dataclass(frozen=True)
class Stored:
    """What one committed batch did: readings new and already stored, its latest reading's
    time (everything up to it is now stored) and how many carried power alone."""

    accepted: int
    duplicates: int
    stored_through_s: int
    power_only: int
    readings: int


def parser_for(content_type: str | None) -> Parser:
    """The validator of a body of this ``Content-Type`` (none: JSON); 415 for any other."""
    media = (content_type or JSON).split(";")[0].strip().lower()
    if media in (JSON, ""):
        return parse_json_batch
    if media in CSV_TYPES:
        return parse_csv_batch
    raise body_error(415, "content-type", "unsupported",
                     f"Content-Type {media[:60]!r}: send application/json or text/csv",
                     loc=["header", "content-type"])


def measured_job(batch: Batch) -> MeasurementJob:
    """The writer's job for a validated batch of logger readings."""
    return MeasurementJob(batch.array_ids, SOURCE_CODES["measured"], batch.ts_s,
                          batch.voltage_v, batch.current_a, batch.power_w, batch.sensors)


async def ingest(writer: Writer, parse: Parser, body: bytes,
                 arrays: dict[str, IngestArray], limits: Limits) -> Stored:
    """Validate ``body`` and store it; returns once the writer has committed it.

    Raises :class:`backend.measurements.parse.IngestError` for a bad batch (nothing
    stored) and :class:`StorageUnavailable` when the commit failed.
    """
    if len(body) > THREAD_FROM_BYTES:
        batch = await asyncio.get_running_loop().run_in_executor(
            _PARSE_THREAD, parse, body, arrays, limits)
    else:
        batch = parse(body, arrays, limits)
    job = measured_job(batch)
    try:
        accepted, duplicates = await asyncio.wrap_future(writer.submit(job))
    except PartlyStored as exc:  # a batch committed in pieces: the first ones are stored
        logger.error("storing %d readings failed after %d: %r", len(job), exc.stored,
                     exc.__cause__)
        raise StorageUnavailable(
            f"storage unavailable ({type(exc.__cause__).__name__}); {exc.stored} of "
            f"{exc.total} readings were stored before it failed: send the batch again (the "
            "stored ones count as duplicates, none twice)") from exc
    except Exception as exc:  # nothing was committed: the logger should send it again
        logger.error("storing %d readings failed: %r", len(job), exc)
        raise StorageUnavailable(f"storage unavailable ({type(exc).__name__}); nothing was "
                                 "stored, send the batch again") from exc
    return Stored(accepted, duplicates, int(np.max(batch.ts_s)), batch.power_only, len(batch))
