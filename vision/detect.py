"""Find the sun in a camera frame: a robust detector and the seeds' own pipelines.

Three named methods, all returning a :class:`SunDetection`:

* ``"robust"`` (default, :func:`detect_robust`) — candidates: field-of-view
  mask (the fisheye's image circle, found from the frame), a threshold that
  adapts to the brightest level (of the frame, or first of a window around
  the ephemeris prediction when one is given — grown while the winning core
  reaches the window's edge, so that a wide glare is never refined cut by it
  — then of the whole frame ranked by appearance alone; the image circle and
  the window are searched in their bounding boxes), connected components
  grouped when a mast splits a glare, streaks (blooming, smear) opened away,
  lens-flare ghosts rejected (on the line through the optical centre,
  opposite a larger blob the frame does not cut). Each
  candidate gets a shape term (second moments; a core cut by trees, the ground or a mast:
  the roundness of its free arc, :func:`_cut_shape`) and glare evidence (isotropic
  fall-off, a sharp drop to the sky, or a saturated core degrees wide — the
  glare itself, when it still lights the sky at 4 core radii:
  :func:`vision.candidates._tail`). What a sun is (issue 24 item 2): a region at or near
  saturation (≥ 250, or a flat clipped top at any level: a darkened frame),
  round, brighter than the sky — or, when no region at the top is the disc's size (a
  neutral-density filter or a short exposure keeps the sun unclipped: item 4, any
  exposure), the one region at half the peak's contrast (the full width at half maximum)
  of the solar disc's size at the camera's scale, holding the peak, with a dark sky around
  it, centred by its intensity-weighted centroid (:func:`_unclipped_disc`). A region
  smaller than the solar disc where it lies
  is no candidate (:func:`vision.confidence.smaller_than_the_disc`: a glint);
  a candidate that is not saturated or has a
  shape no sun has gets probability 0 (:func:`vision.confidence.admissible`);
  the others get ``confidence``, a probability: a logistic model of shape,
  glare evidence, contrast against the sky (the frame's median, or its
  border's when lower: a small ROI around the sun), a size below a sun's core
  or above any glare, the runner-up's score and the distance from the
  ephemeris (:mod:`vision.confidence`, fitted on the synthetic development
  split and the real cameras, and evaluated leave-one-camera-out). The distance is
  a feature, never a veto: it cannot lower the probability of a round,
  saturated core with its glare, so a wrong place or time gives the sun it
  sees and how far it is from the prediction (``distance_from_ephemeris_px``),
  not "no sun". The sub-pixel centre: for a core wider than any sun's glare at a
  normal exposure (15° in radius, with a known scale: the sky saturated around the sun,
  a long exposure), a censored fit of a power-law glare on a plane of sky to the light
  around it (:func:`vision.glare.censored_glare_centre`); for a colour frame whose white core (every
  channel saturated; on a one-channel frame, the grey level within 1 of its top) is at
  least 3° in radius while the grey core, saturated by
  the blue sky's glare, reaches well beyond it, the centroid of that core opened
  by a disc (:func:`_white_core_centre`) — moved across the radius from the optical
  centre (a fisheye camera's given, else the image circle's: the field stop's edge,
  :func:`vision.fov.estimate_fov`) to the centre of the symmetric glare around it
  (:func:`_across_from_glare`, :func:`vision.glare.symmetric_glare_centre`); for a core
  with a glare around it and a fisheye model (given, or the image circle's), the small
  circle on the camera's sphere through most of the core's limb that leaves none of it
  inside — the clear-sky disc, which thin cloud (adding light near the sun)
  can only grow on one side (:func:`vision.limb.contained_limb_centre`,
  RANSAC after Fischler & Bolles 1981; outline on the image circle's or the frame's edge or
  along an obstacle (trees, a mast) is never limb, and a core the image circle
  cuts keeps that circle however
  little of its outline lies on it); otherwise the intensity-weighted
  centroid of a complete (point-symmetric) core, or a RANSAC + least-squares
  fit to the saturated limb of a cut one (on the camera's sphere when a model
  is known; :mod:`vision.limb`). A centre is never reported off the frame or outside the
  image circle (:func:`_inside`). A centre whose solar disc is darker than the sky and
  nowhere at the core's level is a sun behind an obstacle, its glare seen above it: no sun
  (:func:`_disc_behind_obstacle`). A "no sun" answer says why (``reason``).
* ``"seed000_hsv"`` and ``"seed003_gray240"`` — the seeds' pipelines
  (:mod:`vision.seeds`), kept for comparison.

Pixel coordinates are ``(x, y)`` = (column, row), origin at the top-left
pixel's centre. OpenCV does the image work.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import cache, lru_cache, partial
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from vision import confidence as conf
from vision.cameras import FisheyeCamera, PinholeCamera, px_per_deg_for_horizon
from vision.candidates import (
    _SATURATED,
    _Candidate,
    _clusters,
    _mark_ghosts,
    _median,
    _prior,
    _ring_values,
    _rings,
    _score,
    _shape,
    _symmetry,
    _weighted_centroid,
    _white_core,
    region_threshold,
)
from vision.detection import CameraModel, FovCircle, SunDetection
from vision.fov import _median_u8, _small, estimate_fov, lens_circle, overlays_unlit, to_gray
from vision.glare import censored_glare_centre, symmetric_glare_centre
from vision.imageio import to_8bit
from vision.limb import _robust_limb_centre, contained_limb_centre
from vision.radial import mapped_coherence
from vision.seeds import detect_seed000, detect_seed003, threshold_moments
from vision.sphere import SUN_RADIUS_DEG

__all__ = ["METHODS", "CameraModel", "FovCircle", "SunDetection", "detect_robust",
           "detect_seed000", "detect_seed003", "detect_sun", "estimate_fov",
           "threshold_moments", "to_gray"]

METHODS: tuple[str, ...] = ("robust", "seed000_hsv", "seed003_gray240")

_SMALL_AREA_PX = 30  # below: intensity-weighted centroid only; above: also a limb fit
_HALO_DROP = 0.97  # a glare: (peak − ring at 1.6 R) < this × (peak − ring at 4 R)
#: A source of a lens-flare ghost: its ring at 1.6 R above the one at 4 R by at least 7 % of
#: its peak's contrast over the far ring (:func:`_lit_around` with this drop). A ghost that
#: clips reflects a source some 10⁴ times the sensor's top, whose glare lights the sky just
#: outside its core: every labelled Wolf and Wettermast sun asked reads 0.49–0.74 of its
#: contrast there, the development split's rendered suns with a ghost 0.14–0.52 (their small
#: glares), a saturated white roof drawn opposite the sun −0.07–0.04 (the hazy sky's own
#: gradient lifts a roof's near ring past the 3 % of :data:`_HALO_DROP`, which made the sun
#: the roof's ghost). 7 % lies between, near their geometric mean (session 33, by hand: the
#: 29 labelled frames with roofs of 60 × 30 to 200 × 80 px; the held-out split's rendered
#: suns, 0.11–0.74, read after it was set).
_GHOST_SOURCE_DROP = 0.93
_CONTAINED_MIN_INLIERS = 0.3  # share of the limb on the contained circle to trust it
_FOV_EDGE_PX = 2.5  # outline points this close to the image circle's edge lie on the edge
#: The least solidity (area / convex hull's area) of a cut core completed by its mirror
#: image (:func:`_mirrored_shape`): the real suns' uncut cores of grey ≥ 250 on the
#: development split (Wolf, Wettermast) are 0.81–0.97; a cloud patch with 5 lobes of ± 35 %
#: of its radius (tests/vision/test_detect.py) 0.73
_MIRROR_SOLIDITY = 0.8
_CUT_SHARE = 0.1  # a core with this share of its outline on the image circle's edge is cut
_ARC_SHARE_FLOOR = 0.45  # a free arc with more than this share on one circle is round
# (:func:`_cut_shape`'s term rises from 0 here to 1 at 0.85); its circle's centre is
# evidence of where a hidden sun is (:func:`_disc_behind_obstacle`) from the term's midpoint
_ARC_EVIDENCE_SHARE = 0.65
_CUT_TRIALS = 512  # RANSAC triples of the contained fit of a cut core (a 20 % arc: P(miss) 2 %)
_ROUND_SPREAD_PX = 1.5  # a core whose outline spans ≤ this + 5 % of R in radius is round
_MAX_CANDIDATES = 12
_SCORED = 4  # candidates whose glare is examined
_SEARCH_DEG = 8.0  # radius of the first search around the ephemeris prediction [°]
_SEARCH_GROW = 1.5  # the window grows by this while the winning core touches its edge
_WHITE_MIN_DEG = 3.0  # a white (every channel saturated) core at least this wide in radius
# is centred by the centroid of its opening (issue 24 item 3; chosen on the Wettermast and
# Wolf labels)
_WHITE_MIN_PX = 25.0  # … and this many pixels: JPEG keeps colour at half resolution in
# 16 px blocks (4:2:0), so a colour outline is good to a pixel or two only
_WHITE_BLUE_EXCESS = 1.3  # … and the grey core this many times its area: a blue sky's glare
# saturating beyond the white core (Wolf: 1.8-2.2; Wettermast's haze: 1.0-1.1)
_WHITE_OPEN = 0.5  # the opening's disc: this share of the white core's inscribed radius
_WHITE_OPEN_MAX_PX = 24.0  # … worked on a mask shrunk until the disc is at most this wide
_WHITE_CUT_STEP_PX = 3.0  # the outline's outward neighbours looked at, this far out
_WHITE_CUT_SHARE = 0.05  # a white core with more of its outline next to darker-than-sky is cut
_COHERENCE_PASSES = 1  # solves of the radial-symmetry fit behind `coherence`
_PLATEAU_SHARE = 0.3  # a core with this share of its pixels at its peak is clipped (flat)
_PLATEAU_MIN_PX = 20  # … tested on cores of at least this many pixels
_JPEG_BLOCK_PX = 16  # a colour JPEG's coding unit (4:2:0: 8 × 8 luma blocks, chroma at half
# resolution): a plateau keeps one level only in such blocks wholly inside it
_WHITE_BLUE_MIN_PX = _JPEG_BLOCK_PX / 2  # the blue glare beyond the white core at least this
# wide in radius: a narrower band is within reach of JPEG's coding error on the colour outline
_GREY_SPREAD = 2  # a colour frame whose channels differ by at most this is a grey frame
_GREY_STRIDE = 8  # … looked at on every 8th pixel of every 8th row


@dataclass(frozen=True)
class _Region:
    """The part of the frame a search looks at: ``pixels`` (masked to zero outside the
    image circle / the window around the prediction), a crop of the frame starting at
    pixel ``(x0, y0)``; everything outside the crop counts as masked. Searching the
    circle's bounding box instead of the whole frame gives the same candidates."""

    pixels: NDArray[np.uint8]
    x0: int
    y0: int

    def value_at(self, x: NDArray[np.intp], y: NDArray[np.intp]) -> NDArray[np.uint8]:
        """Grey levels at frame pixels ``(x, y)`` (0 outside the crop)."""
        h, w = self.pixels.shape
        xi, yi = x - self.x0, y - self.y0
        if xi.size and xi.min() >= 0 and yi.min() >= 0 and xi.max() < w and yi.max() < h:
            return self.pixels[yi, xi]  # all inside the crop (the common case)
        inside = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        out = np.zeros(x.shape, np.uint8)
        out[inside] = self.pixels[yi[inside], xi[inside]]
        return out


@lru_cache(maxsize=32)
def _disc_mask(h: int, w: int, cx: int, cy: int, radius: int) -> NDArray[np.uint8]:
    """A filled disc drawn by ``cv2.circle`` on an ``h × w`` zero mask (cached: a fixed
    camera's image circle is the same disc frame after frame; read-only)."""
    mask = np.zeros((h, w), np.uint8)
    cv2.circle(mask, (cx, cy), radius, 255, -1)
    mask.flags.writeable = False
    return mask


def _disc_region(src: _Region, cx: int, cy: int, radius: int) -> _Region:
    """``src`` masked to the filled disc of ``radius`` about pixel ``(cx, cy)`` (as
    ``cv2.circle`` draws it), cropped to the disc's bounding box."""
    h, w = src.pixels.shape
    x0, y0 = max(0, cx - radius - 1 - src.x0), max(0, cy - radius - 1 - src.y0)
    x1, y1 = min(w, cx + radius + 2 - src.x0), min(h, cy + radius + 2 - src.y0)
    if x1 <= x0 or y1 <= y0:
        return _Region(np.zeros((0, 0), np.uint8), src.x0, src.y0)
    mask = _disc_mask(y1 - y0, x1 - x0, cx - src.x0 - x0, cy - src.y0 - y0, radius)
    return _Region(np.asarray(cv2.bitwise_and(src.pixels[y0:y1, x0:x1], mask), np.uint8),
                   src.x0 + x0, src.y0 + y0)


