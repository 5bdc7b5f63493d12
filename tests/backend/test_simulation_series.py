"""``GET /api/v1/simulations/{run_id}/series`` streamed (issue 23 item 2): ranges, a
coarser step, CSV and JSON alike, and a per-address allowance for reads without a token.

One service in this process (SQLite) and one three-day run at 60 s (4,320 rows); the
reference for every read is the run's packed series read whole (``npz_to_series``).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from typing import Any

import numpy as np
import pandas as pd
import pytest
from live_service import InProcessServer, new_database

from backend.twin.export import export_names
from backend.twin.series_read import bucket_means

CELLS_PER_MIN = 100_000  # one full read of the run (4,320 rows × ≈ 20 values) a minute


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    db = new_database("sqlite", tmp_path_factory.mktemp("series"))
    server = InProcessServer(db.url, extra_env={
        "HELIOTWIN_ANONYMOUS_SERIES_CELLS_PER_MIN": str(CELLS_PER_MIN)}).start()
    try:
        auth = {"Authorization": f"Bearer {server.token()}"}
        with server.client(headers=auth) as c:
            r = c.post("/api/v1/simulations", json={
                "site_id": "tehuantepec", "start": "2024-06-01", "end": "2024-06-04"})
            assert r.status_code == 200, r.text
        run_id = r.json()["run_id"]
        series = server.ctx.simulations.series(run_id)
        assert series is not None
        yield {"server": server, "auth": auth, "run_id": run_id, "series": series,
               "url": f"/api/v1/simulations/{run_id}/series"}
    finally:
        server.stop()


def test_a_range_at_full_resolution(run: dict[str, Any]) -> None:
    """A local day of a three-day run: its 1,440 minutes as computed, NaN as null."""
    with run["server"].client(headers=run["auth"]) as c:
        got = c.get(run["url"], params={"start": "2024-06-02", "end": "2024-06-03"}).json()
    ref = run["series"]
    day = ref[(ref.index >= pd.Timestamp("2024-06-02", tz="America/Mexico_City"))
              & (ref.index < pd.Timestamp("2024-06-03", tz="America/Mexico_City"))]
    assert got["bucket_s"] == 0 and len(got["points"]) == len(day) == 1440
    assert got["points"][0]["ts"] == "2024-06-02T06:00:00Z"  # local midnight, UTC−6
    names = export_names(list(ref.columns))
    assert got["columns"] == names
    values = np.array([[np.nan if p[n] is None else p[n] for n in names]
                       for p in got["points"]])
    np.testing.assert_allclose(values, day.to_numpy(), rtol=1e-12, equal_nan=True)


def test_a_coarser_step_and_csv(run: dict[str, Any]) -> None:
    """``step_s`` 600: means of 10 rows each, the same in JSON and CSV; a step that is not a
    whole multiple of the run's is a 422 naming ``step_s``."""
    ref = run["series"]
    want = bucket_means(ref.to_numpy(), 10)
    with run["server"].client(headers=run["auth"]) as c:
        got = c.get(run["url"], params={"step_s": 600}).json()
        text = c.get(run["url"], params={"step_s": 600, "format": "csv"}).text
        bad = c.get(run["url"], params={"step_s": 90})
        empty = c.get(run["url"], params={"start": "2025-01-01", "format": "csv"})
    assert got["bucket_s"] == 600 and len(got["points"]) == 432
    power = np.array([p["tracker_power_w"] for p in got["points"]])
    np.testing.assert_allclose(power, want[:, list(ref.columns).index("tracker_power_w")],
                               rtol=1e-12)
    rows = list(csv.DictReader(io.StringIO(text)))
    assert len(rows) == 432 and rows[0]["time_local"] == "2024-06-01T00:00:00-06:00"
    np.testing.assert_allclose([float(r["tracker_power_w"]) for r in rows], power, atol=1e-4)
    assert bad.status_code == 422 and "step_s" in bad.json()["detail"]
    assert empty.status_code == 200 and empty.text.startswith("time_utc,time_local,")
    assert empty.text.count("\n") == 1


def test_reads_without_a_token_are_bounded(run: dict[str, Any]) -> None:
    """Without a token an address reads ``HELIOTWIN_ANONYMOUS_SERIES_CELLS_PER_MIN`` values a
    minute: a second whole read is a 429 with Retry-After; a thinned read still fits."""
    with run["server"].client() as c:
        first = c.get(run["url"], params={"format": "csv"})
        second = c.get(run["url"], params={"format": "csv"})
        thin = c.get(run["url"], params={"max_points": 100})
    assert first.status_code == 200 and first.text.count("\n") == 4321
    assert second.status_code == 429, second.text[:200]
    assert "HELIOTWIN_ANONYMOUS_SERIES_CELLS_PER_MIN" in second.json()["detail"]
    assert int(second.headers["retry-after"]) >= 1
    assert thin.status_code == 200 and len(thin.json()["points"]) <= 100


def test_ended_runs_in_memory_are_bounded(run: dict[str, Any]) -> None:
    """The runner remembers the newest ``KEEP_ENDED`` ended runs (issue 23 item 5: runs
    with a token stayed in memory forever); an older one is still read from the
    database."""
    from backend.twin.simulations import KEEP_ENDED, RunState

    runner = run["server"].ctx.simulations
    with runner._lock:
        for k in range(KEEP_ENDED + 50):
            runner._runs[f"old-{k}"] = RunState(f"old-{k}", "tehuantepec", "done")
    runner._ended(RunState("old-0", "tehuantepec", "running"), "done")
    assert sum(s.status in ("done", "failed") for s in runner._runs.values()) == KEEP_ENDED
    assert run["run_id"] not in runner._runs and "old-0" not in runner._runs
    state = runner.get(run["run_id"])            # the real run, from its row
    assert state is not None and state.status == "done" and state.summary


def test_the_suns_azimuth_is_averaged_as_a_direction(run: dict[str, Any]) -> None:
    """At Tehuantepec in June the noon sun passes north of the zenith: its azimuth crosses
    360° → 0° inside a bucket. The bucket's azimuth is the circular mean of its minutes
    (scipy's circmean, an independent implementation), not the plain one (≈ 180°, south;
    the midnight sun's hour read 272° at Tromsø: a tester's finding); a joint angle, which
    winds on past 360°, keeps its plain mean."""
    from scipy.stats import circmean

    ref = run["series"]
    with run["server"].client(headers=run["auth"]) as c:
        got = c.get(run["url"], params={"step_s": 3600}).json()
    served = np.array([np.nan if p["solar_azimuth_deg"] is None else p["solar_azimuth_deg"]
                       for p in got["points"]])
    az = ref["solar_azimuth"].to_numpy().reshape(-1, 60)
    crossing = [k for k in range(len(az)) if az[k].max() - az[k].min() > 180]
    assert crossing, "no hour of the run has the sun cross north"
    for k in crossing:
        assert served[k] == pytest.approx(circmean(az[k], high=360.0), abs=1e-6)
        assert min(served[k], 360.0 - served[k]) < 45.0            # north, not south
    joint = np.array([p["azimuth_joint_deg"] for p in got["points"]])
    np.testing.assert_allclose(
        joint, ref["azimuth_joint_deg"].to_numpy().reshape(-1, 60).mean(axis=1), rtol=1e-9)
