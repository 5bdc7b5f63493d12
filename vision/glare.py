"""The centre of a glare whose saturated core the sky has joined (a long exposure).

A longer exposure saturates the sky around the sun as well as the sun's glare: the clipped
region grows by tens of degrees, mostly toward the brighter sky (the horizon), and its
outline no longer tells where the sun is (issue 24 item 4: the Wolf frames brightened × 1.15
put its centroid 36 px off at the median and 159 px at worst, × 1.3 100 / 181 px). What
survives is the light around it: a radially symmetric glare on a smooth sky. The model of
the frame near the core is

    I(x) = s0 + s · (x − x0) + A (|x − c| / R)^(−p),

a plane of sky plus the aureole's power law about the sun's pixel ``c`` (the solar aureole
falls off as a power of the angle from the sun: Deepak et al. 1982, Appl. Opt. 21:2451;
a lens's veiling glare likewise, ISO 9358), fitted to the frame's unsaturated sky pixels
within a few core radii and *censored* at the clip level: a saturated pixel says only that
the model reaches the clip there (censored regression, Tobin 1958, Econometrica 26:24).
Robust (soft-L1) loss, so trees' edges, a roof or a lens ray cost little
(``scipy.optimize.least_squares``; Triggs et al. 2000 on robust bundle-type fits). The power
is kept in [0.3, 6] and the sky's level at or above 0: unbounded, the two trade off into a
logarithmic profile (a power near 0, a huge amplitude and a negative sky) that fits clear
glare and overcast alike.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from vision.detection import FovCircle

_REACH = 3.0  # sky pixels within this many core radii (+ 10 px) of the core's centroid
_SAMPLES = 1500  # about this many pixels, on a regular grid
_DARK = 0.6  # pixels below this × the sky's level are not sky (trees, the ground, a mask)
_LOSS_SCALE = 4.0  # grey levels: the soft-L1 loss is quadratic within this
_FOV_MARGIN_PX = 3.0  # pixels this close to the image circle's edge are left out


def _window(cx: float, cy: float, radius_px: float, w: int, h: int
            ) -> tuple[float, int, int, int, int] | None:
    """The glare fits' window about a core centred at ``(cx, cy)`` of ``radius_px`` in a
    ``w`` × ``h`` frame → ``(reach, x0, y0, x1, y1)``: :data:`_REACH` core radii + 10 px,
    cut to the frame; None when under 8 px on a side."""
    reach = _REACH * radius_px + 10.0
    x0, y0 = max(0, int(cx - reach)), max(0, int(cy - reach))
    x1, y1 = min(w, int(cx + reach) + 1), min(h, int(cy + reach) + 1)
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None
    return reach, x0, y0, x1, y1


def _sky_level(img: NDArray[Any], fov: FovCircle | None, every: int) -> float:
    """The sky's level for the glare fits' dark test: the median of min(B, G, R) (or the
    grey level) of every ``every``-th pixel on both axes, inside the image circle when one
    is given (0 when none is)."""
    grid = img[::every, ::every]
    grid = grid if grid.ndim == 2 else grid.min(axis=2)
    if fov is not None:
        h, w = img.shape[:2]
        gy, gx = np.mgrid[0:h:every, 0:w:every]
        grid = grid[np.hypot(gx - fov.cx_px, gy - fov.cy_px) < fov.radius_px]
    return float(np.median(grid)) if grid.size else 0.0


def censored_glare_centre(image: NDArray[Any], cx: float, cy: float, radius_px: float,
                          fov: FovCircle | None = None) -> tuple[float, float] | None:
    """The sun's pixel ``(x, y)`` from the glare around a clipped core (see the module
    docstring), or None when too few sky pixels are left or the fit fails.

    ``image``: the frame, grey or colour — a colour frame is fitted on min(B, G, R), where
    a blue sky adds least to the glare (its red is some 0.6 of its grey level) and the
    glare's own excess is largest; ``(cx, cy)``, ``radius_px``: the clipped core's
    centroid and equivalent radius (the fit's start and scale). A pixel is clipped from
    3 levels under the top of the pixels fitted; the sky's level is the median of the
    fitted channel in the image circle (every 16th pixel, :func:`_sky_level`; pixels under
    :data:`_DARK` × it are left out, one by one, and those within :data:`_FOV_MARGIN_PX` of
    the image circle's edge). The window (:func:`_window`) is
    :func:`symmetric_glare_centre`'s; its sky is sampled twice as densely (that fit's every
    32nd pixel here moves no Wolf frame's answer, but every 16th there moves Wolf 13:41
    brightened × 1.15 by 1.8 px, so each keeps the sampling it was measured with)."""
    img = np.asarray(image)
    gray = img if img.ndim == 2 else cv2.min(cv2.min(img[:, :, 0], img[:, :, 1]), img[:, :, 2])
    h, w = gray.shape
    sky = _sky_level(gray, fov, 16)
    win = _window(cx, cy, radius_px, w, h)
    if win is None:
        return None
    reach, x0, y0, x1, y1 = win
    step = max(1, int(np.sqrt((x1 - x0) * (y1 - y0) / _SAMPLES)))
    yy, xx = np.mgrid[y0:y1:step, x0:x1:step]
    v = gray[y0:y1:step, x0:x1:step].astype(float)
    keep = (np.hypot(xx - cx, yy - cy) < reach) & (v >= _DARK * sky)
    if fov is not None:
        keep &= np.hypot(xx - fov.cx_px, yy - fov.cy_px) < fov.radius_px - _FOV_MARGIN_PX
    xs, ys, vs = xx[keep].astype(float), yy[keep].astype(float), v[keep]
    clip = float(vs.max()) - 3.0 if vs.size else 0.0
    sat = vs >= clip
    if int(np.count_nonzero(~sat)) < 50 or not sat.any():
        return None
    dx, dy = (xs - cx) / radius_px, (ys - cy) / radius_px
    s_lo = float(np.percentile(vs[~sat], 5))

    def residuals(q: NDArray[np.float64]) -> NDArray[np.float64]:
        r = np.hypot(xs - q[0], ys - q[1]) / radius_px
        glare = np.exp(min(q[2], 20.0)) * np.maximum(r, 0.05) ** (-q[3])
        # a glare term past 10⁴ grey levels (a wild step of the solver) is as wrong as 10⁴
        m = q[4] + q[5] * dx + q[6] * dy + np.minimum(glare, 1e4)
        out = m - vs
        out[sat] = np.minimum(m[sat] - clip, 0.0)  # censored: only the shortfall counts
        return np.asarray(out, float)

    q0 = np.array([cx, cy, np.log(max(clip - s_lo, 1.0)), 2.0, s_lo, 0.0, 0.0])
    try:
        lo = [-np.inf, -np.inf, -np.inf, 0.3, 0.0, -np.inf, -np.inf]
        hi = [np.inf, np.inf, np.inf, 6.0, np.inf, np.inf, np.inf]
        sol = least_squares(residuals, q0, bounds=(lo, hi), loss="soft_l1", f_scale=_LOSS_SCALE,
                            max_nfev=150)
    except (ValueError, np.linalg.LinAlgError):
        return None
    x, y = float(sol.x[0]), float(sol.x[1])
    if not (np.isfinite(x) and np.isfinite(y)) or np.hypot(x - cx, y - cy) > reach:
        return None
    return x, y


# symmetric_glare_centre: the knots of the free radial profile, in core radii
_KNOTS = np.array([0.0, 0.5, 0.8, 1.0, 1.2, 1.4, 1.7, 2.0, 2.5, 3.0, 3.5])
_SYM_SAMPLES = 700  # about this many blocks (more: the normal equations reach threaded BLAS)
_SYM_ITER = 8  # Gauss-Newton steps at most
_SYM_TOL_PX = 0.1  # … stopped when the centre moves less than this


def _hats(r: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The piecewise-linear ("hat") basis on :data:`_KNOTS` at radii ``r`` (core radii) and
    its derivative in ``r`` → two ``[N, K]`` arrays (0 beyond the last knot)."""
    kn = _KNOTS
    k = np.clip(np.searchsorted(kn, r, side="right") - 1, 0, kn.size - 2)
    width = kn[k + 1] - kn[k]
    f = np.clip((r - kn[k]) / width, 0.0, 1.0)
    inside = (r <= kn[-1]).astype(float)
    n = r.size
    rows = np.arange(n)
    basis = np.zeros((n, kn.size))
    slope = np.zeros((n, kn.size))
    basis[rows, k] = (1.0 - f) * inside
    basis[rows, k + 1] = f * inside
    slope[rows, k] = -inside / width
    slope[rows, k + 1] = inside / width
    return basis, slope


def symmetric_glare_centre(image: NDArray[Any], cx: float, cy: float, radius_px: float,
                           fov: FovCircle | None = None,
                           start: tuple[float, float] | None = None
                           ) -> tuple[float, float] | None:
    """The centre of the radially symmetric glare around a saturated core → ``(x, y)``, or
    None (too few sky pixels, a singular system).

    The model of the frame within 3 core radii is a plane of sky plus a glare that is any
    function of the distance from its centre, ``I(x) = s0 + s · x + P(|x − c|)``, ``P``
    piecewise linear on knots at 0 … 3.5 core radii (a free profile: the lens's veiling
    glare and the aureole fall off with the angle from the sun, ISO 9358, Deepak et al.
    1982, but by no law one power fits — the power-law fit of :func:`censored_glare_centre`
    ends at or near its lower bound, 0.3, on the Wolf frames), fitted to min(B, G, R) of a
    colour frame, *censored* at the clip level (a clipped block says only that the model
    reaches at least its mean there; Tobin 1958), with a soft-L1 loss by iteratively
    reweighted least squares (Holland & Welsch 1977) so trees' edges, lens rays and
    overlays cost little. The profile and the plane enter linearly; the centre by
    Gauss-Newton from ``start`` (default ``(cx, cy)``), each step one linear solve on the
    normal equations, at most :data:`_SYM_ITER` steps.

    ``(cx, cy)``, ``radius_px``: the clipped core's centroid and equivalent radius (the
    window and the scale of the knots). Left out: every block whose mean is under
    :data:`_DARK` (0.6) × the sky's level (trees, the ground), *and its 8 neighbours* (a
    block partly over a tree is darker than the glare without being dark), and every block
    whose centre lies within :data:`_FOV_MARGIN_PX` (3 px) + half a block of the image
    circle's edge.

    Why (issue 24 item 3): on the Wolf camera the white core's outline is ragged (lens
    rays, 16-px JPEG colour blocks) and its centre scatters 4.24 px RMS across the radius
    from the optical centre (against SPA through an equidistant fit, by hand); the
    detector's positions, which take the glare's centre across, 2.40 px blind and 2.42 px
    guided (``benchmarks/bench_vision_calibration.py``, centre study). Along that radius
    the glare's centre is biased inward (vignetting, a sky that is no plane: 7.7 px inside
    the hand labels on Wolf), which is why :func:`vision.detect.detect_robust` takes only its
    component *across* the radius (:func:`vision.detect._across_from_glare`).
    Samples are block means (about :data:`_SYM_SAMPLES` blocks: one pixel per sample
    aliases with the JPEG blocks), each colour's, then their minimum; a block within 3
    levels of the top is clipped, censored at its mean. The sky's level for the dark test
    is the median of every 32nd pixel in the image circle (:func:`_sky_level`; the window is
    :func:`_window`, both shared with :func:`censored_glare_centre`, which samples the sky
    at every 16th pixel: taken here, that moves Wolf 13:41 brightened × 1.15 by 1.8 px, so
    each keeps the sampling it was measured with; its dark test is per pixel, this one per
    block with the neighbours)."""
    img = np.asarray(image)
    h, w = img.shape[:2]
    win = _window(cx, cy, radius_px, w, h)
    if win is None:
        return None
    reach, x0, y0, x1, y1 = win
    sky = _sky_level(img, fov, 32)
    # block means (step × step pixels each; one pixel per sample aliases with the 16-px
    # JPEG blocks), each channel's, then their minimum; a block within 3 levels of the
    # top is clipped (censored at its mean: the truth is at least that)
    step = max(1, int(np.sqrt((x1 - x0) * (y1 - y0) / _SYM_SAMPLES)))
    nx, ny = (x1 - x0) // step, (y1 - y0) // step
    if nx < 4 or ny < 4:
        return None
    crop = img[y0:y0 + ny * step, x0:x0 + nx * step]
    blocks = cv2.resize(crop, (nx, ny), interpolation=cv2.INTER_AREA) if step > 1 else crop
    v = (blocks if blocks.ndim == 2 else blocks.min(axis=2)).astype(float)
    sat_all = v >= float(v.max()) - 3.0
    yy, xx = np.mgrid[0:ny, 0:nx]
    xx = x0 + (xx + 0.5) * step - 0.5
    yy = y0 + (yy + 0.5) * step - 0.5
    # not sky: a block under _DARK × the sky's level (trees, the ground) and its neighbours
    # (a block partly over a tree is darker than the glare there without being dark)
    dark = cv2.dilate((v < _DARK * sky).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    keep = (np.hypot(xx - cx, yy - cy) < reach) & ~dark
    if fov is not None:
        keep &= np.hypot(xx - fov.cx_px, yy - fov.cy_px) \
            < fov.radius_px - _FOV_MARGIN_PX - 0.5 * step
    xs, ys, vs, sat = xx[keep], yy[keep], v[keep], sat_all[keep]
    if int(np.count_nonzero(~sat)) < 50 or not sat.any():
        return None
    dx, dy = (xs - cx) / radius_px, (ys - cy) / radius_px
    ones = np.ones_like(dx)
    c = np.array(start if start is not None else (cx, cy), float)
    use = ~sat
    wgt = np.ones(vs.size)
    q: NDArray[np.float64] | None = None
    for it in range(_SYM_ITER):
        ex, ey = (xs - c[0]) / radius_px, (ys - c[1]) / radius_px
        r = np.maximum(np.hypot(ex, ey), 1e-6)
        basis, slope = _hats(r)
        if q is None:  # the plane and the profile about the start, the clipped pixels out
            a = np.column_stack([ones, dx, dy, basis])[use]
            got = _normal_solve(a, vs[use], wgt[use])
            if got is None:
                return None
            q = got
        m = q[0] + q[1] * dx + q[2] * dy + basis @ q[3:]
        use = (~sat) | (m < vs)  # censored: a clipped block counts where the model falls short
        res = m - vs
        wgt = 1.0 / np.sqrt(1.0 + (res / _LOSS_SCALE) ** 2)  # soft-L1
        dp = slope @ q[3:]  # P'(r), grey levels per core radius
        jac = np.column_stack([-dp * ex / r / radius_px, -dp * ey / r / radius_px,
                               ones, dx, dy, basis])
        delta = _normal_solve(jac[use], -res[use], wgt[use])
        if delta is None:
            return None
        moved = float(np.hypot(delta[0], delta[1]))
        if moved > 0.25 * radius_px:  # a step past a quarter of the core: damped
            delta[:2] *= 0.25 * radius_px / moved
        c += delta[:2]
        q = q + delta[2:]
        if moved < _SYM_TOL_PX and it > 0:  # the first step is before the censoring
            break
    if not np.all(np.isfinite(c)) or np.hypot(c[0] - cx, c[1] - cy) > reach:
        return None
    return float(c[0]), float(c[1])


def _normal_solve(a: NDArray[np.float64], b: NDArray[np.float64], w: NDArray[np.float64]
                  ) -> NDArray[np.float64] | None:
    """Weighted least squares ``min Σ w (a x − b)²`` by its normal equations (a few
    columns: a small dense solve, no threaded LAPACK least-squares on the frame's
    samples), with a tiny ridge on the diagonal so that a knot no sample reaches stays
    defined."""
    aw = a * w[:, None]
    ata = a.T @ aw
    ata[np.diag_indices_from(ata)] += 1e-9 * max(float(np.trace(ata)), 1.0)
    try:
        return np.asarray(np.linalg.solve(ata, aw.T @ b), float)
    except np.linalg.LinAlgError:
        return None