@dataclass
class _Pick:
    """The winner of one search, with what the confidence and the answer need."""

    best: _Candidate
    work: _Region  # the frame as searched (masked outside the window / image circle)
    labels: NDArray[Any]
    peak: float
    bg: float
    thr: float
    n_candidates: int
    ghosts: int
    x: NDArray[np.float64]
    p: float
    values: dict[str, float]
    unclipped: bool = False  # the sun's disc read unclipped (:func:`_unclipped_disc`)
    sphere: CameraModel | None = None  # the projection the glare chose (:func:`_glare_sphere`)


def px_per_deg_of(camera: CameraModel | None, fov: FovCircle | None, width_px: int) -> float:
    """The frame's scale near the sun [px °⁻¹]: from the camera model, else from the image
    circle (a 180° lens), else a 67° pinhole (seed 000's tracker camera)."""
    if isinstance(camera, FisheyeCamera):
        return float(camera.px_per_deg)
    if isinstance(camera, PinholeCamera):
        return float(camera.focal_px * np.pi / 180.0)
    if fov is not None:
        return lens_circle(fov).radius_px / 90.0
    return width_px / 67.0


def _local_px_per_deg(model: CameraModel, x: float, y: float) -> tuple[float, float]:
    """The camera's scale at pixel (x, y) [px/°], largest and smallest over the directions
    of the sky there (the singular values of the projection's Jacobian, by differences of
    0.1°): a fisheye draws a small disc as an ellipse whose axes change over the frame
    (an orthographic lens shrinks it to cos θ of the zenith's across the radius, a
    reviewer's finding). ``(0, 0)`` — no size refused — where the model cannot tell (a step
    beyond the lens's edge: the nominal scale there was an orthographic lens's largest).
    A fisheye's in closed form (:meth:`vision.cameras.FisheyeCamera.local_px_per_deg`: the
    differences' round trip through the sky cost a tenth of a 640-px frame's detection)."""
    if isinstance(model, FisheyeCamera):
        return model.local_px_per_deg(x, y)
    step = np.radians(0.1)
    dx, dy, dz = (float(c) for c in np.asarray(model.pixel_to_direction(x, y),
                                                 dtype=np.float64).reshape(3))
    # u = d × (z, or x near the zenith), v = d × u: two directions across the line of sight
    # (written out: np.cross and np.linalg.svd cost a tenth of a 640-px frame's detection)
    ux, uy, uz = (dy, -dx, 0.0) if abs(dz) < 0.9 else (0.0, dz, -dy)
    n = np.sqrt(ux * ux + uy * uy + uz * uz)
    ux, uy, uz = ux / n, uy / n, uz / n
    vx, vy, vz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
    points = np.array([[dx, dy, dz], [dx + step * ux, dy + step * uy, dz + step * uz],
                       [dx + step * vx, dy + step * vy, dz + step * vz]])
    px, py = model.direction_to_pixel(points / np.linalg.norm(points, axis=1, keepdims=True))
    px, py = np.asarray(px, dtype=np.float64), np.asarray(py, dtype=np.float64)
    a, b, c, e = px[1] - px[0], px[2] - px[0], py[1] - py[0], py[2] - py[0]
    if not all(np.isfinite((a, b, c, e))):
        return 0.0, 0.0
    # the singular values of the 2 × 2 Jacobian [[a, b], [c, e]], in closed form
    total, det = a * a + b * b + c * c + e * e, a * e - b * c
    root = np.sqrt(max(total * total - 4.0 * det * det, 0.0))
    major, minor = np.sqrt(0.5 * (total + root)), np.sqrt(max(0.5 * (total - root), 0.0))
    return float(major / np.degrees(step)), float(minor / np.degrees(step))



def _lit_around(gray: NDArray[np.uint8], c: _Candidate, peak: float,
                fov: FovCircle | None = None, drop: float = _HALO_DROP) -> bool:
    """Whether a core has a glare: the ring just outside it (1.6 R + 2 px) still above the far
    sky (4 R + 3 px) by 1 − ``drop`` of the peak's contrast over that sky (:data:`_HALO_DROP`:
    3 %; a ghost's source, :data:`_GHOST_SOURCE_DROP`: 7 %), the rings' points inside the
    image circle ``fov`` (the unlit frame beyond it is no sky).
    Only a source far brighter than the sensor's top — the sun — lights its surround so;
    a white overlay, a sunlit wall or a cloud's edge clipped by the exposure does not."""
    r_eq = float(np.sqrt(c.area / np.pi))
    near, far = _rings(gray, c.cx, c.cy, (1.6 * r_eq + 2.0, 4.0 * r_eq + 3.0), fov)
    return bool(near.size >= 8 and far.size >= 8
                and peak - _median(near) < drop * (peak - _median(far)))


def _regions(gray: NDArray[np.uint8], work: _Region, row_max: NDArray[np.uint8], level: int,
             centre: tuple[float, float], peak: float, fov: FovCircle | None
             ) -> tuple[NDArray[Any], list[_Candidate], int] | str:
    """The bright regions of ``work`` above ``level`` → ``(labels, candidates, ghosts)``:
    connected components, lens-flare ghosts marked, clusters grouped; or a reason.
    ``peak``: the frame's top level (:func:`_clip_level`); ``fov``: the image circle."""
    rows = np.flatnonzero(row_max > level)
    if rows.size == 0:
        return "no bright region above the threshold"
    by, bh = int(rows[0]), int(rows[-1] - rows[0]) + 1
    cols = np.flatnonzero(work.pixels[by:by + bh].max(axis=0) > level)
    bx, bw = int(cols[0]), int(cols[-1] - cols[0]) + 1
    binary = cv2.threshold(work.pixels[by:by + bh, bx:bx + bw], float(level), 255,
                           cv2.THRESH_BINARY)[1]
    ox, oy = bx + work.x0, by + work.y0  # the box's origin in the frame
    n, labels, stats, cents = cv2.connectedComponentsWithStats(binary, connectivity=8)
    if n < 2:
        return "no bright region above the threshold"
    stats[:, 0] += ox
    stats[:, 1] += oy
    cents = cents + (ox, oy)
    order = np.argsort(-stats[1:, cv2.CC_STAT_AREA])[:_MAX_CANDIDATES] + 1
    # ghosts first, per component, so that a ghost next to the sun (the sun near the
    # optical centre) is not merged into the sun's cluster
    st, ce = stats.tolist(), cents.tolist()  # Python numbers: the same values, cheaper reads
    singles = [_Candidate([i], st[i][4], st[i][0], st[i][1], st[i][2], st[i][3], ce[i][0],
                          ce[i][1]) for i in order.tolist()]
    # a region the frame cuts casts no ghost: its centroid is the cut's, not its source's
    # (a tester's white bar across the top of a Wolf frame made the sun opposite it a ghost)
    # and only a source with a glare of its own casts one: a lens-flare ghost bright enough
    # to clip is a reflection of something some 10⁴ times brighter than the sensor's top,
    # which lights the sky around its own core (_lit_around); a sunlit white roof opposite
    # the sun through the image centre, larger than its core, made the sun its ghost
    fh, fw = gray.shape
    sources = [c for c in singles if not _box_on_frame_edge(c.x, c.y, c.x + c.w - 1,
                                                            c.y + c.h - 1, fh, fw)]
    ghosts = _mark_ghosts(singles, centre, sources,
                          casts=lambda c: _lit_around(gray, c, peak, fov, _GHOST_SOURCE_DROP))
    real = np.array([c.labels[0] for c in singles if not c.ghost], dtype=np.int64)
    return labels, _clusters(stats, cents, real, ox, oy), ghosts


#: An unclipped disc's region at half its contrast (the full width at half maximum) spans
#: this share of the solar disc's radius at least, less the pixel grid's √2/2: limb darkening
#: I(μ) = 1 − u (1 − μ) puts the half level at 0.99 of the radius for u = 0.6 (the visible
#: band's; an edge 0.4 of the centre), 0.93 for u = 0.8 (the blue's), a little inside that
#: when noise raises the peak the level is taken from
_UNCLIPPED_MIN_RADIUS = 0.85
#: … and at most this share of it plus a pixel (a lens's blur of a pixel or two, the grid):
#: a glare that reaches half the disc's contrast is a saturated sun's, not this one's
_UNCLIPPED_MAX_RADIUS = 1.3
#: … and the sky around it, at 2-3 radii, stays below this share of its contrast: the disc is
#: some 10⁵ times the sky, so a filter that keeps its centre unclipped leaves the sky dark
_UNCLIPPED_RING = 0.25
#: An unclipped disc is centred by its intensity-weighted centroid above this share of its
#: contrast: the whole disc's light, limb included (its top alone, the clipped core's 80 %,
#: was 0.122 mrad RMS against 0.046 on a 4.5-px disc; docs/validation-vision.md)
_UNCLIPPED_CENTROID_SHARE = 0.1


def _unclipped_disc(gray: NDArray[np.uint8], work: _Region, row_max: NDArray[np.uint8],
                    peak: float, bg: float, centre: tuple[float, float], model: CameraModel,
                    fov: FovCircle | None) -> tuple[NDArray[Any], list[_Candidate], int] | str:
    """The sun a neutral-density filter or a short exposure keeps under the sensor's top
    (issue 24 item 4: any exposure), when no region at the top is as large as the solar
    disc → the regions with the disc alone, or why there is none.

    Its top is smaller than the disc (limb darkening), so the regions are cut again at half
    the peak's contrast over the sky (the full width at half maximum, which limb darkening
    puts at the disc's edge). The sun is the one region there whose size is the solar disc's
    at the camera's scale (its radius between :data:`_UNCLIPPED_MIN_RADIUS` of the disc's,
    less the grid's √2/2, and :data:`_UNCLIPPED_MAX_RADIUS` of it and a pixel), that holds
    the frame's peak, and around which the sky at 2-3 radii stays under
    :data:`_UNCLIPPED_RING` of the contrast. A glint or a speck is smaller than the disc at
    half its contrast too, a bright cloud larger or in a bright surround; roundness is then
    judged as for any core."""
    contrast = peak - bg
    level = int(np.floor(bg + 0.5 * contrast - 0.5))
    got = _regions(gray, work, row_max, level, centre, peak, fov)
    if isinstance(got, str):
        return got
    labels, cands, ghosts = got
    clip = "not clipped" if peak < _SATURATED else "at the sensor's top"
    sized, large = [], []
    for c in cands:
        major, minor = _local_px_per_deg(model, c.cx, c.cy)
        rho1, rho2 = SUN_RADIUS_DEG * major, SUN_RADIUS_DEG * minor
        half = np.sqrt(0.5)
        if c.area < np.pi * max(_UNCLIPPED_MIN_RADIUS * rho1 - half, 0.0) * max(
                _UNCLIPPED_MIN_RADIUS * rho2 - half, 0.0):
            continue
        if c.area > np.pi * (_UNCLIPPED_MAX_RADIUS * rho1 + 1.0) * (
                _UNCLIPPED_MAX_RADIUS * rho2 + 1.0) and major > 0.0:
            large.append((c, rho1))
            continue
        sized.append(c)
    if not sized and large:
        c, rho1 = large[0]
        r_eq = float(np.sqrt(c.area / np.pi))
        return (f"the brightest region (peak {peak:.0f} of 255, {clip}) is {2 * r_eq:.0f} px "
                f"across at half its contrast, where the solar disc is {2 * rho1:.0f} px at "
                "the camera's scale: too large for the sun's disc — a bright cloud, or the "
                "sun through a field of view (fov_deg) narrower than the one used")
    if not sized:
        if peak < _SATURATED:
            return (f"the brightest region (peak {peak:.0f} of 255) is not clipped and, at "
                    "half its contrast over the sky, smaller than the solar disc where it "
                    "lies: a glint or a speck, not the sun")
        return ("every bright region is smaller than the solar disc where it lies "
                "(a glint or a speck, not the sun)")
    if len(sized) > 1:
        return (f"{len(sized)} regions the solar disc's size above half the contrast of the "
                f"brightest (peak {peak:.0f} of 255, {clip}): none stands out as the sun")
    c = sized[0]
    if float(gray[c.y:c.y + c.h, c.x:c.x + c.w].max()) < region_threshold(peak, bg)[0]:
        return (f"the region the solar disc's size at half the brightest's contrast (peak "
                f"{peak:.0f} of 255, {clip}) does not hold that peak: no sun stands out")
    r_eq = float(np.sqrt(c.area / np.pi))
    ring = _rings(gray, c.cx, c.cy, (2.0 * r_eq + 2.0, 3.0 * r_eq + 3.0), None)
    values = np.concatenate(ring) if ring else np.zeros(0)
    if values.size < 8 or float(np.median(values)) > bg + _UNCLIPPED_RING * contrast:
        return (f"the brightest region (peak {peak:.0f} of 255, {clip}) is the solar disc's "
                "size at half its contrast but not far brighter than the sky around it: "
                "not the sun's disc")
    return labels, [c], ghosts

