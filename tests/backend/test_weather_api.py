"""``POST /api/v1/simulations/weather``: a twin run on an uploaded TMY3/EPW file, over real
HTTP against ``heliotwin serve`` (SQLite and PostgreSQL), checked against the CLI."""

from __future__ import annotations

import csv
import io
import json
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest
from live_service import InProcessServer

from sim.sky import pvlib_tmy3_path

RANGE = {"site_id": "tehuantepec", "start": "2023-05-01", "end": "2023-05-04",
         "step_s": "600"}


def _files(path: Path | None = None) -> dict:
    path = path or pvlib_tmy3_path()
    return {"file": (path.name, path.read_bytes(), "text/csv")}


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the twin, not storage
def test_a_distant_station_is_refused_unless_forced_and_then_runs_as_the_cli(
        client: httpx.Client, heliotwin_cli: Callable) -> None:
    r = client.post("/api/v1/simulations/weather", data=RANGE, files=_files())
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert detail.startswith("force:") and "2672 km from site tehuantepec" in detail
    r = client.post("/api/v1/simulations/weather", data={**RANGE, "force": "true"},
                    files=_files())
    assert r.status_code == 200, r.text
    http = r.json()
    cli = heliotwin_cli("simulate", "--site", "tehuantepec", "--start", RANGE["start"],
                        "--end", RANGE["end"], "--step-s", RANGE["step_s"], "--tmy3",
                        str(pvlib_tmy3_path()), "--force", "--json")
    assert cli.returncode == 0, cli.stderr
    ref = json.loads(cli.stdout)
    assert http["sky"] == "weather" and http["steps"] == ref["steps"] == 432
    assert http["tracker_energy_wh"] == pytest.approx(ref["tracker_energy_wh"], rel=1e-12)
    assert http["fixed_energy_wh"] == pytest.approx(ref["fixed_energy_wh"], rel=1e-12)


def test_measured_weather_is_read_from_the_upload_and_runs_as_the_cli(
        client: httpx.Client, heliotwin_cli: Callable, tmp_path: Path) -> None:
    """A CSV that is neither TMY3 nor EPW is read as measured weather (``weather_stamped``
    as ``--weather-stamped``); a run outside its dates is a 422 naming them."""
    from tests.test_cli_sim import _measured_day

    path = _measured_day(tmp_path / "day.csv")
    day = {"site_id": "tehuantepec", "start": "2024-03-15", "end": "2024-03-16",
           "step_s": "300", "weather_stamped": "interval_end"}
    r = client.post("/api/v1/simulations/weather", data=day, files=_files(path))
    assert r.status_code == 200, r.text
    cli = heliotwin_cli("simulate", "--start", "2024-03-15", "--end", "2024-03-16",
                        "--step-s", "300", "--weather-csv", str(path), "--json")
    assert cli.returncode == 0, cli.stderr
    assert r.json()["tracker_energy_wh"] == pytest.approx(
        json.loads(cli.stdout)["tracker_energy_wh"], rel=1e-12)
    # the file's shift from the sun as the CLI says (sim.weather_clock): none read from a
    # half sine, which is no clear day's shape, and no warning
    for key in ("weather_shift_min", "weather_warning"):
        assert r.json()[key] == json.loads(cli.stdout)[key] is None, key
    # stamped at the intervals' starts, the file covers 00:10 to 00:10 the next day
    r = client.post("/api/v1/simulations/weather", data={**day, "weather_stamped":
                                                         "interval_start"}, files=_files(path))
    assert r.status_code == 422
    assert r.json()["detail"].startswith("file: weather: the measured weather covers "
                                         "2024-03-15 00:10:00-06:00 to 2024-03-16 00:10")
    r = client.post("/api/v1/simulations/weather", data={**day, "weather_stamped": "end"},
                    files=_files(path))
    assert r.status_code == 422 and r.json()["detail"].startswith("weather_stamped:")


