"""The sun's centre as the centre of radial symmetry of its glare (Parthasarathy 2012).

Follows R. Parthasarathy, "Rapid, accurate particle tracking by calculation of
radial symmetry centers", Nature Methods 9:724–726 (2012): at every corner
between four pixels the intensity gradient (Roberts cross, smoothed 3 × 3)
defines a line; for a radially symmetric image every line passes through the
centre, so the centre is the point with the least weighted squared distance
to all lines — a 2 × 2 linear system, no iteration over a model. Weights as in
the paper: the squared gradient magnitude over the distance from the current
estimate.

Made robust for sky frames (our additions, each a plain reweighting):

* only gradients that point toward the estimate (the glare brightens inward)
  take part, and lines far from the estimate are down-weighted with a Cauchy
  function of their distance (iteratively reweighted least squares), so a
  cloud edge, a flare ghost or a tree line in the window barely moves it;
* pixels darker than the sky around the glare (trees, an obstacle, outside
  the image circle, a text box) and their neighbours are left out, so the
  mask edge contributes no gradient;
* with a camera model, the lines are moved to the tangent (gnomonic) plane of
  the sphere at the estimate before the solve: there a glare that is a small
  circle on the sky is a circle centred on the sun, where the fisheye draws
  it as an off-centre oval near the horizon.

A saturated core has no gradient inside; its limb and the halo around it
carry all the weight, so a clipped (saturated) sun is handled as a flat-top
radially symmetric spot. A limb cut by the horizon or an obstacle still
points at the centre on the arc that is left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.detection import CameraModel


@dataclass(frozen=True)
class RadialFit:
    """Result of :func:`radial_symmetry_centre`.

    ``coherence`` is the fraction of the inward-pointing gradient weight whose
    lines pass within the inlier band of the centre (≈ 1 for a sun's glare, low
    for a cloud highlight); ``spread_px`` the weighted RMS distance of the
    inlier lines from the centre [px]; ``n_lines`` how many lines took part.
    """

    x_px: float
    y_px: float
    coherence: float
    spread_px: float
    n_lines: int


def _solve(px: NDArray[np.float64], py: NDArray[np.float64], nx: NDArray[np.float64],
           ny: NDArray[np.float64], w: NDArray[np.float64]) -> tuple[float, float] | None:
    """Point nearest (weighted least squares) to the lines through (px, py) along (nx, ny):
    ``Σ w (I − n nᵀ) c = Σ w (I − n nᵀ) p``, a 2 × 2 system (dot products only)."""
    wnx, wny = w * nx, w * ny
    sw = float(w.sum())
    a11 = sw - float(wnx @ nx)
    a22 = sw - float(wny @ ny)
    a12 = -float(wnx @ ny)
    det = a11 * a22 - a12 * a12
    if not math.isfinite(det) or det <= 1e-9 * max(a11 * a22, 1e-30):
        return None
    q = nx * px + ny * py
    b1 = float(w @ px) - float(wnx @ q)
    b2 = float(w @ py) - float(wny @ q)
    return (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det


def _tangent(camera: CameraModel, x: NDArray[np.float64], y: NDArray[np.float64],
             axis: NDArray[np.float64], e1: NDArray[np.float64], e2: NDArray[np.float64]
             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gnomonic coordinates [rad] about ``axis`` of pixels (x, y)."""
    v = camera.pixel_to_direction(x, y)
    d = v @ axis
    d = np.where(d > 1e-6, d, np.nan)
    return (v @ e1) / d, (v @ e2) / d


# a 2 × 2 erosion / dilation anchored at its first pixel: the four pixels of a corner
_TWO = np.ones((2, 2), np.uint8)
_THREE = np.ones((3, 3), np.uint8)
_FOUR = np.ones((4, 4), np.uint8)


