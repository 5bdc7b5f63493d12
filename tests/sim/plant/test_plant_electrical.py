"""Bypass-diode loss: Martinez-Moreno (2010) eq. 6 worked by hand on the collector layout."""

from __future__ import annotations

import numpy as np
import pytest

from sim.plant.electrical import beam_factors
from sim.plant.layout import load_plant
from sim.plant.shading import PlantShade

C = load_plant("penarroya").collector


def _shade(rect: list[float], n: int = 2) -> PlantShade:
    area = (rect[1] - rect[0]) * (rect[3] - rect[2])
    frac = np.zeros((1, n))
    frac[0, 0] = area / C.area
    return PlantShade(frac, np.array([0]), np.array([0]), np.array([[rect]], dtype=float),
                      np.array([[1]]))


def test_a_strip_along_the_bottom_drops_the_bottom_string() -> None:
    # 0.2 m of shade along the full width: every block of the bottom string (36) is hit
    area, elec = beam_factors(_shade([-6, 6, -2.5, -2.3]), C)
    f_string = 0.2 / (5 / 3)
    expected = (2 + (1 - f_string) * (1 - 36 / 37)) / 3          # eq. 6, strings averaged
    assert elec[0, 0] == pytest.approx(expected, rel=1e-12)
    assert area[0, 0] == pytest.approx(1 - 0.2 * 12 / 60)
    assert elec[0, 1] == area[0, 1] == 1.0


def test_a_corner_hits_only_its_blocks() -> None:
    # 0.5 m × 0.5 m in the lower-left corner: portrait modules 1 m wide, 3 blocks each
    # of 1/3 m → blocks at u ∈ [−6, −5.667] and [−5.667, −5.333] are hit (2 of 36)
    area, elec = beam_factors(_shade([-6, -5.5, -2.5, -2.0]), C)
    f_string = 0.25 / (12 * 5 / 3)
    expected = (2 + (1 - f_string) * (1 - 2 / 37)) / 3
    assert elec[0, 0] == pytest.approx(expected, rel=1e-12)
    assert area[0, 0] > elec[0, 0]
