"""Bright-region candidates: clusters of components, their shape, core, glare and ghosts."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision.detection import FovCircle

_CORE_MAX_RADIUS_PX = 64.0  # above: the core's opening runs on a shrunk mask
_SATURATED = 250.0  # grey level of a saturated core


_RING_COS = np.cos(np.linspace(0.0, 2 * np.pi, 24, endpoint=False))
_RING_SIN = np.sin(np.linspace(0.0, 2 * np.pi, 24, endpoint=False))


def _ring_values(gray: NDArray[np.uint8], cx: float, cy: float, radius: float,
                 fov: FovCircle | None) -> NDArray[np.float64]:
    """Grey values at 24 points of a circle (nearest pixel), those inside the frame/FOV."""
    xs = cx + radius * _RING_COS
    ys = cy + radius * _RING_SIN
    h, w = gray.shape
    if cx - radius >= 0 and cy - radius >= 0 and cx + radius <= w - 1 \
            and cy + radius <= h - 1 and (fov is None or np.hypot(
                cx - fov.cx_px, cy - fov.cy_px) + radius < fov.radius_px):
        # the whole circle is inside (the common case): no per-point test
        return gray[(ys + 0.5).astype(np.intp), (xs + 0.5).astype(np.intp)].astype(float)
    ok = (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    if fov is not None:
        ok &= (xs - fov.cx_px) ** 2 + (ys - fov.cy_px) ** 2 < fov.radius_px**2
    return gray[(ys[ok] + 0.5).astype(np.intp), (xs[ok] + 0.5).astype(np.intp)].astype(float)


def _rings(gray: NDArray[np.uint8], cx: float, cy: float, radii: tuple[float, ...],
           fov: FovCircle | None) -> list[NDArray[np.float64]]:
    """:func:`_ring_values` for several radii about one centre, gathered together when
    every circle lies inside the frame and the image circle (the common case)."""
    h, w = gray.shape
    r_max = max(radii)
    if not (cx - r_max >= 0 and cy - r_max >= 0 and cx + r_max <= w - 1
            and cy + r_max <= h - 1 and (fov is None or np.hypot(
                cx - fov.cx_px, cy - fov.cy_px) + r_max < fov.radius_px)):
        return [_ring_values(gray, cx, cy, r, fov) for r in radii]
    rad = np.array(radii)[:, None]
    xs = cx + rad * _RING_COS
    ys = cy + rad * _RING_SIN
    v = gray[(ys + 0.5).astype(np.intp), (xs + 0.5).astype(np.intp)].astype(float)
    return list(v)


def _median(v: NDArray[np.float64]) -> float:
    """Median of a short vector (``np.median``'s value, without its overhead)."""
    s = np.sort(v)
    n = s.size
    return float(0.5 * (s[(n - 1) // 2] + s[n // 2]))


def _clamp(v: float, lo: float, hi: float) -> float:
    return float(min(max(v, lo), hi))


def _weighted_centroid(gray: NDArray[np.uint8], cx: float, cy: float, radius: float,
                       level: float) -> tuple[float, float] | None:
    """Intensity-weighted centroid of ``gray − level`` (clipped at 0) in a disc window."""
    h, w = gray.shape
    x0, y0 = max(0, int(cx - radius)), max(0, int(cy - radius))
    x1, y1 = min(w, int(cx + radius) + 2), min(h, int(cy + radius) + 2)
    if x1 <= x0 or y1 <= y0:
        return None
    win = gray[y0:y1, x0:x1].astype(np.float32) - np.float32(level)
    np.maximum(win, 0, out=win)
    disc = np.zeros(win.shape, np.float32)
    cv2.circle(disc, (int(round((cx - x0) * 16)), int(round((cy - y0) * 16))),
               int(round(radius * 16)), 1.0, -1, cv2.LINE_8, 4)  # 1/16 px centre
    m = cv2.moments(win * disc, False)
    if m["m00"] <= 0:
        return None
    return x0 + m["m10"] / m["m00"], y0 + m["m01"] / m["m00"]


@dataclass
class _Candidate:
    """A cluster of bright components (a glare cut by a mast stays one candidate)."""

    labels: list[int]
    area: int
    x: int
    y: int
    w: int
    h: int
    cx: float
    cy: float
    score: float = 0.0
    glare: float = 0.0  # set by _score(): the glare evidence 0–1
    wide: float = 0.0  # set by _score(): a wide core's own glare credit 0–1
    shape: float = 0.0  # set by the detector: the shape term 0–1
    upright: float = 0.0  # set by _prior(): the shape term without the lens's squash allowed
    ghost: bool = False
    ox: int = 0  # where the label image (a region of interest) starts in the frame
    oy: int = 0

    core: NDArray[np.uint8] | None = None  # set by _core(): the disc without its streaks

    def mask(self, labels: NDArray[Any]) -> NDArray[np.uint8]:
        if self.core is not None:
            return self.core
        y0, x0 = self.y - self.oy, self.x - self.ox
        roi = labels[y0:y0 + self.h, x0:x0 + self.w]
        if len(self.labels) == 1:
            return (roi == self.labels[0]).astype(np.uint8)
        return np.isin(roi, self.labels).astype(np.uint8)


def _clusters(stats: NDArray[Any], cents: NDArray[Any], order: NDArray[np.int64],
              ox: int = 0, oy: int = 0) -> list[_Candidate]:
    """Group components whose boxes lie within a quarter radius (+3 px) of each other."""
    items = [int(i) for i in order]
    if len(items) == 1:  # the common case: one component, the same sums written out
        i = items[0]
        x0, y0, w0, h0, area = (int(v) for v in stats[i])
        cx0, cy0 = float(cents[i, 0]), float(cents[i, 1])
        return [_Candidate(items, area, x0, y0, w0, h0, cx0 * area / area, cy0 * area / area,
                           ox=ox, oy=oy)]
    parent = {i: i for i in items}

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    for ai, a in enumerate(items):
        xa, ya, wa, ha, aa = stats[a]
        for b in items[ai + 1:]:
            xb, yb, wb, hb, ab = stats[b]
            gap_x = max(xb - (xa + wa), xa - (xb + wb), 0)
            gap_y = max(yb - (ya + ha), ya - (yb + hb), 0)
            reach = 3.0 + 0.25 * np.sqrt(max(aa, ab) / np.pi)
            if max(gap_x, gap_y) <= reach:
                parent[root(b)] = root(a)
    groups: dict[int, list[int]] = {}
    for i in items:
        groups.setdefault(root(i), []).append(i)
    out = []
    for members in groups.values():
        st = stats[members]
        area = int(st[:, 4].sum())
        x0, y0 = int(st[:, 0].min()), int(st[:, 1].min())
        x1, y1 = int((st[:, 0] + st[:, 2]).max()), int((st[:, 1] + st[:, 3]).max())
        cx = float((cents[members, 0] * st[:, 4]).sum() / area)
        cy = float((cents[members, 1] * st[:, 4]).sum() / area)
        out.append(_Candidate(members, area, x0, y0, x1 - x0, y1 - y0, cx, cy, ox=ox, oy=oy))
    return out


_STRETCHES = np.linspace(0.0, 1.0, 17)  # the radial un-compressions tried, 0 → the most


def _aspect(mu20: float, mu02: float, mu11: float) -> float:
    """``√(λ2/λ1)`` of a second-moment matrix."""
    half_tr = 0.5 * (mu20 + mu02)
    disc = np.sqrt(max(half_tr**2 - (mu20 * mu02 - mu11**2), 0.0))
    return float(np.sqrt(max(half_tr - disc, 1e-6) / max(half_tr + disc, 1e-6)))


def _shape(c: _Candidate, labels: NDArray[Any],
           circle: tuple[float, float, float] | None = None) -> float:
    """Circularity 0–1 from the cluster's second moments.

    ``aspect = √(λ2/λ1)`` and ``fill = A / (4π√(λ1 λ2))`` (1 for a filled disc);
    thin spikes (a flare streak, blooming) barely move them, ragged or
    elongated cloud edges do.

    With ``circle`` (the fisheye's image circle: centre x, y and radius, px) the aspect is
    the roundest the region becomes when stretched along the radius from the circle's centre
    by any factor from 1 to the most a fisheye compresses a small disc there: a lens maps
    the sky's zenith angle θ to a radius r(θ), drawing a disc r′(θ) / (r(θ) / sin θ) times as
    wide along the radius as across it; of the common projections the orthographic one
    (r ∝ sin θ: cos θ, to 0 at its 90° rim) compresses most, so at ρ / R of a 180° circle
    the factor is at least √(1 − (ρ/R)²). An equidistant lens draws the sun at 10° elevation
    0.64 times as wide along the radius (within the 0.75 allowed), an equisolid one 0.51 and an
    orthographic one 0.17 (a tester's lenses, refused as "not round"). The stretch keeps the
    fill (area and √(λ1 λ2) both scale by it)."""
    if c.area < 5:
        return 1.0
    m = cv2.moments(c.mask(labels), True)
    mu20, mu02, mu11 = m["mu20"] / m["m00"], m["mu02"] / m["m00"], m["mu11"] / m["m00"]
    half_tr = 0.5 * (mu20 + mu02)
    disc = np.sqrt(max(half_tr**2 - (mu20 * mu02 - mu11**2), 0.0))
    l1, l2 = half_tr + disc, max(half_tr - disc, 1e-6)
    aspect = float(np.sqrt(l2 / l1))
    fill = c.area / (4.0 * np.pi * np.sqrt(l1 * l2))
    if circle is not None and aspect < 0.75:
        ox, oy, radius = circle
        gx, gy = c.cx, c.cy
        rho = float(np.hypot(gx - ox, gy - oy))
        if rho > 0.0:
            most = 1.0 / max(np.sqrt(max(1.0 - (rho / radius) ** 2, 0.0)), 1e-3)
            ux, uy = (gx - ox) / rho, (gy - oy) / rho  # the radial direction
            # the moments along the radius (a), across it (cc) and their covariance (b)
            a = ux * ux * mu20 + 2 * ux * uy * mu11 + uy * uy * mu02
            cc = uy * uy * mu20 - 2 * ux * uy * mu11 + ux * ux * mu02
            b = (mu02 - mu20) * ux * uy + mu11 * (ux * ux - uy * uy)
            for t in _STRETCHES[1:]:
                k = most ** t
                aspect = max(aspect, _aspect(k * k * a, cc, k * b))
    return min(1.0, aspect / 0.75) * _clamp(fill / 0.85, 0.0, 1.0)


def _core(c: _Candidate, labels: NDArray[Any]) -> _Candidate | None:
    """The candidate's disc without the streaks attached to it (blooming, smear, a flare).

    A morphological opening with a disc of 0.6 × the largest inscribed radius
    (the distance transform's maximum) removes everything thinner than the
    core; the opened component under that maximum is the core. Returns a
    candidate restricted to it, or None when nothing was removed.
    """
    mask = c.mask(labels)
    # a zero border: a blob that fills its box (a saturated rectangle) has no zero pixel
    padded = cv2.copyMakeBorder(mask, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    dist = cv2.distanceTransform(padded, cv2.DIST_L2, 3)[1:-1, 1:-1]
    _, d_max, _, (px, py) = cv2.minMaxLoc(dist)
    if d_max < 2.0:
        return None
    # the opening's cost grows with the kernel's area: past an inscribed radius of
    # _CORE_MAX_RADIUS_PX it runs on a shrunk mask (enough to cut thin streaks)
    f = min(1.0, _CORE_MAX_RADIUS_PX / d_max)
    k = max(1, int(0.6 * d_max * f))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))
    if f < 1.0:
        small = cv2.resize(mask, None, fx=f, fy=f, interpolation=cv2.INTER_NEAREST)
        opened_small = cv2.morphologyEx(small, cv2.MORPH_OPEN, kernel)
        opened = cv2.bitwise_and(
            cv2.resize(opened_small, (mask.shape[1], mask.shape[0]),
                       interpolation=cv2.INTER_NEAREST),
            mask,
        )
    else:
        opened = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
    n, lab, stats, cents = cv2.connectedComponentsWithStats(opened, connectivity=8)
    i = int(lab[py, px])
    if n < 2 or i == 0 or stats[i, 4] >= 0.97 * c.area:
        return None
    x, y, w, h, area = (int(v) for v in stats[i])
    core = (lab[y:y + h, x:x + w] == i).astype(np.uint8)
    # only streaks count: what was removed must be thin, straight and centred on
    # the core (spikes on both sides), not the lobes of a ragged cloud highlight
    rest = mask.copy()
    rest[y:y + h, x:x + w] -= core
    m = cv2.moments(rest, True)
    if m["m00"] <= 0:
        return None
    mu20, mu02, mu11 = m["mu20"] / m["m00"], m["mu02"] / m["m00"], m["mu11"] / m["m00"]
    half_tr = 0.5 * (mu20 + mu02)
    disc = np.sqrt(max(half_tr**2 - (mu20 * mu02 - mu11**2), 0.0))
    aspect = np.sqrt(max(half_tr - disc, 0.0) / max(half_tr + disc, 1e-9))
    off = np.hypot(m["m10"] / m["m00"] - cents[i, 0], m["m01"] / m["m00"] - cents[i, 1])
    if aspect > 0.35 or off > max(2.0, 0.5 * d_max):
        return None
    return _Candidate(c.labels, area, c.x + x, c.y + y, w, h, c.x + float(cents[i, 0]),
                      c.y + float(cents[i, 1]), ox=c.ox, oy=c.oy, core=core)


def _prior(c: _Candidate, labels: NDArray[Any], diam: float,
           circle: tuple[float, float, float] | None = None) -> tuple[float, float]:
    """``(shape term, size term)`` of the score: cheap, so computed for every candidate.

    A candidate that is not a clean disc is narrowed to its core
    (:func:`_core`) when the core is the cleaner disc: a sun with blooming or
    smear along its columns is a disc with spikes. With ``circle`` (a fisheye's image
    circle) the shape term allows for the lens squashing a disc along the radius
    (:func:`_shape`); ``c.upright`` keeps the term without that allowance.
    """
    raw = _shape(c, labels)
    if raw < 0.95 and c.area >= 30:
        core = _core(c, labels)
        if core is not None:
            core_shape = _shape(core, labels)
            if core_shape > raw:
                c.area, c.x, c.y, c.w, c.h = core.area, core.x, core.y, core.w, core.h
                c.cx, c.cy, c.core = core.cx, core.cy, core.core
                raw = core_shape
    shape = c.upright = _clamp((raw - 0.45) / 0.4, 0.0, 1.0)
    if circle is not None and raw < 1.0:  # a disc the lens squashed along the radius
        shape = _clamp((_shape(c, labels, circle) - 0.45) / 0.4, 0.0, 1.0)
    min_area = max(4.0, np.pi * (0.0025 * diam) ** 2)
    return shape, _clamp(c.area / min_area, 0.25, 1.0)


_GLARE_CORE_DEG = (1.0, 3.0)  # a saturated core this wide in radius [°] is a glare (0 → 1)
_TAIL = (0.0, 0.1)  # share of the contrast the glare keeps at 4 R: no credit → full credit


def _score(c: _Candidate, gray: NDArray[np.uint8], shape: float, size: float, peak: float,
           bg: float, fov: FovCircle | None, diam: float, ppd: float,
           scale_known: bool = True, image: NDArray[Any] | None = None) -> float:
    """Sun-likeness 0–1 of one bright cluster.

    ``shape²`` (a sun's saturated core is a clean disc; cloud highlights are
    ragged) × glare evidence × a size prior (radius ≥ ~0.25 % of the
    diameter). The glare evidence is the larger of (a) an isotropic glare that
    falls off outward — three rings at 1.6 R, 2.5 R and 4 R whose
    inter-quartile spread is small and whose medians decline by ≥ 15 % of the
    frame's contrast — and (b) a sharp drop right outside the disc to no less
    than the sky's level (a clear-sky sun next to a cloud; not white text on a
    dark overlay box) — and (c) the saturated core itself, when it is several
    degrees wide (:data:`_GLARE_CORE_DEG`, at ``ppd`` px/°), its glare still lights
    the sky at 4 R (:func:`_tail`) and it is solid (:func:`_solid`: no gaps inside its
    star-shaped hull, as a cloud field's lit elements have): the sun's disc is 0.27° in
    radius, so a core
    3° wide is its glare, saturated out to where a clear blue sky around it leaves no
    ring of fall-off inside the rings (the Wolf frames of issue 24); only when the frame's
    scale is known (``scale_known``: a camera model or an image circle — a crop of a frame,
    such as the tracker's region of interest, has neither, and its px/° guessed from its
    width is wrong by the crop's ratio). A bright cloud highlight passes none of them.
    """
    r_eq = np.sqrt(c.area / np.pi)
    contrast = max(peak - bg, 1.0)
    iso = 1.0
    medians = []
    for v in _rings(gray, c.cx, c.cy,
                    (1.6 * r_eq + 2.0, 2.5 * r_eq + 3.0, max(4.0 * r_eq, 0.03 * diam)), fov):
        if v.size < 8:
            iso *= 0.5
            medians.append(np.nan)
            continue
        v.sort()
        n = v.size
        q25, med, q75 = v[n // 4], v[n // 2], v[(3 * n) // 4]
        medians.append(float(med))
        iso *= _clamp(1.0 - ((q75 - q25) / contrast - 0.06) / 0.25, 0.0, 1.0)
    m1, _, m3 = medians
    falloff = (m1 - m3) / contrast if math.isfinite(m1) and math.isfinite(m3) else 0.0
    iso_glare = iso ** (1.0 / 3.0) * _clamp((falloff - 0.05) / 0.15, 0.0, 1.0)
    drop = (peak - m1) / contrast if math.isfinite(m1) else 0.0
    sharp = _clamp((drop - 0.3) / 0.3, 0.0, 1.0)
    if math.isfinite(m1) and m1 < bg - 0.15 * contrast:
        sharp = 0.0  # ringed by something darker than the sky: white text on a dark box
    # a wide core is a glare when its limb drops sharply to the sky or its glare lights
    # the sky out to 4 R (c.wide also stands in for the coherence: vision.detect._search);
    # the ranking takes its width alone — the most sun-like region of the frame — and the
    # confidence weighs whether its glare is a sun's
    wide = _wide_core(r_eq, ppd) if scale_known else 0.0
    c.wide = wide
    if wide > 0.0 and sharp < 1.0:
        c.wide *= max(_tail(gray, c, m3, bg, contrast, peak, fov, image), sharp)
    if c.wide > 0.0:
        c.wide *= _solid(gray, c, region_threshold(peak, bg)[1])
    c.glare = float(max(iso_glare, sharp, c.wide))
    return float(shape**2 * (0.25 + 0.75 * max(iso_glare, sharp, wide)) * size)


def region_threshold(peak: float, bg: float) -> tuple[float, int]:
    """The threshold the bright regions are cut at → ``(thr, level)``: ``thr`` = the peak less
    the larger of 3 grey levels and 4 % of the contrast ``peak − bg``, and ``level`` the
    8-bit grey level it comes to — a region keeps the pixels *above* ``level`` (⌊thr − 0.5⌋,
    as ``cv2.threshold`` at ``thr − 0.5`` on 8-bit pixels). The only place of the rule:
    ``vision.detect._search`` cuts the regions with it, :func:`_score` measures a wide core's
    solidity (:func:`star_fill`) on the same pixels."""
    thr = peak - max(3.0, 0.04 * (peak - bg))
    return thr, int(np.floor(thr - 0.5))


def _wide_core(r_eq: float, ppd: float) -> float:
    """0–1: how plainly a saturated core of equivalent radius ``r_eq`` [px] at ``ppd`` px/° is
    a glare by its width alone (:data:`_GLARE_CORE_DEG`: the sun's disc is 0.27° in radius)."""
    lo, hi = _GLARE_CORE_DEG
    return _clamp((r_eq / max(ppd, 1e-9) - lo) / (hi - lo), 0.0, 1.0)


_SOLID = (0.5, 0.8)  # share of a core's star-shaped hull that is clipped: no credit → full
_RAY_COS = np.cos(np.linspace(0.0, 2 * np.pi, 72, endpoint=False))
_RAY_SIN = np.sin(np.linspace(0.0, 2 * np.pi, 72, endpoint=False))


def star_fill(gray: NDArray[np.uint8], c: _Candidate, level: float) -> float:
    """The share of a candidate's star-shaped hull about its centroid that is above
    ``level`` (the grey level its region was cut at, :func:`region_threshold`: the region
    kept the pixels above it), 0–1.

    Along 72 rays from the centroid, every pixel out to the farthest one above ``level`` in the
    candidate's box is counted, weighted by its distance (the area a ray stands for grows
    with it). A region that is star-shaped about its centroid without holes — a disc, an
    oval, a disc cut by the horizon or notched by trees — fills its hull: 1. Gaps inside
    the hull (darker sky between bright cloud elements) lower it."""
    x0, y0 = c.x, c.y
    box = gray[y0:y0 + c.h, x0:x0 + c.w] > level
    cx, cy = c.cx - x0, c.cy - y0
    n = int(np.ceil(np.hypot(max(cx, c.w - cx), max(cy, c.h - cy)))) + 1
    t = np.arange(n, dtype=np.float64)
    xs = np.rint(cx + t[None, :] * _RAY_COS[:, None]).astype(np.intp)
    ys = np.rint(cy + t[None, :] * _RAY_SIN[:, None]).astype(np.intp)
    inside = (xs >= 0) & (xs < c.w) & (ys >= 0) & (ys < c.h)
    # the box's pixel at each sample, False off the box (clamped indices, then masked)
    hit = box[np.minimum(np.maximum(ys, 0), c.h - 1), np.minimum(np.maximum(xs, 0), c.w - 1)]
    hit &= inside
    # each ray's farthest hit + 1 (0: none); the pixels out to it weigh t + 0.5 each, which
    # sum to (last + 1)² / 2 — exact in floating point, as the sums of halves they replace
    reach = (hit * (t + 1.0)).max(axis=1)
    total = 0.5 * float(reach @ reach)
    # a hit lies within its ray's reach: the hits' weights are the numerator
    return float((hit @ (t + 0.5)).sum()) / total if total > 0.0 else 1.0


def _solid(gray: NDArray[np.uint8], c: _Candidate, level: float) -> float:
    """0–1: whether a wide core is solid, as the clipped glare of one point source is — the
    second condition (after :func:`_tail`) for a wide saturated core to count as its own
    glare (issue 24).

    The sun's glare — its aureole (a power law of the angle from it: Deepak et al. 1982)
    and the lens's veiling glare (its glare spread function, ISO 9358) — falls off
    monotonically from the sun, so the set of pixels where it clips is a level set of a
    radially decreasing function: star-shaped about the sun and without holes; what stands
    in front of it (a mast, wires, tree tops) takes a small share. A broken cloud field lit
    from behind by a hidden sun (altocumulus in its aureole, brightened: FE3 × 1.1–1.3) clips
    on its bright elements and not on the darker gaps between them, a region degrees wide
    with holes. :func:`star_fill` measures it: the real suns fill 0.85–1.00 of their hull at
    every exposure tried (Wolf, Wettermast, EUROCONTROL, gains 1–1.3, gamma 0.7), the
    brightened cloud fields 0.47–0.65 (FE3 × 1.3 0.64 → 0.65 when star_fill came to count
    the pixels the region kept). No credit at a fill of 0.5 (:data:`_SOLID`: half
    the hull unclipped, as much gap as core), full credit from 0.8 (a fifth of the hull may
    be lost to what stands in front of the glare)."""
    lo, hi = _SOLID
    return _clamp((star_fill(gray, c, level) - lo) / (hi - lo), 0.0, 1.0)


def _tail(gray: NDArray[np.uint8], c: _Candidate, m4: float, bg: float, contrast: float,
          peak: float, fov: FovCircle | None, image: NDArray[Any] | None) -> float:
    """0–1: whether the glare around a core still lights the sky at 4 core radii — the
    condition for a wide saturated core to count as its own glare (issue 24).

    A point source bright enough to saturate a core degrees wide has a glare — its
    aureole and the lens's scattered light, falling off as a power of the angle from it
    (the aureole: Moffat 1969, A&A 3:455; a lens's veiling glare: ISO 9358) — still well
    above the sky at 4 R: the real suns keep 54–68 % (Wolf), 41–51 % (Wettermast) and 17 %
    (EUROCONTROL's low sun) of their contrast there (median grey level of the ring against
    the sky's level ``bg``). The brightest patch of an overcast deck — its overexposed zenith,
    the second renderer's held-out overcast frames — is back at the sky's median by then
    (−13 to +4 %). ``m4`` is that ring's median about the grey core ``c``; on a colour
    frame with a white core (:func:`_white_core`) the ring is drawn 4 × the white core's
    radius about its centre instead — the sun's own core, not the blue sky saturated in
    grey around it, which a longer exposure grows by tens of degrees (the Wolf frames
    brightened ×1.1–1.15 in ``tests/vision/test_real_sky.py``) and pushes the ring past
    the horizon. Full credit from ``_TAIL[1]`` of the contrast; a ring with no sky to read
    (under 8 points inside the frame and image circle) is no evidence either way (1)."""
    core = _white_core(image, c, min(_SATURATED, peak - 1.0))
    if core is not None:
        m = cv2.moments(core[0])
        if m["m00"] > 0 and m["m00"] < c.area:
            v = _ring_values(gray, core[1] + m["m10"] / m["m00"], core[2] + m["m01"] / m["m00"],
                             4.0 * float(np.sqrt(m["m00"] / np.pi)), fov)
            m4 = _median(v) if v.size >= 8 else float("nan")
    if not math.isfinite(m4):
        return 1.0
    lo, hi = _TAIL
    return _clamp(((m4 - bg) / contrast - lo) / (hi - lo), 0.0, 1.0)


_GREY_TOP_TOL = 1.5  # a one-channel frame's "white" core: within 1 level of its top


def _white_core(image: NDArray[Any] | None, c: _Candidate, level: float,
                one_channel: bool = False
                ) -> tuple[NDArray[Any], int, int, NDArray[np.uint8]] | None:
    """The *white* core of a candidate on an 8-bit colour frame → (its outline as OpenCV
    returns it, in the crop; the crop's origin x0, y0 in the frame; the crop's mask), or
    None (a grey frame unless ``one_channel``, or no pixel of min(B, G, R) up to ``level``
    in the candidate's box).

    The sun saturates every colour channel; a blue sky's glare around it saturates the
    blue channel, and so the grey level, much farther out. The white core — pixels within
    3 levels of the top of min(B, G, R) in the candidate's box, its largest outline — is
    the part of the glare no colour of the sky reaches: the sun's own core
    (``vision.detect._white_core_centre`` centres a large glare on it).

    With ``one_channel``, a grey frame's core is its pixels within 1 grey level of the top
    (:data:`_GREY_TOP_TOL`): a monochrome frame made from a colour sensor (its luma, BT.601
    Y = 0.299 R + 0.587 G + 0.114 B) keeps the colour channels' clipping in its grey
    levels, and a pixel within 1 level of the top has its red channel — the one a blue
    sky's glare lacks, weighted 0.299 — within 1 / 0.299 ≈ 3.3 levels of its top: the
    white core's own 3.5 levels. Beyond it the blue glare clips blue and green only (the
    Wolf frames: red 245–247 there, grey 252–253), so the grey core is 1.6–2.3 times this
    core's area on Wolf made monochrome (Wettermast 1.2, the second renderer's frames at
    most 1.24; both keep the limb fits, as in colour). Within 0.5 of the top (the top level
    alone) took the renderer's cirrus and cumulus frames made monochrome past that
    condition and put them farther off (held-out cirrus 0.71° → 1.18° RMS). A sensor
    without a colour filter clips its whole saturated disc to one level: this core is then
    the grey core itself, and the caller's condition that the grey core be larger
    (``vision.detect._WHITE_BLUE_EXCESS``) leaves such a frame to the limb fits."""
    img = np.asarray(image) if image is not None else None
    grey = one_channel and img is not None and img.ndim == 2 and img.dtype == np.uint8
    if img is None or not grey and (img.ndim != 3 or img.shape[2] < 3
                                    or img.dtype != np.uint8):
        return None
    h, w = img.shape[:2]
    x0, y0 = max(0, c.x - 2), max(0, c.y - 2)
    x1, y1 = min(w, c.x + c.w + 2), min(h, c.y + c.h + 2)
    crop = img[y0:y1, x0:x1]
    white = crop if grey else cv2.min(cv2.min(crop[:, :, 0], crop[:, :, 1]), crop[:, :, 2])
    top = float(white.max()) if white.size else 0.0
    if top < level:  # no pixel white up to the grey core's top
        return None
    tol = _GREY_TOP_TOL if grey else 3.5
    binary = np.asarray(cv2.threshold(white, top - tol, 1, cv2.THRESH_BINARY)[1], np.uint8)
    contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return None
    return max(contours, key=cv2.contourArea), x0, y0, binary


def _mark_ghosts(cands: list[_Candidate], centre: tuple[float, float],
                 sources: list[_Candidate] | None = None,
                 casts: Callable[[_Candidate], bool] | None = None) -> int:
    """Flag clusters on the line through the optical centre, opposite a larger one of
    ``sources`` (default: any of ``cands``) that ``casts`` a ghost (default: every one;
    asked once per source, and only of one with a smaller cluster opposite it)."""
    n = 0
    ox, oy = centre
    verdicts: dict[int, bool] = {}
    for a in cands if sources is None else sources:
        for b in cands:
            if a is b or b.ghost or a.ghost or b.area >= a.area:
                continue
            va = np.array([a.cx - ox, a.cy - oy])
            vb = np.array([b.cx - ox, b.cy - oy])
            na, nb = np.linalg.norm(va), np.linalg.norm(vb)
            if na < 3 or nb < 3:
                continue
            if float(va @ vb / (na * nb)) < -np.cos(np.radians(6.0)):
                if casts is not None:
                    if id(a) not in verdicts:
                        verdicts[id(a)] = casts(a)
                    if not verdicts[id(a)]:
                        continue
                b.ghost = True
                n += 1
    return n


def _symmetry(mask: NDArray[np.uint8]) -> float:
    """Overlap (IoU) of a blob with itself turned 180° about its centroid: ~1 for a disc,
    an oval, or a disc with spikes on both sides; low for a disc cut by a box or the
    horizon."""
    m = cv2.moments(mask, True)
    if m["m00"] <= 0:
        return 0.0
    mx, my = m["m10"] / m["m00"], m["m01"] / m["m00"]
    h, w = mask.shape
    turn = np.array([[-1.0, 0.0, 2.0 * mx], [0.0, -1.0, 2.0 * my]])
    rot = cv2.warpAffine(mask, turn, (w, h), flags=cv2.INTER_NEAREST)
    inter = cv2.countNonZero(cv2.bitwise_and(mask, rot))
    union = cv2.countNonZero(cv2.bitwise_or(mask, rot))
    return inter / union if union else 0.0