def gradient_lines(gray: NDArray[np.uint8], x0: int, y0: int, x1: int, y1: int,
                   dark_level: float, glare_level: float = 0.0, saturated_level: float = 256.0,
                   sky_gradient: tuple[float, float] = (0.0, 0.0)
                   ) -> tuple[NDArray[Any], ...]:
    """Midpoints, unit gradient directions and squared magnitudes in a window.

    Window ``[x0, x1) × [y0, y1)`` of ``gray``; gradients by the Roberts
    cross at the corners between pixels, smoothed by a 3 × 3 box
    (Parthasarathy 2012); corners touching a pixel below ``dark_level`` (or
    next to one) are dropped, as are gradients weaker than 2 % of the
    strongest, and corners whose four pixels are all below ``glare_level``
    (plain sky: its own gradient, e.g. toward the horizon, says nothing about
    the sun). ``sky_gradient`` [grey px⁻¹] is subtracted from every gradient
    that does not touch a saturated pixel (≥ ``saturated_level``): there the
    frame is glare + sky, and a radially symmetric glare's own gradient points
    at its centre. Returns ``(px, py, nx, ny, g2, clipped)``.
    """
    raw = gray[y0:y1, x0:x1]
    win: NDArray[Any] = raw.astype(np.float32)
    d_u: NDArray[Any] = cv2.blur(win[:-1, 1:] - win[1:, :-1], (3, 3))  # along (+x, −y)
    d_v: NDArray[Any] = cv2.blur(win[:-1, :-1] - win[1:, 1:], (3, 3))  # along (−x, −y)
    gx = 0.5 * (d_u - d_v)
    gy = -0.5 * (d_u + d_v)
    if saturated_level <= 255.0:
        sat = cv2.dilate((raw >= saturated_level).view(np.uint8), _THREE)
        clip4 = cv2.dilate(sat, _TWO, anchor=(0, 0))[:-1, :-1] > 0  # the blur's reach
        gx = np.where(clip4, gx, gx - np.float32(sky_gradient[0]))
        gy = np.where(clip4, gy, gy - np.float32(sky_gradient[1]))
    else:
        clip4 = None  # no saturated level: nothing clipped
        if sky_gradient != (0.0, 0.0):
            gx -= np.float32(sky_gradient[0])
            gy -= np.float32(sky_gradient[1])
    g2 = gx * gx + gy * gy
    # no dark pixel next to a corner's four: the 3 × 3 erosion (edge replicated), then the
    # 2 × 2 one anchored at its first pixel, as one 4 × 4 erosion anchored at (1, 1)
    ok4 = np.asarray(cv2.erode((raw >= dark_level).view(np.uint8), _FOUR, anchor=(1, 1),
                               borderType=cv2.BORDER_REPLICATE)[:-1, :-1], np.uint8)
    if glare_level > 0:
        hi = np.asarray(cv2.dilate((raw >= glare_level).view(np.uint8), _TWO, anchor=(0, 0)),
                        np.uint8)
        ok4 &= hi[:-1, :-1]
    gmax = float(g2.max()) if g2.size else 0.0
    sel = (ok4 > 0) & (g2 > max(4e-4 * gmax, 1.0))
    # the selected corners by flat index (1-D gathers are cheaper than 2-D ones)
    at = np.flatnonzero(sel)
    iy = at // sel.shape[1]
    ix = at - iy * sel.shape[1]
    g2s = g2.ravel()[at].astype(np.float64)
    mag = np.sqrt(g2s)
    return (ix + (x0 + 0.5), iy + (y0 + 0.5), gx.ravel()[at] / mag, gy.ravel()[at] / mag, g2s,
            clip4.ravel()[at] if clip4 is not None else np.zeros(at.size, bool))


