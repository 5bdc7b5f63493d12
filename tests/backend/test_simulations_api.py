"""``/api/v1/simulations``: synchronous summary, background runs with progress, series."""

from __future__ import annotations

import csv
import io
import os
import re
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import pandas as pd
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import event, select

from backend.app import create_app
from backend.settings import get_settings
from backend.storage.tables import SimulationRun, SimulationSeries
from backend.twin.simulations import npz_to_series
from sim.sites import load_site
from sim.twin import simulate


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the answer, not storage
def test_sync_summary_is_the_twin_summary(client: httpx.Client) -> None:
    """The synchronous answer is ``simulate``'s summary to 1e-9. On SQLite only: the
    answer is computed, not read back (a run's storage on both back-ends:
    ``test_background_run_progress_and_series``)."""
    r = client.post("/api/v1/simulations", json={"site_id": "tehuantepec",
                                                 "start": "2024-03-15", "end": "2024-03-16"})
    assert r.status_code == 200, r.text
    got = r.json()
    site = load_site("tehuantepec")
    ref = simulate(site, pd.Timestamp("2024-03-15", tz=site.timezone),
                   pd.Timestamp("2024-03-16", tz=site.timezone)).summary()
    for key in ("tracker_energy_wh", "fixed_energy_wh", "gain_pct", "tracker_peak_w",
                "fixed_peak_w"):
        assert got[key] == pytest.approx(ref[key], rel=1e-9)
    assert got["site_id"] == "tehuantepec" and got["run_id"]


def test_background_run_progress_and_series(client: httpx.Client) -> None:
    r = client.post("/api/v1/simulations", json={
        "site_id": "tehuantepec", "start": "2024-01-01", "end": "2024-03-01", "step_s": 60,
        "background": True})
    assert r.status_code == 202, r.text
    run = r.json()
    assert set(run) >= {"run_id", "status", "progress"}
    url = f"/api/v1/simulations/{run['run_id']}"
    seen = []
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        state = client.get(url).json()
        seen.append(state["progress"])
        if state["status"] in ("done", "failed"):
            break
        time.sleep(0.05)
    assert state["status"] == "done", state
    assert seen == sorted(seen) and seen[-1] == 1.0
    assert state["summary"]["tracker_energy_wh"] > state["summary"]["fixed_energy_wh"] > 0
    series = client.get(f"{url}/series", params={"max_points": 500}).json()
    assert 0 < len(series["points"]) <= 500 and series["bucket_s"] > 0
    assert "tracker_power_w" in series["points"][0]
    text = client.get(f"{url}/series", params={"format": "csv", "max_points": 100}).text
    rows = list(csv.DictReader(io.StringIO(text)))
    assert len(rows) <= 100 and float(max(r["tracker_power_w"] for r in rows)) > 0


def test_simulation_errors(client: httpx.Client) -> None:
    r = client.post("/api/v1/simulations", json={"start": "2024-01-02", "end": "2024-01-01"})
    assert r.status_code == 422
    r = client.post("/api/v1/simulations", json={"start": "2024-01-01", "end": "2030-01-01",
                                                 "step_s": 1})
    assert r.status_code == 422 and "limit" in r.json()["detail"]
    assert "189,388,800 steps" in r.json()["detail"]  # a number a person reads, not 1.894e+08
    r = client.post("/api/v1/simulations", json={"site_id": "mars", "start": "2024-01-01",
                                                 "end": "2024-01-02"})
    assert r.status_code == 404
    assert client.get("/api/v1/simulations/nope").status_code == 404
    for path in ("/api/v1/simulations/%00", "/api/v1/simulations/a%00b/series"):
        assert client.get(path).status_code == 404  # a NUL: PostgreSQL's error was a 500
    assert client.delete("/api/v1/simulations/%00").status_code == 404


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # answers, not storage
def test_sites_and_meta(client: httpx.Client) -> None:
    sites = {s["site_id"]: s for s in client.get("/api/v1/sites").json()}
    assert set(sites["tehuantepec"]["arrays"]) == {"tracker", "fixed"}
    one = client.get("/api/v1/sites/tehuantepec").json()
    assert one["arrays"]["tracker"]["kind"] == "tracker"
    assert one["arrays"]["fixed"]["calibration"]["current_sensitivity_mv_per_a"] == 100.0
    assert client.get("/healthz").json() == {"status": "ok"}
    assert "ideal" in client.get("/api/v1/meta").json()["controllers"]
    assert client.get("/docs").status_code == 200
    paths = client.get("/openapi.json").json()["paths"]
    ingest = paths["/api/v1/sites/{site_id}/measurements"]
    assert set(ingest) == {"get", "post"}  # POST is served by the middleware, documented once
    assert set(ingest["post"]["requestBody"]["content"]) == {"application/json", "text/csv"}
    assert {"401", "413", "422"} <= set(ingest["post"]["responses"])


