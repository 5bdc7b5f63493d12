"""The detector's confidence: a logistic model of "this candidate is the sun".

Features of the winning candidate (:func:`features`) are combined by a
logistic regression whose coefficients were fitted on the DEVELOPMENT split
only (``benchmarks/bench_vision.py --fit-confidence``: synthetic frames of
both renderers with development seeds and the development real frames; L2
penalty, Newton–Raphson) and are stored in ``confidence.json`` beside this
module. The held-out split's reliability table (confidence bins → fraction
correct) is in ``docs/validation-vision.md``. A candidate counts as correct
when the sun is visible and the answer lies within max(3 px, 0.5°) of the
truth.

Every "no sun" answer gets a reason a person can read (:func:`reason`): the
feature that pulled the probability down the most.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

FEATURES: tuple[str, ...] = (
    "shape",             # circularity of the bright core 0–1 (second moments)
    "glare",             # glare evidence 0–1: isotropic fall-off or sharp drop to the sky
    "saturated",         # 1 when the core reaches the sensor's top (≥ 250)
    "contrast",          # (peak − sky median) / 255
    "size_misfit",       # |ln(equivalent radius [°] / 2.5°)|: disc + glare against its usual size
    "runner_up",         # heuristic score of the runner-up / the winner's
    "coherence",         # radial-symmetry coherence of the glare's gradients 0–1
    "ephemeris_known",   # 1 when a prediction from time, place and camera was given
    "ephemeris_far",     # min(distance from the prediction [°], 30) / 10, 0 when unknown
)

_PATH = Path(__file__).with_name("confidence.json")


def load_model(path: Path = _PATH) -> tuple[NDArray[np.float64], float]:
    """``(weights over FEATURES, intercept)`` from ``confidence.json``."""
    d = json.loads(path.read_text())
    if tuple(d["features"]) != FEATURES:
        raise ValueError(f"{path.name} was fitted on other features: {d['features']}")
    return np.asarray(d["weights"], dtype=float), float(d["intercept"])


_MODEL: tuple[NDArray[np.float64], float] | None = None


def _model() -> tuple[NDArray[np.float64], float]:
    global _MODEL  # noqa: PLW0603 - a read-only cache of the module's own data file
    if _MODEL is None:
        _MODEL = load_model()
    return _MODEL


def features(shape: float, glare: float, peak: float, bg: float, radius_deg: float,
             runner_up: float, coherence: float, ephemeris_deg: float | None
             ) -> NDArray[np.float64]:
    """The feature vector (order of :data:`FEATURES`) of one candidate.

    ``peak``, ``bg`` are grey levels; ``radius_deg`` the core's equivalent
    radius on the sky [°]; ``ephemeris_deg`` its distance from the predicted
    sun [°] or None.
    """
    known = ephemeris_deg is not None
    far = min(float(ephemeris_deg), 30.0) / 10.0 if ephemeris_deg is not None else 0.0
    return np.array([
        shape, glare, float(peak >= 250.0), max(peak - bg, 0.0) / 255.0,
        abs(float(np.log(max(radius_deg, 1e-3) / 2.5))), runner_up, coherence,
        float(known), far], dtype=float)


def probability(x: NDArray[np.float64], model: tuple[NDArray[np.float64], float] | None = None
                ) -> float:
    """P(candidate is the sun) = σ(w·x + b)."""
    w, b = model if model is not None else _model()
    return float(1.0 / (1.0 + np.exp(-(float(w @ x) + b))))


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
    "glare": "no glare falling off around the brightest region: bright cloud, not the sun",
    "saturated": "brightest region is not saturated (peak {peak:.0f}): sun hidden or overcast",
    "contrast": "too little contrast ({contrast:.0f} grey levels above the sky): overcast",
    "size_misfit": "brightest region is {radius_deg:.1f}° in radius, not the size of a sun's "
                   "disc and glare",
    "runner_up": "two regions look equally like the sun: ambiguous",
    "coherence": "brightness around the brightest region is not radially symmetric "
                 "(coherence {coherence:.2f}): cloud",
    "ephemeris_known": "no region where the ephemeris puts the sun",
    "ephemeris_far": "brightest round region is {ephemeris_deg:.1f}° from where the ephemeris "
                     "puts the sun",
}


def reason(x: NDArray[np.float64], values: dict[str, float],
           model: tuple[NDArray[np.float64], float] | None = None) -> str:
    """Why the probability is low: the feature whose term lowers the logit the most,
    measured against an ideal sun's value of that feature."""
    w, _ = model if model is not None else _model()
    ideal = np.array([1.0, 1.0, 1.0, 0.6, 0.0, 0.0, 1.0, x[7], 0.0])
    loss = w * (ideal - x)
    i = int(np.argmax(loss))
    return _REASONS[FEATURES[i]].format(**values)