def _search(gray: NDArray[np.uint8], work: _Region, small_bg: float,
            fov: FovCircle | None, diam: float, centre: tuple[float, float],
            ppd: float, expected_px: tuple[float, float] | None,
            prefer_near: bool = True, scale_known: bool = True,
            image: NDArray[Any] | None = None, model: CameraModel | None = None
            ) -> _Pick | str:
    """Candidates in ``work`` (the frame, masked and cropped), the winner and its probability;
    or a reason.

    With ``prefer_near`` the candidates are ranked by their score weighted by their
    nearness to ``expected_px`` (the search around the prediction); without it by their
    score alone (the blind search), the distance entering only the confidence. ``image``:
    the frame in colour, for the white core of a wide glare (:func:`_score`); ``model``:
    the camera, or the image circle's approximate one, for the arc of a cut core
    (:func:`_cut_shape`)."""
    bg = small_bg
    # each row's brightest pixel: the peak, then the bright pixels' bounding box from it
    row_max = work.pixels.max(axis=1) if work.pixels.size else np.zeros(1, np.uint8)
    peak = _clip_level(work, row_max, float(row_max.max()), image)
    contrast = peak - bg
    if contrast < 20.0:
        return f"no bright region: the brightest pixel is {max(contrast, 0):.0f} grey levels " \
               "above the sky"
    thr, level = region_threshold(peak, bg)
    got_regions = _regions(gray, work, row_max, level, centre, peak, fov)
    if isinstance(got_regions, str):
        return got_regions
    labels, cands, ghosts = got_regions
    unclipped = False
    if scale_known and model is not None:  # a core smaller than the solar disc is no sun
        cands = [c for c in cands if not conf.smaller_than_the_disc(
            c.area, *_local_px_per_deg(model, c.cx, c.cy))]
        if not cands:
            disc = _unclipped_disc(gray, work, row_max, peak, bg, centre, model, fov)
            if isinstance(disc, str):
                return disc
            (labels, cands, ghosts), thr, unclipped = disc, float(bg + 0.5 * contrast), True
    # after that rule: a speck it refused took a slot of the few scored below (a reviewer's
    # finding: a sun behind a branch among six specks was never scored)
    # a fisheye's image circle: the disc a low sun is drawn as, squashed along the radius
    circle = None if fov is None else (fov.cx_px, fov.cy_px, fov.radius_px)
    priors = {id(c): _prior(c, labels, diam, circle) for c in cands}

    def near(c: _Candidate) -> float:
        if expected_px is None or not prefer_near:
            return 1.0
        d_deg = float(np.hypot(c.cx - expected_px[0], c.cy - expected_px[1])) / ppd
        return float(np.exp(-0.5 * (d_deg / 5.0) ** 2)) + 0.05

    # the glare rings are the costly part: only for the best few by shape and size
    ranked = sorted(priors, key=lambda k: -priors[k][0] ** 2 * priors[k][1])[:_SCORED]
    for c in cands:
        c.shape = priors[id(c)][0]
        if id(c) in ranked:
            # the lens's squash along the radius allowed (vision.candidates._prior) only a
            # free disc — a core an obstacle cuts (a sun behind trees) is judged on its free
            # arc — with the sun's glare (below): a sunlit roof at the rim is as oval as a
            # low sun there (a Wolf frame with its sun occulted, 0.90 without it)
            squashed = c.shape > c.upright
            if squashed and _cut_outline(c, labels, gray, bg, fov):
                c.shape, squashed = c.upright, False
            if c.shape < 1.0 and c.area >= _SMALL_AREA_PX:
                c.shape = max(c.shape, _cut_shape(c, labels, gray, bg, model))
            c.score = _score(c, gray, c.shape, priors[id(c)][1], peak, bg, fov, diam, ppd,
                             scale_known, image)
            if squashed and c.glare < conf.SMALL_CORE_GLARE:
                c.shape = c.upright
                if c.area >= _SMALL_AREA_PX:
                    c.shape = max(c.shape, _cut_shape(c, labels, gray, bg, model))
                c.score = _score(c, gray, c.shape, priors[id(c)][1], peak, bg, fov, diam,
                                 ppd, scale_known, image)
    cands.sort(key=lambda c: -c.score * near(c))
    best = cands[0]
    runner = max((c.score for c in cands[1:]), default=0.0) / max(best.score, 1e-9)
    r_eq = float(np.sqrt(best.area / np.pi))
    eph = None
    if expected_px is not None:
        eph = float(np.hypot(best.cx - expected_px[0], best.cy - expected_px[1])) / ppd
    radius_deg = r_eq / ppd
    # an unclipped disc of the sun's size, round and alone above half its contrast
    # (_unclipped_disc) stands where the clipped core stands: the disc, read whole
    saturated = float(unclipped or peak >= _SATURATED or (
        best.area >= _PLATEAU_MIN_PX and _clipped(gray, best, labels, peak)))
    # a saturated core degrees wide that is a glare (vision.candidates._score: `wide`) has
    # no gradient inside the window (the Wolf frames' coherence is 0.02–0.06): its width
    # stands for the symmetry — wholly when it is 1, the most a coherence can be (a share of
    # the gradients' weight), so the fit is not needed then (most fisheye suns)
    coherence, sphere = best.wide, None
    if coherence < 1.0:
        fitted, sphere = _glare_sphere(gray, best, r_eq, peak, fov, bg, model)
        coherence = max(fitted, coherence)
    # a crop without a camera (the tracker's region of interest) has no known scale: its
    # px/° guessed from its width is wrong by the crop's ratio, so its size is no evidence
    x = conf.features(best.shape, best.glare, saturated, peak, bg,
                      radius_deg if scale_known else None,
                      min(runner, 1.0), coherence, eph)
    values = {"shape": best.shape, "peak": peak, "contrast": peak - bg,
              "radius_deg": radius_deg, "coherence": coherence,
              "ephemeris_deg": eph if eph is not None else float("nan")}
    return _Pick(best, work, labels, peak, bg, thr, len(cands), ghosts, x, conf.probability(x),
                 values, unclipped, sphere)


#: Two projections whose local aspect (the scale along the radius over the scale across it,
#: :func:`_sky_map`) differs by less than this at a core draw its glare alike: a
#: gradient's direction moves by at most half of it [rad], a quarter of the 0.08 rad the
#: coherence allows a line (:func:`vision.radial.radial_symmetry_centre`), so the image
#: cannot tell them apart there (near the zenith every projection is locally the same)
_SPHERE_ASPECT = 0.04
#: A projection other than the model's is chosen only when the glare is more radially
#: symmetric on its sphere by this much (coherence 0–1) …
_SPHERE_MARGIN = 0.02
#: … and symmetric there at all: the majority of its gradients' weight on lines through one
#: centre. A glare the skyline cuts, or a ragged one, has less on every sphere (0.06–0.24 on
#: the independent renderer's cut frames 12102–12120) and cannot tell the projection
_SPHERE_MAJORITY = 0.5
#: … for a core at least this wide in radius [px]: a limb fitted on another projection's
#: sphere moves by the change of the lens's scale across the core, which grows as its radius
#: squared — 0.3–2.6 px for 21-px cores on test_ridge's equisolid frames, so under a pixel
#: below some 16 px (the small cores of a 640-px frame, where the choice cost a fifth of the
#: detection's time): there the image cannot tell it and the error is small anyway
_SPHERE_MIN_PX = 16.0


def _telling_projections(c: _Candidate, model: FisheyeCamera
                         ) -> list[tuple[FisheyeCamera, NDArray[np.float64]]]:
    """``model`` and those of its candidate projections (:func:`_candidate_projections`) whose
    local aspect at the core ``c`` differs from the model's by :data:`_SPHERE_ASPECT` or
    more — the ones the glare's shape can tell from it — each with its map to the sky there
    (:func:`_sky_map`)."""
    out: list[tuple[FisheyeCamera, NDArray[np.float64]]] = []
    aspect0 = 0.0
    for m in _candidate_projections(model):
        if not isinstance(m, FisheyeCamera):
            continue
        a, aspect = _sky_map(m, c.cx, c.cy)
        if not out:
            aspect0 = aspect
        if not out or abs(aspect - aspect0) >= _SPHERE_ASPECT:
            out.append((m, a))
    return out


def _sky_map(model: FisheyeCamera, x: float, y: float) -> tuple[NDArray[np.float64], float]:
    """The fisheye's map from pixels to the sky near pixel (x, y), to first order and up to a
    rotation and a scale (which leave a glare's radial symmetry as it is) → ``(A, aspect)``:
    A stretches the image along the radius from the optical centre by √(across / along) and
    shrinks it across by the same, ``aspect`` = along / across — the lens's scales r′(θ)
    along the radius and r(θ) / sin θ across it (a tilt turns the sky before the projection
    and changes neither). Closed form: a map per gradient line through the camera cost 2.7
    times a 640-px frame's detection."""
    dx, dy = x - model.cx_px, y - model.cy_px
    r = float(np.hypot(dx, dy))
    theta = float(model.theta_rad(r))
    if r < 1e-6 or not 1e-6 < theta < np.pi:
        return np.eye(2), 1.0
    along, across = model.radial_scales(theta)
    if not (along > 0.0 and across > 0.0):
        return np.eye(2), 1.0
    k = float(np.sqrt(across / along))
    ux, uy = dx / r, dy / r
    radial = np.array([[ux * ux, ux * uy], [ux * uy, uy * uy]])
    return k * radial + (np.eye(2) - radial) / k, along / across


def _glare_sphere(gray: NDArray[np.uint8], c: _Candidate, r_eq: float, peak: float,
                  fov: FovCircle | None, bg: float, model: CameraModel | None
                  ) -> tuple[float, CameraModel | None]:
    """The radial symmetry of the glare around the core ``c`` (``r_eq`` px in radius) on the
    sky, and the sphere it was measured on → ``(coherence 0–1, model)``.

    The coherence of the glare's gradients (:func:`vision.radial.mapped_coherence`, after
    Parthasarathy 2012) is measured on the sphere of a fisheye ``model``, where a sun's
    glare is round — not in the image, where the lens draws it as an oval near the horizon
    (an equisolid sun 4° over a ridge: 0.10 in the image, 0.77 on its sphere). A plain
    fisheye may be the image circle's equidistant guess (:func:`_candidate_projections`),
    on whose sphere an equisolid low sun's glare is still oval (0.31): the glare is measured
    on each projection the image circle may have, and the one on whose sphere it is most
    symmetric — the lens's own, on which the centre is then fitted (:func:`_refine`) — is
    chosen when the projections' local aspects at the core differ by :data:`_SPHERE_ASPECT`
    or more and its coherence beats ``model``'s by :data:`_SPHERE_MARGIN` and is at least
    :data:`_SPHERE_MAJORITY`; else ``model`` (the image cannot tell). The coherence returned
    is the highest on any of them (evidence of a sun's glare, whichever lens drew it).
    Without a fisheye model, in the image plane."""
    telling = _telling_projections(c, model) if isinstance(model, FisheyeCamera) else []
    spheres: list[CameraModel | None] = [m for m, _ in telling] or [None]
    ring = _ring_values(gray, c.cx, c.cy, 2.0 * r_eq + 3.0, fov)
    local_bg = _median(ring) if ring.size else bg
    coherence = mapped_coherence(
        gray, (c.cx, c.cy), 2.0 * r_eq + 4.0, 0.6 * local_bg, local_bg + 0.3 * (peak - local_bg),
        [a for _, a in telling] or [None], _COHERENCE_PASSES)
    i = int(np.argmax(coherence))
    if coherence[i] < max(coherence[0] + _SPHERE_MARGIN, _SPHERE_MAJORITY):
        i = 0
    return max(coherence), spheres[i] if spheres[i] is not None else model


#: How far above a clipped plateau JPEG's ringing may reach [grey levels]: on the real
#: frames darkened, up to 6–11 at quality 95, 14 at 75, 22 at 60 (docs/validation-vision.md)
_JPEG_OVERSHOOT = 32
#: The most a clipped (white) plateau's colour channels may differ [grey levels]: the sun
#: clips every channel, and JPEG's coding of a flat colour moves them by a few levels (at
#: most 6 on the real frames darkened, qualities 50–95); a sunlit sky's blue stands 30–82
#: above its red (the synthetic and occulted frames this rule refuses)
_WHITE_SPREAD = 16
#: A coding block's reach from a pixel (± 8 px: the 8 × 8 luma block the pixel shares)
_BLOCK_REACH = np.ones((_JPEG_BLOCK_PX + 1, _JPEG_BLOCK_PX + 1), np.uint8)
#: A coding unit's reach from the centre of a flat unit (± 16 px: its own half and the edge
#: block beyond it, where the plateau's ringing lies)
_UNIT_REACH = np.ones((2 * _JPEG_BLOCK_PX + 1, 2 * _JPEG_BLOCK_PX + 1), np.uint8)


