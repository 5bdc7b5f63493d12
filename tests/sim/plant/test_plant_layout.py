"""Plant configs and seed 004's frame (x west, y south, z zenith) → ENU."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sim.plant.layout import (
    UnknownPlantError,
    default_plants_dir,
    enu_from_seed004,
    list_plants,
    load_plant,
    plant_from_dict,
)
from sim.sun import solar_position

# seed 004 Table 1, copied in from the shared reference folder (tests/data/reference/README.md)
TABLE1 = Path(__file__).resolve().parents[2] / "data" / "reference" / "seed004_penarroya.csv"


def test_penarroya_matches_seed_table_1() -> None:
    plant = load_plant("penarroya")
    rows = np.loadtxt(TABLE1, delimiter=",", comments="#", skiprows=3)
    assert plant.n_trackers == 29 == len(rows)
    assert plant.tracker_ids == tuple(int(r) for r in rows[:, 0])
    # x west, y south → east = −x, north = −y
    np.testing.assert_allclose(plant.positions[:, 0], -rows[:, 1])
    np.testing.assert_allclose(plant.positions[:, 1], -rows[:, 2])
    c = plant.collector
    assert (c.width, c.height) == (12.0, 5.0)
    assert (plant.latitude, plant.longitude, plant.timezone) == (38.299224, -5.303114,
                                                                  "Europe/Madrid")
    # the electrical layout covers the collector exactly
    blocks, owner = c.blocks()
    area = np.sum((blocks[:, 1] - blocks[:, 0]) * (blocks[:, 3] - blocks[:, 2]))
    assert area == pytest.approx(c.area)
    assert np.bincount(owner).tolist() == [36, 36, 36]


def _seed004_sun_vector(latitude_deg: float, day_of_year: int, hour_angle_rad: float
                        ) -> np.ndarray:
    """Seed 004 eqs. 1–3 (Spencer declination) in the seed's frame (x W, y S, z zenith)."""
    g = 2 * np.pi * (day_of_year - 1) / 365
    dec = (0.006918 - 0.399912 * np.cos(g) + 0.070257 * np.sin(g) - 0.006758 * np.cos(2 * g)
           + 0.000907 * np.sin(2 * g) - 0.002697 * np.cos(3 * g) + 0.00148 * np.sin(3 * g))
    phi = np.radians(latitude_deg)
    w = hour_angle_rad
    return np.array([
        np.sin(w) * np.cos(dec),
        np.cos(w) * np.cos(dec) * np.sin(phi) - np.sin(dec) * np.cos(phi),
        np.cos(w) * np.cos(dec) * np.cos(phi) + np.sin(dec) * np.sin(phi),
    ])


@pytest.mark.parametrize("tst_h", [8.4, 12.0, 15.4])
def test_seed_sun_vector_through_the_frame_conversion_matches_spa(tst_h: float) -> None:
    """Seed 004 eq. 1 sun vector, converted, points where NREL SPA puts the sun (≤ 0.5°)."""
    from pvlib.solarposition import equation_of_time_spencer71

    lat, lon = 38.299224, -5.303114
    day = pd.Timestamp("2021-12-21", tz="UTC")
    eot = float(equation_of_time_spencer71(day.day_of_year))
    t = day + pd.Timedelta(hours=tst_h - lon / 15) - pd.Timedelta(minutes=eot)
    s_enu = enu_from_seed004(_seed004_sun_vector(lat, day.day_of_year,
                                                 np.radians(15 * (tst_h - 12))))
    pos = solar_position(t, lat, lon)
    z, a = np.radians(pos["zenith"].iloc[0]), np.radians(pos["azimuth"].iloc[0])
    spa = np.array([np.sin(z) * np.sin(a), np.sin(z) * np.cos(a), np.cos(z)])
    assert np.degrees(np.arccos(np.clip(s_enu @ spa, -1, 1))) < 0.5


def test_frame_conversion_is_a_proper_rotation() -> None:
    m = enu_from_seed004(np.eye(3))
    assert np.linalg.det(m) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="last axis"):
        enu_from_seed004([1.0, 2.0])


def test_a_dropped_in_plant_is_listed(tmp_path: Path) -> None:
    shutil.copy(default_plants_dir() / "penarroya.json", tmp_path / "penarroya.json")
    d = json.loads((tmp_path / "penarroya.json").read_text())
    d.update(plant_id="two", frame="enu", trackers=[
        {"tracker_id": 1, "east_m": 0.0, "north_m": 0.0},
        {"tracker_id": 2, "east_m": 0.0, "north_m": 20.0}])
    (tmp_path / "two.json").write_text(json.dumps(d))
    assert [p.plant_id for p in list_plants(tmp_path)[0]] == ["penarroya", "two"]
    assert load_plant("two", tmp_path).positions[1].tolist() == [0.0, 20.0, 0.0]
    with pytest.raises(UnknownPlantError, match="known plants: penarroya, two"):
        load_plant("nope", tmp_path)


