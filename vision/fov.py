"""Grey conversion, frame statistics and the fisheye image circle (field-of-view mask)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.detection import FovCircle
from vision.imageio import to_8bit


def to_gray(image: NDArray[Any]) -> NDArray[np.uint8]:
    """8-bit grey (ITU-R BT.601 luma, cv2.cvtColor) from a BGR, BGRA or grey frame, its
    samples brought to 8 bits by :func:`vision.imageio.to_8bit`."""
    img = to_8bit(image)
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return np.asarray(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), dtype=np.uint8)
    if img.ndim == 3 and img.shape[2] == 4:
        return np.asarray(cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY), dtype=np.uint8)
    if img.ndim == 3 and img.shape[2] == 1:
        return img[:, :, 0]
    raise ValueError(f"image must be H×W, H×W×3 or H×W×4, got shape {img.shape}")


def _small(gray: NDArray[np.uint8]) -> tuple[NDArray[np.uint8], int]:
    """A ~96 px thumbnail by plain subsampling (every s-th pixel, centred): cheap, and
    enough for the frame's statistics and its image circle."""
    h, w = gray.shape
    s = max(1, min(h, w) // 96)
    if s == 1:
        return gray, 1
    return np.ascontiguousarray(gray[s // 2::s, s // 2::s]), s


def _median_u8(a: NDArray[np.uint8], mask: NDArray[np.uint8] | None = None) -> float:
    """Median of 8-bit values (under ``mask``) from their histogram (cv2.calcHist): the
    ⌈n/2⌉-th smallest of the n values (the lower middle one of an even count)."""
    if mask is None:
        # unmasked (a thumbnail's crop, a few thousand values): the same order statistic by
        # np.partition, a third of the histogram's cost there
        v = a.ravel()
        if v.size == 0:
            return 0.0
        k = (v.size + 1) // 2 - 1
        return float(np.partition(v, k)[k])
    hist = cv2.calcHist([np.ascontiguousarray(a)], [0], mask, [256], [0, 256]).ravel()
    # the histogram's total, counted directly (exact: whole counts below 2**24)
    total = cv2.countNonZero(mask)
    if total <= 0:
        return 0.0
    return float(np.searchsorted(np.cumsum(hist), 0.5 * total))


#: the circle :func:`estimate_fov` returns is the lens's image circle shrunk by this share,
#: to keep the detector off the dark rim; :func:`lens_circle` undoes it (the one place of it)
RIM_MARGIN = 0.98


def estimate_fov(gray: NDArray[np.uint8], small: NDArray[np.uint8] | None = None,
                 scale: int = 1) -> FovCircle | None:
    """The fisheye image circle: the bright disc surrounded by dark corners, or None.

    A frame whose four corners are not dark (by their mean, or on 90 % of their pixels; a
    pinhole frame) has no circle — unless they are a lifted black: at most half the centre's
    level with the frame just outside the circle at their level, a sharp rim
    (:func:`_sharp_rim`; a brighter exposure or gamma lifts the unlit corners past the dark
    level).
    Works on a ~96 px thumbnail; the circle is the minimum enclosing circle of
    the largest bright region, shrunk by 2 % — unless that region fills less than
    :data:`_FILLED` of the circle (trees, buildings, masts or the frame cut the disc and pull
    the enclosing circle off: Wolf 37–111 px), when the field stop's edge is fitted on the
    full-resolution frame where it is seen (:func:`_rim_circle`). A frame with no circle
    found that was padded with a flat lit band (:func:`_padding`) is read inside the band
    (a gamma-lifted black reads as such a band: read first, it moved circles already found).
    """
    found = _fov(gray, small, scale)
    pad = None if found is not None else _padding(gray)
    if pad is None:
        return found
    top, bottom, left, right = pad  # the frame inside the band; its circle in the frame's pixels
    inner = _fov(np.ascontiguousarray(gray[top:gray.shape[0] - bottom,
                                           left:gray.shape[1] - right]))
    return None if inner is None else FovCircle(inner.cx_px + left, inner.cy_px + top,
                                                inner.radius_px)


def _fov(gray: NDArray[np.uint8], small: NDArray[np.uint8] | None = None,
         scale: int = 1) -> FovCircle | None:
    """:func:`estimate_fov` of a frame without a padding band."""
    if small is None:
        small, scale = _small(gray)
    small = _without_overlays(small)
    h, w = small.shape
    ph, pw = max(2, h // 12), max(2, w // 12)
    corners = [small[:ph, :pw], small[:ph, -pw:], small[-ph:, :pw], small[-ph:, -pw:]]
    means = sorted(cv2.mean(c)[0] for c in corners)
    corner_level = 0.5 * (means[1] + means[2])  # the median of four
    centre_level = _median_u8(small[h // 3: 2 * h // 3, w // 3: 2 * w // 3])
    dark_max = max(35.0, 0.25 * centre_level)
    if corner_level > dark_max:
        # or dark on 90 % of their pixels: the overlay text a station prints there (its name,
        # the time) lifts the corners' mean past the dark level on a brighter exposure; a
        # pinhole view with something dark across part of its corners (a window frame,
        # foliage) stays without a circle
        px = np.stack([c.ravel() for c in corners])
        k = (9 * px.shape[1]) // 10
        p90 = np.sort(np.partition(px, k, axis=1)[:, k])
        corner_dark = 0.5 * (float(p90[1]) + float(p90[2]))  # the median of four
    else:
        corner_dark = corner_level
    lifted = False  # the corners passed only as a lifted black behind a sharp rim
    # the centre lit: at 20 grey levels, or 10 levels and twice above the unlit corners (a
    # darkened frame: the EUROCONTROL low sun at gain 0.4, its sky at 17 over corners at 3-4,
    # lost its circle and with it the scale camera=fisheye alone needs)
    if centre_level < 20.0 and (centre_level - corner_level < 10.0
                                or centre_level < 2.0 * corner_level):
        return None
    # the unlit level the lifted-black test reads: the corners' mean, or their 90th
    # percentile when overlay text lifts the mean
    unlit = min(corner_level, corner_dark)
    if corner_dark > dark_max:
        if unlit > _LIFTED_MAX * centre_level:
            return None
        lifted = True
    level = corner_level + 0.3 * (centre_level - corner_level)
    # small > level (an 8-bit threshold compares with ⌊level⌋: the same pixels)
    binary = cv2.threshold(small, level, 1, cv2.THRESH_BINARY)[1]
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return None
    big = max(contours, key=cv2.contourArea)
    if cv2.contourArea(big) < 0.2 * h * w:
        return None
    (cx, cy), r = cv2.minEnclosingCircle(big)
    if lifted and not _sharp_rim(small, cx, cy, r, unlit, centre_level):
        return None
    off = float(scale // 2)  # thumbnail pixel i is full-res pixel i·s + s//2
    cx, cy, r = cx * scale + off, cy * scale + off, r * scale
    if cv2.contourArea(big) >= _FILLED * np.pi * (r / scale) ** 2:
        return FovCircle(cx, cy, RIM_MARGIN * r)  # a disc nothing cuts: its enclosing circle
    rim = _rim_circle(gray, cx, cy, r, corner_level, centre_level)
    if rim is not None:
        cx, cy, r = rim
    return FovCircle(cx, cy, RIM_MARGIN * r)


#: A padding band's pixels lie within this of its level [grey levels] (JPEG at quality 95
#: keeps a flat band within ±1 on most of a row up to its inner edge, ±5 at the most)
_PAD_FLAT_DN = 4
#: … and it is at most this share of the frame's side (thicker flat bands are a flat sky)
_PAD_MAX_SHARE = 0.1
#: … and lit above this (a darker band is the unlit field already) [grey levels]
_PAD_MIN_DN = 35


def _flat(line: NDArray[np.uint8], level: int) -> bool:
    """Whether most of ``line`` lies within :data:`_PAD_FLAT_DN` of ``level`` (text printed on
    a border, or JPEG's ringing next to the frame's content, moves a minority of a row)."""
    return 2 * int(np.count_nonzero(np.abs(line.astype(np.int16) - level) <= _PAD_FLAT_DN)) \
        > line.size


def _band(lines: NDArray[np.uint8], level: int) -> int:
    """How many of ``lines`` (rows, outermost first) are :func:`_flat` from the first on;
    ``len(lines)`` when the last is (a flat sky: no band)."""
    if _flat(lines[-1], level):
        return len(lines)
    n = 0
    while _flat(lines[n], level):
        n += 1
    return n


def _padding(gray: NDArray[np.uint8]) -> tuple[int, int, int, int] | None:
    """Widths (top, bottom, left, right) [px] of the flat lit band a frame was padded with
    (a border of one grey or colour all round, or bars above and below or beside it), or
    None. The band is no sky: a fisheye's field stop leaves the frame outside its image
    circle unlit (:func:`_sharp_rim`), and a grey or blue border hid the dark corners — no
    circle was found on 23 of 23 Wolf frames padded by 15 or 40 px, and a calibration with
    times an hour off then went unchecked (a tester's finding). White borders are overlays
    (:func:`_without_overlays`). A band reaching :data:`_PAD_MAX_SHARE` of a side is a flat
    sky, not a border; the corners' four pixels decide at once on every other frame."""
    h, w = gray.shape
    level = int(gray[0, 0])
    corners = (gray[0, -1], gray[-1, 0], gray[-1, -1])
    if not _PAD_MIN_DN < level < _OVERLAY_WHITE or any(
            abs(int(c) - level) > _PAD_FLAT_DN for c in corners):
        return None
    cap_h, cap_w = max(1, int(_PAD_MAX_SHARE * h)), max(1, int(_PAD_MAX_SHARE * w))
    widths = (_band(gray[:cap_h], level), _band(gray[::-1][:cap_h], level),
              _band(gray.T[:cap_w], level), _band(gray.T[::-1][:cap_w], level))
    top, bottom, left, right = widths
    if max(top, bottom) >= cap_h or max(left, right) >= cap_w:
        return None
    if not ((top and bottom) or (left and right)):
        return None
    return widths


#: An overlay's white [grey level]: what a station draws is 255 (JPEG: 250–255 around text)
_OVERLAY_WHITE = 250


def _white_on_edge(img: NDArray[np.uint8]) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """The pixels ``(ys, xs)`` of each white region (≥ :data:`_OVERLAY_WHITE`, 8-connected)
    that touches the edge of ``img``: what a station draws over its frames (a time-stamp bar
    or box, a white border). None to find — nothing white on the edge — costs four rows."""
    if max(img[0].max(), img[-1].max(), img[:, 0].max(), img[:, -1].max()) < _OVERLAY_WHITE:
        return []
    _, labels, stats, _ = cv2.connectedComponentsWithStats(
        (img >= _OVERLAY_WHITE).view(np.uint8), connectivity=8)
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    out = []
    for k in edge[edge > 0]:
        x0, y0, w, h = (int(v) for v in stats[k, :4])  # within its box: a few pixels each
        ys, xs = np.nonzero(labels[y0:y0 + h, x0:x0 + w] == k)
        out.append((ys + y0, xs + x0))
    return out


def _without_overlays(small: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """The thumbnail with white regions that touch its edge (:func:`_white_on_edge`) set to
    0 (unlit): what a station draws on its frames is no lit sky, and a fisheye's field stop
    leaves the frame's edge dark (a tester's finding: a 48 px white bar across the top, a
    520 × 60 box in a corner or a 10 px white border lifted the corners' level or joined the
    image circle, and no circle was found on 29, 6 and 29 of 29 labelled frames). A copy
    where anything is set."""
    regions = _white_on_edge(small)
    if not regions:
        return small
    out = small.copy()
    for ys, xs in regions:
        out[ys, xs] = 0
    return out


def overlays_unlit(gray: NDArray[np.uint8], fov: FovCircle) -> NDArray[np.uint8]:
    """``gray`` with each white region that touches the frame's edge
    (:func:`_white_on_edge`) and reaches outside the image circle ``fov`` set to 0: a
    station's time-stamp bar or box, a white border, drawn over the frame — never the sun,
    whose glare lies inside the image circle (a tester's 48 px bar across a Wolf frame's
    top, where the circle reaches within 16 px of the edge, was the sun at 0.94–0.996 once
    the circle was read, :func:`_without_overlays`). A copy where anything is set; ``gray``
    itself otherwise."""
    out = gray
    for ys, xs in _white_on_edge(gray):
        if (np.hypot(xs - fov.cx_px, ys - fov.cy_px) > lens_circle(fov).radius_px).any():
            if out is gray:
                out = gray.copy()
            out[ys, xs] = 0
    return out


_LIFTED_MAX = 0.5  # a lifted black: corners at most this share of the centre's level
_RIM_OUT = 1.1  # the ring just outside the image circle [× its radius]
_RIM_TOL = 0.15  # … within this share of the step from the corners' level: unlit
_RIM_IN = 0.9  # the ring just inside it [× its radius]
_RIM_LIT = 0.5  # … at least this share of the way up the step: lit to the rim
_RIM_MIN_POINTS = 8  # … read on at least this many of its 96 points inside the frame: a
# median that three stray pixels (overlay text, a branch) cannot decide; not tuned — the real
# frames that reach the test read 26–79 points on the outer ring
_RIM_COS = np.cos(np.linspace(0.0, 2 * np.pi, 96, endpoint=False))
_RIM_SIN = np.sin(np.linspace(0.0, 2 * np.pi, 96, endpoint=False))


def _sharp_rim(small: NDArray[np.uint8], cx: float, cy: float, r: float, corner: float,
               centre: float) -> bool:
    """Whether the frame just outside a candidate image circle (thumbnail pixels: centre
    ``cx, cy``, radius ``r``) is at the unlit corners' level — the circle's edge a step.

    A fisheye's image circle is the shadow of its field stop (Ray 2002, *Applied
    Photographic Optics*, 3rd ed., ch. 24: the field stop bounds the image sharply): outside
    it the sensor sees nothing, whatever the tone curve. A brighter exposure or a lifted
    gamma raises that unlit level (UCEEB and Wolf at gamma 0.7: 16–19 → 36–41 grey levels,
    past the dark level of :func:`estimate_fov`), but the ring at :data:`_RIM_OUT` × the
    radius stays within :data:`_RIM_TOL` of the step from the corners' level (the real suns'
    and UCEEB's frames that reach this test at gammas 0.5 and 0.7, the gamma on the colour
    frame: −0.05 to +0.08), and the sky inside is lit to the rim: the ring at
    :data:`_RIM_IN` × the radius at least :data:`_RIM_LIT` of the way up the step (at gamma
    0.7: 0.54–1.45 on 8 frames, Wolf 09:44 the lowest; at gamma 0.5 Wolf 10:59 reads 0.500,
    exactly on the limit, and keeps its circle because the test is ``< _RIM_LIT``, while six
    Wolf frames at 0.38–0.45 stay without one). A pinhole view's vignetting falls off
    gradually; a glare filling a small crop (the tracker's region of interest, whose corners
    are sky) falls off inside its ring (0.23–0.34 of the way up); the tracker's whole frames
    never reach this test — their corners are 0.74 of the centre's level, past
    :data:`_LIFTED_MAX` (their inner ring would read 0.32–0.37); and a view framed by
    something dark (a window frame) has its dark edges inside the frame's corners, not on a
    ring about a bright disc: the ring lies past the frame's corners and has too few points
    to read (:data:`_RIM_MIN_POINTS`). ``corner``: the unlit level that passed the
    lifted-black test (:func:`estimate_fov`: the corners' mean, or their 90th percentile
    when overlay text lifts the mean), from which the step is measured."""
    h, w = small.shape
    step = centre - corner
    for k in (_RIM_OUT, _RIM_IN):
        xs = np.rint(cx + k * r * _RIM_COS).astype(np.intp)
        ys = np.rint(cy + k * r * _RIM_SIN).astype(np.intp)
        ok = (xs >= 0) & (xs < w) & (ys >= 0) & (ys < h)
        if int(ok.sum()) < _RIM_MIN_POINTS:
            return False
        level = (float(np.median(small[ys[ok], xs[ok]])) - corner) / step
        if (k > 1.0 and abs(level) > _RIM_TOL) or (k < 1.0 and level < _RIM_LIT):
            return False
    return True


# a bright region filling this share of its enclosing circle is the whole disc: a tenth of it
# missing is something cutting it (measured on the thumbnail: an uncut rendered disc 0.97–0.98,
# Wettermast and FE3 with their masts 0.95–0.96, Wolf behind its trees 0.82–0.87)
_FILLED = 0.9
_RIM_RAYS = 120  # rays from the coarse centre, 3° apart
_RIM_SAMPLES = 96  # samples along each, from _RIM_BAND[0] to _RIM_BAND[1] × the coarse radius
_RIM_BAND = (0.8, 1.25)
_RIM_STEP_WIDTH = 0.015  # the step's drop is read across this share of the radius
_RIM_STEP_MIN = 0.06  # … and is sharp from this share of the centre's level above the corners'
_RIM_STEP_MIN_DN = 6.0  # … or this many grey levels, whichever is more
_RIM_TAIL = 6  # the ray's last samples in the frame: the unlit level outside the rim
_RIM_BEYOND = 4  # samples just outside the drop …
_RIM_FLAT_DN = 3.0  # … within this many grey levels of the ray's unlit tail
_RIM_RANSAC = 64  # RANSAC samples of three rim points (Fischler & Bolles 1981)
_RIM_INLIER = 0.005  # an inlier lies within this share of the radius of the circle (≥ 2 px)
_RIM_MIN_INLIERS = 24  # … at least this many rays (a 72° arc in all) …
_RIM_MAX_GAP_DEG = 180.0  # … on more than half the circle: no gap between them wider than this
_RIM_ANG = np.linspace(0.0, 2 * np.pi, _RIM_RAYS, endpoint=False)
_RIM_RCOS = np.cos(_RIM_ANG).astype(np.float32)
_RIM_RSIN = np.sin(_RIM_ANG).astype(np.float32)
_RIM_RNG_IDX = np.random.default_rng(0).random((_RIM_RANSAC, 3))  # fixed: deterministic


def _rim_points(gray: NDArray[np.uint8], cx: float, cy: float, r: float, corner: float,
                centre: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Points of the field stop's edge (full-resolution pixels) on rays from a coarse centre
    ``cx, cy`` (a coarse radius ``r``): on each ray, the outermost sharp step down to the
    unlit level, where the ray leaves the frame unlit.

    The image circle is the shadow of the field stop (Ray 2002, ch. 24): a step from the lit
    image to the unlit frame, as sharp as the lens draws it, wherever the scene reaches the
    rim — sky, or trees and buildings brighter than the unlit sensor. What stands in front of
    the rim darker than that, or a frame edge that cuts the circle, leaves a ray without such
    a step or with a step elsewhere (a tree line, the glare): outliers for the robust fit.
    A ray counts when its last :data:`_RIM_TAIL` samples in the frame are within 0.15 of the
    step from the corners' level (as :func:`_sharp_rim`); its edge is the outermost place
    where the level drops by :data:`_RIM_STEP_MIN` of the step (at least
    :data:`_RIM_STEP_MIN_DN`) across :data:`_RIM_STEP_WIDTH` of the radius — a gradual glow
    outside the circle (a lens barrel lit by the sky) drops by less — at the steepest point
    of that drop (a parabola through the drop's three largest samples), and only when just
    outside the drop (:data:`_RIM_BEYOND` samples) the ray is already within
    :data:`_RIM_FLAT_DN` of its unlit tail: trees as dark as the unlit frame (the second
    renderer's, 3–6 grey levels above it) leave the skyline as the outermost sharp drop, with
    the faint rim beyond it. That test also refuses EUROCONTROL's rim, whose frame glows
    unevenly just outside it: its circle stays the enclosing one."""
    h, w = gray.shape
    rs = np.linspace(_RIM_BAND[0] * r, _RIM_BAND[1] * r, _RIM_SAMPLES, dtype=np.float32)
    ds = float(rs[1] - rs[0])
    mx = np.float32(cx) + _RIM_RCOS[:, None] * rs[None, :]
    my = np.float32(cy) + _RIM_RSIN[:, None] * rs[None, :]
    prof = cv2.remap(gray, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    prof = cv2.GaussianBlur(prof.astype(np.float32), (0, 0), 0.7, sigmaY=0.7)
    n_in = np.count_nonzero((mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1), axis=1)
    m = max(1, int(round(_RIM_STEP_WIDTH * r / ds)))
    drop = prof[:, :-m] - prof[:, m:]  # the fall from sample k to k + m (outward)
    nd = drop.shape[1]
    step = centre - corner
    cand = (drop > max(_RIM_STEP_MIN_DN, _RIM_STEP_MIN * step)) \
        & (np.arange(nd)[None, :] + m < n_in[:, None] - 1)
    last = nd - 1 - np.argmax(cand[:, ::-1], axis=1)  # the outermost sharp drop
    tail = np.clip(n_in[:, None] - 1 - np.arange(_RIM_TAIL)[None, :], 0, _RIM_SAMPLES - 1)
    unlit = np.median(np.take_along_axis(prof, tail, axis=1), axis=1)
    # just outside the drop the ray is already at its unlit level: a skyline of trees as dark
    # as the unlit frame leaves a second, smaller step (the rim) beyond it
    beyond = np.clip(last[:, None] + m + 1 + np.arange(_RIM_BEYOND)[None, :], 0,
                     n_in[:, None] - 1)
    outside = np.median(np.take_along_axis(prof, beyond, axis=1), axis=1)
    ok = (cand.any(axis=1) & (n_in >= _RIM_TAIL + m + 2) & (unlit <= corner + _RIM_TOL * step)
          & (np.abs(outside - unlit) <= _RIM_FLAT_DN))
    rows = np.arange(_RIM_RAYS)
    win = np.clip(last[:, None] - np.arange(m + 1)[None, :], 0, nd - 1)
    k = win[rows, np.argmax(np.take_along_axis(drop, win, axis=1), axis=1)]
    k = np.clip(k, 1, nd - 2)
    a, b, c = drop[rows, k - 1], drop[rows, k], drop[rows, k + 1]
    den = a - 2.0 * b + c
    sub = np.clip(np.where(den < 0, 0.5 * (a - c) / np.where(den < 0, den, -1.0), 0.0), -1, 1)
    rr = rs[0] + (k + sub + 0.5 * m) * ds
    return ((cx + _RIM_RCOS * rr)[ok].astype(np.float64),
            (cy + _RIM_RSIN * rr)[ok].astype(np.float64))


def _kasa(x: NDArray[np.float64], y: NDArray[np.float64]) -> tuple[float, float, float]:
    """The algebraic least-squares circle through points (Kåsa 1976): x² + y² = 2a x + 2b y + c,
    linear in (a, b, c); centre (a, b), radius √(c + a² + b²)."""
    sol = np.linalg.lstsq(np.column_stack([x, y, np.ones_like(x)]), x * x + y * y,
                          rcond=None)[0]
    a, b = 0.5 * float(sol[0]), 0.5 * float(sol[1])
    return a, b, float(np.sqrt(max(float(sol[2]) + a * a + b * b, 0.0)))


def _rim_circle(gray: NDArray[np.uint8], cx: float, cy: float, r: float, corner: float,
                centre: float) -> tuple[float, float, float] | None:
    """The image circle fitted to the field stop's edge (full-resolution pixels) → (x, y,
    radius), or None when the edge is not seen on enough of the rim (keep the coarse circle).

    The coarse circle (the bright region's minimum enclosing circle) is pulled off by
    whatever cuts the bright disc at the rim — trees, buildings, masts (Wolf: 90 px from the
    optical centre) — and by a frame that crops the circle. The edge points of
    :func:`_rim_points` are fitted by RANSAC (Fischler & Bolles 1981: circles through three
    points, the one most points lie within :data:`_RIM_INLIER` of the radius) and refined by
    Kåsa's least squares on its inliers (Kåsa 1976). Accepted when at least
    :data:`_RIM_MIN_INLIERS` rays agree and no gap between them exceeds
    :data:`_RIM_MAX_GAP_DEG` (an arc on one side alone leaves the centre free along it), and
    the circle lies within the band the rays searched."""
    x, y = _rim_points(gray, cx, cy, r, corner, centre)
    n = x.size
    if n < _RIM_MIN_INLIERS:
        return None
    idx = np.minimum((_RIM_RNG_IDX * n).astype(np.intp), n - 1)
    x1, y1, x2, y2, x3, y3 = (x[idx[:, 0]], y[idx[:, 0]], x[idx[:, 1]], y[idx[:, 1]],
                              x[idx[:, 2]], y[idx[:, 2]])
    d = 2.0 * (x1 * (y2 - y3) + x2 * (y3 - y1) + x3 * (y1 - y2))
    good = np.abs(d) > 1e-6 * r * r
    d = np.where(good, d, 1.0)
    s1, s2, s3 = x1 * x1 + y1 * y1, x2 * x2 + y2 * y2, x3 * x3 + y3 * y3
    ux = (s1 * (y2 - y3) + s2 * (y3 - y1) + s3 * (y1 - y2)) / d
    uy = (s1 * (x3 - x2) + s2 * (x1 - x3) + s3 * (x2 - x1)) / d
    ur = np.hypot(x1 - ux, y1 - uy)
    tol = max(2.0, _RIM_INLIER * r)
    res = np.abs(np.hypot(x[None, :] - ux[:, None], y[None, :] - uy[:, None]) - ur[:, None])
    count = np.where(good, np.count_nonzero(res < tol, axis=1), -1)
    inl = res[int(np.argmax(count))] < tol
    fx, fy, fr = cx, cy, r
    for _ in range(3):  # Kåsa on the inliers, the inliers again
        if int(inl.sum()) < _RIM_MIN_INLIERS:
            return None
        fx, fy, fr = _kasa(x[inl], y[inl])
        inl = np.abs(np.hypot(x - fx, y - fy) - fr) < tol
    if int(inl.sum()) < _RIM_MIN_INLIERS:
        return None
    ang = np.sort(np.arctan2(y[inl] - fy, x[inl] - fx))
    gap = float(np.max(np.diff(np.concatenate([ang, ang[:1] + 2 * np.pi]))))
    if np.degrees(gap) > _RIM_MAX_GAP_DEG:
        return None
    if not (_RIM_BAND[0] * r < fr < _RIM_BAND[1] * r) or np.hypot(fx - cx, fy - cy) > 0.25 * r:
        return None
    return fx, fy, fr


def lens_circle(fov: FovCircle) -> FovCircle:
    """The lens's whole image circle (its lit disc: a 180° lens's horizon) of the circle
    ``fov`` that :func:`estimate_fov` found, which is shrunk by :data:`RIM_MARGIN` to keep
    the detector off the dark rim."""
    return FovCircle(fov.cx_px, fov.cy_px, fov.radius_px / RIM_MARGIN)


def image_circle(gray: NDArray[np.uint8]) -> tuple[FovCircle, bool] | None:
    """The lens's whole image circle (not shrunk) and whether it reaches the frame's edge.

    :func:`estimate_fov` shrinks the circle by 2 % to keep the detector off the
    dark rim; a camera whose scale is unknown wants the rim itself: the circle
    a 180° lens draws is the horizon (θ = 90°). ``clipped`` is True when the
    circle leaves the frame, so the frame's edge, not the lens, bounds what was
    measured. None when the frame has no dark corners (no circle).
    """
    fov = estimate_fov(gray)
    if fov is None:
        return None
    circle = lens_circle(fov)
    h, w = gray.shape[:2]
    clipped = (circle.cx_px - circle.radius_px < -0.5 or circle.cy_px - circle.radius_px < -0.5
               or circle.cx_px + circle.radius_px > w - 0.5
               or circle.cy_px + circle.radius_px > h - 0.5)
    return circle, bool(clipped)
