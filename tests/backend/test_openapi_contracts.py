"""Typed contracts: every operation's 2xx body has a declared schema, and real answers match it.

The app is built in process (``backend.app.create_app`` on a temp SQLite file;
``TestClient`` as a context manager runs the lifespan). A real answer is checked
against the schema ``/openapi.json`` declares for its operation and status (what
schemathesis and any client read), with every object closed to undeclared keys: a key
the model lacks fails here instead of being silently filtered by ``response_model``.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import jsonschema_rs
import numpy as np
import pandas as pd
import pvlib
import pytest
from fastapi.testclient import TestClient

from backend.app import create_app
from backend.settings import Settings
from vision.cameras import FisheyeCamera
from vision.synth import fisheye_frame

ADMIN = "admin-token-for-contract-tests"
SITE = "tehuantepec"
TEHUANTEPEC = (16.288750, -95.240871)  # data/sites/tehuantepec.json (seed 000)

def _settings(tmp: Path) -> Settings:
    return Settings(database_url=f"sqlite:///{tmp / 'contracts.sqlite'}", viser=False,
                    live_twin=False, demo_logger=False, alerts=False, admin_token=ADMIN,
                    sites_dir=tmp / "user-sites")


def _openapi() -> dict[str, Any]:
    """The OpenAPI document, built at collection time to parametrize over its operations."""
    return create_app(Settings(database_url="sqlite://", viser=False, live_twin=False,
                               demo_logger=False)).openapi()


OPENAPI = _openapi()
OPERATIONS = [(path, method, op) for path, item in OPENAPI["paths"].items()
              for method, op in item.items()
              if method in ("get", "post", "put", "delete", "patch")]


def _is_declared(schema: dict[str, Any] | None, json: bool) -> bool:
    """A JSON body must name its fields: a model (``$ref``), an array of models, or an
    object with ``properties`` — not ``{}`` nor the free-form object of ``dict[str, Any]``;
    another media type needs a schema of its own (``{"type": "string", ...}``)."""
    if not schema:
        return False
    if not json:
        return "type" in schema
    if schema.get("type") == "array":
        return _is_declared(schema.get("items"), json)
    return "$ref" in schema or bool(schema.get("properties"))


@pytest.mark.parametrize(("path", "method", "op"),
                         [pytest.param(p, m, o, id=o["operationId"]) for p, m, o in OPERATIONS])
def test_every_operation_declares_its_2xx_bodies(path: str, method: str,
                                                 op: dict[str, Any]) -> None:
    ok = {code: r for code, r in op["responses"].items() if str(code).startswith("2")}
    assert ok, f"{method.upper()} {path}: no 2xx response documented"
    for code, resp in ok.items():
        content = resp.get("content")
        assert content, f"{method.upper()} {path} {code}: no media type documented"
        for media, body in content.items():
            assert _is_declared(body.get("schema"), media == "application/json"), (
                f"{method.upper()} {path} {code} {media}: no schema ({body.get('schema')})")


def test_the_list_of_operations_is_complete() -> None:
    """The parametrized test sees every operation (none hidden from the schema by accident:
    42 when this test was written)."""
    assert len(OPERATIONS) >= 42


# --------------------------------------------------------------------------- real answers


def _closed(schema: Any) -> Any:
    """``schema`` with every object that lists its ``properties`` closed to other keys
    (``additionalProperties: false``, as pydantic's ``extra="forbid"``): an answer's key the
    model does not declare — which ``response_model`` would silently drop — fails."""
    if isinstance(schema, list):
        return [_closed(s) for s in schema]
    if not isinstance(schema, dict):
        return schema
    out = {k: _closed(v) for k, v in schema.items()}
    if "properties" in out and "additionalProperties" not in out:
        out["additionalProperties"] = False
    return out


class Checker:
    """Sends requests and checks each JSON answer against the schema the OpenAPI document
    declares for its operation and status, closed to undeclared keys."""

    def __init__(self, client: TestClient, spec: dict[str, Any]) -> None:
        self.client = client
        self.spec = spec
        self.components = _closed(spec["components"])
        self.checked: list[str] = []

    def __call__(self, method: str, template: str, status: int = 200,
                 **kwargs: Any) -> Any:
        url = template.format(**kwargs.pop("path", {}))
        r = self.client.request(method, url, **kwargs)
        assert r.status_code == status, f"{method} {url}: {r.status_code} {r.text[:300]}"
        assert r.headers["content-type"].startswith("application/json")
        body = r.json()
        op = self.spec["paths"][template][method.lower()]
        schema = op["responses"][str(status)]["content"]["application/json"]["schema"]
        validator = jsonschema_rs.Draft202012Validator(
            {**_closed(schema), "components": self.components})
        errors = [f"{'/'.join(map(str, e.instance_path))}: {e.message}"
                  for e in validator.iter_errors(body)]
        assert not errors, f"{method} {template} {status}: " + "; ".join(errors[:5])
        self.checked.append(f"{method} {template} {status}")
        return body


def _spa(ts: str) -> tuple[float, float]:
    sp = pvlib.solarposition.get_solarposition(pd.DatetimeIndex([pd.Timestamp(ts)]),
                                               *TEHUANTEPEC, method="nrel_numpy")
    return float(sp.azimuth.iloc[0]), float(sp.apparent_elevation.iloc[0])


def _png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return buf.tobytes()


def _day_of_readings(day: str) -> list[dict[str, Any]]:
    """A clear-ish day: the tracker every minute with encoder angles, the fixed array
    every 5 minutes (a half-sine power profile; only the shapes matter here)."""
    rows: list[dict[str, Any]] = []
    base = dt.datetime.fromisoformat(f"{day}T06:00:00-06:00")
    for i in range(13 * 60):
        ts = base + dt.timedelta(minutes=i)
        p = max(0.0, 200.0 * float(np.sin(np.pi * (i / 60.0 - 0.5) / 12.0)))
        rows.append({"ts": ts.isoformat(), "array": "tracker", "voltage_v": 30.0,
                     "current_a": p / 30.0, "power_w": p, "azimuth_deg": 90.0 + i * 0.2,
                     "elevation_deg": 40.0})
        if i % 5 == 0:
            rows.append({"ts": ts.isoformat(), "array": "fixed", "voltage_v": 29.0,
                         "current_a": 0.8 * p / 29.0, "power_w": 0.8 * p})
    return rows


@pytest.fixture(scope="module")
def checked(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Checker]:
    app = create_app(_settings(tmp_path_factory.mktemp("contracts")))
    with TestClient(app) as client:
        yield Checker(client, app.openapi())


def test_service_and_sites_answers(checked: Checker) -> None:
    admin = {"Authorization": f"Bearer {ADMIN}"}
    checked("GET", "/healthz")
    checked("GET", "/api/v1/meta")
    checked("GET", "/api/v1/sites")
    checked("GET", "/api/v1/sites/schema.json")
    checked("GET", "/api/v1/sites/{site_id}", path={"site_id": SITE})
    config = checked("GET", "/api/v1/sites/{site_id}/config", path={"site_id": SITE})
    new = {**config, "site_id": "contracts_site", "name": "Contracts"}
    created = checked("PUT", "/api/v1/sites/{site_id}", 201, path={"site_id": new["site_id"]},
                      json=new, headers=admin)
    assert created["created"] is True
    checked("PUT", "/api/v1/sites/{site_id}", path={"site_id": new["site_id"]}, json=new,
            headers=admin)
    checked("GET", "/api/v1/sites/{site_id}/arrays/{array}/calibration",
            path={"site_id": SITE, "array": "tracker"})
    checked("GET", "/api/v1/sites/{site_id}/status", path={"site_id": SITE})
    checked("GET", "/api/v1/alerts")


def test_alert_answers(checked: Checker) -> None:
    """An alert stored as the evaluator stores one, listed and acknowledged."""
    from sqlalchemy import insert

    from backend.storage.tables import AlertRow

    ctx = checked.client.app.state.ctx  # type: ignore[attr-defined]
    alert_id = ctx.writer.call(lambda conn: conn.execute(insert(AlertRow).values(
        site_id=SITE, array_name="tracker", kind="fault", fault_kind="stuck", state="active",
        since_s=1_764_000_000, raised_at_s=1_764_090_000, detail="stuck", data_json="{}",
        webhook_status="off")).inserted_primary_key[0]).result(60)
    listed = checked("GET", "/api/v1/alerts", params={"acknowledged": "false"})
    assert [a["id"] for a in listed["alerts"]] == [alert_id]
    acked = checked("POST", "/api/v1/alerts/{alert_id}/acknowledge", path={"alert_id": alert_id},
                    json={"note": "on it"}, headers={"Authorization": f"Bearer {ADMIN}"})
    assert (acked["acknowledged_by"], acked["acknowledged_note"]) == ("admin", "on it")


def test_token_answers(checked: Checker) -> None:
    admin = {"Authorization": f"Bearer {ADMIN}"}
    made = checked("POST", "/api/v1/tokens", 201, json={"site_id": SITE, "label": "c"},
                   headers=admin)
    listed = checked("GET", "/api/v1/tokens", headers=admin)
    assert made["id"] in [t["id"] for t in listed["tokens"]]
    checked("DELETE", "/api/v1/tokens/{token_id}", path={"token_id": made["id"]},
            headers=admin)


def test_measured_energy_and_diagnosis_answers(checked: Checker) -> None:
    admin = {"Authorization": f"Bearer {ADMIN}"}
    token = checked.client.post("/api/v1/tokens", json={"site_id": SITE},
                                headers=admin).json()["token"]
    write = {"Authorization": f"Bearer {token}"}
    checked("POST", "/api/v1/sites/{site_id}/measurements", path={"site_id": SITE},
            json={"readings": _day_of_readings("2024-03-14")}, headers=write)
    checked("PUT", "/api/v1/sites/{site_id}/arrays/{array}/calibration",
            path={"site_id": SITE, "array": "fixed"}, json={"adc_bits": 12}, headers=admin)
    rng = {"start": "2024-03-14", "end": "2024-03-16"}
    site = {"site_id": SITE}
    for max_points in (2000, 50):  # as stored, then min/mean/max buckets
        body = checked("GET", "/api/v1/sites/{site_id}/measurements", path=site,
                       params={**rng, "array": "tracker", "max_points": max_points})
        assert body["points"] and (body["bucket_s"] > 0) == (max_points == 50)
    for interval in ("hour", "day", "month"):
        body = checked("GET", "/api/v1/sites/{site_id}/energy", path=site,
                       params={**rng, "interval": interval})
        assert body["rows"]
    body = checked("GET", "/api/v1/sites/{site_id}/energy", path=site,
                   params={**rng, "source": "twin_weather"})
    assert "twin_weather_gain_pct" in body["rows"][0]
    checked("GET", "/api/v1/sites/{site_id}/report", path=site, params=rng)
    days = checked("GET", "/api/v1/sites/{site_id}/diagnosis", path=site, params=rng)["days"]
    assert days[0]["tracker"]["measured_wh"] is not None
    pointing = checked("GET", "/api/v1/sites/{site_id}/pointing", path=site, params=rng)
    assert pointing["summary"] is not None and pointing["points"]


def test_simulation_answers(checked: Checker) -> None:
    scenario = {"site_id": SITE, "start": "2024-03-15", "end": "2024-03-16", "step_s": 900}
    summary = checked("POST", "/api/v1/simulations", json=scenario)
    run = checked("GET", "/api/v1/simulations/{run_id}", path={"run_id": summary["run_id"]})
    assert run["summary"] == summary
    checked("GET", "/api/v1/simulations/{run_id}/series", path={"run_id": summary["run_id"]},
            params={"max_points": 10})
    accepted = checked("POST", "/api/v1/simulations", 202,
                       json={**scenario, "controller": "hybrid", "background": True})
    assert accepted["run_id"]


def test_plant_answers(checked: Checker) -> None:
    plants = checked("GET", "/api/v1/plants")
    plant = {"plant_id": plants[0]["plant_id"]}
    checked("GET", "/api/v1/plants/{plant_id}", path=plant)
    for strategy in ("sun", "backtrack", "sky_scan"):
        checked("GET", "/api/v1/plants/{plant_id}/positions", path=plant,
                params={"time": "2024-03-15T08:00:00+01:00", "strategy": strategy})
    checked("GET", "/api/v1/plants/{plant_id}/sky-map", path=plant,
            params={"time": "2024-03-15T12:00:00+01:00", "resolution_deg": 10})
    checked("GET", "/api/v1/plants/{plant_id}/day", path=plant,
            params={"date": "2024-03-15", "step_s": 3600})


def test_vision_answers(checked: Checker) -> None:
    ts = "2024-02-10T10:30:00-06:00"
    cam = FisheyeCamera(319.5, 239.5, 2.6, north_offset_deg=12.0, east="left")
    frame = _png(fisheye_frame(*_spa(ts), camera=cam, seed=1).image)
    fisheye = checked("POST", "/api/v1/vision/sun",
                      files={"file": ("s.png", frame, "image/png")},
                      data={"camera": "fisheye", "cx_px": "319.5", "cy_px": "239.5",
                            "px_per_deg": "2.6", "north_offset_deg": "12", "east": "left",
                            "timestamp": ts, "site_id": SITE})
    assert fisheye["error"]["separation_deg"] < 0.2
    checked("POST", "/api/v1/vision/sun", files={"file": ("s.png", frame, "image/png")},
            data={"camera": "fisheye", "timestamp": ts, "latitude_deg": "16.29",
                  "longitude_deg": "-95.24"})  # the scale derived from the image circle
    disc = np.full((480, 640, 3), 40, np.uint8)
    cv2.circle(disc, (400, 200), 9, (255, 255, 255), -1)
    pinhole = checked("POST", "/api/v1/vision/sun",
                      files={"file": ("p.png", _png(disc), "image/png")},
                      data={"camera": "pinhole", "fov_deg": "67", "timestamp": ts,
                            "site_id": SITE})
    assert len(pinhole["pointing_error_deg"]) == 2
    times = [f"2024-03-05T{h:02d}:15:00-06:00" for h in (8, 11, 14)]
    files = [("files", (f"f{i}.png", _png(fisheye_frame(*_spa(t), camera=cam, seed=i).image),
                        "image/png")) for i, t in enumerate(times)]
    place = {"timestamps": times, "site_id": SITE}
    cal = checked("POST", "/api/v1/vision/calibrations", 201, files=files, data=place)
    checked("GET", "/api/v1/vision/calibrations")
    ident = {"calibration_id": cal["calibration_id"]}
    checked("GET", "/api/v1/vision/calibrations/{calibration_id}", path=ident)
    checked("POST", "/api/v1/vision/evaluate", files=files,
            data={**place, "camera": "fisheye", "px_per_deg": "2.6", "north_offset_deg": "12",
                  "east": "left"})
    found = checked("GET", "/api/v1/vision/detections",
                    params={"site_id": SITE, "start": "2024-02-10", "end": "2024-02-11"})
    assert {d["camera"] for d in found["detections"]} == {"fisheye", "pinhole"}
    token = checked.client.post("/api/v1/tokens", json={"site_id": SITE, "scope": "site"},
                                headers={"Authorization": f"Bearer {ADMIN}"}).json()["token"]
    write = {"Authorization": f"Bearer {token}"}  # deleting a site's results: scope site
    checked("DELETE", "/api/v1/vision/detections", headers=write,
            params={"site_id": SITE, "start": "2024-02-10", "end": "2024-02-11"})
    checked("DELETE", "/api/v1/vision/calibrations/{calibration_id}", path=ident,
            headers=write)