def test_a_bad_plant_file_is_named_and_the_others_listed(tmp_path: Path) -> None:
    """One malformed file left no plant listed (``plant list`` failed, rc 2)."""
    shutil.copy(default_plants_dir() / "penarroya.json", tmp_path / "penarroya.json")
    (tmp_path / "broken.json").write_text('{"plant_id": "broken", "name": ')
    plants, skipped = list_plants(tmp_path)
    assert [p.plant_id for p in plants] == ["penarroya"]
    assert skipped == [("broken.json", "not valid JSON: Expecting value: line 1 column 32 "
                                       "(char 31)")]


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d.pop("latitude_deg"), "missing field 'latitude_deg'"),
    (lambda d: d.update(latitude_deg=95), "'latitude_deg' = 95.0 outside"),
    (lambda d: d.update(timezone="Mars/Olympus"), "'timezone' 'Mars/Olympus'"),
    (lambda d: d["collector"].update(width_m=-1), "collector: field 'width_m' must be positive"),
    (lambda d: d["collector"].update(height_m=5000), "collector: field 'height_m' 5000 m is "
     "more than 50 m"),
    (lambda d: d["collector"].update(bypass_diodes=0), "'bypass_diodes' must be a positive"),
    (lambda d: d["trackers"][3].pop("y_m"), r"trackers\[3\]: missing field 'y_m'"),
    (lambda d: d["trackers"][1].update(tracker_id=1), "duplicate tracker_id \\[1\\]"),
    (lambda d: d["trackers"][1].update(x_m=18.5, y_m=30.0), "trackers 1 and 2 are 7.30 m apart"),
    (lambda d: [t.update(x_m=100 * t["x_m"], y_m=100 * t["y_m"]) for t in d["trackers"]],
     r"field 'trackers': ground cover ratio 1.4e-05 \(collector area over the ground the "
     r"trackers cover\) is below 0.02, .* trackers 26 and 27, the nearest, are 1839 m apart "
     "for a 12 m x 5 m collector; give positions in metres"),  # typed in cm: GCR 0.00001
    (lambda d: d.update(frame="nwu"), "field 'frame' must be one of"),
    (lambda d: d.update(plant_id="other"), "does not match the file name"),
])
def test_bad_config_names_the_field(tmp_path: Path, edit, message: str) -> None:  # type: ignore[no-untyped-def]
    d = json.loads((default_plants_dir() / "penarroya.json").read_text())
    edit(d)
    (tmp_path / "penarroya.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match=message):
        load_plant("penarroya", tmp_path)


def test_a_plant_reports_its_ground_cover_ratio() -> None:
    """The plant's GCR was shown nowhere: Peñarroya I's 29 collectors of 60 m² cover 0.145 of
    its ground; a single row (a degenerate hull) has one too, two trackers none."""
    d = load_plant("penarroya").to_dict()
    assert d["gcr"] == pytest.approx(0.1449, abs=1e-4)
    assert d["land_m2"] == pytest.approx(29 * 60 / d["gcr"])
    row = dict(d, trackers=[{"tracker_id": k, "east_m": 20.0 * k, "north_m": 0.0}
                            for k in range(1, 5)])
    # a segment of 60 m grown by 10 m: 2·60·10 + π·10² m²
    assert plant_from_dict(row).to_dict()["land_m2"] == pytest.approx(1200 + 100 * np.pi)
    assert plant_from_dict(dict(d, trackers=d["trackers"][:2])).to_dict()["gcr"] is None


@pytest.mark.parametrize(("latitude_deg", "tilt_deg", "azimuth_deg"), [
    (38.3, 32.2, 180.0),    # 0.76 · 38.3 + 3.1, facing south
    (-23.5, 20.4, 0.0),     # 0.87 · 23.5, facing north: it faced the pole (south) before
])
def test_a_plant_without_fixed_compares_with_an_equator_facing_plant(
        tmp_path: Path, latitude_deg: float, tilt_deg: float, azimuth_deg: float) -> None:
    """A southern plant file without ``fixed`` was compared with collectors tilted 30° to the
    south, away from the sun: its gain over the fixed plant read 114 % where 41 % was due.
    Left out, the fixed plant takes a site's rule (Landau's tilt, facing the equator)."""
    d = json.loads((default_plants_dir() / "penarroya.json").read_text())
    d.pop("fixed")
    d["latitude_deg"] = latitude_deg
    (tmp_path / "penarroya.json").write_text(json.dumps(d))
    plant = load_plant("penarroya", tmp_path)
    assert (plant.fixed_tilt, plant.fixed_azimuth) == (pytest.approx(tilt_deg), azimuth_deg)
