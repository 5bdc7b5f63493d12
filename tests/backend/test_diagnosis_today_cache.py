"""Today's diagnosis (a day in progress) is kept in memory, keyed on what it rests on: a
read in the same minute with no new reading answers it without the fits, a new reading
or the next minute computes it again. Every read of today re-ran the weather-aware twin
and the fits before (160-185 ms over HTTP at Delhi's afternoon, 9 h of demo readings).
In process on a SQLite file of its own, the clock set by the test (``now_s``)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from live_service import service_context

import backend.diagnosis.service as service
from backend.context import ServiceContext
from backend.measurements.writer import MeasurementJob
from sim.sites import load_site
from tests.sim.realistic_sky import logger_days

DAY = "2025-10-06"


@pytest.fixture
def ctx(tmp_path: Path) -> Iterator[ServiceContext]:
    with service_context("sqlite", tmp_path, alerts=False) as context:
        yield context


def _store(ctx: ServiceContext, array: str, times: pd.DatetimeIndex, power_w: np.ndarray
           ) -> None:
    aid = ctx.registry.sites["tehuantepec"].arrays[array].array_id
    ok = np.isfinite(power_w)
    ts = times[ok].as_unit("s").asi8
    nan = np.full(ts.size, np.nan)
    job = MeasurementJob(np.full(ts.size, aid), 0, ts, nan, nan, power_w[ok])
    assert ctx.writer.submit(job).result(timeout=60)[0] == ts.size


def test_todays_diagnosis_is_cached_until_a_reading_or_the_minute_changes(
        ctx: ServiceContext, monkeypatch: pytest.MonkeyPatch) -> None:
    site = load_site("tehuantepec")
    day0 = pd.Timestamp(DAY, tz=site.timezone)
    d = logger_days(site, day0, 1, seed=25)
    noon = day0 + pd.Timedelta(hours=12)
    before = d.times < noon - pd.Timedelta(minutes=5)  # the last 5 minutes come later
    _store(ctx, "fixed", d.times[before], d.fixed_power_w[before])
    _store(ctx, "tracker", d.times[before], d.tracker_power_w[before])
    computed: list[int] = []
    real = service._compute

    def compute(*args: Any, **kwargs: Any) -> dict[int, dict[str, Any]]:
        computed.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(service, "_compute", compute)
    info = ctx.registry.sites["tehuantepec"]
    start, end = day0.to_pydatetime(), (day0 + pd.Timedelta(days=1)).to_pydatetime()

    def today(at: pd.Timestamp) -> dict[str, Any]:
        return service.diagnosis(ctx, info, start, end, now_s=at.timestamp())

    first = today(noon + pd.Timedelta(seconds=5))
    assert first["days"][0]["status"] == "in_progress" and len(computed) == 1
    again = today(noon + pd.Timedelta(seconds=50))  # the same minute, no new reading
    assert len(computed) == 1 and again == first
    late = (d.times >= noon - pd.Timedelta(minutes=5)) & (d.times < noon)
    _store(ctx, "tracker", d.times[late], d.tracker_power_w[late])
    fresh = today(noon + pd.Timedelta(seconds=55))  # a new reading: computed again
    assert len(computed) == 2
    gained = fresh["days"][0]["tracker"]["measured_wh"] - first["days"][0]["tracker"][
        "measured_wh"]
    assert gained > 0, (fresh["days"][0]["tracker"], first["days"][0]["tracker"])
    assert today(noon + pd.Timedelta(seconds=56)) == fresh and len(computed) == 2
    today(noon + pd.Timedelta(seconds=65))  # the next minute: judged up to it
    assert len(computed) == 3