def sky_plane_gradient(gray: NDArray[np.uint8], cx: float, cy: float, r_in: float,
                       r_out: float, lo: float, hi: float) -> tuple[float, float]:
    """Gradient (d/dx, d/dy) [grey px⁻¹] of a plane fitted to the annulus
    ``r_in ≤ r < r_out`` around (cx, cy), pixels in ``[lo, hi)`` only.

    A radially symmetric glare contributes no slope to a plane fitted over a
    whole annulus centred on it; what is left is the sky's own gradient
    (brighter toward the horizon). Returns (0, 0) with too few pixels.
    """
    h, w = gray.shape
    x0, y0 = max(0, int(cx - r_out)), max(0, int(cy - r_out))
    x1, y1 = min(w, int(cx + r_out) + 1), min(h, int(cy + r_out) + 1)
    if x1 - x0 < 3 or y1 - y0 < 3:
        return 0.0, 0.0
    step = max(1, int(r_out // 40))
    win = gray[y0:y1:step, x0:x1:step].astype(np.float64)
    yy, xx = np.mgrid[y0:y1:step, x0:x1:step]
    dx, dy = xx - cx, yy - cy
    rr = np.hypot(dx, dy)
    m = (rr >= r_in) & (rr < r_out) & (win >= lo) & (win < hi)
    if m.sum() < 24:
        return 0.0, 0.0
    # a full annulus is needed for the glare's symmetric part to cancel: all four quadrants
    quads = {(bool(a), bool(b)) for a, b in zip(dx[m] > 0, dy[m] > 0, strict=True)}
    if len(quads) < 4:
        return 0.0, 0.0
    a = np.column_stack([np.ones(int(m.sum())), dx[m], dy[m]])
    coef, *_ = np.linalg.lstsq(a, win[m], rcond=None)
    return float(coef[1]), float(coef[2])


def mapped_coherence(gray: NDArray[np.uint8], start_px: tuple[float, float],
                     radius_px: float, dark_level: float, glare_level: float,
                     maps: list[NDArray[np.float64] | None], n_iter: int = 1) -> list[float]:
    """The ``coherence`` of :func:`radial_symmetry_centre`'s fit (no camera) with the window's
    gradient lines first carried by each linear map of ``maps`` (:func:`vision.detect._sky_map`;
    None: the image plane) — the points as vectors (A p), the gradients as the normals of their
    isophotes (A⁻ᵀ n) — one entry per map, 0 where no fit. The lines are found once."""
    lines = _window_lines(gray, start_px, radius_px, dark_level, glare_level, 256.0,
                          (0.0, 0.0))
    if lines is None:
        return [0.0] * len(maps)
    px, py, nx, ny, g2 = lines
    out = []
    for a in maps:
        if a is None:
            fit = _radial_flat(px, py, nx, ny, g2, start_px[0], start_px[1], n_iter)
        else:
            inv_t = np.linalg.inv(a).T
            mx, my = inv_t[0, 0] * nx + inv_t[0, 1] * ny, inv_t[1, 0] * nx + inv_t[1, 1] * ny
            norm = np.hypot(mx, my)
            sx, sy = a @ np.asarray(start_px, dtype=np.float64)
            fit = _radial_flat(a[0, 0] * px + a[0, 1] * py, a[1, 0] * px + a[1, 1] * py,
                               mx / norm, my / norm, g2, float(sx), float(sy), n_iter)
        out.append(fit.coherence if fit is not None else 0.0)
    return out


def _window_lines(gray: NDArray[np.uint8], start_px: tuple[float, float], radius_px: float,
                  dark_level: float, glare_level: float, saturated_level: float,
                  sky_gradient: tuple[float, float]) -> tuple[NDArray[Any], ...] | None:
    """:func:`gradient_lines` of the square window of half-width ``radius_px`` (at least 4)
    about ``start_px`` → ``(px, py, nx, ny, g2)``, those touching a saturated pixel left out
    when 30 others are left; None when the window or the lines are too few."""
    h, w = gray.shape
    cx, cy = start_px
    r = max(4.0, float(radius_px))
    x0, y0 = max(0, int(cx - r)), max(0, int(cy - r))
    x1, y1 = min(w, int(cx + r) + 2), min(h, int(cy + r) + 2)
    if x1 - x0 < 4 or y1 - y0 < 4:
        return None
    px, py, nx, ny, g2, clipped = gradient_lines(gray, x0, y0, x1, y1, dark_level, glare_level,
                                                 saturated_level, sky_gradient)
    if clipped.any() and int((~clipped).sum()) >= 30:
        px, py, nx, ny, g2 = px[~clipped], py[~clipped], nx[~clipped], ny[~clipped], g2[~clipped]
    if px.size < 8:
        return None
    return px, py, nx, ny, g2


def radial_symmetry_centre(gray: NDArray[np.uint8], start_px: tuple[float, float],
                           radius_px: float, dark_level: float, glare_level: float = 0.0,
                           camera: CameraModel | None = None, n_iter: int = 5,
                           saturated_level: float = 256.0,
                           sky_gradient: tuple[float, float] = (0.0, 0.0)
                           ) -> RadialFit | None:
    """Centre of radial symmetry of the glare around ``start_px`` (see the module docstring).

    Parameters
    ----------
    gray : 8-bit grey frame.
    start_px : first estimate ``(x, y)`` [px] (the bright blob's centroid).
    radius_px : half-width of the square window [px] (about twice the blob's
        equivalent radius: the limb and the inner halo).
    dark_level : grey level below which a pixel is not sky (trees, mask, box).
    glare_level : grey level a corner must reach to count (part of the glare).
    camera : optional pixel ↔ direction model: the lines are solved in the
        tangent plane of the sphere at the estimate.
    n_iter : reweighting passes.
    saturated_level, sky_gradient : see :func:`gradient_lines`; gradients
        touching a saturated pixel are used only when fewer than 30 others are
        left (a bare disc on a flat sky).

    Returns None when too few gradient lines are left.
    """
    cx, cy = start_px
    lines = _window_lines(gray, start_px, radius_px, dark_level, glare_level, saturated_level,
                          sky_gradient)
    if lines is None:
        return None
    px, py, nx, ny, g2 = lines
    if camera is None:
        return _radial_flat(px, py, nx, ny, g2, float(cx), float(cy), n_iter)
    ux, uy, mx, my = px, py, nx, ny  # the solve's coordinates (image, or tangent plane)
    axis: Any = None
    e1: Any = None
    e2: Any = None
    scale = 1.0  # tangent-plane units per pixel
    ex, ey = float(cx), float(cy)
    band = 1.0
    base = g2
    nux, nuy = ex, ey
    perp_after: NDArray[np.float64] | None = None  # line distances from the new estimate
    for it in range(n_iter):
        if camera is not None and it in (0, 2):
            axis = camera.pixel_to_direction(np.array([ex]), np.array([ey]))[0]
            helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0, 0])
            e1 = np.cross(helper, axis)
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(axis, e1)
            tx, ty = _tangent(camera, px, py, axis, e1, e2)
            # a gradient is the normal of its isophote, and a normal is not carried by the
            # map's Jacobian J as a vector is (J n) but as J⁻ᵀ n: the isophote's tangent
            # (n turned −90°) is carried by J, and the normal is that turned back +90°,
            # with the map's orientation (det J: a mirrored camera turns it the other way)
            sx, sy = _tangent(camera, px + 0.5 * ny, py - 0.5 * nx, axis, e1, e2)
            turn = _orientation(camera, ex, ey, axis, e1, e2)
            dx, dy = turn * (ty - sy), turn * (sx - tx)
            step = np.hypot(dx, dy)
            good = np.isfinite(step) & (step > 0)
            if good.sum() < 8:
                camera = None
            else:
                scale = float(np.median(step[good])) / 0.5
                ux = np.where(good, tx / scale, 0.0)
                uy = np.where(good, ty / scale, 0.0)
                mx = np.where(good, dx / np.where(good, step, 1.0), 0.0)
                my = np.where(good, dy / np.where(good, step, 1.0), 0.0)
                g2 = np.where(good, g2, 0.0)
        if camera is not None and axis is not None:
            cux, cuy = _tangent_of(camera, ex, ey, axis, e1, e2, scale)
        else:
            cux, cuy = ex, ey
        ddx, ddy = cux - ux, cuy - uy
        dist = np.hypot(ddx, ddy)
        perp = np.abs(ddx * my - ddy * mx)
        if it > 0:
            # the inlier band: the weighted median line distance from the last estimate
            # (last pass's weights), at least 0.5 px
            perp_b = perp if perp_after is None else perp_after
            order = np.argsort(perp_b)
            cw = np.cumsum(base[order])
            med = float(perp_b[order][min(int(np.searchsorted(cw, 0.5 * cw[-1])),
                                          len(order) - 1)])
            band = max(0.5, 1.5 * med)
        cos_min = 0.3 if it == 0 else 0.7
        # inward: the gradient points at the estimate (the glare brightens toward it)
        base = g2 * ((mx * ddx + my * ddy) > cos_min * np.maximum(dist, 1e-9)) \
            / np.maximum(dist, 2.0)
        if float(base.sum()) <= 0:
            return None
        wgt = base if it == 0 else base / (1.0 + (perp / band) ** 2)
        got = _solve(ux, uy, mx, my, wgt)
        if got is None:
            return None
        nux, nuy = got
        if camera is not None and axis is not None:
            v = axis + (nux * scale) * e1 + (nuy * scale) * e2
            qx, qy = camera.direction_to_pixel(v / np.linalg.norm(v))
            ex, ey = float(qx), float(qy)
        else:
            ex, ey = float(nux), float(nuy)
        if not (math.isfinite(ex) and math.isfinite(ey)):
            return None
        if camera is not None:  # the tangent plane may move before the next pass
            perp_after = np.abs((nux - ux) * my - (nuy - uy) * mx)
    ddx, ddy = nux - ux, nuy - uy
    perp = np.abs(ddx * my - ddy * mx)
    dist = np.hypot(ddx, ddy)
    inward = (mx * ddx + my * ddy) / np.maximum(dist, 1e-9)
    base = g2 * (inward > 0.0) / np.maximum(dist, 2.0)
    tol = np.maximum(1.5, 0.08 * dist)
    inl = perp <= tol
    total = float((g2 / np.maximum(dist, 2.0)).sum())
    coherence = float(base[inl].sum() / total) if total > 0 else 0.0
    wi = base * inl
    spread = float(np.sqrt((wi * perp**2).sum() / wi.sum())) if wi.sum() > 0 else float("inf")
    return RadialFit(ex, ey, coherence, spread, int(px.size))


