"""The second renderer's geometry and the logistic fit, each against an independent reference."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from vision.confidence import FEATURES, fit_logistic, load_model
from vision.skyrender import random_scene, render


def test_sun_is_drawn_at_the_camera_models_pixel() -> None:
    """The brightest unsaturated sky is around the truth: the glare is centred there."""
    s = random_scene(3, sky="clear", width_px=640, height_px=480)
    fr = render(s)
    g = fr.image.astype(float).mean(axis=2)
    ys, xs = np.nonzero(g >= 250)
    x, y = fr.sun_px
    near = np.hypot(xs - x, ys - y) < 6 * s.glare_deg * s.camera.px_per_deg
    assert near.sum() > 10
    assert np.hypot(xs[near].mean() - x, ys[near].mean() - y) < 2.0
    # deterministic by seed
    assert np.array_equal(render(s).image, fr.image)


def test_an_hdr_tone_map_keeps_the_sun_the_brightest_point_unclipped_around_it() -> None:
    """``tone="reinhard"`` (Reinhard et al. 2002, eq. 4, white point the frame's maximum):
    the frame's brightest pixel is at the sun and reaches the top, where the clipping
    sensor's frame of the same scene saturates a disc of hundreds of pixels; the sky keeps
    its order (the pixel nearer the sun brighter, as in the linear frame)."""
    s = replace(random_scene(3, sky="clear", width_px=640, height_px=480), noise_dn=0.0,
                jpeg_quality=100)
    clipped, hdr = render(s).image, render(replace(s, tone="reinhard")).image
    x, y = render(s).sun_px
    g = hdr.astype(float).mean(axis=2)
    yy, xx = np.unravel_index(int(np.argmax(g)), g.shape)
    assert np.hypot(xx - x, yy - y) <= 1.5 and g.max() >= 254
    assert int((g >= 250).sum()) < 0.1 * int((clipped.mean(axis=2) >= 250).sum())
    step = 3 * s.glare_deg * s.camera.px_per_deg
    near, far = g[int(y), int(x + step)], g[int(y), int(x + 2 * step)]
    assert near > far


def test_overcast_hides_the_sun_and_sizes_follow_the_seed() -> None:
    s = random_scene(11, sky="overcast", width_px=480, height_px=480)
    fr = render(s)
    assert not fr.sun_visible and fr.image.max() < 255
    sizes = {min(random_scene(k).width_px, random_scene(k).height_px) for k in range(40)}
    assert min(sizes) == 480 and max(sizes) == 3000
    ppd = [random_scene(k).camera.px_per_deg for k in range(40)]
    assert 2.0 <= min(ppd) and max(ppd) <= 15.0


def test_logistic_fit_recovers_known_coefficients() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4000, 3))
    w_true, b_true = np.array([1.5, -2.0, 0.5]), -0.3
    p = 1 / (1 + np.exp(-(x @ w_true + b_true)))
    y = (rng.random(4000) < p).astype(float)
    w, b = fit_logistic(x, y, l2=0.0)
    assert np.allclose(w, w_true, atol=0.15) and abs(b - b_true) < 0.12


def test_stored_model_matches_the_features() -> None:
    w, b = load_model()
    assert w.shape == (len(FEATURES),) and np.isfinite(b)
