"""One frame rule for the CLI, the service and the dashboard (issue 22 item 10).

``heliotwin vision detect`` needed ``--px-per-deg`` for a fisheye whose scale the service
derives from the image circle, and ignored the time in the file name that the dashboard
read (in JavaScript of its own). Both now go through ``backend.vision.frames.frame_inputs``
and the dashboard asks ``GET /api/v1/vision/frame-times``; the same file gives the same
answer either way. Expected sun positions come from pvlib's SPA, not from the code.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import httpx
import pandas as pd
import pvlib
import pytest

from backend.cli import main
from vision.synth import fisheye_frame

TEHUANTEPEC = (16.288750, -95.240871)  # sim/data/sites/tehuantepec.json
NAME = "sky_20240210_103000UTCm6.png"  # 10:30 at UTC-6 = 16:30 UTC
UTC = "2024-02-10T16:30:00Z"


def _spa(ts: str, lat: float, lon: float) -> tuple[float, float]:
    sp = pvlib.solarposition.get_solarposition(pd.DatetimeIndex([pd.Timestamp(ts)]), lat, lon,
                                               method="nrel_numpy")
    return float(sp.azimuth.iloc[0]), float(sp.apparent_elevation.iloc[0])


@pytest.fixture(scope="module")
def frame_png() -> bytes:
    az, el = _spa(UTC, *TEHUANTEPEC)
    ok, buf = cv2.imencode(".png", fisheye_frame(az, el, seed=3).image)  # 2.6 px/deg, 180°
    assert ok
    return buf.tobytes()


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # names, not storage
def test_frame_times_reads_the_names_the_dashboard_shows(client: httpx.Client) -> None:
    names = ["Wettermast_20160615_093900UTCp1_sunrow1202_suncol535.jpg",
             "UCEEB_20180321061000_11.jpg", "cam-20240210T103000-UTC-6.png",
             "IMG_20241399_250000.jpg", "sky.png"]
    r = client.get("/api/v1/vision/frame-times", params=[("filename", n) for n in names])
    assert r.status_code == 200, r.text
    got = [(f["filename"], f["wall_time"], f["utc_offset_h"]) for f in r.json()["frames"]]
    assert got == [
        (names[0], "2016-06-15T09:39:00", 1),
        (names[1], "2018-03-21T06:10:00", None),  # no zone in the name
        (names[2], "2024-02-10T10:30:00", -6),
        (names[3], None, None),  # month 13, hour 25: not a time
        (names[4], None, None),
    ]
    assert client.get("/api/v1/vision/frame-times").status_code == 422


def test_service_takes_the_time_and_scale_from_the_frame(client: httpx.Client,
                                                         frame_png: bytes) -> None:
    r = client.post("/api/v1/vision/sun", files={"file": (NAME, frame_png, "image/png")},
                    data={"camera": "fisheye", "site_id": "tehuantepec"})
    assert r.status_code == 200, r.text
    d = r.json()
    assert d["timestamp"] == UTC
    assert d["timestamp_source"].startswith("file name")
    az, el = _spa(UTC, *TEHUANTEPEC)
    assert d["ephemeris"]["azimuth_deg"] == pytest.approx(az, abs=0.02)
    assert d["ephemeris"]["elevation_deg"] == pytest.approx(el, abs=0.02)
    assert d["camera_derived"]["px_per_deg"] == pytest.approx(2.6, rel=0.03)
    assert d["error"]["separation_deg"] < 1.5
    # a time sent wins over the name's
    r = client.post("/api/v1/vision/sun", files={"file": (NAME, frame_png, "image/png")},
                    data={"camera": "fisheye", "site_id": "tehuantepec",
                          "timestamp": "2024-02-10T17:30:00Z"})
    assert r.json()["timestamp"] == "2024-02-10T17:30:00Z"
    assert r.json()["timestamp_source"] == "given"


def test_cli_gives_the_service_answer_without_px_per_deg_or_timestamp(
        client: httpx.Client, frame_png: bytes, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / NAME
    path.write_bytes(frame_png)
    code = main(["vision", "detect", str(path), "--camera", "fisheye", "--site", "tehuantepec",
                 "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    cli = json.loads(captured.out)
    api = client.post("/api/v1/vision/sun", files={"file": (NAME, frame_png, "image/png")},
                      data={"camera": "fisheye", "site_id": "tehuantepec"}).json()
    assert cli["timestamp"].replace("+00:00", "Z") == api["timestamp"] == UTC
    assert cli["camera_derived"] == api["camera_derived"]
    for key in ("azimuth_deg", "elevation_deg", "confidence"):
        assert cli[key] == pytest.approx(api[key], abs=1e-9), key
    for key in ("azimuth_deg", "elevation_deg"):
        assert cli["ephemeris"][key] == pytest.approx(api["ephemeris"][key], abs=1e-9), key


def test_cli_names_px_per_deg_when_the_frame_has_no_circle(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "flat.png"
    ok, buf = cv2.imencode(".png", (fisheye_frame(120.0, 40.0, seed=1).image * 0 + 200))
    assert ok
    path.write_bytes(buf.tobytes())
    code = main(["vision", "detect", str(path), "--camera", "fisheye", "--json"])
    err = capsys.readouterr().err
    assert code == 2
    assert "--px-per-deg: required" in err


def test_zones_in_names_read_to_the_minute_or_refused(client: httpx.Client,
                                                      frame_png: bytes) -> None:
    """Minute offsets, ISO ``Z``/``±hhmm`` suffixes and bare ``UTC`` are read exactly; a zone
    the reader cannot read is refused with the reason, never truncated to whole hours."""
    names = {
        "sky_20240315_180000_UTC+05:30.jpg": ("2024-03-15T18:00:00", 5.5),
        "sky_20240315_180000_UTC+0530.jpg": ("2024-03-15T18:00:00", 5.5),
        "sky_20240315_180000_UTCp5.5.jpg": ("2024-03-15T18:00:00", 5.5),
        "sky_20240315_180000_UTCm3.75.jpg": ("2024-03-15T18:00:00", -3.75),
        "sky_20240315T180000Z.jpg": ("2024-03-15T18:00:00", 0),
        "sky_20240315T120000+0100.jpg": ("2024-03-15T12:00:00", 1),
        "sky_20240315T120000-04:30.jpg": ("2024-03-15T12:00:00", -4.5),
        "sky_20240315_120000_UTC.jpg": ("2024-03-15T12:00:00", 0),
        "Wolf_20160530_094400_UTCp1__o6.jpg": ("2016-05-30T09:44:00", 1),
        "sky_20240315_120000-01.jpg": ("2024-03-15T12:00:00", None),  # a sequence number
    }
    r = client.get("/api/v1/vision/frame-times", params=[("filename", n) for n in names])
    assert r.status_code == 200, r.text
    got = {f["filename"]: (f["wall_time"], f["utc_offset_h"]) for f in r.json()["frames"]}
    assert got == names
    bad = ["sky_20240315_180000_UTC+5:3.jpg", "sky_20240315_180000_UTC+25.jpg",
           "sky_20240315_180000_UTCp5.33.jpg", "sky_20240315_180000_UTC+05:30x.jpg",
           "sky_20240315T180000Z_UTCp1.jpg"]
    r = client.get("/api/v1/vision/frame-times", params=[("filename", n) for n in bad])
    for f in r.json()["frames"]:
        assert f["wall_time"] is None and f["utc_offset_h"] is None, f
        assert "send the frame's time" in f["zone_error"], f
    # detection reads the minutes (10:30 at UTC-06:00 written as UTC-0600) …
    named = "sky_20240210T103000-0600.png"
    d = client.post("/api/v1/vision/sun", files={"file": (named, frame_png, "image/png")},
                    data={"camera": "fisheye", "site_id": "tehuantepec"}).json()
    assert d["timestamp"] == UTC and "UTC-06:00" in d["timestamp_source"]
    # a name without a zone: the site's zone, or UTC at a bare place — and the source says
    # which (it said "the place's zone" for both)
    bare = "sky_20240210_103000.png"
    d = client.post("/api/v1/vision/sun", files={"file": (bare, frame_png, "image/png")},
                    data={"camera": "fisheye", "site_id": "tehuantepec"}).json()
    assert d["timestamp"] == UTC and "America/Mexico_City" in d["timestamp_source"]
    d = client.post("/api/v1/vision/sun", files={"file": (bare, frame_png, "image/png")},
                    data={"camera": "fisheye", "latitude_deg": "16.28875",
                          "longitude_deg": "-95.240871"}).json()
    assert d["timestamp"] == "2024-02-10T10:30:00Z" and "read as UTC" in d["timestamp_source"]
    # … and refuses a zone it cannot read unless the time is sent
    named = "sky_20240210_103000_UTC-6:3.png"
    r = client.post("/api/v1/vision/sun", files={"file": (named, frame_png, "image/png")},
                    data={"camera": "fisheye", "site_id": "tehuantepec"})
    assert r.status_code == 422 and r.json()["detail"].startswith("timestamp:"), r.text
    r = client.post("/api/v1/vision/sun", files={"file": (named, frame_png, "image/png")},
                    data={"camera": "fisheye", "site_id": "tehuantepec", "timestamp": UTC})
    assert r.status_code == 200 and r.json()["timestamp_source"] == "given"


@pytest.mark.parametrize("live_server", ["sqlite"], indirect=True)  # the fit, not storage
def test_cli_and_service_calibrate_the_same_frames_alike(client: httpx.Client, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]
                                                          ) -> None:
    """No ``n_radial`` given: both let the frames decide (``auto``), so one camera."""
    times = [f"2024-02-11T{h:02d}:10:00-06:00" for h in (8, 10, 12, 14, 16)]
    paths = []
    for i, ts in enumerate(times):
        az, el = _spa(ts, *TEHUANTEPEC)
        paths.append(tmp_path / f"c{i}.png")
        cv2.imwrite(str(paths[-1]), fisheye_frame(az, el, seed=i).image)
    r = client.post("/api/v1/vision/calibrations",
                    files=[("files", (p.name, p.read_bytes(), "image/png")) for p in paths],
                    data={"timestamps": times, "site_id": "tehuantepec"})
    assert r.status_code == 201, r.text
    code = main(["vision", "calibrate", *map(str, paths), "--timestamps", *times, "--site",
                 "tehuantepec", "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    cli, api = json.loads(captured.out), r.json()
    assert cli["model_selection"] == api["model_selection"] != []
    for key, value in api["camera"].items():
        assert cli["camera"][key] == (pytest.approx(value, abs=1e-9)
                                      if isinstance(value, float) else value), key


def test_a_camera_without_a_known_north_is_searched_blind(client: httpx.Client) -> None:
    """A place without the camera's north (no calibration, no ``north_offset_deg``): the
    default north of 0 is a guess, so the ephemeris does not guide the search nor count
    against a sun (issue 24: only "the ephemeris of a calibrated camera"). EUROCONTROL's
    plain sun was refused at confidence 0.018, 128° from the guessed prediction; the
    answer still compares with the ephemeris. A north offset that is no angle is a 422."""
    path = Path(__file__).parents[1] / "data" / "real-sky" / "eurocontrol" \
        / "image_20250215080830.jpg"
    place = {"camera": "fisheye", "latitude_deg": "48.600518", "longitude_deg": "2.346795"}
    with path.open("rb") as fh:
        r = client.post("/api/v1/vision/sun", data=place, files={"file": (path.name, fh)})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["sun_found"] and body["confidence"] >= 0.5, body
    assert body["distance_from_ephemeris_px"] is None and body["ephemeris"] is not None
    blind = client.post("/api/v1/vision/sun", data={"camera": "fisheye"},
                        files={"file": (path.name, path.read_bytes())}).json()
    assert body["centroid_px"] == blind["centroid_px"]
    assert client.post("/api/v1/vision/sun", data={**place, "north_offset_deg": "1e308"},
                       files={"file": (path.name, path.read_bytes())}).status_code == 422


def test_zone_abbreviations_and_bare_plus_hours_are_refused(client: httpx.Client,
                                                            frame_png: bytes) -> None:
    """A zone the reader does not read — an abbreviation (``CEST``, ``GMT+1``, which is
    UTC−1 in the tz database) or a bare ``+hh`` after the time — was read as UTC without a
    word (``cam_20160530_100600_CEST.jpg`` detected at 10:06Z, two hours off); now it gets
    a ``zone_error`` and detection a 422 naming ``timestamp`` unless the time is sent."""
    bad = ["cam_20160530_100600_CEST.jpg", "cam_20160530_100600_CET.jpg",
           "cam_20160530_100600_GMT+1.jpg", "cam_20160530_100600_PST.jpg",
           "cam_20160530_100600_MESZ.jpg", "cam_20160530_100600+01.jpg",
           "cam_20160530_100600_cest.jpg"]
    r = client.get("/api/v1/vision/frame-times", params=[("filename", n) for n in bad])
    assert r.status_code == 200, r.text
    for f in r.json()["frames"]:
        assert f["wall_time"] is None and f["utc_offset_h"] is None, f
        assert "send the frame's time" in f["zone_error"], f
    # words that are no zone after the time still leave the name's time (read in UTC)
    # (nor a letter pair and a number: a camera's "ut1", "est2" — a reviewer's finding)
    fine = ["cam_20160530_100600_west.jpg", "cam_20160530_100600_test.jpg",
            "cam_20160530_100600_ut1.jpg", "cam_20160530_100600_est2.jpg"]
    r = client.get("/api/v1/vision/frame-times", params=[("filename", n) for n in fine])
    assert [(f["wall_time"], f["zone_error"]) for f in r.json()["frames"]] == \
        [("2016-05-30T10:06:00", None)] * 4
    named = "sky_20240210_103000_CST.png"
    r = client.post("/api/v1/vision/sun", files={"file": (named, frame_png, "image/png")},
                    data={"camera": "fisheye", "site_id": "tehuantepec"})
    assert r.status_code == 422 and r.json()["detail"].startswith("timestamp:"), r.text
    assert "'CST'" in r.json()["detail"]
    r = client.post("/api/v1/vision/sun", files={"file": (named, frame_png, "image/png")},
                    data={"camera": "fisheye", "site_id": "tehuantepec", "timestamp": UTC})
    assert r.status_code == 200 and r.json()["timestamp_source"] == "given"