def test_results_are_written_by_the_writer(tmp_path: Path) -> None:
    """A run's series and its summary reach the database through the one writer thread of
    the web process (the worker process sends them back; it opens no database)."""
    settings = get_settings(database_url=f"sqlite:///{tmp_path / 'sim.sqlite'}", viser=False,
                            live_twin=False, demo_logger=False, alerts=False, mqtt_url=None)
    writes: list[tuple[str, str, int]] = []
    with TestClient(create_app(settings)) as client:
        ctx = client.app.state.ctx  # type: ignore[attr-defined]

        @event.listens_for(ctx.engine, "before_cursor_execute")
        def note(_conn: Any, _cur: Any, statement: str, *_: Any) -> None:
            table = re.search(r"\bsimulation_\w+", statement)
            if statement.split()[0] in ("INSERT", "UPDATE", "DELETE") and table:
                writes.append((table.group(), threading.current_thread().name, os.getpid()))

        r = client.post("/api/v1/simulations", json={
            "site_id": "tehuantepec", "start": "2024-03-15", "end": "2024-03-17"})
        assert r.status_code == 200, r.text
        run_id = r.json()["run_id"]
        with ctx.engine.connect() as conn:
            status = conn.execute(select(SimulationRun.status).where(
                SimulationRun.run_id == run_id)).scalar_one()
            blob = conn.execute(select(SimulationSeries.npz).where(
                SimulationSeries.run_id == run_id)).scalar_one()
    assert status == "done"
    assert len(npz_to_series(blob)) == 2 * 1440
    assert {table for table, _, _ in writes} == {"simulation_runs", "simulation_series"}
    assert {(name, pid) for _, name, pid in writes} == {("heliotwin-writer", os.getpid())}


def test_cancel_queued_and_running_runs(client: httpx.Client, live_server: Any) -> None:
    """``DELETE /api/v1/simulations/{id}``: a running run's worker is stopped, a queued run
    leaves the queue; both end ``failed`` with the error ``cancelled`` and no series."""
    year = {"site_id": "tehuantepec", "start": "2023-01-01", "end": "2024-01-01",
            "controller": "hybrid", "background": True}  # minutes of work: never done here
    auth = {"Authorization": f"Bearer {live_server.write_token}"}  # beyond an anonymous run
    running = client.post("/api/v1/simulations", json=year, headers=auth).json()["run_id"]
    queued = client.post("/api/v1/simulations", json=year, headers=auth).json()["run_id"]
    deadline = time.monotonic() + 60
    while client.get(f"/api/v1/simulations/{running}").json()["status"] == "queued":
        assert time.monotonic() < deadline, "the first run never started"
        time.sleep(0.05)
    for run_id in (queued, running):
        r = client.delete(f"/api/v1/simulations/{run_id}")
        assert r.status_code == 200, r.text
        assert (r.json()["status"], r.json()["error"]) == ("failed", "cancelled")
        assert client.get(f"/api/v1/simulations/{run_id}").json()["error"] == "cancelled"
        assert client.get(f"/api/v1/simulations/{run_id}/series").status_code == 409
    assert client.delete("/api/v1/simulations/nope").status_code == 404
    r = client.post("/api/v1/simulations", json={"site_id": "tehuantepec",
                                                 "start": "2024-03-15", "end": "2024-03-16"})
    assert r.status_code == 200, r.text  # the slot is free again


def test_open_loop_model_takes_the_pointing_model_answers_terms(client: httpx.Client) -> None:
    """POST with the terms as GET …/pointing-model answers them: the model cancels the
    pedestal yaw; the terms are kept in the run's params; misuse is a 422 naming the field."""
    body = {"site_id": "tehuantepec", "start": "2024-03-15T10:00-06:00",
            "end": "2024-03-15T12:00-06:00", "controller": "open_loop_model",
            "pedestal_yaw_deg": 2.0,
            "pointing_model_terms": {"azimuth_zero_deg": {"value": 2.0, "std": None}}}
    r = client.post("/api/v1/simulations", json=body)
    assert r.status_code == 200, r.text
    assert r.json()["controller"] == "open_loop_model"
    assert r.json()["pointing_error_max_mrad"] < 3.0  # measured 2.69 (the dead band's)
    run = client.get(f"/api/v1/simulations/{r.json()['run_id']}").json()
    assert run["params"]["pointing_model_terms"]["azimuth_zero_deg"] == 2.0
    # the whole answer, as the CLI's --pointing-model-terms takes it (a tester's was a 422
    # dumping the schema's union over HTTP)
    whole = {"site_id": "tehuantepec", "n_observations": 380,
             "terms": {"azimuth_zero_deg": {"value": 2.0, "std": 0.01}}}
    r = client.post("/api/v1/simulations", json={**body, "pointing_model_terms": whole})
    assert r.status_code == 200, r.text
    assert r.json()["pointing_error_max_mrad"] < 3.0
    for change in ({"controller": "hybrid"}, {"pointing_model_terms": {"yaw_deg": 1.0}},
                   {"pointing_model_terms": {"azimuth_zero_deg": 45.0}},
                   {"pointing_model_terms": {"azimuth_zero_deg": {"value": 2, "foo": 1}}}):
        bad = client.post("/api/v1/simulations", json={**body, **change})
        assert bad.status_code == 422 and "pointing_model_terms" in bad.text, bad.text
    assert "unknown key 'foo'" in bad.text


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # a refusal, not storage
def test_the_ideal_controller_refuses_disturbances_naming_the_field(
        client: httpx.Client) -> None:
    """``ideal`` is the reference that no disturbance reaches: a disturbance sent with it is
    a 422 naming the field (a 5° yaw read 1.6e-13 mrad RMS while the answer echoed it as
    applied, a tester's finding); the ideal run's own parameters and any other controller
    take them."""
    from backend.twin.parameters import DISTURBANCE_NAMES

    body = {"site_id": "tehuantepec", "start": "2024-03-15T10:00-06:00",
            "end": "2024-03-15T11:00-06:00"}
    for name in DISTURBANCE_NAMES:
        bad = client.post("/api/v1/simulations", json={**body, name: 1.0})
        assert bad.status_code == 422 and bad.json()["detail"].startswith(f"{name}: the ideal"), (
            bad.text)
    ok = client.post("/api/v1/simulations", json={**body, "receiver": "cpv",
                                                  "acceptance_angle_deg": 1.0})
    assert ok.status_code == 200, ok.text
    yawed = client.post("/api/v1/simulations", json={**body, "controller": "open_loop_spa",
                                                     "pedestal_yaw_deg": 5.0})
    assert yawed.status_code == 200 and yawed.json()["pointing_error_rms_mrad"] > 40, yawed.text