def test_a_background_run_on_weather_keeps_its_station_and_exports_units(
        client: httpx.Client) -> None:
    r = client.post("/api/v1/simulations/weather", files=_files(),
                    data={**RANGE, "start": "2023-06-01", "end": "2023-06-02",
                          "force": "on", "background": "true"})
    assert r.status_code == 202, r.text
    url = r.headers["Location"]
    deadline = time.monotonic() + 120
    while (run := client.get(url).json())["status"] not in ("done", "failed"):
        assert time.monotonic() < deadline, run
        time.sleep(0.3)
    assert run["status"] == "done", run
    station = run["params"]["weather_station"]
    assert station["format"] == "tmy3" and station["name"] == "GREENSBORO PIEDMONT TRIAD INT"
    assert station["forced"] is True and station["utc_offset_h"] == -5.0
    rows = list(csv.DictReader(io.StringIO(client.get(f"{url}/series",
                                                      params={"format": "csv"}).text)))
    assert len(rows) == 144
    assert rows[0]["time_utc"] == "2023-06-01T06:00:00+00:00"
    assert rows[0]["time_local"] == "2023-06-01T00:00:00-06:00"  # Mexico: no DST since 2022
    assert "tracker_poa_global_w_m2" in rows[0] and "tracker_temp_cell_c" in rows[0]
    assert max(float(r["tracker_poa_global_w_m2"]) for r in rows) > 100
    cols = client.get(f"{url}/series", params={"max_points": 10}).json()["columns"]
    assert "solar_azimuth_deg" in cols and "solar_azimuth" not in cols


@pytest.mark.parametrize("data, files, status, field", [
    ({**RANGE, "force": "true"}, None, 422, "file:"),
    ({**RANGE, "force": "true"}, {"file": ("x.csv", b"a,b\n1,2\n", "text/csv")}, 422, "file:"),
    ({**RANGE, "step_s": "-5", "force": "true"}, "tmy3", 422, "step_s"),
    ({**RANGE, "start": "2023-05-04T00:00", "force": "true"}, "tmy3", 422, "offset"),
    ({**RANGE, "force": "maybe"}, "tmy3", 422, "force:"),
    ({**RANGE, "site_id": "atlantis", "force": "true"}, "tmy3", 404, "atlantis"),
    # an EPW whose hour is text: pvlib's TypeError was a 500 (adversary, session 27)
    ({**RANGE, "force": "true"}, {"file": ("x.epw", b"LOCATION,A,B,C,D,1,10,10,1,10\n"
                                  + b"DESIGN CONDITIONS,0\n" * 7 + b"2021,1,1,1,60,x,"
                                  + b"1," * 30 + b"\n",
                                  "text/csv")}, 422, "file: x.epw is not a readable TMY3"),
    # a header line of 2 MB was quoted whole in the 422: a message is cut to 1,000 characters
    ({**RANGE, "force": "true"}, {"file": ("x.csv", b"a" * 2_000_000 + b"\n1\n2\n",
                                  "text/csv")}, 422, "not found among aaaa"),
])
def test_bad_uploads_name_the_field(client: httpx.Client, data: dict, files: object,
                                    status: int, field: str) -> None:
    if files is None:  # a form without the file
        r = client.post("/api/v1/simulations/weather", data=data,
                        files={"note": ("n.txt", b"x", "text/plain")})
    else:
        r = client.post("/api/v1/simulations/weather", data=data,
                        files=_files() if files == "tmy3" else files)
    assert r.status_code == status, r.text[:500]
    assert field in r.json()["detail"] and len(r.content) < 1200


def test_the_upload_is_bounded_and_must_be_multipart(tmp_path: Path) -> None:
    """A TMY3 file (1.2 MB) over a 500 kB limit is a 413; JSON is a 415."""
    server = InProcessServer(f"sqlite:///{tmp_path / 'w.sqlite'}",
                             extra_env={"HELIOTWIN_MAX_UPLOAD_BYTES": "500000"})
    with server, server.client(timeout_s=60) as c:
        r = c.post("/api/v1/simulations/weather", data={**RANGE, "force": "true"},
                   files=_files())
        assert r.status_code == 413 and "HELIOTWIN_MAX_UPLOAD_BYTES" in r.json()["detail"]
        r = c.post("/api/v1/simulations/weather", json=RANGE)
        assert r.status_code == 415 and "multipart" in r.json()["detail"]
        assert c.get("/healthz").status_code == 200
