"""Sky: clear sky, transposition, AOI/IAM vs pvlib recipes and closed forms; TMY3 reading."""

import numpy as np
import pandas as pd
import pytest
from pvlib import location

from sim.sky import (
    angle_of_incidence,
    clearsky_ineichen,
    effective_irradiance,
    iam_physical,
    poa_irradiance,
    pvlib_tmy3_path,
    read_tmy3,
)

LAT, LON, ALT = 16.28875, -95.240871, 50.0


def test_clearsky_matches_pvlib_location() -> None:
    loc = location.Location(LAT, LON, altitude=ALT)
    times = pd.date_range("2024-03-15 12:00", periods=600, freq="1min", tz="UTC")
    sp = loc.get_solarposition(times)
    ref = loc.get_clearsky(times, solar_position=sp)
    ours = clearsky_ineichen(times, sp["apparent_zenith"].to_numpy(), LAT, LON, ALT)
    for k in ("ghi", "dni", "dhi"):
        assert ours[k] == pytest.approx(ref[k].fillna(0).to_numpy(), rel=1e-9, abs=1e-9)
    assert ours["ghi"].max() > 900  # a clear March noon in the tropics


def test_horizontal_plane_gets_ghi() -> None:
    zen, az = np.array([20.0, 50.0]), np.array([120.0, 240.0])
    dni, dhi = np.array([850.0, 600.0]), np.array([100.0, 120.0])
    ghi = dni * np.cos(np.deg2rad(zen)) + dhi
    for model in ("haydavies", "isotropic"):
        poa = poa_irradiance(
            0.0, 180.0, zen, az, dni, ghi, dhi, np.array([1361.0, 1361.0]), model=model
        )
        assert poa["poa_global"] == pytest.approx(ghi, rel=1e-9)
    with pytest.raises(ValueError, match="haydavies"):
        poa_irradiance(
            0.0, 180.0, zen, az, dni, ghi, dhi, np.array([1361.0, 1361.0]), model="klucher"
        )


def test_aoi_and_iam() -> None:
    assert angle_of_incidence(30.0, 200.0, np.array([30.0]), np.array([200.0]))[0] == pytest.approx(
        0, abs=1e-6
    )
    assert angle_of_incidence(0.0, 180.0, np.array([40.0]), np.array([90.0]))[0] == pytest.approx(
        40
    )
    m = iam_physical(np.array([0.0, 60.0, 90.0]))
    assert m[0] == pytest.approx(1.0) and 0.8 < m[1] < 1.0 and m[2] == pytest.approx(0.0)
    assert effective_irradiance(np.array([800.0]), np.array([100.0]), np.array([0.0]))[
        0
    ] == pytest.approx(900)


def test_reads_pvlib_shipped_tmy3() -> None:
    weather, meta = read_tmy3(pvlib_tmy3_path(), coerce_year=1990)
    assert len(weather) == 8760
    assert str(weather.index.tz) == "UTC"
    assert meta["latitude"] == pytest.approx(36.1)
    assert {"ghi", "dni", "dhi", "temp_air", "wind_speed"} <= set(weather.columns)
    # Greensboro NC: annual global horizontal irradiation of roughly 1.5-1.8 MWh/m2
    assert 1400 < weather["ghi"].sum() / 1000 < 1900