def test_a_large_trackers_gust_is_taken() -> None:
    """A gust on an 80 m² tracker (8 m chord) is ½ρv²·A·1.2·(0.1-0.25 chord): 3-7.5 kN m at
    8 m/s, 19-47 kN m at 20 m/s; the bound of 1,000 N m had refused them (a tester's
    finding). Beyond the bound the refusal names the field."""
    from backend.twin.scenario import Scenario

    day = (pd.Timestamp("2024-03-15", tz="UTC"), pd.Timestamp("2024-03-16", tz="UTC"))
    s = Scenario("tehuantepec", *day, controller="open_loop_spa",
                 machine={"gust_torque_nm": 47_000.0})
    assert s.disturbances().gust_torque_nm == 47_000.0
    with pytest.raises(ValueError, match="^gust_torque_nm: .* outside"):
        Scenario("tehuantepec", *day, controller="open_loop_spa",
                 machine={"gust_torque_nm": 2e6})


def test_a_run_frees_its_worker_before_its_caller_hears_it_ended(tmp_path: Path) -> None:
    """With one worker and no queue, a caller that sends its next run on the answer of the
    last one is never refused as busy: the slot is free before the run's future resolves
    (CI once got a 503 there). The future's callback runs in the worker's thread as the
    result is set, so it sees exactly what the next request would see."""
    from backend.twin.scenario import Scenario

    settings = get_settings(database_url=f"sqlite:///{tmp_path / 'sim.sqlite'}", viser=False,
                            live_twin=False, demo_logger=False, alerts=False, mqtt_url=None,
                            simulation_workers=1, simulation_queue=0)
    with TestClient(create_app(settings)) as client:
        runner = client.app.state.ctx.simulations  # type: ignore[attr-defined]
        running_when_answered: list[tuple[str, int]] = []
        _, fut = runner.submit(Scenario("tehuantepec", pd.Timestamp("2024-03-15", tz="UTC"),
                                        pd.Timestamp("2024-03-15 02:00", tz="UTC"), step_s=600.0),
                                False)
        assert not fut.done()  # the worker process takes a second to start: the callback
        # below runs in the slot's thread as it sets the result, not later in this one
        fut.add_done_callback(lambda _: running_when_answered.append(
            (threading.current_thread().name, len(runner._running))))
        fut.result(timeout=120)
    assert running_when_answered == [("heliotwin-sim-0", 0)]


def test_a_failure_in_the_bookkeeping_after_a_run_still_ends_it(tmp_path: Path) -> None:
    """The cost model, the allowance or the pruning raising after a run was stored does not
    leave its caller waiting forever nor kill the slot: the run is done and the next runs."""
    from backend.twin.scenario import Scenario

    settings = get_settings(database_url=f"sqlite:///{tmp_path / 'sim.sqlite'}", viser=False,
                            live_twin=False, demo_logger=False, alerts=False, mqtt_url=None,
                            simulation_workers=1, simulation_queue=0)
    with TestClient(create_app(settings)) as client:
        runner = client.app.state.ctx.simulations  # type: ignore[attr-defined]

        def broken(*_: Any) -> None:
            raise RuntimeError("a bug in the cost model")

        runner.costs.learn = broken
        day = (pd.Timestamp("2024-03-15", tz="UTC"), pd.Timestamp("2024-03-15 02:00", tz="UTC"))
        first = runner.run_sync(Scenario("tehuantepec", *day, step_s=600.0))
        second = runner.run_sync(Scenario("tehuantepec", *day, step_s=300.0))
        assert runner.get(first["run_id"]).status == "done"
        assert runner.get(second["run_id"]).status == "done"
