"""``heliotwin vision detect|calibrate`` as a user runs them, on frames rendered with the sun
where pvlib's SPA puts it (the ephemeris here is pvlib's own, not the product's). ``calibrate``
runs as a real process (the entry point); the others through ``backend.cli.main`` in this
process (``heliotwin_cli``: the same parser, output and exit code)."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import cv2
import pandas as pd
import pvlib
import pytest

from vision.cameras import FisheyeCamera
from vision.synth import fisheye_frame

ROOT = Path(__file__).resolve().parents[1]
LAT, LON = 20.676, -103.347  # Guadalajara (seed 003)
TIMES = pd.date_range("2018-03-02T15:00Z", periods=6, freq="50min")
CAMERA = FisheyeCamera(cx_px=320.4, cy_px=238.7, px_per_deg=2.6, north_offset_deg=7.0)


def heliotwin(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "backend", *args], capture_output=True,
                          text=True, cwd=ROOT, timeout=120)


@pytest.fixture(scope="module")
def frames(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    sun = pvlib.solarposition.spa_python(TIMES, LAT, LON)
    out = []
    for i, (az, el) in enumerate(zip(sun["azimuth"], sun["apparent_elevation"], strict=True)):
        path = tmp_path_factory.mktemp("sky") / f"frame_{i}.png"
        cv2.imwrite(str(path), fisheye_frame(float(az), float(el), CAMERA, seed=i).image)
        out.append(path)
    return out


def test_calibrate_recovers_the_camera(frames: list[Path]) -> None:
    p = heliotwin("vision", "calibrate", *map(str, frames), "--timestamps",
                  *[t.isoformat() for t in TIMES], "--lat", str(LAT), "--lon", str(LON),
                  "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    cam = out["camera"]
    assert cam["px_per_deg"] == pytest.approx(2.6, abs=0.03)
    assert cam["north_offset_deg"] == pytest.approx(7.0, abs=0.5)
    assert (cam["cx_px"], cam["cy_px"]) == pytest.approx((320.4, 238.7), abs=1.5)
    assert out["rms_deg"] < 0.3 and len(out["frames"]) == 6


def test_detect_with_time_and_place_reports_the_ephemeris_error(frames: list[Path],
                                                                heliotwin_cli) -> None:
    p = heliotwin_cli("vision", "detect", str(frames[2]), "--camera", "fisheye", "--px-per-deg",
                  "2.6", "--cx-px", "320.4", "--cy-px", "238.7", "--north-offset-deg", "7",
                  "--timestamp", TIMES[2].isoformat(), "--lat", str(LAT), "--lon", str(LON),
                  "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["sun_found"]
    assert out["error"]["separation_deg"] < 0.5
    text = heliotwin_cli("vision", "detect", str(frames[2]), "--camera", "fisheye",
                         "--px-per-deg", "2.6")
    assert text.returncode == 0 and text.stdout.startswith("sun at (")


def test_bad_input_exits_2_naming_the_problem(tmp_path: Path, heliotwin_cli) -> None:
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image")
    p = heliotwin_cli("vision", "detect", str(junk), "--camera", "fisheye")
    assert p.returncode == 2 and "image" in p.stderr and "PNG or JPEG" in p.stderr
    p = heliotwin_cli("vision", "calibrate", str(junk), "--timestamps", "2018-03-02T15:00",
                      "--lat", "20")
    assert p.returncode == 2 and "no UTC offset" in p.stderr


def test_detect_checks_the_place_and_warns_as_the_service(frames: list[Path], tmp_path: Path,
                                                          heliotwin_cli) -> None:
    """The place is checked by the service's function (an impossible or NaN latitude is
    refused, naming the flag), the answer carries the service's ``warnings``, and a frame
    over the pixel bound names the bound the command applies."""
    base = ("vision", "detect", str(frames[2]), "--camera", "fisheye", "--px-per-deg", "2.6",
            "--timestamp", TIMES[2].isoformat())
    for lat, lon, flag in (("100", "10", "--lat"), ("nan", "10", "--lat"),
                           ("20", "500", "--lon")):
        p = heliotwin_cli(*base, "--lat", lat, "--lon", lon, "--json")
        assert p.returncode == 2 and p.stderr.count(f"{flag}:") == 1, p.stderr
        assert p.stdout == ""
    # Sydney at this UTC time is night (the sun 40° down): the bright disc is no sun, as the
    # service answers (vision.analyse.SUN_DOWN_DEG); it was a sun found with a warning
    p = heliotwin_cli(*base, "--lat", "-33.9", "--lon", "151.2", "--json")
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert not out["sun_found"] and out["confidence"] == 0.0 and out["centroid_px"] is None
    assert "below the horizon" in out["reason"] and "moon or a light" in out["reason"]
    text = heliotwin_cli(*base, "--lat", "-33.9", "--lon", "151.2")
    assert text.stdout.startswith("no sun (confidence 0.00)"), text.stdout
    # a PNG header claiming 30000 × 30000 px: refused before decoding, naming the CLI's bound
    ihdr = struct.pack(">IIBBBBB", 30000, 30000, 8, 2, 0, 0, 0)
    bomb = tmp_path / "bomb.png"
    bomb.write_bytes(b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr
                     + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr)))
    p = heliotwin_cli("vision", "detect", str(bomb), "--camera", "fisheye")
    assert p.returncode == 2 and "command line" in p.stderr, p.stderr
    assert "HELIOTWIN_VISION_MAX_PIXELS" not in p.stderr


def test_calibrate_chooses_the_radial_terms_as_the_service(frames: list[Path],
                                                           heliotwin_cli) -> None:
    """``--n-radial`` defaults to ``auto``, the service's default: the frames decide."""
    args = ("vision", "calibrate", *map(str, frames[:5]), "--timestamps",
            *[t.isoformat() for t in TIMES[:5]], "--lat", str(LAT), "--lon", str(LON), "--json")
    p = heliotwin_cli(*args)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert [m["n_radial"] for m in out["model_selection"]][:1] == [0]
    assert heliotwin_cli(*args, "--n-radial", "auto").stdout == p.stdout
    p = heliotwin_cli(*args, "--n-radial", "3")
    assert p.returncode == 2 and "--n-radial" in p.stderr


