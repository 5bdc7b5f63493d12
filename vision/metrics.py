"""Error metrics between a detected and a reference sun position.

MAD, MSE, RMSE and MAPE per axis as in seed 003 (Garcia-Gil & Ramirez 2019,
eqs. 17–20, with ``A_t`` the reference — their NOAA column — and ``F_t`` the
estimate), plus the angular separation on the sphere. Azimuth differences are
wrapped to (−180°, 180°] so that 359° vs 1° counts as 2°.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vision.sphere import angular_separation_deg


def _pair(actual: ArrayLike, estimate: ArrayLike
          ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    a = np.asarray(actual, dtype=float).ravel()
    f = np.asarray(estimate, dtype=float).ravel()
    if a.shape != f.shape:
        raise ValueError(f"actual and estimate differ in length: {a.size} vs {f.size}")
    if a.size == 0:
        raise ValueError("no values to compare")
    return a, f


def wrap_deg(diff_deg: ArrayLike) -> NDArray[np.float64]:
    """Wrap angle differences [°] to (−180, 180]."""
    d = np.asarray(diff_deg, dtype=float)
    return 180.0 - (180.0 - d) % 360.0


def mad(actual: ArrayLike, estimate: ArrayLike, circular: bool = False) -> float:
    """Mean absolute deviation Σ|A − F|/n (seed 003, eq. 17)."""
    a, f = _pair(actual, estimate)
    d = wrap_deg(a - f) if circular else a - f
    return float(np.mean(np.abs(d)))


def mse(actual: ArrayLike, estimate: ArrayLike, circular: bool = False) -> float:
    """Mean square error Σ(A − F)²/n (seed 003, eq. 18)."""
    a, f = _pair(actual, estimate)
    d = wrap_deg(a - f) if circular else a - f
    return float(np.mean(d**2))


def rmse(actual: ArrayLike, estimate: ArrayLike, circular: bool = False) -> float:
    """Root mean square error √MSE (seed 003, eq. 19)."""
    return float(np.sqrt(mse(actual, estimate, circular)))


def mape(actual: ArrayLike, estimate: ArrayLike, circular: bool = False) -> float:
    """Mean absolute percentage error 100·Σ(|A − F|/|A|)/n [%] (seed 003, eq. 20)."""
    a, f = _pair(actual, estimate)
    if np.any(a == 0):
        raise ValueError("MAPE is undefined when a reference value is zero")
    d = wrap_deg(a - f) if circular else a - f
    return float(100.0 * np.mean(np.abs(d) / np.abs(a)))


def error_table(
    azimuth_ref_deg: ArrayLike,
    elevation_ref_deg: ArrayLike,
    azimuth_deg: ArrayLike,
    elevation_deg: ArrayLike,
) -> dict[str, dict[str, float]]:
    """Seed 003's Table 3 for one batch: MAD/MSE/RMSE/MAPE per axis, plus separation.

    Returns ``{"azimuth": {...}, "elevation": {...}, "separation": {"mean_deg",
    "rmse_deg", "max_deg"}}``; the per-axis figures are in degrees (MSE in
    deg², MAPE in %).
    """
    out: dict[str, dict[str, float]] = {}
    for name, ref, est, circ in (
        ("azimuth", azimuth_ref_deg, azimuth_deg, True),
        ("elevation", elevation_ref_deg, elevation_deg, False),
    ):
        out[name] = {
            "mad_deg": mad(ref, est, circ),
            "mse_deg2": mse(ref, est, circ),
            "rmse_deg": rmse(ref, est, circ),
            "mape_pct": mape(ref, est, circ),
        }
    sep = angular_separation_deg(azimuth_ref_deg, elevation_ref_deg, azimuth_deg, elevation_deg)
    out["separation"] = {
        "mean_deg": float(np.mean(sep)),
        "rmse_deg": float(np.sqrt(np.mean(sep**2))),
        "max_deg": float(np.max(sep)),
    }
    return out
