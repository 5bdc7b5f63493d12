"""The detector's confidence: a logistic model of "this candidate is the sun".

Features of the winning candidate (:func:`features`) are combined by a
logistic regression whose coefficients were fitted on the DEVELOPMENT split
only (``benchmarks/bench_vision.py --fit-confidence``: synthetic frames of
both renderers with development seeds, the development real frames, and frames
whose ephemeris is wrong — :func:`vision.evalset.wrong_ephemeris_scenes`,
:func:`vision.evalset.wrong_ephemeris_discs`, the development real frames with
the clock three hours off; Newton–Raphson with an L2 penalty whose strength is
chosen by 5-fold cross-validation grouped by frame, lowest held-out log loss —
a calibrated probability is what a proper scoring rule rewards, Gneiting &
Raftery 2007, JASA 102:359) and are stored in ``confidence.json`` beside this
module. The reliability tables (confidence bins → fraction correct,
development and held-out) are in ``docs/validation-vision.md``. A candidate
counts as correct when the sun is visible and the winning region's centroid
lies within max(3 px, 1°, the region's own radius) of the truth.

The distance from the ephemeris prediction is a *feature*, never a veto: it
enters as ``ephemeris_far_unclear`` = (distance, capped at 30°, / 10°) ×
(1 − :func:`plain_disc`), so it can lower the probability of an ambiguous
candidate (a cloud highlight, a fragment of glare) but not of a plainly
visible, round, saturated disc with its glare — there a far prediction means
the place, the time or the camera is wrong, and the answer says how far
(``SunDetection.distance_from_ephemeris_px``; the service warns when no
camera error can explain it).

Every "no sun" answer gets a reason a person can read (:func:`reason`): the
feature that pulled the probability down the most.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vision.sphere import SUN_RADIUS_DEG

FEATURES: tuple[str, ...] = (
    "shape",             # circularity of the bright core 0–1 (second moments): round
    "glare",             # glare evidence 0–1: fall-off, a sharp drop to the sky, or a core
                         # degrees wide whose glare lights the sky at 4 R and that fills
                         # its star-shaped hull (vision.candidates._score, _tail, _solid):
                         # such a core is its own glare
    "saturated",         # 1 when the core is clipped (≥ 250, or a flat top at any level)
    "contrast",          # 1 − sky median / peak: brighter than its surroundings, any gain
    "too_small",         # max(0, ln(0.5° / equivalent radius)): smaller than a sun's core
    "too_large",         # max(0, ln(equivalent radius / 15°)): wider than any sun's glare
    "runner_up",         # heuristic score of the runner-up / the winner's: ambiguous
    "coherence",         # radial-symmetry coherence of the glare's gradients 0–1, or the
                         # core's width alone when it is degrees wide (no gradient inside)
    "ephemeris_known",   # 1 when a prediction from time, place and camera was given
    "ephemeris_far_unclear",  # min(distance from the prediction [°], 30) / 10 × (1 − plain
                              # disc), 0 when unknown: never counts against a plain disc
)
"""What the logistic model sees (issue 24 item 2): the sun is a region at or near
saturation, round (allowing for the projection: the region's aspect is taken along the
radius from the image circle's centre up to the most a fisheye squashes a disc there —
an orthographic lens's cos θ — for a free core with the sun's glare,
:func:`vision.candidates._shape`), brighter than the sky, of a size a sun with its glare
can have at this px/°.
A saturated core degrees wide counts as glare and as radially symmetric by its width alone
(``glare``, ``coherence``): on the Wolf frames a round saturated core on a bright clear
sky has no ring-shaped fall-off, and the model before issue 24 (fitted without a Wolf
frame) found 9 of the 23 suns, refusing the rest as "no glare falling off" or "not
radially symmetric". The glare's ring-shaped fall-off and the coherence remain evidence *for*
a sun, no longer needed by a wide round core."""

_SMALLEST_DEG = 0.5  # equivalent radius of the smallest saturated sun core [°]
ROUND = 0.8  # circularity from which a region is said to be a disc in a reason
LARGEST_DEG = 15.0  # … of the widest saturated glare (the M12 fisheye of issue 24: ≈ 14°)


def load_model(path: Path | None = None) -> tuple[NDArray[np.float64], float]:
    """``(weights over FEATURES, intercept)`` from ``path``, by default the package data
    ``vision/confidence.json`` (read through importlib.resources, so an installed wheel has it)."""
    source = resources.files("vision") / "confidence.json" if path is None else path
    d = json.loads(source.read_text(encoding="utf-8"))
    if tuple(d["features"]) != FEATURES:
        raise ValueError(f"{source.name} was fitted on other features: {d['features']}")
    return np.asarray(d["weights"], dtype=float), float(d["intercept"])


_MODEL: tuple[NDArray[np.float64], float] | None = None


def _model() -> tuple[NDArray[np.float64], float]:
    global _MODEL  # noqa: PLW0603 - a read-only cache of the module's own data file
    if _MODEL is None:
        _MODEL = load_model()
    return _MODEL


def plain_disc(shape: float, glare: float, saturated: float) -> float:
    """How plainly a candidate is a visible sun, 0–1: round (``shape``) × glare evidence
    (``glare``) × saturated (0 or 1)."""
    return float(min(max(shape, 0.0), 1.0) * min(max(glare, 0.0), 1.0) * saturated)


def features(shape: float, glare: float, saturated: float, peak: float, bg: float,
             radius_deg: float | None, runner_up: float, coherence: float,
             ephemeris_deg: float | None) -> NDArray[np.float64]:
    """The feature vector (order of :data:`FEATURES`) of one candidate.

    ``glare`` 0–1 (:func:`vision.candidates._score`); ``saturated`` 0 or 1 (the core
    clipped); ``peak``, ``bg`` grey levels; ``radius_deg`` the core's equivalent radius on
    the sky [°], None when the frame's scale is unknown (a crop without a camera: no size
    evidence either way); ``ephemeris_deg`` its distance from the
    predicted sun [°] or None. The distance is gated by ``1 −`` :func:`plain_disc`: it is
    zero for a round, saturated core with its glare, whatever the distance.
    """
    known = ephemeris_deg is not None
    far = 0.0
    if ephemeris_deg is not None:
        far = min(float(ephemeris_deg), 30.0) / 10.0 * (1.0 - plain_disc(shape, glare,
                                                                         saturated))
    small = large = 0.0
    if radius_deg is not None:
        r = max(radius_deg, 1e-3)
        small = max(0.0, float(np.log(_SMALLEST_DEG / r)))
        large = max(0.0, float(np.log(r / LARGEST_DEG)))
    return np.array([
        shape, glare, saturated, max(peak - bg, 0.0) / max(peak, 1.0), small, large,
        runner_up, coherence, float(known), far], dtype=float)


_GATE_SAT = True
_MIN_SHAPE = 0.2  # below: a shape no sun has, cut by the horizon or not
SMALL_CORE_GLARE = 0.7
"""The glare evidence (``glare``) a core smaller than a sun's (``too_small`` > 0) needs. The
solar disc is 0.53° across; a core that small or smaller is a sun only by its aureole, the
glare falling off radially over degrees around it (a tone-mapped HDR sun: a core near a pixel
wide in a strong aureole; the synthetic development suns with such a core have ``glare``
0.90–1.0). A saturated highlight on a cloud, 0.3–0.45° in radius in a frame resized to
another width, sits in the bright cloud, not in a fall-off of its own (FE3, UCEEB 06:10:
``glare`` 0.23–0.54), and the model's weight on ``too_small`` — positive, fitted on those
HDR suns — rated it up to 0.86."""


def smaller_than_the_disc(area_px: float, px_per_deg: float,
                          px_per_deg_minor: float | None = None) -> bool:
    """Whether a bright core of ``area_px`` pixels is smaller than the solar disc at
    ``px_per_deg`` (and ``px_per_deg_minor`` across it, where a fisheye draws the disc as
    an ellipse: :func:`vision.detect._local_px_per_deg`): a size no sun has (issue 24 item
    2, positive evidence against it).

    The disc (:data:`vision.sphere.SUN_RADIUS_DEG` in radius, ρ px) is some 10⁵ times the
    clear sky's radiance (a direct normal irradiance of 1000 W m⁻² over its 6.8 × 10⁻⁵ sr
    against a sky of 30–100 W m⁻² sr⁻¹), and its limb still 0.4 times its centre (limb
    darkening): on a frame exposed for the sky every pixel wholly inside the disc — its
    centre within ρ − √2/2 of the disc's edge — is at the frame's top, clipped by a sensor
    or mapped there by a tone-mapping HDR camera, and glare and blur only add to it. So the
    sun's brightest region holds at least π (ρ₁ − √2/2)(ρ₂ − √2/2) pixels; a smaller one is
    a glint (a sunlit roof, a speck of the glare of a hidden sun, sky through leaves). Where
    the disc spans under a pixel and a half across (ρ₂ ≤ √2/2: 2.7 px/°) nothing is
    refused. The region may be cut by the image circle or an obstacle, which a sun only a
    sliver of which shows is too: such a sun is not reported."""
    minor = px_per_deg if px_per_deg_minor is None else px_per_deg_minor
    r1 = SUN_RADIUS_DEG * px_per_deg - np.sqrt(0.5)
    r2 = SUN_RADIUS_DEG * minor - np.sqrt(0.5)
    return bool(r1 > 0.0 and r2 > 0.0 and area_px < np.pi * r1 * r2)


def _small_without_glare(x: NDArray[np.float64]) -> bool:
    """A core smaller than a sun's (``too_small`` > 0) without the sun's glare
    (:data:`SMALL_CORE_GLARE`)."""
    return bool(x[4] > 0.0 and x[1] < SMALL_CORE_GLARE)


def admissible(x: NDArray[np.float64]) -> bool:
    """Whether a candidate can be the sun at all: its core clipped (the sun saturates any
    camera exposed for the sky: it is some 10⁵ times brighter) and not of a shape no sun
    has (``shape`` ≥ :data:`_MIN_SHAPE`; a half disc cut by the horizon scores ≈ 0.75).
    The positive evidence against a candidate of issue 24 item 2, applied before the
    model: a candidate that fails it gets probability 0 and is never fitted on. A core
    smaller than a sun's (``too_small`` > 0, known scale only) must carry the sun's glare
    (``glare`` ≥ :data:`SMALL_CORE_GLARE`): it has nothing else to show it is the sun."""
    if _small_without_glare(x):
        return False
    return bool((x[2] >= 0.5 or not _GATE_SAT) and x[0] >= _MIN_SHAPE)


def probability(x: NDArray[np.float64], model: tuple[NDArray[np.float64], float] | None = None
                ) -> float:
    """P(candidate is the sun) = σ(w·x + b) for an :func:`admissible` candidate, else 0."""
    if not admissible(x):
        return 0.0
    w, b = model if model is not None else _model()
    return float(1.0 / (1.0 + np.exp(-(float(w @ x) + b))))


AGREES_DEG = 1.0
"""A candidate this close to where the ephemeris puts the sun [°] agrees with it: the
tolerance within which a calibration counts a frame's sun as its model's
(:data:`vision.calibrate.OUTLIER_DEG`)."""

_EPHEMERIS = [FEATURES.index("ephemeris_known"), FEATURES.index("ephemeris_far_unclear")]


def agreeing_probability(x: NDArray[np.float64], ephemeris_deg: float | None,
                         model: tuple[NDArray[np.float64], float] | None = None) -> float:
    """:func:`probability` of a candidate found by its appearance alone (the blind search's
    winner), never below what it is without an ephemeris when it lies within
    :data:`AGREES_DEG` of the predicted sun. The model learned a small penalty for a known
    ephemeris (``ephemeris_known`` −0.36: a search near a prediction picks *something*, a
    prior against the pick), which lowered a clear sun found blind at 0.62–0.73 to
    0.39–0.48 and refused it once its camera was given — exactly where the ephemeris put it
    (a tester's equisolid frames, a bright sky). Agreement with the ephemeris is no evidence
    against a candidate; far from it, the penalties stand."""
    p = probability(x, model)
    if ephemeris_deg is None or not ephemeris_deg <= AGREES_DEG:
        return p
    blind = x.copy()
    blind[_EPHEMERIS] = 0.0
    return max(p, probability(blind, model))


def fit_logistic(x: NDArray[np.float64], y: NDArray[np.float64], l2: float = 1.0,
                 n_iter: int = 50) -> tuple[NDArray[np.float64], float]:
    """L2-penalised logistic regression by Newton–Raphson (intercept not penalised).

    ``x`` [n, k] features, ``y`` [n] 0/1 labels. Returns ``(weights, intercept)``.
    """
    n, k = x.shape
    a = np.column_stack([x, np.ones(n)])
    beta = np.zeros(k + 1)
    pen = np.full(k + 1, l2)
    pen[-1] = 0.0
    for _ in range(n_iter):
        z = np.clip(a @ beta, -30, 30)
        p = 1.0 / (1.0 + np.exp(-z))
        grad = a.T @ (p - y) + pen * beta
        hess = (a * (p * (1 - p))[:, None]).T @ a + np.diag(pen) + 1e-9 * np.eye(k + 1)
        step = np.linalg.solve(hess, grad)
        beta -= step
        if float(np.max(np.abs(step))) < 1e-8:
            break
    return beta[:-1], float(beta[-1])


_REASONS = {
    "shape": "brightest region is not round (circularity {shape:.2f}): cloud edge or highlight",
    "glare": "no glare around the brightest region and too small to be one: bright cloud",
    "saturated": "brightest region is not saturated (peak {peak:.0f}): sun hidden or overcast",
    "contrast": "too little contrast ({contrast:.0f} grey levels above the sky): a sky "
                "nearly as bright as its brightest region",
    "contrast_disc": "a round saturated region {radius_deg:.1f}° in radius, but only "
                     "{contrast:.0f} grey levels above the sky around it: too little "
                     "contrast to tell it from a washed-out sky (over-exposed?)",
    "too_small": "brightest region is {radius_deg:.2f}° in radius, under the "
                 f"{_SMALLEST_DEG:g}° of a saturated sun's core with its glare",
    "small_no_glare": "brightest region is {radius_deg:.2f}° in radius, under the "
                      f"{_SMALLEST_DEG:g}° of a saturated sun's core with its glare, and "
                      "without the glare falling off around it: cloud highlight",
    "too_large": "brightest region is {radius_deg:.1f}° in radius, wider than a sun's glare",
    "runner_up": "two regions look equally like the sun: ambiguous",
    "coherence": "brightness around the brightest region is not radially symmetric "
                 "(coherence {coherence:.2f}): cloud",
    "ephemeris_known": "no region where the ephemeris puts the sun",
    "ephemeris_far_unclear": "the brightest region is {ephemeris_deg:.1f}° from where the "
                             "ephemeris puts the sun and does not look plainly like a sun",
}


def reason(x: NDArray[np.float64], values: dict[str, float],
           model: tuple[NDArray[np.float64], float] | None = None) -> str:
    """Why the probability is low: the feature whose term lowers the logit the most,
    measured against an ideal sun's value of that feature."""
    if x[2] < 0.5 and _GATE_SAT:
        return _REASONS["saturated"].format(**values)
    if x[0] < _MIN_SHAPE:
        return _REASONS["shape"].format(**values)
    if _small_without_glare(x):
        return _REASONS["small_no_glare"].format(**values)
    w, _ = model if model is not None else _model()
    ideal = np.array([1.0, 1.0, 1.0, 0.6, 0.0, 0.0, 0.0, 1.0, x[8], 0.0])
    loss = w * (ideal - x)
    i = int(np.argmax(loss))
    if FEATURES[i] == "contrast" and x[0] >= ROUND and x[2] >= 0.5:
        # a round clipped disc on a bright sky: what was measured, not a guessed overcast
        # (a tester's clear sky at six times the exposure, the sun a large saturated disc,
        # was refused as "overcast")
        return _REASONS["contrast_disc"].format(**values)
    return _REASONS[FEATURES[i]].format(**values)