def test_a_calibration_file_is_applied_as_a_stored_calibration(frames: list[Path],
                                                                tmp_path: Path,
                                                                heliotwin_cli) -> None:
    """``vision calibrate`` stores nothing (no ``calibration_id``) and ``vision detect``
    had no flag for the fitted radial terms or tilt: a command-line user could not use the
    camera just fitted. ``calibrate --json > FILE`` is read by ``detect --calibration-file
    FILE`` and applied as a stored calibration is (``calibration_record``): its camera with
    radial terms and tilt, its size, its place, its worst residual."""
    p = heliotwin_cli("vision", "calibrate", *map(str, frames[::2]), *map(str, frames[1::2]),
                      "--timestamps", *[t.isoformat() for t in (*TIMES[::2], *TIMES[1::2])],
                      "--lat", str(LAT), "--lon", str(LON), "--n-radial", "0", "--json")
    assert p.returncode == 0, p.stderr
    fitted = json.loads(p.stdout)
    assert fitted.get("calibration_id") is None  # stored nowhere
    path = tmp_path / "cam.json"
    path.write_text(p.stdout)
    out = json.loads(heliotwin_cli("vision", "detect", str(frames[2]), "--calibration-file",
                                   str(path), "--timestamp", TIMES[2].isoformat(),
                                   "--json").stdout)
    assert out["sun_found"] and out["error"]["separation_deg"] < 0.5
    assert out["calibration_file"] == str(path)
    assert out["place_source"].startswith(f"calibration file {path} (no place given")
    # the radial terms and tilt are applied: the ephemeris sun's pixel is the file's camera's
    bent = {**fitted, "camera": {**fitted["camera"], "radial_coeffs": [0.05],
                                 "tilt_north_deg": 2.0, "tilt_east_deg": -1.0}}
    path.write_text(json.dumps(bent))
    out = json.loads(heliotwin_cli("vision", "detect", str(frames[2]), "--calibration-file",
                                   str(path), "--timestamp", TIMES[2].isoformat(),
                                   "--json").stdout)
    eph = out["ephemeris"]
    want = FisheyeCamera.from_dict(bent["camera"]).sky_to_pixel(eph["azimuth_deg"],
                                                                eph["elevation_deg"])
    assert eph["centroid_px"] == pytest.approx([float(v) for v in want], abs=1e-6)
    plain = FisheyeCamera.from_dict(fitted["camera"]).sky_to_pixel(eph["azimuth_deg"],
                                                                   eph["elevation_deg"])
    assert abs(eph["centroid_px"][0] - float(plain[0])) > 3.0
    # as a stored calibration: only on frames of its size, and not with a typed camera
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), cv2.resize(cv2.imread(str(frames[2])), (320, 240)))
    p = heliotwin_cli("vision", "detect", str(small), "--calibration-file", str(path))
    assert p.returncode == 2 and "--calibration-file: the frame decodes to 320×240" in p.stderr
    p = heliotwin_cli("vision", "detect", str(frames[2]), "--calibration-file", str(path),
                      "--px-per-deg", "2.6")
    assert p.returncode == 2 and p.stderr.count("--px-per-deg: a --calibration-file") == 1
    path.write_text("{}")
    p = heliotwin_cli("vision", "detect", str(frames[2]), "--calibration-file", str(path))
    assert p.returncode == 2 and "--calibration-file:" in p.stderr, p.stderr


def test_calibrate_reads_the_times_in_the_file_names_as_detect_does(
        frames: list[Path], tmp_path: Path, heliotwin_cli) -> None:  # type: ignore[no-untyped-def]
    """Without ``--timestamps`` each image's time is the one in its file name, read as
    ``vision detect`` reads it (``backend.vision.frames.frame_time``: here the name's zone,
    UTC−6): the same answer as with the times given. A name without a time asks for them."""
    named = []
    for path, t in zip(frames, TIMES, strict=True):
        local = (t - pd.Timedelta(hours=6)).strftime("%Y%m%d_%H%M%S")
        copy = tmp_path / f"guadalajara_{local}UTCm6.png"
        copy.write_bytes(path.read_bytes())
        named.append(copy)
    place = ("--lat", str(LAT), "--lon", str(LON), "--json")
    given = heliotwin_cli("vision", "calibrate", *map(str, named), "--timestamps",
                          *[t.isoformat() for t in TIMES], *place)
    assert given.returncode == 0, given.stderr
    from_names = heliotwin_cli("vision", "calibrate", *map(str, named), *place)
    assert from_names.returncode == 0, from_names.stderr
    assert from_names.stdout == given.stdout
    p = heliotwin_cli("vision", "calibrate", *map(str, named[:2]), str(frames[2]), *place)
    assert p.returncode == 2 and "--timestamps" in p.stderr and "frame_2.png" in p.stderr, \
        p.stderr
