"""Sky-direction geometry (``vision/sphere.py``) against hand-worked directions."""

import numpy as np
import pytest

from vision.sphere import angular_separation_deg, enu_from_sky, sky_from_enu


def test_enu_from_sky_cardinal_directions() -> None:
    assert enu_from_sky(123.0, 90.0) == pytest.approx([0, 0, 1], abs=1e-12)  # zenith
    assert enu_from_sky(90.0, 0.0) == pytest.approx([1, 0, 0], abs=1e-12)  # east horizon
    assert enu_from_sky(180.0, 45.0) == pytest.approx([0, -np.sqrt(0.5), np.sqrt(0.5)])
    v = enu_from_sky(np.array([180.0, 45.0]), np.array([60.0, 30.0]))
    assert v.shape == (2, 3)
    assert np.linalg.norm(v, axis=-1) == pytest.approx([1, 1])


def test_sky_from_enu_inverts_and_wraps_azimuth() -> None:
    az, el = sky_from_enu(np.array([[-1.0, 0.0, 0.0], [0.0, 2.0, 2.0]]))
    assert az == pytest.approx([270.0, 0.0])
    assert el == pytest.approx([0.0, 45.0])


def test_separation_across_north_and_at_zenith() -> None:
    assert float(angular_separation_deg(359.0, 0.0, 1.0, 0.0)) == pytest.approx(2.0)
    assert float(angular_separation_deg(10.0, 90.0, 200.0, 90.0)) == pytest.approx(0, abs=1e-6)
    assert float(angular_separation_deg(0.0, 0.0, 0.0, 30.0)) == pytest.approx(30.0)
