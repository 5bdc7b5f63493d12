"""Camera models against closed-form geometry written out here (not the code under test)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import approx_fprime

from vision.cameras import PROJECTIONS, FisheyeCamera, PinholeCamera


def test_pinhole_focal_length_from_fov() -> None:
    cam = PinholeCamera(640, 480, 67.0)
    assert cam.focal_px == pytest.approx(320.0 / math.tan(math.radians(33.5)), rel=1e-12)


def test_pinhole_edge_of_field_is_half_fov() -> None:
    cam = PinholeCamera(640, 480, 67.0)
    h, v, total = cam.pointing_error(639.5, 239.5)
    assert float(h) == pytest.approx(33.5, abs=1e-9)
    assert float(v) == pytest.approx(0.0, abs=1e-12)
    assert float(total) == pytest.approx(math.radians(33.5) * 1000, rel=1e-9)


def test_pinhole_signs_right_and_up_positive() -> None:
    cam = PinholeCamera()
    h, v, _ = cam.pointing_error(400.0, 200.0)
    assert h > 0 and v > 0
    h, v, _ = cam.pointing_error(100.0, 400.0)
    assert h < 0 and v < 0


def test_pinhole_total_mrad_small_offset() -> None:
    cam = PinholeCamera(640, 480, 64.0)  # seed 001's webcam
    f = 320.0 / math.tan(math.radians(32.0))
    _, _, total = cam.pointing_error(319.5 + 3.0, 239.5 - 4.0)
    assert float(total) == pytest.approx(1000 * math.atan(5.0 / f), rel=1e-6)


def test_pinhole_reference_pixel() -> None:
    cam = PinholeCamera(reference_x_px=300.0, reference_y_px=250.0)
    h, v, total = cam.pointing_error(300.0, 250.0)
    assert abs(float(h)) < 1e-12 and abs(float(v)) < 1e-12 and float(total) < 1e-6


@pytest.mark.parametrize("h_deg,v_deg", [(0.0, 0.0), (1.5, -2.0), (-20.0, 15.0), (30.0, 25.0)])
def test_pinhole_round_trip(h_deg: float, v_deg: float) -> None:
    cam = PinholeCamera(cx_px=322.0, cy_px=236.0, reference_x_px=310.0, reference_y_px=245.0)
    x, y = cam.pixel_from_pointing_error(h_deg, v_deg)
    h, v, _ = cam.pointing_error(x, y)
    assert float(h) == pytest.approx(h_deg, abs=1e-9)
    assert float(v) == pytest.approx(v_deg, abs=1e-9)


def test_fisheye_contract_case_is_north_west() -> None:
    """Up-right of centre, north up, east left → north-west (seed 003 eqs. 9–11)."""
    cam = FisheyeCamera(320.0, 240.0, 2.6, 0.0, "left")
    az, el = cam.pixel_to_sky(400.0, 200.0)
    assert float(az) == pytest.approx(360.0 - math.degrees(math.atan2(80.0, 40.0)), abs=1e-9)
    assert float(el) == pytest.approx(90.0 - math.hypot(80.0, 40.0) / 2.6, abs=1e-9)


def test_fisheye_cardinal_points() -> None:
    cam = FisheyeCamera(100.0, 100.0, 1.0, 0.0, "left")
    # east at el 0 → left by 90 px; south → down
    assert np.allclose(cam.sky_to_pixel(90.0, 0.0), (10.0, 100.0))
    assert np.allclose(cam.sky_to_pixel(180.0, 0.0), (100.0, 190.0))
    mirrored = FisheyeCamera(100.0, 100.0, 1.0, 0.0, "right")
    assert np.allclose(mirrored.sky_to_pixel(90.0, 0.0), (190.0, 100.0))
    rotated = FisheyeCamera(100.0, 100.0, 1.0, 90.0, "left")  # north to the right
    assert np.allclose(rotated.sky_to_pixel(0.0, 0.0), (190.0, 100.0))


@pytest.mark.parametrize("projection,expected", [
    ("equidistant", math.pi / 2),
    ("equisolid", 2 * math.sin(math.pi / 4)),
    ("stereographic", 2 * math.tan(math.pi / 4)),
    ("orthographic", 1.0),
])
def test_fisheye_horizon_radius(projection: str, expected: float) -> None:
    cam = FisheyeCamera(0.0, 0.0, 3.0, projection=projection)
    assert cam.horizon_radius_px == pytest.approx(3.0 * 180 / math.pi * expected, rel=1e-12)


@pytest.mark.parametrize("projection", PROJECTIONS)
@pytest.mark.parametrize("extra", [{}, {"radial_coeffs": (0.02, -0.01)},
                                   {"tilt_north_deg": 2.0, "tilt_east_deg": -1.5}])
def test_fisheye_round_trip(projection: str, extra: dict) -> None:
    cam = FisheyeCamera(330.0, 250.0, 2.7, 37.0, "right", projection, **extra)
    rng = np.random.default_rng(3)
    az = rng.uniform(0, 360, 50)
    el = rng.uniform(5, 89, 50)
    x, y = cam.sky_to_pixel(az, el)
    az2, el2 = cam.pixel_to_sky(x, y)
    assert np.allclose(((az2 - az + 180) % 360) - 180, 0, atol=1e-6)
    assert np.allclose(el2, el, atol=1e-6)


def test_fisheye_tilt_moves_zenith() -> None:
    cam = FisheyeCamera(100.0, 100.0, 2.0, tilt_north_deg=2.0)
    az, el = cam.pixel_to_sky(100.0, 100.0)
    assert float(el) == pytest.approx(88.0, abs=1e-9)
    assert float(az) % 360 == pytest.approx(0.0, abs=1e-6)


def test_fisheye_rejects_bad_parameters() -> None:
    with pytest.raises(ValueError, match="projection"):
        FisheyeCamera(0, 0, 1.0, projection="fisheye")
    with pytest.raises(ValueError, match="east"):
        FisheyeCamera(0, 0, 1.0, east="up")
    with pytest.raises(ValueError, match="px_per_deg"):
        FisheyeCamera(0, 0, -1.0)
    with pytest.raises(ValueError, match="fov_deg"):
        PinholeCamera(fov_deg=180.0)


def test_fisheye_dict_round_trip() -> None:
    cam = FisheyeCamera(1.0, 2.0, 3.0, 4.0, "right", "equisolid", (0.1,), 0.5, -0.5)
    assert FisheyeCamera.from_dict(cam.to_dict()) == cam


def test_camera_from_form_fields() -> None:
    from vision.cameras import camera_from_params

    pin = camera_from_params("pinhole", {"fov_deg": "64", "reference_x_px": "300"}, 640, 480)
    assert isinstance(pin, PinholeCamera) and pin.fov_deg == 64 and pin.reference_px[0] == 300
    fish = camera_from_params("fisheye", {"px_per_deg": "2.6", "east": "right",
                                          "projection": "equisolid"}, 640, 480)
    assert isinstance(fish, FisheyeCamera)
    assert (fish.cx_px, fish.cy_px, fish.east, fish.projection) == (319.5, 239.5, "right",
                                                                     "equisolid")
    for kind, params, field in [("fisheye", {}, "px_per_deg"),
                                ("fisheye", {"px_per_deg": "x"}, "px_per_deg"),
                                ("fisheye", {"px_per_deg": "2", "east": "up"}, "east"),
                                ("pinhole", {"fov_deg": "200"}, "fov_deg"),
                                ("pinhole", {"cx_px": "nan"}, "cx_px"),
                                # the other kind's parameter: refused, not ignored
                                ("fisheye", {"px_per_deg": "2", "fov_deg": "nan"},
                                 "fov_deg: a fisheye camera does not take it"),
                                ("pinhole", {"px_per_deg": "2"},
                                 "px_per_deg: a pinhole camera does not take it"),
                                ("tele", {}, "camera")]:
        with pytest.raises(ValueError, match=field):
            camera_from_params(kind, params, 640, 480)


@pytest.mark.parametrize("projection", PROJECTIONS)
@pytest.mark.parametrize("east", ["left", "right"])
def test_fisheye_pixel_jacobian_is_the_finite_difference(projection: str, east: str) -> None:
    """``sky_to_pixel_jacobian`` (the fit's analytic Jacobian) against scipy's forward
    differences of ``sky_to_pixel`` at random cameras with two radial terms and a tilt:
    measured within 5e-6 px per unit of each parameter (the differences' own error);
    a term of the chain rule left out or of the wrong sign is off by far more."""
    rng = np.random.default_rng(7)
    az, el = rng.uniform(0, 360, 30), rng.uniform(15, 88, 30)

    def pixels(p: np.ndarray) -> np.ndarray:
        cam = FisheyeCamera(p[0], p[1], p[2], p[3], east, projection, (p[4], p[5]), p[6], p[7])
        return np.concatenate(cam.sky_to_pixel(az, el))

    for _ in range(3):
        p = np.array([rng.uniform(300, 700), rng.uniform(300, 700), rng.uniform(2, 12),
                      rng.uniform(0, 360), *rng.normal(0, 0.05, 2), *rng.uniform(-8, 8, 2)])
        cam = FisheyeCamera(p[0], p[1], p[2], p[3], east, projection, (p[4], p[5]), p[6], p[7])
        jac = cam.sky_to_pixel_jacobian(az, el).reshape(-1, p.size)
        fd = approx_fprime(p, pixels, 1e-7 * np.maximum(1.0, np.abs(p)))
        assert np.abs(jac - fd).max() < 1e-5, np.abs(jac - fd).max(axis=0)
        # without the tilt's columns: the same others
        assert np.array_equal(cam.sky_to_pixel_jacobian(az, el, tilt=False), jac.reshape(
            2, az.size, p.size)[..., :6])
