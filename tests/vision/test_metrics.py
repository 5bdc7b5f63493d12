"""Seed 003's metrics (eqs. 17–20) on its own Table 2, computed by hand here."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vision import metrics, sphere

# seed 003 Table 2 (../shared/reference/seed003_noaa_table2.csv): NOAA vs fisheye
AZ_NOAA = [147.83, 177.2, 207.4, 228.6, 241.96, 250.88]
AZ_FISH = [148.32, 175.4, 206.6, 225.2, 242.18, 252.74]
EL_NOAA = [58.4, 62.8, 59.8, 50.6, 39.0, 26.18]
EL_FISH = [55.28, 61.93, 61.98, 55.32, 40.5, 27.2]


def test_per_axis_metrics_match_hand_computation() -> None:
    d = [a - f for a, f in zip(AZ_NOAA, AZ_FISH, strict=True)]
    n = len(d)
    assert metrics.mad(AZ_NOAA, AZ_FISH) == pytest.approx(sum(abs(v) for v in d) / n)
    assert metrics.mse(AZ_NOAA, AZ_FISH) == pytest.approx(sum(v * v for v in d) / n)
    assert metrics.rmse(AZ_NOAA, AZ_FISH) == pytest.approx(math.sqrt(sum(v * v for v in d) / n))
    mape = 100 * sum(abs(v) / a for v, a in zip(d, AZ_NOAA, strict=True)) / n
    assert metrics.mape(AZ_NOAA, AZ_FISH) == pytest.approx(mape)
    # the literal numbers: MAD of the azimuth column is 8.57 / 6
    assert metrics.mad(AZ_NOAA, AZ_FISH) == pytest.approx(8.57 / 6, abs=1e-9)


def test_error_table_elevation_column() -> None:
    t = metrics.error_table(AZ_NOAA, EL_NOAA, AZ_FISH, EL_FISH)
    d = np.subtract(EL_NOAA, EL_FISH)
    assert t["elevation"]["rmse_deg"] == pytest.approx(float(np.sqrt(np.mean(d**2))))
    assert t["elevation"]["mad_deg"] == pytest.approx(13.41 / 6, abs=1e-9)
    assert t["separation"]["max_deg"] >= t["separation"]["mean_deg"] > 0


def test_azimuth_wraps() -> None:
    assert metrics.mad([359.0], [1.0], circular=True) == pytest.approx(2.0)
    assert metrics.mad([359.0], [1.0]) == pytest.approx(358.0)


def test_angular_separation_against_dot_product() -> None:
    rng = np.random.default_rng(0)
    a1, a2 = rng.uniform(0, 360, (2, 100))
    e1, e2 = rng.uniform(-10, 90, (2, 100))

    def unit(a: np.ndarray, e: np.ndarray) -> np.ndarray:
        a, e = np.radians(a), np.radians(e)
        return np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], -1)

    ref = np.degrees(np.arccos(np.clip(np.sum(unit(a1, e1) * unit(a2, e2), -1), -1, 1)))
    assert np.allclose(sphere.angular_separation_deg(a1, e1, a2, e2), ref, atol=1e-6)
    assert float(sphere.angular_separation_deg(10, 90, 200, 90)) == pytest.approx(0, abs=1e-6)


def test_metric_misuse() -> None:
    with pytest.raises(ValueError, match="length"):
        metrics.mad([1, 2], [1])
    with pytest.raises(ValueError, match="zero"):
        metrics.mape([0.0], [1.0])
