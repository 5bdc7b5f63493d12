"""A tracker's pointing model fitted from the sun's offsets in its own camera (issue 25).

The mount's geometric errors are fitted, TPOINT-style, from observations of one
known source — the sun, by SPA (:func:`sim.sun.solar_position`) — as telescopes
are (P. T. Wallace, *TPOINT — A Telescope Pointing Analysis System*, terms IA,
IE, AN, AW, NPAE, CA for an altazimuth mount) and heliostats are from camera
observations of the sun (e.g. Stone 1986, "Automatic heliostat track alignment
method", US 4,564,275; Berenguel et al. 2004, Solar Energy 76, 563–575; Sattler
et al. 2020, Solar Energy 207, 110–132, for the error terms of a two-axis
heliostat).

Definitions (issue 25, one frame for every part of the product):

* ENU site frame (x east, y north, z up). A joint pose (``az``, ``el``) points the
  optical axis along n = (sin az cos el, cos az cos el, sin el); the camera's x
  axis is h = (cos az, −sin az, 0), its y axis u = (−sin az sin el, −cos az sin el,
  cos el).
* ``sun_offset_x_mrad`` = 1000·atan2(s·h, s·n), ``sun_offset_y_mrad`` =
  1000·atan2(s·u, s·n), s the true sun and (n, h, u) the mount's real axes.
* Terms: ``azimuth_zero_deg`` (true azimuth joint = encoder + this; IA with
  TPOINT's opposite sign; a pedestal yaw), ``elevation_zero_deg`` (likewise; IE),
  ``pedestal_tilt_north_deg`` / ``pedestal_tilt_east_deg`` (the azimuth axis
  leans toward north / east; the mount is rotated by R = R_y(t_east)·R_x(−t_north);
  AN and −AW), and, where the sky coverage separates them, ``collimation_deg``
  (CA: the camera's axis turned toward increasing azimuth, about the camera's u)
  and ``nonperpendicularity_deg`` (NPAE: the elevation axis's +h end raised by
  this angle out of the plane perpendicular to the azimuth axis).

The camera only sees its own axis: a camera axis turned *up* from the panel
normal is indistinguishable from ``elevation_zero_deg``, and nothing in the
offsets tells the camera's axis from the panel normal. The fitted model, and
:func:`command_angles`, describe the camera's optical axis.

Chain (rotations right-handed, applied to the camera's local axes h=(1,0,0),
n=(0,1,0), u=(0,0,1)): ``R · Rz(−az) · Ry(−np) Rx(el) Ry(np) · Rz(−c)``, with az, el
the true joint angles, np the non-perpendicularity and c the collimation.
Pure functions, vectorised over observations; no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from sim.sun import solar_position
from vision.sphere import enu_from_sky, sky_from_enu

__all__ = [
    "CORE_TERMS",
    "MIN_OBSERVATIONS",
    "OPTIONAL_TERMS",
    "MAX_TERM_DEG",
    "PointingModel",
    "PointingFit",
    "predict_offsets_mrad",
    "fit_pointing_model",
    "fit_pointing_model_to_sun",
    "command_angles",
    "pointing_std_mrad",
]

#: Always fitted (issue 25's names, degrees).
CORE_TERMS = ("azimuth_zero_deg", "elevation_zero_deg",
              "pedestal_tilt_north_deg", "pedestal_tilt_east_deg")
#: Fitted only where the data's sky coverage separates them from the core terms.
OPTIONAL_TERMS = ("collimation_deg", "nonperpendicularity_deg")
_ALL_TERMS = CORE_TERMS + OPTIONAL_TERMS

#: Two terms whose estimates correlate beyond this are not separated by the data.
CORRELATION_LIMIT = 0.98
#: An observation whose residual exceeds this many robust sigmas is an outlier.
OUTLIER_SIGMAS = 5.0
#: An optional term is fitted when its value exceeds this many standard errors …
SIGNIFICANCE_SIGMAS = 3.0
#: … and this size [°] (0.005° ≈ 0.09 mrad: below any tracker camera's precision).
MIN_TERM_DEG = 0.005
#: The least robust sigma of the outlier rule [mrad]: :data:`MIN_TERM_DEG`, below any tracker
#: camera's precision. Without it noise-free readings (σ ≈ 0) made 38 of 138 observations
#: "outliers" at 6e-5 mrad from the model (a tester's finding).
MIN_SIGMA_MRAD = float(np.radians(MIN_TERM_DEG) * 1000.0)
#: A term is determined when its standard error is under this [°]: 0.5 mrad, the tracker
#: camera's pointing target (issue 24). Ten observations over 18 minutes left every term
#: uncorrelated yet uncertain by 0.24–0.33°, larger than the terms, and the dashboard said
#: "separated by the data: yes" (a tester's finding); a day of them, 0.001°.
MAX_DETERMINED_STD_DEG = float(np.degrees(0.5e-3))
#: Fewer observations than this cannot fit the four core terms with any redundancy.
MIN_OBSERVATIONS = 10
#: The robust pass that finds the outliers runs on at most this many observations, evenly
#: spaced in the given order (a year of minutes is 40× more than it needs: its terms serve
#: only to tell a glint from the noise; the reported terms are fitted to all the inliers).
ROBUST_SAMPLE = 5000
#: A term given to :meth:`PointingModel.from_terms` is at most this large [°]: a mount
#: further off is not tracking (the tracker camera's field is ±33°).
MAX_TERM_DEG = 30.0


@dataclass(frozen=True)
class PointingModel:
    """Mount terms [°] (module docstring: definitions of issue 25); all 0 = a perfect mount."""

    azimuth_zero_deg: float = 0.0
    elevation_zero_deg: float = 0.0
    pedestal_tilt_north_deg: float = 0.0
    pedestal_tilt_east_deg: float = 0.0
    collimation_deg: float = 0.0
    nonperpendicularity_deg: float = 0.0

    def as_dict(self) -> dict[str, float]:
        """The terms by their boundary names."""
        return {k: float(getattr(self, k)) for k in _ALL_TERMS}

    @classmethod
    def from_terms(cls, terms: Mapping[str, Any]) -> PointingModel:
        """The model of ``terms``: ``{name: value}`` or, as ``GET …/pointing-model`` answers
        them, ``{name: {"value": v, "std": s}}`` (``std`` is ignored), or that whole answer
        (its ``terms`` are read); a term not given is 0. The CLI's
        ``--pointing-model-terms`` and the API's ``pointing_model_terms`` both come here (a
        tester's whole answer was read by the CLI and refused over HTTP).

        Raises ValueError naming the term for an unknown name, a key of a term other than
        ``value`` and ``std``, or a value that is not a finite number within
        ±:data:`MAX_TERM_DEG`.
        """
        if isinstance(terms.get("terms"), Mapping):
            terms = terms["terms"]
        values: dict[str, float] = {}
        for name, given in terms.items():
            if name not in _ALL_TERMS:
                raise ValueError(f"{name}: not a pointing-model term; known: "
                                 f"{', '.join(_ALL_TERMS)}")
            extra = sorted(set(given) - {"value", "std"}) if isinstance(given, Mapping) else []
            if extra:
                raise ValueError(f"{name}: unknown key {extra[0]!r} (a term is a number of "
                                 "degrees or {\"value\": degrees, \"std\": degrees})")
            raw = given.get("value") if isinstance(given, Mapping) else given
            if isinstance(raw, bool) or not isinstance(raw, (int, float)) or not (
                    math.isfinite(raw) and abs(raw) <= MAX_TERM_DEG):
                raise ValueError(f"{name}: {raw!r} is not a number of degrees within "
                                 f"±{MAX_TERM_DEG:g}")
            values[name] = float(raw)
        return cls(**values)


@dataclass(frozen=True)
class PointingFit:
    """Result of :func:`fit_pointing_model`.

    ``std`` are standard errors [°] from the Jacobian scaled by the residual
    variance (inliers); ``identifiable`` the terms the data separate;
    ``correlated`` the pairs (a, b, r) with |r| > :data:`CORRELATION_LIMIT`;
    ``outlier`` a boolean mask over the observations; ``residual_rms_mrad`` the
    RMS over both axes of the inliers' residuals; ``covariance`` the terms' covariance
    [°²] over ``fitted_terms`` (what ``std`` is the diagonal's root of).
    """

    model: PointingModel
    std: dict[str, float]
    identifiable: tuple[str, ...]
    correlated: tuple[tuple[str, str, float], ...]
    outlier: NDArray[np.bool_]
    residual_rms_mrad: float
    n_observations: int
    fitted_terms: tuple[str, ...] = field(default=CORE_TERMS)
    covariance: NDArray[np.float64] | None = None

    @property
    def n_outliers(self) -> int:
        """How many observations were rejected as outliers."""
        return int(np.count_nonzero(self.outlier))


def _tilt_rotation(tilt_north_rad: float, tilt_east_rad: float) -> NDArray[np.float64]:
    """R = R_y(t_east)·R_x(−t_north): base frame → ENU (issue 25)."""
    cn, sn = np.cos(-tilt_north_rad), np.sin(-tilt_north_rad)
    ce, se = np.cos(tilt_east_rad), np.sin(tilt_east_rad)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cn, -sn], [0.0, sn, cn]])
    ry = np.array([[ce, 0.0, se], [0.0, 1.0, 0.0], [-se, 0.0, ce]])
    return ry @ rx


class _Observations:
    """Observations with the trigonometry of the encoder angles done once (the fit's hot loop).

    Component arrays, not (N, 3) ones: NumPy's (N, 3) @ (3, 3) is ~10× slower
    than three multiply-adds on 200,000 rows.
    """

    _FIELDS = ("sun_e", "sun_n", "sun_u", "ca", "sa", "ce", "se")

    def __init__(self, sun_enu: NDArray, azimuth_deg: NDArray, elevation_deg: NDArray,
                 ox: NDArray | None = None, oy: NDArray | None = None) -> None:
        az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
        self.sun_e, self.sun_n, self.sun_u = (np.ascontiguousarray(sun_enu[:, k]) for k in range(3))
        self.ca, self.sa, self.ce, self.se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
        self.offsets = None if ox is None else np.concatenate([ox, oy])

    def subset(self, keep: NDArray) -> _Observations:
        """The observations where ``keep`` is true."""
        out = object.__new__(_Observations)
        for name in self._FIELDS:
            setattr(out, name, getattr(self, name)[keep])
        n = self.ca.size
        out.offsets = None if self.offsets is None else np.concatenate(
            [self.offsets[:n][keep], self.offsets[n:][keep]])
        return out


def _sun_in_camera(params_deg: NDArray[np.float64], terms: tuple[str, ...],
                   obs: _Observations) -> tuple[NDArray, NDArray, NDArray]:
    """The sun's (h, n, u) components in the camera frame for encoder angles and terms.

    The inverse of the chain in the module docstring applied to s:
    ``Rz(c) · Ry(−np) Rx(−el) Ry(np) · Rz(az) · Rᵀ s``; az = encoder + zero by
    the angle-addition formulas on the precomputed sines and cosines.
    """
    p = dict.fromkeys(_ALL_TERMS, 0.0)
    p.update(zip(terms, (float(v) for v in params_deg), strict=True))
    r = _tilt_rotation(np.radians(p["pedestal_tilt_north_deg"]),
                       np.radians(p["pedestal_tilt_east_deg"]))
    e, n, u = obs.sun_e, obs.sun_n, obs.sun_u  # Rᵀ s: the sun in the base frame
    s = [r[0, k] * e + r[1, k] * n + r[2, k] * u for k in range(3)]
    a0, e0 = np.radians(p["azimuth_zero_deg"]), np.radians(p["elevation_zero_deg"])
    ca = obs.ca * np.cos(a0) - obs.sa * np.sin(a0)
    sa = obs.sa * np.cos(a0) + obs.ca * np.sin(a0)
    # Rz(az) s: inverse of the azimuth turn (clockwise by az)
    x = ca * s[0] - sa * s[1]
    y = sa * s[0] + ca * s[1]
    z = s[2]
    npe = np.radians(p["nonperpendicularity_deg"])
    if npe != 0.0:  # Ry(np): into the tilted elevation axis' frame
        cp, sp = np.cos(npe), np.sin(npe)
        x, z = cp * x + sp * z, -sp * x + cp * z
    ce = obs.ce * np.cos(e0) - obs.se * np.sin(e0)
    se = obs.se * np.cos(e0) + obs.ce * np.sin(e0)
    y, z = ce * y + se * z, -se * y + ce * z  # Rx(−el)
    if npe != 0.0:  # Ry(−np): back
        x, z = cp * x - sp * z, sp * x + cp * z
    c = np.radians(p["collimation_deg"])
    if c != 0.0:  # Rz(c): into the collimated camera frame
        cc, sc = np.cos(c), np.sin(c)
        x, y = cc * x - sc * y, sc * x + cc * y
    return x, y, z


def predict_offsets_mrad(model: PointingModel, sun_azimuth_deg: ArrayLike,
                         sun_elevation_deg: ArrayLike, azimuth_deg: ArrayLike,
                         elevation_deg: ArrayLike) -> tuple[NDArray, NDArray]:
    """The offsets [mrad] (x, y) a mount with ``model`` shows at encoder angles (forward model)."""
    saz, sel, az, el = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float)).ravel()
                                             for v in (sun_azimuth_deg, sun_elevation_deg,
                                                       azimuth_deg, elevation_deg)))
    obs = _Observations(enu_from_sky(saz, sel), az, el)
    x, y, z = _sun_in_camera(np.array([model.as_dict()[k] for k in _ALL_TERMS]), _ALL_TERMS, obs)
    return 1000.0 * np.arctan2(x, y), 1000.0 * np.arctan2(z, y)


def _residuals(params: NDArray, terms: tuple[str, ...], obs: _Observations) -> NDArray[np.float64]:
    """Predicted minus observed offsets [mrad], x then y."""
    assert obs.offsets is not None, "observations without offsets have no residuals"
    x, y, z = _sun_in_camera(params, terms, obs)
    return 1000.0 * np.concatenate([np.arctan2(x, y), np.arctan2(z, y)]) - obs.offsets


def _jacobian(params: NDArray, terms: tuple[str, ...], obs: _Observations) -> NDArray:
    """Forward differences [mrad/°] with a step far below any term's uncertainty."""
    h = 1e-6
    r0 = _residuals(params, terms, obs)
    jac = np.empty((r0.size, len(params)))
    for k in range(len(params)):
        dp = np.zeros_like(params)
        dp[k] = h
        jac[:, k] = (_residuals(params + dp, terms, obs) - r0) / h
    return jac


def _serial_inflation(res: NDArray) -> float:
    """The factor τ = 1 + 2·Σₖ ρₖ by which residuals correlated from one observation to the
    next inflate the variance of the terms (the integrated autocorrelation time: n
    observations count as n/τ independent ones); ρₖ the autocorrelation at lag k of the
    residuals in the given order (the two axes pooled), summed up to the first lag where it
    is no longer positive (Geyer's initial positive sequence); at least 1 and at most the
    number of observations.

    A camera's error is not independent from frame to frame: the sun's blob stays on the same
    sub-pixel phase for minutes, and its centroid's bias with it (a tester's 72 frames a
    second apart were all off by −0.29/+0.36 mrad). Frames every 10 s over a day with a
    0.3 mrad pixel-phase bias put the terms 15–21 standard errors from the truth without it.
    """
    n = res.size // 2
    if n < 3:
        return 1.0
    size = 1 << int(2 * n - 1).bit_length()
    power = sum(np.abs(np.fft.rfft(r - r.mean(), size)) ** 2 for r in (res[:n], res[n:]))
    acov = np.fft.irfft(power, size)[:n]
    if acov[0] <= 0:
        return 1.0
    rho = acov[1:] / acov[0]
    stop = int(np.argmax(rho <= 0.0)) if np.any(rho <= 0.0) else rho.size
    return float(min(max(1.0 + 2.0 * float(rho[:stop].sum()), 1.0), n))


def _covariance(jac: NDArray, res: NDArray, n_params: int) -> NDArray:
    """s²·(JᵀJ)⁻¹·:func:`_serial_inflation`, s² the residual variance: the least-squares
    covariance of the terms, widened for residuals correlated in time."""
    dof = max(res.size - n_params, 1)
    s2 = float(res @ res) / dof
    return s2 * _serial_inflation(res) * np.linalg.pinv(jac.T @ jac)


def _correlated_pairs(cov: NDArray, terms: tuple[str, ...]) -> list[tuple[str, str, float]]:
    d = np.sqrt(np.diag(cov))
    corr = cov / np.outer(d, d)
    return [(terms[i], terms[j], round(float(corr[i, j]), 4))
            for i in range(len(terms)) for j in range(i + 1, len(terms))
            if abs(corr[i, j]) > CORRELATION_LIMIT]


def _solve(terms: tuple[str, ...], obs: _Observations, x0: NDArray, loss: str,
           f_scale: float = 1.0) -> NDArray:
    return least_squares(_residuals, x0, jac=_jacobian, args=(terms, obs), loss=loss,
                         f_scale=f_scale, method="trf" if loss != "linear" else "lm").x


def _select_terms(p_core: NDArray, obs: _Observations) -> tuple[str, ...]:
    """Core terms plus the optional ones the data support, by forward selection (TPOINT's
    practice: a term stays when it is significant).

    Each round linearises all six terms at the current solution (one Jacobian), solves
    each candidate set (current + one optional term) by linear least squares, and keeps
    the candidate whose value is the most significant, if it exceeds
    :data:`SIGNIFICANCE_SIGMAS` standard errors and :data:`MIN_TERM_DEG` and the data
    determine it (standard error at most :data:`MAX_DETERMINED_STD_DEG`: 72 frames a second
    apart had selected a collimation of 16.9° ± 0.46°, a tester's finding). The candidates'
    least squares come from the normal equations JᵀJ, Jᵀr (6 × 6, formed once), their
    residual sums of squares from rᵀr + 2 δᵀJᵀr + δᵀJᵀJ δ: no candidate passes over the
    observations again.
    """
    p_full = np.concatenate([p_core, np.zeros(len(OPTIONAL_TERMS))])
    jac = _jacobian(p_full, _ALL_TERMS, obs)
    res = _residuals(p_full, _ALL_TERMS, obs)
    gram, grad, rr = jac.T @ jac, jac.T @ res, float(res @ res)
    inflation = _serial_inflation(res)
    chosen = list(CORE_TERMS)
    while True:
        best: tuple[float, str] | None = None
        for cand in (t for t in OPTIONAL_TERMS if t not in chosen):
            cols = [_ALL_TERMS.index(t) for t in (*chosen, cand)]
            inv = np.linalg.pinv(gram[np.ix_(cols, cols)])
            step = -inv @ grad[cols]
            ss = rr + 2.0 * float(step @ grad[cols]) + float(step @ gram[np.ix_(cols, cols)]
                                                             @ step)
            cov = max(ss, 0.0) / max(res.size - len(cols), 1) * inflation * inv
            value, std = abs(step[-1]), float(np.sqrt(cov[-1, -1]))
            if value > max(SIGNIFICANCE_SIGMAS * std, MIN_TERM_DEG) \
                    and std <= MAX_DETERMINED_STD_DEG \
                    and (best is None or value / std > best[0]):
                best = (value / std, cand)
        if best is None:
            return tuple(chosen)
        chosen.append(best[1])


def fit_pointing_model_to_sun(
    sun_azimuth_deg: ArrayLike, sun_elevation_deg: ArrayLike,
    azimuth_deg: ArrayLike, elevation_deg: ArrayLike,
    sun_offset_x_mrad: ArrayLike, sun_offset_y_mrad: ArrayLike,
    terms: tuple[str, ...] | None = None,
) -> PointingFit:
    """Fit the mount terms to observations whose true sun direction is given.

    Robust non-linear least squares (:func:`scipy.optimize.least_squares`,
    ``soft_l1`` loss with a 1 mrad scale, on at most :data:`ROBUST_SAMPLE` evenly spaced
    observations): observations whose residual exceeds
    :data:`OUTLIER_SIGMAS` robust sigmas (1.4826 × the median absolute residual, at
    least :data:`MIN_SIGMA_MRAD`)
    are outliers (glints, a wrong blob); the reported terms are then a plain
    least-squares fit to the inliers, so the standard errors from the Jacobian
    (scaled by the residual variance, and widened by the residuals' autocorrelation time in
    the given order, :func:`_serial_inflation`: give the observations in time order)
    hold. ``terms=None`` fits :data:`CORE_TERMS` plus those of :data:`OPTIONAL_TERMS` the
    data support (:func:`_select_terms`); ``identifiable`` then names the fitted terms that no
    other fitted term correlates with beyond :data:`CORRELATION_LIMIT` and whose standard
    error is at most :data:`MAX_DETERMINED_STD_DEG`.
    """
    az, el, ox, oy, saz, sel = (np.asarray(v, dtype=float).ravel() for v in (
        azimuth_deg, elevation_deg, sun_offset_x_mrad, sun_offset_y_mrad,
        sun_azimuth_deg, sun_elevation_deg))
    n = az.size
    if not (el.size == ox.size == oy.size == saz.size == sel.size == n):
        raise ValueError("all observation arrays must have the same length")
    if n < MIN_OBSERVATIONS:
        raise ValueError(f"{n} observations; the fit needs at least {MIN_OBSERVATIONS}")
    if terms is not None:
        unknown = [t for t in terms if t not in _ALL_TERMS]
        if unknown:
            raise ValueError(f"unknown pointing terms {unknown}; known: {', '.join(_ALL_TERMS)}")
    obs = _Observations(enu_from_sky(saz, sel), az, el, ox, oy)
    core = CORE_TERMS
    sample = obs if n <= ROBUST_SAMPLE else obs.subset(
        np.isin(np.arange(n), np.linspace(0, n - 1, ROBUST_SAMPLE).round().astype(np.int64)))
    p = _solve(core, sample, np.zeros(len(core)), "soft_l1", f_scale=1.0)
    res = _residuals(p, core, obs)
    sigma = max(1.4826 * float(np.median(np.abs(res))), MIN_SIGMA_MRAD)
    outlier = np.hypot(res[:n], res[n:]) > OUTLIER_SIGMAS * sigma
    inliers = obs.subset(~outlier)

    if terms is None:
        fit_terms = _select_terms(p, inliers)
    else:
        fit_terms = tuple(terms)
    x0 = np.array([p[core.index(t)] if t in core else 0.0 for t in fit_terms])
    p = _solve(fit_terms, inliers, x0, "linear")
    res = _residuals(p, fit_terms, inliers)
    cov = _covariance(_jacobian(p, fit_terms, inliers), res, len(fit_terms))
    correlated = _correlated_pairs(cov, fit_terms)
    not_separated = {t for a, b, _ in correlated for t in (a, b)}
    std = dict(zip(fit_terms, (float(v) for v in np.sqrt(np.diag(cov))), strict=True))
    model = PointingModel(**dict(zip(fit_terms, (float(v) for v in p), strict=True)))
    return PointingFit(
        model=model, std=std,
        identifiable=tuple(t for t in fit_terms if t not in not_separated
                           and std[t] <= MAX_DETERMINED_STD_DEG),
        correlated=tuple(correlated), outlier=outlier,
        residual_rms_mrad=float(np.sqrt(np.mean(res**2))), n_observations=n,
        fitted_terms=fit_terms, covariance=cov)


def fit_pointing_model(
    times: pd.DatetimeIndex, azimuth_deg: ArrayLike, elevation_deg: ArrayLike,
    sun_offset_x_mrad: ArrayLike, sun_offset_y_mrad: ArrayLike,
    latitude: float, longitude: float, altitude: float = 0.0,
    pressure: float = 101325.0, temperature: float = 12.0,
    terms: tuple[str, ...] | None = None,
) -> PointingFit:
    """:func:`fit_pointing_model_to_sun` with the true sun at ``times`` (UTC) by SPA.

    The camera sees the refracted sun: SPA's apparent elevation
    (:func:`sim.sun.solar_position`, ``method="spa"``; ``pressure`` [Pa] and
    ``temperature`` [°C] for the refraction) is the target.
    """
    sun = solar_position(pd.DatetimeIndex(times), latitude, longitude, altitude, pressure,
                         temperature)
    return fit_pointing_model_to_sun(sun["azimuth"].to_numpy(),
                                     sun["apparent_elevation"].to_numpy(), azimuth_deg,
                                     elevation_deg, sun_offset_x_mrad, sun_offset_y_mrad,
                                     terms=terms)


def command_angles(model: PointingModel, sun_azimuth_deg: ArrayLike, sun_elevation_deg: ArrayLike,
                   iterations: int = 6) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Encoder angles [°] that put the model's real optical axis on the sun.

    Closed form for the yaw, zeros and tilts (the sun into the tilted base frame,
    :func:`vision.sphere.sky_from_enu`, minus the zeros), then Newton steps on the
    forward model's offsets (x ≈ Δaz·cos el, y ≈ Δel) for collimation and
    non-perpendicularity; each step is checked by :func:`predict_offsets_mrad`.
    """
    saz = np.atleast_1d(np.asarray(sun_azimuth_deg, dtype=float))
    sel = np.atleast_1d(np.asarray(sun_elevation_deg, dtype=float))
    sun = enu_from_sky(saz, sel)
    r = _tilt_rotation(np.radians(model.pedestal_tilt_north_deg),
                       np.radians(model.pedestal_tilt_east_deg))
    base_az, base_el = sky_from_enu(sun @ r)
    az = base_az - model.azimuth_zero_deg
    el = base_el - model.elevation_zero_deg
    if model.collimation_deg or model.nonperpendicularity_deg:
        for _ in range(iterations):
            ox, oy = predict_offsets_mrad(model, saz, sel, az, el)
            cos_el = np.maximum(np.cos(np.radians(el + model.elevation_zero_deg)), 1e-6)
            az = az + np.degrees(ox / 1000.0) / cos_el
            el = el + np.degrees(oy / 1000.0)
    return az, el


def pointing_std_mrad(fit: PointingFit, sun_azimuth_deg: ArrayLike, sun_elevation_deg: ArrayLike,
                      azimuth_deg: ArrayLike, elevation_deg: ArrayLike) -> NDArray[np.float64]:
    """Standard error [mrad] of the optical axis's place on the sky at encoder angles under
    ``fit``'s model, relative to the sun: √(σx² + σy²), each σ² = g·C·gᵀ with C the terms'
    covariance (:attr:`PointingFit.covariance`) and g the derivatives of
    :func:`predict_offsets_mrad` by the fitted terms (central differences). At the angles of
    :func:`command_angles` it is how far the command may miss the sun: a model fitted from
    72 s of frames commanded the afternoon 39–52 mrad off (a tester's finding), where the
    day's sky near the frames was within 5 mrad. NaN without a covariance.
    """
    saz, sel, az, el = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, dtype=float)).ravel()
                                             for v in (sun_azimuth_deg, sun_elevation_deg,
                                                       azimuth_deg, elevation_deg)))
    if fit.covariance is None:
        return np.full(saz.shape, np.nan)
    step = 1e-4  # [°]
    base = fit.model.as_dict()
    gx = np.empty((saz.size, len(fit.fitted_terms)))
    gy = np.empty_like(gx)
    for k, term in enumerate(fit.fitted_terms):
        hi = PointingModel(**{**base, term: base[term] + step})
        lo = PointingModel(**{**base, term: base[term] - step})
        (xh, yh), (xl, yl) = (predict_offsets_mrad(m, saz, sel, az, el) for m in (hi, lo))
        gx[:, k], gy[:, k] = (xh - xl) / (2 * step), (yh - yl) / (2 * step)
    cov = fit.covariance
    var = np.einsum("ij,jk,ik->i", gx, cov, gx) + np.einsum("ij,jk,ik->i", gy, cov, gy)
    return np.sqrt(np.maximum(var, 0.0))
