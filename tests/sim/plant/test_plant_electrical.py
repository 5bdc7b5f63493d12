"""Bypass-diode loss: Martinez-Moreno (2010) eq. 6 worked by hand on the collector layout."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sim.plant.electrical import beam_factors
from sim.plant.layout import Collector, load_plant
from sim.plant.shading import PlantShade, plant_shade

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


def _brute_force_factors(shade: PlantShade, collector: Collector) -> np.ndarray:
    """Eq. 6 per string from scratch: shapely areas, and every block tested for overlap."""
    import shapely

    blocks, owner = collector.blocks()
    strings = collector.strings()
    n_tb = len(blocks) // len(strings)
    out = np.empty(len(shade.group_step))
    for g in range(len(out)):
        rects = [r for r, b in zip(shade.group_rects[g], shade.group_by[g], strict=True)
                 if b >= 0]
        union = shapely.union_all([shapely.box(r[0], r[2], r[1], r[3]) for r in rects])
        factors = []
        for s, st in enumerate(strings):
            f_s = shapely.area(union & shapely.box(st[0], st[2], st[1], st[3])) / (
                (st[1] - st[0]) * (st[3] - st[2]))
            hit = [min(r[1], b[1]) - max(r[0], b[0]) > 1e-6 and
                   min(r[3], b[3]) - max(r[2], b[2]) > 1e-6
                   for b in blocks[owner == s] for r in rects]
            n_sb = int(np.asarray(hit).reshape(-1, len(rects)).any(axis=1).sum())
            factors.append((1 - f_s) * (1 - n_sb / (n_tb + 1)))
        out[g] = np.mean(factors)
    return out


@pytest.mark.parametrize("orientation", ["portrait", "landscape"])
def test_bypass_factors_of_plant_shade_equal_a_block_by_block_count(
        orientation: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Real shade (low winter suns): the bit-mask count of shaded blocks and the
    string areas kept by ``plant_shade`` give eq. 6 as a block-by-block count does;
    the union route (wide collectors, > 63 blocks across) gives the same."""
    import sim.plant.electrical as electrical

    plant = load_plant("penarroya")
    col = dataclasses.replace(plant.collector, module_orientation=orientation)
    rng = np.random.default_rng(5)
    az, el = rng.uniform(70, 290, 30), rng.uniform(1, 25, 30)
    shade = plant_shade(plant.positions, az, el, az, el, col.width, col.height,
                        band_edges=col.string_boundaries())
    assert len(shade.group_step) > 40 and (shade.group_by >= 0).sum(axis=1).max() >= 3
    _, elec = beam_factors(shade, col)
    ours = elec[shade.group_step, shade.group_tracker]
    np.testing.assert_allclose(ours, _brute_force_factors(shade, col), atol=1e-9)
    monkeypatch.setattr(electrical, "_MASK_BITS", 0)
    _, elec_union = beam_factors(shade, col)
    np.testing.assert_array_equal(elec_union, elec)


@pytest.mark.parametrize("numpy_has_bitwise_count", [True, False])
def test_popcount(numpy_has_bitwise_count: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Set bits of 64-bit masks, with numpy's bitwise_count (numpy ≥ 2) or the byte table."""
    from sim.plant.electrical import _popcount

    if not numpy_has_bitwise_count and hasattr(np, "bitwise_count"):
        monkeypatch.delattr(np, "bitwise_count")
    x = np.random.default_rng(8).integers(0, 2**63, (50, 3), dtype=np.uint64)
    x[0, 0] = np.uint64(2**63 - 1)
    expected = np.array([[bin(int(v)).count("1") for v in row] for row in x])
    np.testing.assert_array_equal(_popcount(x), expected)
