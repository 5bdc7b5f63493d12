"""``heliotwin vision detect --calibration-id``: a calibration stored over HTTP by the service,
used by the CLI on the same database; the text answer states the error against SPA. The CLI
runs in this process (``heliotwin_cli``) with the service's ``HELIOTWIN_*`` settings: the
database is the point, not the process (tests/test_cli_vision.py runs a real one)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import cv2
import httpx
import pandas as pd
import pvlib
import pytest
from live_service import LiveServer

from vision.cameras import FisheyeCamera
from vision.synth import fisheye_frame

TEHUANTEPEC = (16.288750, -95.240871, 50.0)
TRUTH = FisheyeCamera(330.0, 238.0, 2.6, north_offset_deg=-20.0, east="left")


def _sun(ts: str) -> tuple[float, float]:
    """pvlib's SPA (not the product's ephemeris) at Tehuantepec."""
    sp = pvlib.solarposition.spa_python(pd.DatetimeIndex([pd.Timestamp(ts)]), *TEHUANTEPEC)
    return float(sp["azimuth"].iloc[0]), float(sp["apparent_elevation"].iloc[0])


def _png(ts: str, seed: int) -> bytes:
    ok, buf = cv2.imencode(".png", fisheye_frame(*_sun(ts), camera=TRUTH, seed=seed).image)
    assert ok
    return buf.tobytes()


def test_detect_with_a_stored_calibration(live_server: LiveServer, client: httpx.Client,
                                          tmp_path: Path, heliotwin_cli: Callable) -> None:
    times = [f"2024-04-10T{h:02d}:20:00-06:00" for h in (8, 10, 12, 14, 16)]
    files = [("files", (f"c{i}.png", _png(ts, i), "image/png")) for i, ts in enumerate(times)]
    r = client.post("/api/v1/vision/calibrations", files=files,
                    data={"timestamps": times, "site_id": "tehuantepec"})
    assert r.status_code == 201, r.text
    cal_id = r.json()["calibration_id"]
    held_out = "2024-04-10T11:05:00-06:00"  # not one of the calibration frames
    frame = tmp_path / "held_out.png"
    frame.write_bytes(_png(held_out, 42))

    def detect(*extra: str):  # type: ignore[no-untyped-def]
        return heliotwin_cli("vision", "detect", str(frame), "--timestamp", held_out, "--site",
                             "tehuantepec", *extra, env=live_server.env)

    p = detect("--calibration-id", str(cal_id), "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    az, el = _sun(held_out)
    assert out["calibration_id"] == cal_id and out["sun_found"]
    assert out["azimuth_deg"] == pytest.approx(az, abs=0.5)
    assert out["elevation_deg"] == pytest.approx(el, abs=0.5)
    assert out["error"]["separation_deg"] < 0.5 and out["warnings"] == []
    assert out["place_source"] == "given"
    # no place given: the calibration's, as over HTTP (the CLI searched blind before)
    p = heliotwin_cli("vision", "detect", str(frame), "--timestamp", held_out,
                      "--calibration-id", str(cal_id), "--json", env=live_server.env)
    assert p.returncode == 0, p.stderr
    own = json.loads(p.stdout)
    assert own["place_source"].startswith(f"calibration {cal_id} ") \
        and "site tehuantepec" in own["place_source"]
    assert own["error"]["separation_deg"] == pytest.approx(out["error"]["separation_deg"],
                                                           abs=1e-9)
    # a frame of another size than the calibration's is refused, as over HTTP
    bigger = tmp_path / "bigger.png"
    bigger.write_bytes(cv2.imencode(".png", cv2.resize(cv2.imread(str(frame)), (800, 600)))[1]
                       .tobytes())
    p = heliotwin_cli("vision", "detect", str(bigger), "--timestamp", held_out, "--site",
                      "tehuantepec", "--calibration-id", str(cal_id), env=live_server.env)
    assert p.returncode == 2 and "--calibration-id:" in p.stderr, p.stderr
    assert "800×600" in p.stderr and "640×480" in p.stderr
    text = detect("--calibration-id", str(cal_id))
    assert text.returncode == 0, text.stderr
    assert f"error against SPA {out['error']['separation_deg']:.3f} deg" in text.stdout
    missing = detect("--calibration-id", "999999")
    assert missing.returncode == 2 and "--calibration-id: no calibration 999999" in missing.stderr
    typed = detect("--calibration-id", str(cal_id), "--px-per-deg", "12")  # was ignored
    assert typed.returncode == 2 and typed.stderr.strip().endswith(
        "--px-per-deg: a --calibration-id carries its own camera (centre, scale, north, "
        "mirror, projection); give --calibration-id or --px-per-deg, not both"), typed.stderr
    pinhole = detect("--calibration-id", str(cal_id), "--camera", "pinhole")
    assert pinhole.returncode == 2 and "fisheye" in pinhole.stderr
    neither = detect()
    assert neither.returncode == 2 and "--camera: required" in neither.stderr