def _orientation(camera: CameraModel, x: float, y: float, axis: NDArray[np.float64],
                 e1: NDArray[np.float64], e2: NDArray[np.float64]) -> float:
    """The sign (±1) of the determinant of the map from pixels to the gnomonic plane about
    ``axis`` at pixel (x, y): −1 where the camera's image is mirrored against that plane."""
    tx, ty = _tangent(camera, np.array([x, x + 1.0, x]), np.array([y, y, y + 1.0]), axis,
                      e1, e2)
    det = (tx[1] - tx[0]) * (ty[2] - ty[0]) - (tx[2] - tx[0]) * (ty[1] - ty[0])
    return 1.0 if not det < 0 else -1.0


def _tangent_of(camera: CameraModel, x: float, y: float, axis: NDArray[np.float64],
                e1: NDArray[np.float64], e2: NDArray[np.float64], scale: float
                ) -> tuple[float, float]:
    tx, ty = _tangent(camera, np.array([x]), np.array([y]), axis, e1, e2)
    return float(tx[0]) / scale, float(ty[0]) / scale


def _radial_flat(px: NDArray[np.float64], py: NDArray[np.float64], nx: NDArray[np.float64],
                 ny: NDArray[np.float64], g2: NDArray[np.float64], cx: float, cy: float,
                 n_iter: int) -> RadialFit | None:
    """:func:`radial_symmetry_centre` in the image plane (no camera model).

    The same reweighting as the tangent-plane path, written with every per-line
    quantity that does not depend on the estimate computed once: a line's
    distance from the estimate c is ``|c × n − p × n|``, its inward dot product
    ``n · c − n · p``, its squared distance ``|c|² − 2 p · c + |p|²``, all
    linear in ``(cx, cy, 1)`` (one matrix product per pass), and the 2 × 2
    normal equations of :func:`_solve` are ``w`` times a fixed n × 5 matrix.
    """
    n = px.size
    q = nx * px + ny * py
    # rows: the coefficients of (cx, cy, 1); columns: signed line distance, inward dot
    # product, squared distance − |c|² of every line (contiguous rows: one product a pass)
    lin = np.empty((3, 3 * n))
    lin[0, :n], lin[1, :n], lin[2, :n] = ny, -nx, py * nx - px * ny
    lin[0, n:2 * n], lin[1, n:2 * n], lin[2, n:2 * n] = nx, ny, -q
    lin[0, 2 * n:], lin[1, 2 * n:], lin[2, 2 * n:] = -2.0 * px, -2.0 * py, px * px + py * py
    normal = np.empty((5, n))
    normal[0], normal[1], normal[2] = 1.0 - nx * nx, 1.0 - ny * ny, -nx * ny
    normal[3], normal[4] = px - nx * q, py - ny * q

    def at(ex: float, ey: float) -> tuple[NDArray[np.float64], ...]:
        v = np.array([ex, ey, 1.0]) @ lin
        perp = np.abs(v[:n])
        dist = np.sqrt(np.maximum(v[2 * n:] + (ex * ex + ey * ey), 0.0))
        return perp, v[n:2 * n], dist

    ex, ey = cx, cy
    band = 1.0
    base = g2
    for it in range(n_iter):
        perp, inward, dist = at(ex, ey)
        if it > 0:
            # the inlier band: the weighted median line distance from the last estimate
            # (last pass's weights), at least 0.5 px
            order = np.argsort(perp)
            cw = np.cumsum(base[order])
            med = float(perp[order][min(int(np.searchsorted(cw, 0.5 * cw[-1])), n - 1)])
            band = max(0.5, 1.5 * med)
        cos_min = 0.3 if it == 0 else 0.7
        base = g2 * (inward > cos_min * np.maximum(dist, 1e-9)) / np.maximum(dist, 2.0)
        if float(base.sum()) <= 0:
            return None
        wgt = base if it == 0 else base / (1.0 + (perp / band) ** 2)
        a11, a22, a12, b1, b2 = (normal @ wgt).tolist()
        det = a11 * a22 - a12 * a12
        if not math.isfinite(det) or det <= 1e-9 * max(a11 * a22, 1e-30):
            return None
        ex, ey = (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det
        if not (math.isfinite(ex) and math.isfinite(ey)):
            return None
    perp, inward, dist = at(ex, ey)
    d2 = np.maximum(dist, 2.0)
    base = g2 * (inward > 0.0) / d2
    inl = perp <= np.maximum(1.5, 0.08 * dist)
    total = float((g2 / d2).sum())
    coherence = float(base[inl].sum() / total) if total > 0 else 0.0
    wi = base * inl
    swi = float(wi.sum())
    spread = float(np.sqrt(float(wi @ (perp * perp)) / swi)) if swi > 0 else float("inf")
    return RadialFit(ex, ey, coherence, spread, int(n))
