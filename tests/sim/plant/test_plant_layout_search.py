"""The layout search (sim.plant.sweep.least_shaded_layout) against Cumpston & Pye's finding.

Cumpston & Pye (2014, doi:10.1016/j.solener.2014.06.012; abstract) optimised regular fields
of two-axis trackers at Barstow, California, for annual shading: "optimal layouts are
rectangular in shape for ground cover ratios less than 0.23. Diamond layouts collect up to
1.4 % more absolute annual solar energy for higher ground cover ratios." Here: the 12 m × 5 m
collector, a clear-sky (Ineichen) year at Barstow at 2-hour steps, each family's best aspect
ratio and rotation on a coarse grid (the full grid at 1 h is benchmarks/bench_plant_layouts.py,
docs/plants.md). Measured with this grid: GCR 0.15 rectangular 1.077 %, diamond 1.066 %
(within 0.02 percentage points: no family wins); GCR 0.35 rectangular 7.676 %, diamond
7.167 % (diamond 0.51 points less shade, half of the paper's "up to 1.4 %").
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sim.plant import load_plant
from sim.plant.fields import collector_from_size
from sim.plant.sweep import SweepSpec, case_sky, least_shaded_layout

BARSTOW = (34.9, -117.0)
COLLECTOR = collector_from_size(12.0, 5.0, load_plant("penarroya").collector)


@pytest.fixture(scope="module")
def barstow_year() -> dict[str, np.ndarray]:
    spec = SweepSpec(*BARSTOW, pd.Timestamp("2021-01-01", tz="UTC"),
                     pd.Timestamp("2022-01-01", tz="UTC"), 7200.0, COLLECTOR)
    return case_sky(spec)


def _families(sky: dict[str, np.ndarray], gcr: float, ratios: list[float]
              ) -> tuple[float, float]:
    rotations = np.array([0.0, 30.0, 60.0, 90.0, 120.0, 150.0])
    rect = least_shaded_layout(COLLECTOR, sky, gcr, 0.0, np.array(ratios), rotations)
    diamond = least_shaded_layout(COLLECTOR, sky, gcr, -0.5, np.array(ratios), rotations)
    return rect[1], diamond[1]


def test_low_gcr_no_family_wins_high_gcr_diamond_wins(barstow_year: dict) -> None:
    rect, diamond = _families(barstow_year, 0.15, [1.5, 1.75, 2.0])
    assert rect == pytest.approx(1.077, abs=0.01) and diamond == pytest.approx(1.066, abs=0.01)
    assert abs(rect - diamond) < 0.05
    rect, diamond = _families(barstow_year, 0.35, [1.0, 1.25])
    assert rect - diamond == pytest.approx(0.51, abs=0.05)


def test_no_feasible_layout_names_the_family() -> None:
    sky = {k: np.array([1.0]) for k in ("apparent_elevation", "solar_azimuth", "dni")}
    with pytest.raises(ValueError, match="offset -0.5 at gcr 0.45"):
        least_shaded_layout(COLLECTOR, sky, 0.45, -0.5, np.array([1.0]), np.array([0.0]))
