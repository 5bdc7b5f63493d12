"""Fisheye calibration: recover a known camera from synthetic sun positions (pvlib SPA)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pvlib
import pytest

from vision.calibrate import fit_fisheye
from vision.cameras import FisheyeCamera


def _sun_track(lat: float, lon: float, day: str, tz: str) -> pd.DataFrame:
    times = pd.date_range(f"{day} 06:00", f"{day} 19:00", freq="30min", tz=tz)
    sp = pvlib.solarposition.get_solarposition(times, lat, lon, method="nrel_numpy")
    return sp[sp.apparent_elevation > 5]


@pytest.mark.parametrize("east", ["left", "right"])
def test_recovers_four_parameters(east: str) -> None:
    # seed 003's site and format (Guadalajara, 640 × 480), a camera turned 25°
    sp = _sun_track(20.8667, -103.05, "2018-03-02", "Etc/GMT+6")
    truth = FisheyeCamera(327.0, 236.0, 2.7, 25.0, east)
    x, y = truth.sky_to_pixel(sp.azimuth.values, sp.apparent_elevation.values)
    rng = np.random.default_rng(0)
    x = x + rng.normal(0, 0.3, x.size)
    y = y + rng.normal(0, 0.3, y.size)
    res = fit_fisheye(x, y, sp.azimuth.values, sp.apparent_elevation.values, (640, 480))
    cam = res.camera
    assert cam.east == east
    assert cam.cx_px == pytest.approx(327.0, abs=1.0)
    assert cam.cy_px == pytest.approx(236.0, abs=1.0)
    assert cam.px_per_deg == pytest.approx(2.7, rel=0.01)
    assert (cam.north_offset_deg - 25.0 + 180) % 360 - 180 == pytest.approx(0, abs=0.5)
    assert res.rms_px < 0.6
    assert res.cost_other_mirror is not None and res.cost_other_mirror > 10 * (res.rms_px**2)


def test_radial_and_tilt_terms() -> None:
    days = [_sun_track(50.0, 14.0, d, "UTC") for d in ("2024-03-21", "2024-06-21", "2024-12-21")]
    sp = pd.concat(days)
    truth = FisheyeCamera(960.0, 950.0, 10.5, 170.0, "left", "equisolid",
                          radial_coeffs=(0.03,), tilt_north_deg=1.5, tilt_east_deg=-1.0)
    x, y = truth.sky_to_pixel(sp.azimuth.values, sp.apparent_elevation.values)
    az, el = sp.azimuth.values, sp.apparent_elevation.values
    plain = fit_fisheye(x, y, az, el, (1920, 1920), projection="equisolid", east="left")
    full = fit_fisheye(x, y, az, el, (1920, 1920), projection="equisolid", east="left",
                       n_radial=1, fit_tilt=True)
    assert full.rms_px < 0.05 < plain.rms_px
    assert full.camera.tilt_north_deg == pytest.approx(1.5, abs=0.05)
    assert full.camera.tilt_east_deg == pytest.approx(-1.0, abs=0.05)


def test_misuse_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="too few"):
        fit_fisheye([1, 2], [1, 2], [100, 120], [30, 40], (640, 480))
    with pytest.raises(ValueError, match="horizon"):
        fit_fisheye([1, 2, 3], [1, 2, 3], [100, 120, 140], [30, -1, 40], (640, 480))
    with pytest.raises(ValueError, match="projection"):
        fit_fisheye([1, 2, 3], [1, 2, 3], [100, 120, 140], [30, 35, 40], (640, 480),
                    projection="pinhole")