def _clip_level(work: _Region, row_max: NDArray[np.uint8], peak: float,
                image: NDArray[Any] | None = None) -> float:
    """The frame's top level: its brightest pixel, unless a flat plateau up to
    :data:`_JPEG_OVERSHOOT` levels below it fills a whole coding unit
    (:func:`_flat_units`), every brighter pixel can be its ringing
    (:func:`_rings_of_a_plateau`), no saturated core lies elsewhere
    (:func:`_saturated_elsewhere`) and, in an 8-bit colour frame, it is white — a clipped
    core written as JPEG. The blocks wholly inside the core keep the level the sensor clipped at
    exactly; those across its edge ring above it and set the peak, and cut at the ringing's
    peak the core fell apart into its edge's overshoot ("every bright region is smaller
    than the solar disc"). ``row_max``: each row's brightest pixel of ``work``;
    ``image``: the colour frame, or None."""
    if work.pixels.size == 0:
        return peak
    lo = max(peak - _JPEG_OVERSHOOT, 0.0)
    rows = (row_max >= lo).nonzero()[0]
    if rows.size == 0:
        return peak
    box = work.pixels[rows[0]:rows[-1] + 1]
    cols = (box.max(axis=0) >= lo).nonzero()[0]
    box = box[:, cols[0]:cols[-1] + 1]
    # the highest level filling a coding unit is the plateau's
    level, plateau = _plateau(box, lo)
    if plateau is None:
        return peak
    if level == int(peak):
        return peak  # the plateau is the peak: nothing rings above it
    if not _rings_of_a_plateau(box, level) or _saturated_elsewhere(box, plateau):
        return peak
    if image is not None and image.ndim == 3:
        if image.dtype != np.uint8:
            return peak  # the white test's levels are 8-bit ones
        ys, xs = np.nonzero(plateau)
        y0, x0 = work.y0 + int(rows[0]), work.x0 + int(cols[0])
        channels = np.median(image[ys + y0, xs + x0, :3], axis=0)
        if float(channels.max() - channels.min()) > _WHITE_SPREAD:
            return peak
    return float(level)


def _plateau(box: NDArray[np.uint8], lo: float) -> tuple[int, NDArray[np.bool_] | None]:
    """The highest level of ``box`` that fills a coding unit (:func:`_flat_units`) when it is
    ``lo`` or more, and the centres of the units wholly at it → ``(level, centres)``; else
    ``(-1, None)``.

    A unit (16 × 16) wholly inside the box holds an 8 × 8 block of the grid aligned to the
    box's corner, and lies within 8 px of it: on a box of more than :data:`_BLOCKS_FROM_PX`
    pixels (a bright cloud field around the sun, hundreds of pixels wide) the units are
    looked for only around the blocks of one level from ``lo`` up (each block's lowest and
    highest level by erosions and dilations along the rows, then down every 8th column:
    about half the cost of the units' own on the whole box); on a smaller one (a sun's core
    and its glare) level by level from the top. The answer is the whole box's either way."""
    h, w = box.shape
    if box.size <= _BLOCKS_FROM_PX:
        # level by level from the top, only the levels with a unit's worth of pixels (most
        # boxes: one), the units wholly at it by one erosion of its mask (squares crossing
        # the box's edge excluded, as by _flat_units)
        count = np.bincount(box.ravel(), minlength=256).tolist()
        for level in range(255, int(np.ceil(lo)) - 1, -1):
            if count[level] >= _JPEG_BLOCK_PX * _JPEG_BLOCK_PX:
                units = cv2.erode((box == level).view(np.uint8), _UNIT,
                                  borderType=cv2.BORDER_CONSTANT, borderValue=0)
                if units.any():
                    return level, units.view(bool)
        return -1, None
    hb, wb = h - h % _BLOCK_PX, w - w % _BLOCK_PX
    blocks = box[:hb, :wb]
    # along the rows, then down the columns of every 8th one (an eighth of the pixels)
    low = cv2.erode(np.ascontiguousarray(cv2.erode(
        blocks, _BLOCK_ROW, anchor=(0, 0))[:, ::_BLOCK_PX]), _BLOCK_COL,
        anchor=(0, 0))[::_BLOCK_PX]
    high = cv2.dilate(np.ascontiguousarray(cv2.dilate(
        blocks, _BLOCK_ROW, anchor=(0, 0))[:, ::_BLOCK_PX]), _BLOCK_COL,
        anchor=(0, 0))[::_BLOCK_PX]
    by, bx = ((low == high) & (low >= lo)).nonzero()
    if by.size == 0:
        return -1, None
    # the units that can hold those blocks: 8 px before a block to 16 px after its start
    y0, y1 = max(_BLOCK_PX * int(by.min()) - _BLOCK_PX, 0), \
        min(_BLOCK_PX * int(by.max()) + 2 * _BLOCK_PX, h)
    x0, x1 = max(_BLOCK_PX * int(bx.min()) - _BLOCK_PX, 0), \
        min(_BLOCK_PX * int(bx.max()) + 2 * _BLOCK_PX, w)
    # units crossing this crop's edge but not the box's hold none of those blocks: not flat
    # from lo up, so the crop's highest flat level from lo up is the box's
    sub = box[y0:y1, x0:x1]
    flat = _flat_units(sub)
    level = int(cv2.minMaxLoc(sub, flat.view(np.uint8))[1]) if flat.any() else -1
    if level < lo:
        return -1, None
    plateau = np.zeros(box.shape, bool)
    plateau[y0:y1, x0:x1] = flat & (sub == level)  # centres of units wholly at the level
    return level, plateau


#: A colour JPEG's coding unit: the square :func:`_flat_units` looks at about each pixel
_UNIT = np.ones((_JPEG_BLOCK_PX, _JPEG_BLOCK_PX), np.uint8)
#: A box of more pixels than this is searched for plateaus around aligned flat blocks only
_BLOCKS_FROM_PX = 64 * 64
_BLOCK_PX = _JPEG_BLOCK_PX // 2
_BLOCK_ROW = np.ones((1, _BLOCK_PX), np.uint8)
_BLOCK_COL = np.ones((_BLOCK_PX, 1), np.uint8)


def _rings_of_a_plateau(box: NDArray[np.uint8], level: int) -> bool:
    """Whether every pixel of ``box`` above ``level`` can be JPEG's ringing of a plateau
    clipped at ``level``: it lies within a coding block of a pixel below the level (ringing
    lives only in the blocks that hold an edge; a rounded or banded top has its brighter
    pixels inside its level's area, away from anything darker)."""
    edge = cv2.dilate((box < level).astype(np.uint8), _BLOCK_REACH)
    return bool(edge[box > level].all())


def _saturated_elsewhere(box: NDArray[np.uint8], plateau: NDArray[np.bool_]) -> bool:
    """Whether ``box`` holds a saturated core of its own — a clump of at least
    :data:`_PLATEAU_MIN_PX` pixels at :data:`_SATURATED` or more — beyond a coding unit's
    reach of the plateau: then the sensor clips up there (a small sun), and the plateau is a
    flat white thing below it, not the clip (a reviewer's finding: a sun 4–6 px in radius
    lost to a white board at 225–245)."""
    sat = (box >= _SATURATED).astype(np.uint8)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(sat, connectivity=8)
    big = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= _PLATEAU_MIN_PX) + 1
    if big.size == 0:
        return False
    near = cv2.dilate(plateau.view(np.uint8), _UNIT_REACH) > 0
    return bool(np.setdiff1d(big, labels[near & (sat > 0)]).size)


