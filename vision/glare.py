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


def censored_glare_centre(image: NDArray[Any], cx: float, cy: float, radius_px: float,
                          fov: FovCircle | None = None) -> tuple[float, float] | None:
    """The sun's pixel ``(x, y)`` from the glare around a clipped core (see the module
    docstring), or None when too few sky pixels are left or the fit fails.

    ``image``: the frame, grey or colour — a colour frame is fitted on min(B, G, R), where
    a blue sky adds least to the glare (its red is some 0.6 of its grey level) and the
    glare's own excess is largest; ``(cx, cy)``, ``radius_px``: the clipped core's
    centroid and equivalent radius (the fit's start and scale). A pixel is clipped from
    3 levels under the top of the pixels fitted; the sky's level is the median of the
    fitted channel in the image circle (every 16th pixel; pixels under :data:`_DARK` × it
    are left out)."""
    img = np.asarray(image)
    gray = img if img.ndim == 2 else cv2.min(cv2.min(img[:, :, 0], img[:, :, 1]), img[:, :, 2])
    h, w = gray.shape
    grid = gray[::16, ::16]
    if fov is not None:
        gy, gx = np.mgrid[0:h:16, 0:w:16]
        grid = grid[np.hypot(gx - fov.cx_px, gy - fov.cy_px) < fov.radius_px]
    sky = float(np.median(grid)) if grid.size else 0.0
    reach = _REACH * radius_px + 10.0
    x0, y0 = max(0, int(cx - reach)), max(0, int(cy - reach))
    x1, y1 = min(w, int(cx + reach) + 1), min(h, int(cy + reach) + 1)
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None
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
