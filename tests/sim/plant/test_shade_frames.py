"""The plant's collector frame against the twin's: one panel frame, the same shade.

The plant (:mod:`sim.plant.shading`, seed 004 §2.1) works in a collector's (u, v)
coordinates; the twin (:mod:`sim.array_shade`) projects a collector's outline posed
by the D–H chain (:func:`sim.kinematics.joint_transforms`) and clips it with its own
polygon code. For seed 004's non-square collector (12 m × 5 m) and a sun off every
axis, the plant's shade rectangle mapped to the world must be the twin's shade
polygon (a width/height or axis mix-up moves it), and it must sit at the collector's
lower edge in the world and at v = −b/2 in the plant's coordinates (v up the slope,
strings bottom to top: the sign that a centred rectangle's area cannot see).
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from sim.array_shade import Layout, fixed_shade
from sim.kinematics import TrackerGeometry, joint_transforms
from sim.plant.shading import collector_axes, plant_shade
from vision.sphere import enu_from_sky

W, H = 12.0, 5.0  # seed 004, Peñarroya I collectors
SUN_AZ, SUN_EL = 118.0, 14.0  # morning, low: the collector behind is shaded from below
NORMAL_AZ, NORMAL_EL = 140.0, 38.0  # parallel collectors not facing the sun
PIVOTS = np.array([[0.0, 0.0, 0.0], [7.0, -9.5, 0.3]])  # j ahead of i, towards the sun


def _twin_frame(azimuth_deg: float, elevation_deg: float, centre: np.ndarray) -> np.ndarray:
    """A collector's world transform from the D–H chain (rotation only, placed at centre)."""
    t = np.eye(4)
    t[:3, :3] = joint_transforms(azimuth_deg, elevation_deg, TrackerGeometry())[2][:3, :3]
    t[:3, 3] = centre
    return t


def test_plant_shade_rectangle_is_the_twin_shade_polygon() -> None:
    sun = enu_from_sky(SUN_AZ, SUN_EL)
    shade = plant_shade(PIVOTS, [SUN_AZ], [SUN_EL], [NORMAL_AZ], [NORMAL_EL], W, H)
    assert shade.fraction[0, 1] == 0.0 and 0.05 < shade.fraction[0, 0] < 0.95
    (g,) = np.nonzero(shade.group_tracker == 0)[0]
    (rect,) = shade.group_rects[g][shade.group_by[g] == 1]
    u0, u1, v0, v1 = rect
    n, u, v = collector_axes(NORMAL_AZ, NORMAL_EL)
    plant_poly = PIVOTS[0] + np.array([[u0, v0], [u1, v0], [u1, v1], [u0, v1]]) @ np.stack([u, v])

    receiver = _twin_frame(NORMAL_AZ, NORMAL_EL, PIVOTS[0])
    layout = Layout(tracker_mount_height_m=0.0, tracker_size_m=(W, H),
                    fixed_centre_enu=PIVOTS[0], fixed_axes=receiver[:3, :3], fixed_size_m=(W, H))
    twin = fixed_shade(layout, _twin_frame(NORMAL_AZ, NORMAL_EL, PIVOTS[1])[None], sun[None])
    twin_poly = twin.polygon_enu[0, :twin.vertices[0]]

    assert twin.fraction[0] == pytest.approx(shade.fraction[0, 0], rel=1e-9)
    # the shade is off-centre both ways (a sign error of u or v would move it), and the
    # same polygon in the world: compared in the horizontal projection (the plane is tilted)
    assert abs(u0 + u1) > 1.0 and abs(v0 + v1) > 1.0
    a, b = shapely.Polygon(plant_poly[:, :2]), shapely.Polygon(twin_poly[:, :2])
    assert a.symmetric_difference(b).area < 1e-9 * a.area
    np.testing.assert_allclose(plant_poly.mean(axis=0), twin_poly.mean(axis=0), atol=1e-9)
    # the low sun shades the lower edge: v0 is the bottom (v up the slope) ...
    assert v0 == pytest.approx(-H / 2, abs=1e-12) and v1 < H / 2
    # ... which is the lower edge in the world, as the twin's frame has it
    lower_edge_z = PIVOTS[0, 2] - H / 2 * receiver[2, 1]
    assert plant_poly[:, 2].min() == pytest.approx(lower_edge_z, abs=1e-9)
    assert twin_poly[:, 2].min() == pytest.approx(lower_edge_z, abs=1e-9)


@pytest.mark.parametrize("azimuth_deg,elevation_deg", [(180.0, 0.0), (95.0, 33.0), (260.0, 71.0)])
def test_collector_axes_are_the_twin_panel_frame(azimuth_deg: float, elevation_deg: float) -> None:
    n, u, v = collector_axes(azimuth_deg, elevation_deg)
    frame = _twin_frame(azimuth_deg, elevation_deg, np.zeros(3))
    np.testing.assert_allclose(np.column_stack([u, v, n]), frame[:3, :3], atol=1e-15)
    assert u[2] == 0.0 and v[2] >= 0.0  # u horizontal, v up the slope