def _flat_units(gray: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """The pixels whose :data:`_JPEG_BLOCK_PX` square about them (a colour JPEG's coding
    unit) is one grey level — its lowest equal to its highest, squares crossing the edge of
    ``gray`` excluded: a plateau JPEG kept flat (a block wholly inside a clipped core is its
    DC term alone, which quantisation moves by well under a level)."""
    return (cv2.erode(gray, _UNIT, borderType=cv2.BORDER_CONSTANT, borderValue=0)
            == cv2.dilate(gray, _UNIT, borderType=cv2.BORDER_CONSTANT, borderValue=255))


def _clipped(gray: NDArray[np.uint8], c: _Candidate, labels: NDArray[Any], peak: float) -> bool:
    """Whether a core below :data:`_SATURATED` is clipped (a frame darkened after the sensor
    clipped it has its flat top below 255): a flat top, one level held by at least
    :data:`_PLATEAU_SHARE` of the core's pixels. A bright cloud's highlight is a rounded
    one whose top few pixels alone reach the peak (the real UCEEB, FE3 and EUROCONTROL
    overcast frames: under 16 %; the suns of Wettermast, Wolf and EUROCONTROL: 41–74 %,
    darkened or not).

    Written as JPEG, the clipped plateau keeps its level exactly in the coding blocks wholly
    inside it (a flat block is its DC term alone, which quantisation moves by well under a
    level), and only the blocks across its edge ring: a few pixels overshoot it (Wolf 12:07 at
    gain 0.92, quality 95: 11,525 pixels at 235, 23 at 236) and set the peak. So the level is
    the core's most common one, not necessarily its peak, and it must also fill a whole
    :data:`_JPEG_BLOCK_PX` square — a plateau JPEG kept flat. A rounded top spreads over its
    levels ring by ring; a tone-mapped (HDR) deck's top is banded over several levels of
    similar area (the second renderer's held-out deck 13018: its most common level 25 % of
    the core); a clipped cloud fleck of a few dozen pixels (FE3 darkened, quality 75) holds
    no such square."""
    roi = gray[c.y:c.y + c.h, c.x:c.x + c.w]
    mask = c.mask(labels)
    if roi.shape != mask.shape:
        return False
    area = max(cv2.countNonZero(mask), 1)
    top = cv2.countNonZero(cv2.bitwise_and(mask, (roi == peak).astype(np.uint8)))
    if top >= _PLATEAU_SHARE * area:
        return True
    if min(roi.shape) < _JPEG_BLOCK_PX:
        return False
    hist = np.bincount(roi[mask > 0], minlength=256)
    level = int(np.argmax(hist))
    if hist[level] < _PLATEAU_SHARE * area:
        return False
    return bool((_flat_units(roi) & (roi == level) & (mask > 0)).any())


def _guided_search(gray: NDArray[np.uint8], work: _Region, bg: float, fov: FovCircle | None,
                   diam: float, centre: tuple[float, float], ppd: float,
                   expected_px: tuple[float, float], image: NDArray[Any] | None = None,
                   model: CameraModel | None = None) -> _Pick | str:
    """The search around the ephemeris prediction: within :data:`_SEARCH_DEG` of it, the
    window grown (× :data:`_SEARCH_GROW`) while the winning core reaches the window's
    edge — a wide glare cut by the window would leave the refinement a truncated core
    — until the window holds the whole searched frame."""
    ex, ey = int(round(expected_px[0])), int(round(expected_px[1]))
    h, w = work.pixels.shape
    # the window that holds all of `work`: the farthest corner of its crop
    full = max(float(np.hypot(max(ex - work.x0, work.x0 + w - ex),
                              max(ey - work.y0, work.y0 + h - ey))), 1.0)
    radius = max(1, int(round(_SEARCH_DEG * ppd)))
    while True:
        got = _search(gray, _disc_region(work, ex, ey, radius), bg, fov, diam, centre, ppd,
                      expected_px, image=image, model=model)
        if not isinstance(got, _Pick) or radius >= full:
            return got
        pts = _limb_points(got.best, got.labels)
        if float(np.max(np.hypot(pts[:, 0] - ex, pts[:, 1] - ey))) < radius - 1.5:
            return got  # the core lies inside the window: not cut by it
        radius = int(np.ceil(min(max(_SEARCH_GROW * radius, radius + 1.0), full)))


#: How far a sun's glare reaches [its core's radii]: the ring where the confidence reads
#: the glare's tail (``vision.candidates._tail``, 4 R)
_GLARE_REACH_RADII = 4.0


def _outshines(blind: _Pick, guided: _Pick, min_confidence: float) -> bool:
    """Whether the guided pick lies in the glare of the blind winner — a sun itself, a
    larger saturated core, beside it but not the same core — and so is a piece of that
    glare: a patch near a wrong prediction (a clock an hour off, a guessed north), the edge
    of the sun's own glare or a streak in it, scored 0.53–1.00 inside its window while the
    sun lay 160–315 px away (11 of 92 Wolf frames with the clock 1–2 h off). A larger
    saturated patch *beyond* the glare's reach (a reflection) does not displace the sun the
    ephemeris found (``tests/vision/test_generalise.py``)."""
    r_blind = np.sqrt(blind.best.area / np.pi)
    apart = np.hypot(blind.best.cx - guided.best.cx, blind.best.cy - guided.best.cy)
    return (blind.p >= min_confidence and blind.best.area > guided.best.area
            and r_blind < apart <= _GLARE_REACH_RADII * r_blind)


def detect_robust(image: NDArray[Any], camera: CameraModel | None = None,
                  fov: FovCircle | None = None, auto_fov: bool = True,
                  min_confidence: float = 0.5,
                  expected_px: tuple[float, float] | None = None) -> SunDetection:
    """The robust detector (see the module docstring).

    Parameters
    ----------
    image : BGR, BGRA or grey frame.
    camera : optional camera model: the limb fit works on its sphere and its
        px/° sets the expected size of the sun's disc and glare.
    fov : the image circle, overriding the one found from the frame
        (``auto_fov=False`` to use the whole frame).
    min_confidence : probability at which a candidate is reported as the sun.
    expected_px : the sun's pixel predicted by the ephemeris through
        ``camera`` (time and place known): searched first, within 8° of it (the
        window grown × 1.5 while the winning core reaches its edge: a glare wider
        than the window is refined whole, as the blind search would);
        the whole frame is searched blind as well, and its winner kept when
        nothing near the prediction reaches ``min_confidence`` and it is more
        probable, or when the guided pick lies in its glare (:func:`_outshines`).
        The answer carries
        its distance from the prediction, however far (a wrong place, time or
        zone moves the prediction, not the sun).
    """
    # 16-bit and float frames read as the service decodes them, so the colour tests (the
    # white core, the clip level's white plateau) see 8-bit levels too
    image = _one_channel_if_grey(to_8bit(image))
    gray = to_gray(image)
    small, scale = _small(gray)
    if fov is None and auto_fov:
        fov = estimate_fov(gray, small, scale)
    h, w = gray.shape
    if fov is not None:
        gray = overlays_unlit(gray, fov)  # a time-stamp bar or box is no candidate
        # the image circle, cropped to its bounding box
        work = _disc_region(_Region(gray, 0, 0), int(round(fov.cx_px)), int(round(fov.cy_px)),
                            int(fov.radius_px))
        # the image circle on the thumbnail (cached by _disc_mask, keyed by the thumbnail's
        # size and the disc's integer centre and radius: a fixed camera's circle is the same
        # frame after frame)
        sh, sw = small.shape
        sm = _disc_mask(sh, sw, int(round((fov.cx_px - scale // 2) / scale)),
                        int(round((fov.cy_px - scale // 2) / scale)), int(fov.radius_px / scale))
        bg = _median_u8(small, sm) if cv2.countNonZero(sm) else _median_u8(small)
        diam = 2.0 * fov.radius_px
        centre = (fov.cx_px, fov.cy_px)
    else:
        work = _Region(gray, 0, 0)
        # the sky's level: the frame's median, or its border's when lower — in a small
        # region of interest around the sun (the control loop's) the glare fills the
        # middle and lifts the median, and the border is the sky farthest from the sun
        edge = np.concatenate([small[0], small[-1], small[1:-1, 0], small[1:-1, -1]])
        bg = min(_median_u8(small), _median_u8(edge.reshape(1, -1)))
        diam = float(min(h, w))
        centre = ((w - 1) / 2.0, (h - 1) / 2.0)
    ppd = px_per_deg_of(camera, fov, w)
    if expected_px is not None and not (np.isfinite(expected_px[0])
                                        and np.isfinite(expected_px[1])):
        expected_px = None
    # no model given: an equidistant 180° lens spanning the image circle
    fallback = None
    if camera is None and fov is not None:
        fallback = FisheyeCamera(fov.cx_px, fov.cy_px, lens_circle(fov).radius_px / 90.0)
    model = camera if camera is not None else fallback
    scale_known = model is not None  # a camera, or the image circle's equidistant guess
    got: _Pick | str = "no search"
    if expected_px is not None:
        got = _guided_search(gray, work, bg, fov, diam, centre, ppd, expected_px, image, model)
    # blind: ranked by appearance alone; the distance from the prediction is a feature of
    # the confidence, which cannot veto a plain disc (vision.confidence)
    blind = _search(gray, work, bg, fov, diam, centre, ppd, expected_px,
                    prefer_near=False, scale_known=scale_known, image=image, model=model)
    if isinstance(blind, _Pick) and expected_px is not None:  # found where it was predicted
        blind.p = conf.agreeing_probability(blind.x, blind.values["ephemeris_deg"])
    if not isinstance(got, _Pick):
        got = blind
    elif isinstance(blind, _Pick) and (blind.p > got.p if got.p < min_confidence
                                       else _outshines(blind, got, min_confidence)):
        got = blind
    if isinstance(got, str):
        return SunDetection(False, 0.0, None, "robust", fov=fov, reason=got)
    found = got.p >= min_confidence
    reason = None if found else conf.reason(got.x, got.values)
    cx = cy = radius = 0.0
    refused = not found
    # a refused glare's confidence is reported too: where its disc is hidden (positive
    # evidence, as for a found one) it is none (issue 24: no sun ≥ 0.3 where none is visible;
    # the independent renderer's hidden suns refused at 0.40-0.46 as "not radially symmetric")
    if found or got.p > 0.0:
        white = None
        r_eq = float(np.sqrt(got.best.area / np.pi))
        if r_eq > conf.LARGEST_DEG * ppd and scale_known:
            # wider than any sun's glare: the sky saturated around it (a long exposure)
            fit = censored_glare_centre(image, got.best.cx, got.best.cy, r_eq, fov)
            if fit is not None:
                white = (fit[0], fit[1], r_eq)
        if white is None:
            white = _white_core_centre(image, gray, got.best, ppd, fov, got.bg, got.peak)
            if white is not None and isinstance(model, FisheyeCamera):
                white = _across_from_glare(image, got.best, r_eq, fov, white, model)
        if white is not None:
            cx, cy, radius = white
        else:
            cx, cy, radius = _refine(gray, got.work, got.labels, got.best, got.peak, got.bg,
                                     got.thr, camera, fallback, fov,
                                     _UNCLIPPED_CENTROID_SHARE if got.unclipped else 0.8,
                                     partial(_sphere_of_glare, gray, got, fov, model))
        if not _inside(cx, cy, gray.shape, fov):
            # a fit carried beyond the frame or the image circle (an outline the frame cut):
            # the core's own centroid, the mean of pixels inside both
            cx, cy = got.best.cx, got.best.cy
        hidden = (_disc_behind_obstacle(gray, cx, cy, model, got, fov) if model is not None
                  else None)
        if hidden is not None:
            found, got.p = False, 0.0
            reason = (f"a glare cut by an obstacle, but the solar disc at its centre "
                      f"({hidden[0]:.0f}, {hidden[1]:.0f}) px is darker than the sky: the sun "
                      "is behind the obstacle, not visible")
    if refused:
        cx = cy = radius = 0.0
    dist = None
    if found and expected_px is not None:
        dist = float(np.hypot(cx - expected_px[0], cy - expected_px[1]))
    return SunDetection(
        sun_found=found,
        confidence=round(got.p, 4),
        centroid_px=(cx, cy) if found else None,
        method="robust",
        radius_px=radius,
        area_px=got.best.area,
        threshold=float(got.thr),
        n_candidates=got.n_candidates,
        ghosts_rejected=got.ghosts,
        fov=fov,
        reason=reason,
        distance_from_ephemeris_px=dist,
        features=dict(zip(conf.FEATURES, (float(v) for v in got.x), strict=True)),
        candidate_px=(float(got.best.cx), float(got.best.cy)),
    )


def _sphere_of_glare(gray: NDArray[np.uint8], pick: _Pick, fov: FovCircle | None,
                     model: CameraModel | None) -> CameraModel | None:
    """The sphere the winner's limb is fitted on: the projection its glare is most radially
    symmetric on (:func:`_glare_sphere`, chosen already when the coherence was measured),
    else ``model`` — the camera given or the image circle's guess — when the image cannot
    tell."""
    r_eq = float(np.sqrt(pick.best.area / np.pi))
    if r_eq < _SPHERE_MIN_PX:
        return model
    if pick.sphere is not None:
        return pick.sphere
    if isinstance(model, FisheyeCamera) and len(_telling_projections(pick.best, model)) > 1:
        return _glare_sphere(gray, pick.best, r_eq, pick.peak, fov, pick.bg, model)[1]
    return model


_DISC_BLUR_PX = 1.0  # the solar disc's reach beyond its radius: a pixel's blur and JPEG's


def _disc_behind_obstacle(gray: NDArray[np.uint8], cx: float, cy: float, model: CameraModel,
                          got: _Pick, fov: FovCircle | None = None
                          ) -> tuple[float, float] | None:
    """Where the solar disc centred at (``cx``, ``cy``) — the centre found for the glare of
    ``got`` — is hidden behind an obstacle (that centre, else None): no pixel within its radius
    (:data:`vision.sphere.SUN_RADIUS_DEG` at the camera's largest local scale, plus
    :data:`_DISC_BLUR_PX`) reaches the core's level (:func:`vision.candidates.region_threshold`)
    and their median is darker than the sky (``got.bg``). Issue 24 item 2's positive
    evidence against a round saturated core: the sun's disc is some 10⁵ times the sky's
    radiance, so wherever it shows it is clipped; a glare whose centre lies on a tree or a
    roof darker than the sky is the aureole of a sun behind it (a tester's sun behind trees
    at the horizon, reported at 0.96: the free arc of the glare above the tree line fits a
    circle centred behind it). A sun the horizon cuts keeps part of its disc above the
    line, clipped, and is kept. Where the model cannot tell the scale, nothing is refused.

    The disc is looked for at the centre found and, when an obstacle cuts the core, at the
    centre of the circle through its free arc (:func:`_free_arc`, when at least
    :data:`_ARC_EVIDENCE_SHARE` of the arc lies on it — half way up :func:`_cut_shape`'s
    roundness term; a ragged arc's circle is no evidence: the EUROCONTROL sun cut through
    its centre, share 0.47, has it 0.6° off, on the trees): the glare's isophote, centred on
    the sun. The centre found for a cut core follows the cut (the limb fit, the core
    completed by its mirror image): the EUROCONTROL low sun with trees 0.3-0.8° beyond its
    disc was reported at 0.98 centred on the tree line (share 0.68-0.70), a stereographic
    sun 3.4° under a skyline at 0.89 (share 1.0). A circle centred beyond the lens's image
    circle (:func:`vision.fov.lens_circle` of ``fov``: the lit disc, not the detector's circle
    shrunk 2 % off the rim, where a sun hidden 1° under a ridge near the horizon lies) is none:
    the unlit frame there is no obstacle (a poly-lens sun 2° high, its arc's circle centred 4°
    beyond the circle's edge). The circle moves with the projection it is fitted on, which a
    blind camera only guesses (the image circle read as equidistant): the arc is fitted on
    every candidate projection of the same image circle (:func:`_candidate_projections`) and
    is evidence when the disc is dark at one such centre inside the lens's circle and wholly
    clipped at none — a visible disc at any candidate's centre keeps the sun (issue 24: a
    tester's visible equisolid sun 9.9° over a ridge was judged hidden on the equidistant
    guess, a case the independent renderer did not reproduce; an equisolid sun 2.5–4° under
    a ridge, read as equidistant, has its arc's circle
    centred 6–9 px beyond the horizon at 1000 px, and on the equisolid candidate on the disc:
    ``tests/vision/test_ridge.py``)."""
    _, level = region_threshold(got.peak, got.bg)
    if _disc_dark(gray, cx, cy, model, level, got.bg):
        return cx, cy
    c = got.best
    full = (got.labels == c.labels[0]) if len(c.labels) == 1 else np.isin(got.labels, c.labels)
    outline = _free_outline(full, c, gray, got.bg)
    if outline is None:  # nothing cuts the core (most frames): no free arc on any projection
        return None
    pts, cut = outline
    lens = None if fov is None else lens_circle(fov)
    centres = []
    for m in _candidate_projections(model):
        x, y, _, share = _robust_limb_centre(pts[~cut], m)
        if share >= _ARC_EVIDENCE_SHARE and _inside(x, y, gray.shape, lens):
            centres.append((float(x), float(y), m))
    dark = [(x, y) for x, y, m in centres if _disc_dark(gray, x, y, m, level, got.bg)]
    if dark and not any(_disc_clipped(gray, x, y, m, level) for x, y, m in centres):
        return dark[0]
    return None


#: The projections a fisheye of unknown make may have (:data:`vision.cameras.PROJECTIONS`
#: but the orthographic, whose radius stops growing at the horizon — dr/dθ = f cos θ → 0 —
#: so that no low sun's glare keeps a round arc on it; the all-sky lenses of issue 24's
#: cameras are equidistant or equisolid, the independent renderer's also stereographic)
_FREE_ARC_PROJECTIONS = ("equidistant", "equisolid", "stereographic")


def _candidate_projections(model: CameraModel) -> list[CameraModel]:
    """``model`` and, for a plain fisheye (no radial terms, no tilt: a projection and a
    scale that may be the image circle's guess, ``backend.vision.checks.derive_fisheye_scale``),
    the same image circle — its horizon at the same radius — under each of
    :data:`_FREE_ARC_PROJECTIONS`. The circle through a glare's free arc moves with the
    projection it is fitted on: an equisolid lens's low glare read as equidistant is squashed
    along the radius (its scale there 4.2 against 5.2 px/° at a 465-px horizon), and the
    circle through its top arc is centred beyond the true one, toward the horizon."""
    if not isinstance(model, FisheyeCamera) or model.radial_coeffs or model.tilt_north_deg \
            or model.tilt_east_deg:
        return [model]
    horizon_px = model.horizon_radius_px
    others: list[CameraModel] = [
        replace(model, projection=p, px_per_deg=px_per_deg_for_horizon(horizon_px, p))
        for p in _FREE_ARC_PROJECTIONS if p != model.projection]
    return [model, *others]


def _disc_dark(gray: NDArray[np.uint8], cx: float, cy: float, model: CameraModel,
               level: float, bg: float) -> bool:
    """Whether no pixel of the solar disc centred at (``cx``, ``cy``) reaches ``level`` and
    their median is below the sky's ``bg`` (:func:`_disc_behind_obstacle`)."""
    # the pixel nearest the centre is 0.71 px from it at most, so inside the disc (whose
    # radius is the blur's 1 px at least): above the level there, the disc is not dark —
    # the answer for nearly every visible sun, without gathering the disc's pixels
    ix, iy = int(np.floor(cx + 0.5)), int(np.floor(cy + 0.5))
    if 0 <= iy < gray.shape[0] and 0 <= ix < gray.shape[1] and int(gray[iy, ix]) > level:
        return False
    disc = _disc_pixels(gray, cx, cy, model)
    return disc is not None and bool(int(disc.max()) <= level and float(np.median(disc)) < bg)


def _disc_clipped(gray: NDArray[np.uint8], cx: float, cy: float, model: CameraModel,
                  level: float) -> bool:
    """Whether every pixel of the solar disc centred at (``cx``, ``cy``) is above ``level``:
    a visible disc, some 10⁵ times the sky's radiance, clips wherever it shows
    (:func:`_disc_behind_obstacle`)."""
    disc = _disc_pixels(gray, cx, cy, model)
    return disc is not None and int(disc.min()) > level


def _disc_pixels(gray: NDArray[np.uint8], cx: float, cy: float, model: CameraModel
                 ) -> NDArray[np.uint8] | None:
    """The grey levels of the solar disc centred at (``cx``, ``cy``): within
    :data:`vision.sphere.SUN_RADIUS_DEG` at ``model``'s largest local scale there, plus
    :data:`_DISC_BLUR_PX`; None where it has no pixel on the frame or no scale."""
    major, _ = _local_px_per_deg(model, cx, cy)
    if not major > 0.0:
        return None
    r = SUN_RADIUS_DEG * major + _DISC_BLUR_PX
    h, w = gray.shape
    x0, x1 = max(int(np.floor(cx - r)), 0), min(int(np.ceil(cx + r)) + 1, w)
    y0, y1 = max(int(np.floor(cy - r)), 0), min(int(np.ceil(cy + r)) + 1, h)
    if x1 <= x0 or y1 <= y0:
        return None
    yy, xx = np.ogrid[y0:y1, x0:x1]
    disc = gray[y0:y1, x0:x1][(xx - cx) ** 2 + (yy - cy) ** 2 <= r * r]
    return disc if disc.size else None


def _inside(x: float, y: float, shape: tuple[int, ...], fov: FovCircle | None) -> bool:
    """Whether pixel (x, y) lies on the frame (−0.5 … size − 0.5, the bounds of
    :func:`vision.cameras.camera_from_params`) and inside the image circle ``fov`` when one
    is known. A visible sun's centre lies nowhere else; a centre beyond them is a fit
    carried past the outline it saw (a white bar along the top of a Wolf frame was
    reported as a sun 367 px above the frame, a tester's finding)."""
    h, w = shape[:2]
    on_frame = -0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5
    return on_frame and (fov is None or np.hypot(x - fov.cx_px, y - fov.cy_px) <= fov.radius_px)


def _one_channel_if_grey(image: NDArray[Any]) -> NDArray[Any]:
    """An 8-bit colour frame whose channels are equal (within :data:`_GREY_SPREAD` on a
    sample every :data:`_GREY_STRIDE` pixels) as its one grey channel, else ``image``.

    A monochrome camera's frame arrives as colour: ``cv2.IMREAD_COLOR`` (the service's
    decoding) repeats a grey PNG's or JPEG's one channel, and a colour JPEG of a grey frame
    codes its chroma flat (±1–2 after quantisation). The detector treats a one-channel
    frame as a monochrome sensor's (its white core is the grey level within 1 of the top,
    :func:`vision.candidates._white_core`); as colour, min(B, G, R) within 3 levels of the
    top took the blue glare's clipped grey levels too — the Wolf frames made monochrome
    and uploaded as a grey PNG lay up to 21.6 px (1.1 % of the width) from their labels,
    0.6–2.7 px as one channel (a tester's finding). A colour patch narrower than the stride
    can fall between the samples: such a frame is taken as grey (a reviewer's check: a
    7 px blue patch on a grey frame)."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or img.dtype != np.uint8 or img.size == 0:
        return image
    # every 4th sample first, a subset of the samples (the same answer): a colour frame
    # shows its colour there (a 640-px colour frame's test 60 → 23 µs)
    for stride in (4 * _GREY_STRIDE, _GREY_STRIDE):
        sample = img[::stride, ::stride, :3].astype(np.int16)
        if int(np.abs(sample[..., 0] - sample[..., 1]).max()) > _GREY_SPREAD \
                or int(np.abs(sample[..., 1] - sample[..., 2]).max()) > _GREY_SPREAD:
            return image
    return to_gray(img)


def _white_core_centre(image: NDArray[Any], gray: NDArray[np.uint8], c: _Candidate,
                       ppd: float, fov: FovCircle | None, bg: float, peak: float
                       ) -> tuple[float, float, float] | None:
    """The centre of a large glare: the centroid of its *white* core → (x, y, radius_px),
    or None (no white core, a core under :data:`_WHITE_MIN_DEG` or
    :data:`_WHITE_MIN_PX` in radius, a grey core less than :data:`_WHITE_BLUE_EXCESS` times
    the white one or reaching less than :data:`_WHITE_BLUE_MIN_PX` beyond it — no blue
    glare beyond it to leave out — or one the image circle or an obstacle cuts).

    The sun saturates every colour channel; the sky's glare around it is blue and
    saturates the blue channel (and so the grey level) much farther out, raggedly, with
    the lens's rays. The white core — pixels within 3 grey levels of the top of
    min(B, G, R) in the winning region's box, holes filled — is the part of the glare
    no colour of the sky reaches; opened (Serra 1982: erosion then dilation) by a disc of
    :data:`_WHITE_OPEN` × its largest inscribed radius, which takes off the rays and
    lobes narrower than that, its centroid (first moments; Hu 1962) is where a person
    puts the sun on a glare hundreds of pixels wide (the hand labels of Wettermast and
    Wolf: ``docs/validation-vision.md``, *The centre of a large glare*).
    A one-channel frame's white core is its grey level within 1 of the top (a colour
    sensor's luma keeps the channels' clipping: :func:`vision.candidates._white_core`;
    the Wolf frames made monochrome, worst 20.4 → 9.8 px from the labels); a sensor
    without a colour filter clips to one level, its grey core is no larger, and it keeps
    :func:`_refine`.
    The blue glare must be wider than what JPEG alone takes off a white core: colour is
    coded at half resolution in 16 px units (4:2:0) and quantised more coarsely than the
    grey level, so the colour outline of a white disc on a blue glare is eroded and moved
    (quality 60: by 2–3 px, its centroid up to 1.3 px, on a clean disc; with the lens's
    lateral colour fringe, by 3.1–3.4 px and 1.8 px along the radius on second-renderer
    development frames — enough to pass the area test on a core of 25 px, whose answer
    then lay 3.4–4.1 px, ~1°, inside the truth). The grey core's outline, at full
    resolution, is then the better one (0.23–0.24° on those frames).
    On the real frames that take this path (Wolf, at every format and exposure of
    ``docs/validation-vision.md``) the blue glare reaches 21–47 px beyond the white core at
    native size and 9.9 px at least (resampled to 880 px wide): none of them changes.
    A core that is visibly cut keeps :func:`_refine` (its arc fits): one that reaches the
    image circle's edge, or one with more than :data:`_WHITE_CUT_SHARE` of its outline
    next to pixels darker than the sky (``bg``: a glare fades into the sky, so darker
    means a mast, the horizon, an overlay); so does a small one (there the limb and the
    weighted centroid are sub-pixel)."""
    # the white core lies in the candidate's box grown by 2 px (vision.candidates._white_core):
    # a box too small for the least radius holds no such core (most suns at ≲ 5 px/°)
    h, w = gray.shape
    box_area = (min(w, c.x + c.w + 2) - max(0, c.x - 2)) \
        * (min(h, c.y + c.h + 2) - max(0, c.y - 2))
    if box_area < np.pi * max(_WHITE_MIN_DEG * ppd, _WHITE_MIN_PX) ** 2:
        return None
    core = _white_core(image, c, min(_SATURATED, peak - 1.0), one_channel=True)
    if core is None:
        return None
    big, x0, y0, binary = core
    x1, y1 = x0 + binary.shape[1], y0 + binary.shape[0]
    area = cv2.contourArea(big)
    r_eq = float(np.sqrt(area / np.pi))
    if r_eq < max(_WHITE_MIN_DEG * ppd, _WHITE_MIN_PX) or c.area < _WHITE_BLUE_EXCESS * area \
            or np.sqrt(c.area / np.pi) - r_eq < _WHITE_BLUE_MIN_PX:
        return None
    pts = big.reshape(-1, 2)
    if fov is not None and float(np.max(np.hypot(pts[:, 0] + x0 - fov.cx_px,
                                                 pts[:, 1] + y0 - fov.cy_px))) \
            > fov.radius_px - _FOV_EDGE_PX:
        return None
    # a glare fades into the sky: an outline next to something darker is cut by it
    if float(np.mean(_next_to_dark(gray, pts + (x0, y0), bg))) > _WHITE_CUT_SHARE:
        return None
    filled = np.zeros(binary.shape, np.uint8)
    cv2.drawContours(filled, [big], -1, 1, -1)
    # the opening: a disc of half the largest inscribed radius, on a mask shrunk so that
    # the disc is at most _WHITE_OPEN_MAX_PX in radius (its cost grows with its area)
    inscribed = float(cv2.distanceTransform(
        cv2.copyMakeBorder(filled, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0),
        cv2.DIST_L2, 3).max())
    k = _WHITE_OPEN * inscribed
    f = min(1.0, _WHITE_OPEN_MAX_PX / max(k, 1e-9))
    kr = max(1, int(round(k * f)))
    if f < 1.0:
        # opened on the shrunk mask, brought back to full size and cut to the core's own
        # outline (as vision.candidates._core does)
        fh, fw = y1 - y0, x1 - x0  # the crop: filled.shape
        small = np.asarray(cv2.resize(filled, None, fx=f, fy=f, interpolation=cv2.INTER_AREA),
                           np.uint8)
        opened = cv2.bitwise_and(cv2.resize(_open_disc(small, kr), (fw, fh),
                                            interpolation=cv2.INTER_NEAREST), filled)
    else:
        opened = _open_disc(filled, kr)
    m = cv2.moments(opened, True)
    if m["m00"] <= 0:
        m = cv2.moments(big)
    return x0 + m["m10"] / m["m00"], y0 + m["m01"] / m["m00"], r_eq


def _open_disc(mask: NDArray[np.uint8], radius: float) -> NDArray[np.uint8]:
    """The opening of a 0/1 mask by a Euclidean disc of ``radius`` pixels (Serra 1982), by
    two exact distance transforms (Felzenszwalb & Huttenlocher 2012, OpenCV's
    ``DIST_MASK_PRECISE``): the erosion keeps the pixels farther than ``radius`` from the
    background, the dilation brings back every pixel within ``radius`` of what is kept. Its
    cost does not grow with the disc, where ``cv2.morphologyEx`` with an elliptic kernel of
    49 px took 5 ms on a Wolf core and this 1.5 ms (the same centres within 0.3 px; by hand,
    ``docs/vision-calibration.md``, *The centre of a large glare*)."""
    pad = cv2.copyMakeBorder(mask, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    inner = cv2.distanceTransform(pad, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) > radius
    if not inner.any():
        return np.zeros_like(mask)
    back = cv2.distanceTransform((~inner).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.asarray(cv2.bitwise_and((back[1:-1, 1:-1] <= radius).view(np.uint8), mask),
                      np.uint8)


def _across_from_glare(image: NDArray[Any], c: _Candidate, r_eq: float, fov: FovCircle | None,
                       white: tuple[float, float, float], model: FisheyeCamera
                       ) -> tuple[float, float, float]:
    """The white core's centre ``white`` (x, y, radius) moved *across* the radius from the
    optical centre (``model``'s centre) to the centre of the symmetric glare around the
    core (:func:`vision.glare.symmetric_glare_centre`); its position *along* that radius
    stays the core's. ``model`` is the camera given (the ephemeris-guided search, a
    calibrated camera) or, blind, the equidistant guess about the image circle, whose centre
    is the field stop's edge fitted behind what cuts the bright disc at the rim
    (:func:`vision.fov.estimate_fov`; Wolf: 6–10 px from the labels' optical centre, where the
    bright region's enclosing circle was 37–111 px off: an 8 px error in the centre turns the
    radius through 8 / D rad, D the sun's distance from it — 400–700 px on Wolf — which
    moves a correction of a few pixels by a tenth of a pixel).

    A rotationally symmetric lens images a point source symmetrically about the meridional
    plane — the line from the optical centre through the image point (Born & Wolf,
    *Principles of Optics*, §5.1: the aberrations of such a system depend on the field
    position only through its distance from the axis) — and vignetting, the lens's radial
    fall-off, is symmetric about it too; so is a clear sky about the sun's vertical, which
    for a level camera is that line. Across the line the glare's centre is therefore
    unbiased (the second renderer, whose truth is known: 0.26 px RMS across) and, fitted to
    hundreds of blocks of glare, less noisy than the ragged outline of the core (Wolf,
    against SPA through an equidistant fit of all 23 frames: the detector's positions
    2.40 px RMS across the radius blind, 2.42 px guided, against the white core's 4.24 px).
    Along it the glare's centre is biased toward the optical centre — vignetting dims its
    outer side, and a sky brightening toward the horizon is no plane (the second renderer:
    −8.25 px along the radius at the mean, where the core is −2.68 px; Wolf: 7.7 px inside
    the hand labels, 0.66 px more for each degree the sun is lower) — and noisier than the
    core there (Wolf: 3.4 px RMS against the core's 2.9 px, by hand), so the core is kept.
    The renderer's and the RMS figures are ``benchmarks/bench_vision_calibration.py``'s
    centre study (``docs/vision-calibration.md``, *The centre of a large glare*).

    Nothing bounds the move across beyond the fit's own window (3 grey-core radii + 10 px):
    the correct moves and the wrong ones lie close. Natively Wolf 12:07 needs 10.6 px (0.97° on
    the blind model's 10.9 px/°: 15.3 → 6.0 px from its label); at gain 0.55, gain 0.7 with
    gamma 1.4 and gammas 0.7 and 0.5 Wolf 12:13 needs 13.2–13.4 px (1.21–1.26°: 17.6 → 5.9
    px), where brightened × 1.1 a fit on a window reaching the brighter sky near the
    horizon moves 12:51 16.2 px the wrong way (≈ 1.5°: 7.6 → 21.9 px); nor does a share of
    the white core's radius part them (0.17 native, 0.14 the wrong one). A bound at 1.1°
    (three times the white core's own scatter across, 0.36° RMS) mended × 1.1 (blind 8.99 →
    8.36 px to SPA) and cost those four exposures their worst frame (≈ 10 → 17.6 px): not
    taken (by hand)."""
    fit = symmetric_glare_centre(image, c.cx, c.cy, r_eq, fov, start=(white[0], white[1]))
    if fit is None:
        return white
    ox, oy = model.cx_px, model.cy_px
    ux, uy = white[0] - ox, white[1] - oy
    norm = float(np.hypot(ux, uy))
    if norm < 1e-6:  # at the optical centre every direction is a radius: the core's centre
        return white
    tx, ty = -uy / norm, ux / norm
    across = (fit[0] - white[0]) * tx + (fit[1] - white[1]) * ty
    return white[0] + across * tx, white[1] + across * ty, white[2]


def _next_to_dark(gray: NDArray[np.uint8], pts: NDArray[Any], bg: float,
                  reach_px: float = _WHITE_CUT_STEP_PX, fov: FovCircle | None = None
                  ) -> NDArray[np.bool_]:
    """Which outline points ``[N, 2]`` (frame pixels) of a core have, within ``reach_px``
    farther out from the outline's mean (every :data:`_WHITE_CUT_STEP_PX`), a pixel darker
    than the sky's level ``bg``: a glare fades into the sky, so darker there means the core
    is cut — by a mast, trees, the horizon, an overlay. With ``fov``, pixels beyond the
    image circle (within :data:`_FOV_EDGE_PX` of its edge) do not count: its edge is a cut
    of its own (:func:`_true_limb`)."""
    h, w = gray.shape
    p = np.asarray(pts, dtype=float)
    out = p - p.mean(axis=0)
    out /= np.maximum(np.hypot(out[:, 0], out[:, 1]), 1e-9)[:, None]
    dark = np.zeros(len(p), bool)
    for step in np.arange(_WHITE_CUT_STEP_PX, reach_px + 1e-9, _WHITE_CUT_STEP_PX):
        ox = np.clip(np.rint(p[:, 0] + step * out[:, 0]), 0, w - 1).astype(np.intp)
        oy = np.clip(np.rint(p[:, 1] + step * out[:, 1]), 0, h - 1).astype(np.intp)
        below = gray[oy, ox] < bg
        if fov is not None:
            below &= np.hypot(ox - fov.cx_px, oy - fov.cy_px) < fov.radius_px - _FOV_EDGE_PX
        dark |= below
    return dark


def _cut_by_obstacle(gray: NDArray[np.uint8], pts: NDArray[Any], bg: float, r_eq: float,
                     fov: FovCircle | None = None) -> NDArray[np.bool_]:
    """The outline points ``[N, 2]`` of a core ``r_eq`` px in radius that an obstacle cuts:
    those next to something darker than the sky (:func:`_next_to_dark`, within a quarter of
    the radius — a saturated core fades over a few pixels of glare before the obstacle's
    edge) when they are at least :data:`_CUT_SHARE` of the outline; else none. The free arc
    (the rest) is what :func:`_cut_shape` judges and :func:`_true_limb` fits. With ``fov``
    (the limb fits) the unlit frame beyond the image circle is no obstacle — its edge is
    left out of the fit by its own rule; without it (the shape score) a core the image
    circle cuts is judged on its free arc too."""
    reach = max(_WHITE_CUT_STEP_PX, 0.25 * r_eq)
    # nothing darker than the sky within reach of the outline: none cut (most cores; cheap)
    h, w = gray.shape
    x0, y0 = (max(int(v - reach) - 1, 0) for v in pts.min(axis=0))
    x1, y1 = int(pts[:, 0].max() + reach) + 2, int(pts[:, 1].max() + reach) + 2
    box = gray[y0:min(y1, h), x0:min(x1, w)]
    if not box.size or float(box.min()) >= bg:
        return np.zeros(len(pts), bool)
    cut = _next_to_dark(gray, pts, bg, reach, fov)
    if float(np.mean(cut)) < _CUT_SHARE:
        cut[:] = False
    return cut


def _cut_outline(c: _Candidate, labels: NDArray[Any], gray: NDArray[np.uint8], bg: float,
                 fov: FovCircle | None) -> bool:
    """Whether an obstacle cuts the core of ``c`` (:func:`_cut_by_obstacle` on its outline;
    the unlit frame beyond the image circle ``fov`` is none)."""
    contours, _ = cv2.findContours(c.mask(labels), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return False
    pts = np.vstack(contours).reshape(-1, 2).astype(float) + (c.x, c.y)
    return bool(_cut_by_obstacle(gray, pts, bg, float(np.sqrt(c.area / np.pi)), fov).any())


def _cut_shape(c: _Candidate, labels: NDArray[Any], gray: NDArray[np.uint8], bg: float,
               model: CameraModel | None = None) -> float:
    """The shape term 0–1 of a core cut by an obstacle (issue 24 item 2: round *allowing
    for the horizon cutting it*): when at least :data:`_CUT_SHARE` of its outline lies next
    to something darker than the sky (:func:`_cut_by_obstacle`), the share of the rest of the
    outline on one circle — on the sphere of ``model`` when given, where a fisheye's oval of
    a low sun is a circle (RANSAC, Fischler & Bolles 1981;
    :func:`vision.limb._robust_limb_centre`) — on the scale of the circularity term
    (:func:`vision.candidates._prior`); or, when higher, the circularity term itself of the
    core completed by its mirror image across the cut (:func:`_mirrored_shape`) — as strict
    as the test of an uncut core, which a real glare's ragged outline passes by its moments
    and not by a circle within a pixel or two (the EUROCONTROL low sun: 0.61 of its whole
    outline on one circle, moments 1.0); else 0. A sun low behind trees keeps a round arc
    above them; a cloud highlight cut by a tree top does not."""
    # the whole cluster's outline (not the core it was narrowed to: vision.candidates._prior)
    full = (labels == c.labels[0]) if len(c.labels) == 1 else np.isin(labels, c.labels)
    got = _free_arc(full, c, gray, bg, model)
    if got is None:
        return 0.0
    pts, cut, (x, y, share) = got
    arc = 0.0
    if _inside(x, y, gray.shape, None):  # else a circle centred off the frame: no centre
        arc = float(min(max((share - _ARC_SHARE_FLOOR) / 0.4, 0.0), 1.0))
    if arc >= 1.0 or int(np.count_nonzero(cut)) < 2:
        return arc
    return max(arc, _mirrored_shape(full.astype(np.uint8), c.ox, c.oy, pts[cut]))


def _free_arc(full: NDArray[np.bool_], c: _Candidate, gray: NDArray[np.uint8], bg: float,
              model: CameraModel | None
              ) -> tuple[NDArray[np.float64], NDArray[np.bool_], tuple[float, float, float]] | None:
    """The outline of the cluster ``full`` (the candidate ``c``'s pixels), which of its
    points an obstacle or the frame cuts, and the circle through most of the rest — the free
    arc (:func:`vision.limb._robust_limb_centre` on the sphere of ``model``): its centre
    ``(x, y)`` [px] and the share of the free arc on it; None when nothing is cut or too
    little is left."""
    outline = _free_outline(full, c, gray, bg)
    if outline is None:
        return None
    pts, cut = outline
    x, y, _, share = _robust_limb_centre(pts[~cut], model)
    return pts, cut, (float(x), float(y), float(share))


def _free_outline(full: NDArray[np.bool_], c: _Candidate, gray: NDArray[np.uint8], bg: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.bool_]] | None:
    """The outline ``[N, 2]`` of the cluster ``full`` (the candidate ``c``'s pixels) and which
    of its points an obstacle or the frame cuts (:func:`_cut_by_obstacle`,
    :func:`_on_frame_edge`); None when the outline has under 24 points, nothing is cut or
    fewer than 12 points are free. It does not depend on the projection: :func:`_free_arc`
    fits its free arc on one, :func:`_disc_behind_obstacle` on each candidate."""
    contours, _ = cv2.findContours(full.astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_NONE)
    if not contours:
        return None
    pts = np.vstack(contours).reshape(-1, 2).astype(float) + (c.ox, c.oy)
    if len(pts) < 24:
        return None
    cut = _cut_by_obstacle(gray, pts, bg, float(np.sqrt(c.area / np.pi)))
    cut |= _on_frame_edge(pts, gray.shape)
    if not cut.any() or int(np.count_nonzero(~cut)) < 12:
        return None
    return pts, cut


def _mirrored_shape(mask: NDArray[np.uint8], ox: int, oy: int, cut_pts: NDArray[np.float64]
                    ) -> float:
    """The circularity term (:func:`vision.candidates._shape`, on the scale of
    :func:`vision.candidates._prior`) of a cut core ``mask`` (its label image's pixels, the
    image starting at ``(ox, oy)`` in the frame) joined with its mirror image across the
    straight line fitted to its cut outline points ``cut_pts`` [N, 2]: symmetry completion of
    an occluded shape (Zabrodsky, Peleg & Avnir, CVPR 1993). A disc cut through its centre
    completes to the disc, one cut short of its centre to a disc a little longer across the
    cut. The largest piece is judged (a cluster's ghost or speck is left out); when it
    holds under 80 % of the union (the mirror image apart from the core: a cut line beside
    it), or is less solid than :data:`_MIRROR_SOLIDITY` (lobes), the term is 0."""
    vx, vy, x0, y0 = (float(v) for v in cv2.fitLine(cut_pts.astype(np.float32), cv2.DIST_L2,
                                                     0, 0.01, 0.01).ravel())
    ys, xs = np.nonzero(mask)
    if xs.size < 5:
        return 0.0
    pad = int(max(np.ptp(xs), np.ptp(ys))) + 2
    bx, by = int(xs.min()) - pad, int(ys.min()) - pad  # a box that holds the mirror image
    w, h = int(np.ptp(xs)) + 2 * pad + 1, int(np.ptp(ys)) + 2 * pad + 1
    box = np.zeros((h, w), np.uint8)
    box[ys - by, xs - bx] = 1
    # the reflection across the line through (x0, y0) along (vx, vy), in the box's pixels
    refl = np.array([[2 * vx * vx - 1, 2 * vx * vy], [2 * vx * vy, 2 * vy * vy - 1]])
    p0 = np.array([x0 - ox - bx, y0 - oy - by])
    warp = np.hstack([refl, (p0 - refl @ p0)[:, None]])
    both = cv2.bitwise_or(box, cv2.warpAffine(box, warp, (w, h), flags=cv2.INTER_NEAREST))
    _, lab, stats, cents = cv2.connectedComponentsWithStats(both, connectivity=8)
    i = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    x, y, bw, bh, area = (int(v) for v in stats[i])
    if area < 0.8 * int(np.count_nonzero(both)):
        return 0.0  # the core and its mirror image apart: the cut line lies beside the core
    # a mirror image is symmetric by construction, so its moments are blind to lobes (a
    # cloud patch's); its solidity is not (area / its convex hull's)
    hull = cv2.convexHull(np.argwhere(lab == i)[:, ::-1].astype(np.int32))
    if area < _MIRROR_SOLIDITY * cv2.contourArea(hull):
        return 0.0
    whole = _Candidate([i], area, x, y, bw, bh, float(cents[i][0]), float(cents[i][1]))
    return float(min(max((_shape(whole, lab) - 0.45) / 0.4, 0.0), 1.0))


def _limb_points(c: _Candidate, labels: NDArray[Any]) -> NDArray[np.float64]:
    """The outline of the candidate's core in frame pixels ``[N, 2]``."""
    contours, _ = cv2.findContours(c.mask(labels), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    pts = (contours[0] if len(contours) == 1 else np.vstack(contours)).reshape(-1, 2).astype(float)
    pts[:, 0] += c.x
    pts[:, 1] += c.y
    return pts


def _box_on_frame_edge(x0: float, y0: float, x1: float, y1: float, h: int, w: int) -> bool:
    """Whether either corner of the box from ``(x0, y0)`` to ``(x1, y1)`` (x0 ≤ x1, y0 ≤ y1)
    lies on the frame's edge (:func:`_on_frame_edge` of the two corners, without arrays)."""
    e = _FOV_EDGE_PX
    return x0 < e or y0 < e or x1 > w - 1 - e or y1 > h - 1 - e


def _on_frame_edge(pts: NDArray[np.float64], shape: tuple[int, ...]) -> NDArray[np.bool_]:
    """Which outline points ``[N, 2]`` lie within :data:`_FOV_EDGE_PX` of the frame's border:
    where the frame cuts a region. The frame's edge is never the sun's limb, as the image
    circle's is not (:func:`_true_limb`): a bright region running along it goes on beyond
    it, and a circle through that straight edge puts the centre wherever the straight line
    lets it (a tester's white bar across the top of a Wolf frame: a limb fit through the
    frame's top row put the sun 367 px above the frame, at confidence 0.999)."""
    h, w = shape[:2]
    x, y = pts[:, 0], pts[:, 1]
    return ((x < _FOV_EDGE_PX) | (y < _FOV_EDGE_PX) | (x > w - 1 - _FOV_EDGE_PX)
            | (y > h - 1 - _FOV_EDGE_PX))


def _true_limb(gray: NDArray[np.uint8], work: _Region, pts: NDArray[np.float64],
               cx: float, cy: float, thr: float, fov: FovCircle | None = None,
               bg: float | None = None, r_eq: float = 0.0
               ) -> tuple[NDArray[np.float64], float]:
    """The outline points that are the sun's limb → (points, share of the outline on the
    image circle's or the frame's edge). Left out: points where a mask cut the core — the
    search window around the prediction: the pixel 1.5 px farther out from (cx, cy) is masked in
    ``work`` while the frame is still bright; the image circle ``fov``: any point within
    :data:`_FOV_EDGE_PX` of its edge, bright beyond it or not (the edge of the image is
    never the sun's limb; the step outward misses it where the outline runs nearly
    radially from (cx, cy), and the lens's own fall-off can leave the frame just beyond
    the mask below the threshold); the frame's own edge likewise (:func:`_on_frame_edge`);
    with the sky's level ``bg``, the points an obstacle
    cuts (trees, a mast, the ground inside the image circle: :func:`_cut_by_obstacle` of a
    core ``r_eq`` px in radius) — their outline is the obstacle's edge, which a circle
    through most of the outline can follow (second renderer, development scene 122: a
    low sun's 9° core cut by trees, 0.88° → 0.27°)."""
    h, w = gray.shape
    f = 1.5 / np.maximum(np.hypot(pts[:, 0] - cx, pts[:, 1] - cy), 1e-9)
    # np.clip's bounds, by minimum / maximum (the same values, less overhead)
    ox = np.minimum(np.maximum(np.rint(pts[:, 0] + (pts[:, 0] - cx) * f), 0), w - 1).astype(np.intp)
    oy = np.minimum(np.maximum(np.rint(pts[:, 1] + (pts[:, 1] - cy) * f), 0), h - 1).astype(np.intp)
    keep = (work.value_at(ox, oy) > 0) | (gray[oy, ox] < thr)
    on_edge = _on_frame_edge(pts, gray.shape)
    if fov is not None:
        on_edge |= np.hypot(pts[:, 0] - fov.cx_px, pts[:, 1] - fov.cy_px) \
            > fov.radius_px - _FOV_EDGE_PX
    edge_share = float(np.count_nonzero(on_edge)) / max(len(pts), 1)
    keep &= ~on_edge
    if bg is not None and len(pts):
        keep &= ~_cut_by_obstacle(gray, pts, bg, r_eq, fov)
    return pts[keep], edge_share


def _refine(gray: NDArray[np.uint8], work: _Region, labels: NDArray[Any],
            c: _Candidate, peak: float, bg: float, thr: float, camera: CameraModel | None,
            fallback: CameraModel | None = None, fov: FovCircle | None = None,
            share: float = 0.8, sphere: Callable[[], CameraModel | None] | None = None
            ) -> tuple[float, float, float]:
    """Sub-pixel centre of the winning cluster → (x, y, radius_px).

    ``sphere``: the model a limb fit runs on instead of ``camera`` (or ``fallback``), asked
    for only when a fit needs one (:func:`_sphere_of_glare`: the projection the glare tells).

    A core with a glare around it, given a fisheye model (or ``fallback``, an
    approximate lens model): the small circle on the camera's sphere through
    most of the core's limb that leaves none of it inside
    (:func:`vision.limb.contained_limb_centre`; outline points where a mask —
    the search window, the image circle — or an obstacle cut the core are left out,
    :func:`_true_limb`) — robust
    to thin cloud that grows the core on one side and to the fisheye's skew of a
    wide glare — when
    at least :data:`_CONTAINED_MIN_INLIERS` of the limb lies on it, or whatever its share
    when the image circle ``fov`` cuts the core (≥ :data:`_CUT_SHARE` of the outline on
    its edge: a low sun's wide glare, which cloud and the brighter sky near the horizon
    stretch along the edge — a plain circle through the rest of the outline follows that
    stretch; refitted with :data:`_CUT_TRIALS` triples, the clear arc being short; on the
    development split 5.55° → 1.41° on such a frame, the only one). Otherwise
    (no glare: a plain disc, whose sharp edge centres it exactly; no fisheye
    model — the tracker's narrow lens, where the 8-bit outline is noisier than
    the centroid and a 1° glare has no skew; too little of the limb on one
    circle) as before: a complete blob —
    point-symmetric about its centroid (:func:`_symmetry` ≥ 0.9): a disc, an
    oval, a disc with blooming or flare spikes on both sides — gets the
    intensity-weighted centroid of a disc window above ``share`` (80 %) of the way from the
    local background to the peak (an unclipped disc's: :data:`_UNCLIPPED_CENTROID_SHARE`).
    A blob cut by the horizon, a mast or an overlay, or merged with a cloud on one side,
    gets the limb fit (:func:`_robust_limb_centre`): on the sphere of ``camera`` when one is
    given, else in the image — or on the sphere of ``fallback`` when that puts
    more of the limb on one circle.
    """
    r_eq = float(np.sqrt(c.area / np.pi))
    model = camera if camera is not None else fallback
    chosen = cache(sphere) if sphere is not None else None  # asked once, when a fit needs it

    def fitted_on(default: CameraModel | None) -> CameraModel | None:
        return default if chosen is None else chosen()

    # a glare (the ring just outside the core still well above the far sky): a limb fit
    if isinstance(model, FisheyeCamera) and c.area >= _SMALL_AREA_PX \
            and _lit_around(gray, c, peak):
        pts, edge_share = _true_limb(gray, work, _limb_points(c, labels), c.cx, c.cy,
                                     thr, fov, bg, r_eq)
        rad = np.hypot(pts[:, 0] - c.cx, pts[:, 1] - c.cy) if len(pts) else np.zeros(1)
        # not already a circle about its centroid (a clear-sky core near the zenith:
        # the centroid below is exact and cheaper)
        if float(rad.max() - rad.min()) > _ROUND_SPREAD_PX + 0.05 * r_eq:
            model = fitted_on(model) or model
            got = contained_limb_centre(pts, model)
            if got is not None and got[2] >= _CONTAINED_MIN_INLIERS:
                return got[0], got[1], r_eq
            if edge_share >= _CUT_SHARE:
                # cut by the image circle (a low sun's wide glare): the arcs left are
                # the clear one and those cloud and the brighter sky near the horizon
                # have pushed outward; a plain circle through most of the outline
                # follows the bulge along the edge, so the contained circle is kept
                # whatever its share (more triples: the clear arc is short)
                got = contained_limb_centre(pts, model, n_trials=_CUT_TRIALS)
                if got is not None:
                    return got[0], got[1], r_eq
    pad = max(3.0, 0.5 * r_eq + 2.0)
    ring = _ring_values(gray, c.cx, c.cy, r_eq + pad + 1.0, None)
    local_bg = _median(ring) if ring.size else bg
    level = local_bg + share * (peak - local_bg)
    got_c = _weighted_centroid(gray, c.cx, c.cy, r_eq + pad, level)
    wx, wy = got_c if got_c is not None else (c.cx, c.cy)
    if c.area < _SMALL_AREA_PX:
        return float(wx), float(wy), r_eq
    if _symmetry(c.mask(labels)) >= 0.9:
        return float(wx), float(wy), r_eq
    pts = _limb_points(c, labels)
    pts = pts[~_on_frame_edge(pts, gray.shape)]
    if len(pts) < 8:
        return float(wx), float(wy), r_eq
    if camera is not None:
        cx, cy, r, _ = _robust_limb_centre(pts, fitted_on(camera))
        return cx, cy, r
    ix, iy, ir, inliers = _robust_limb_centre(pts, None)
    if fallback is not None and inliers < 0.6:
        sx, sy, sr, s_in = _robust_limb_centre(pts, fitted_on(fallback))
        if s_in > inliers:
            return sx, sy, sr
    return ix, iy, ir


_DISPATCH: dict[str, Callable[..., SunDetection]] = {
    "robust": detect_robust,
    "seed000_hsv": detect_seed000,
    "seed003_gray240": detect_seed003,
}


def detect_sun(image: NDArray[Any], method: str = "robust", camera: CameraModel | None = None,
               **kwargs: Any) -> SunDetection:
    """Run one of :data:`METHODS` on a BGR (or grey) frame (``camera`` and
    ``expected_px`` go to ``robust`` only)."""
    if method not in _DISPATCH:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    image = to_8bit(image)  # every method reads a 16-bit or float frame as 8-bit levels
    if method == "robust":
        return detect_robust(image, camera=camera, **kwargs)
    kwargs.pop("expected_px", None)
    return _DISPATCH[method](image, **kwargs)
