"""Mount faults named from the tracker camera's sun offsets (issue 25 item 5).

Where the diagnosed range holds camera observations (tracker readings with the encoder
angles ``azimuth_deg``/``elevation_deg`` and the sun's offset ``sun_offset_x_mrad``/
``sun_offset_y_mrad``; frames, offsets and terms as defined in ``docs/pointing-model.md``),
the mount terms are fitted with the existing pointing-model fit
(:func:`sim.pointing_model.fit_pointing_model_to_sun`: robust least squares, standard
errors from the Jacobian) against SPA's apparent sun with the site's refraction (as
:mod:`backend.diagnosis.pointing_model`), and two kinds of finding are made:

- ``mount_offset``: a term that is significant, |value| > max(:data:`SIGNIFICANCE_SIGMAS`
  · std, :data:`MIN_TERM_DEG`). k = 5 rather than the fit's own 3 (its forward selection of
  the optional terms): the standard errors are widened by the residuals' autocorrelation
  time (a camera's residuals are correlated from frame to frame: a blob centre biased by its
  sub-pixel phase, a thin cloud; ``sim.pointing_model._serial_inflation``), an estimate
  that is itself noisy; and four to six terms are tested at once. The minimum, 1 mrad (0.057°) of
  pointing, is what a term must reach to matter: above the fit's stated accuracy (every
  term within 0.05° ≈ 0.87 mrad from a day of data, issue 25's check), and a sixth of the
  ±0.3° (5 mrad) acceptance of a high-concentration module, while a flat plate loses
  1 − cos(1 mrad) = 5·10⁻⁷ of its beam (nothing: it is named for a CPV tracker and for the
  open loop, whose commands it corrects).
- ``encoder_slip``: a term that changes from one local day to the next. Each day with at
  least :data:`MIN_DAY_OBSERVATIONS` observations is fitted on its own; a step between
  consecutive fitted days larger than max(:data:`SIGNIFICANCE_SIGMAS` · the combined
  standard error √(σ₁² + σ₂²), :data:`MIN_SLIP_DEG`) is a slip starting on the later day
  (the detail says so when days without enough observations lie between the two).
  The terms then named as ``mount_offset`` are those fitted from the last slip on (the
  mount as it is now), not a blend of before and after.

A term the data's sky coverage does not separate from another (``identifiable`` of the fit,
correlation beyond :data:`sim.pointing_model.CORRELATION_LIMIT`) is named with that said; a
term the data do not determine (standard error over
:data:`sim.pointing_model.MAX_DETERMINED_STD_DEG`, 0.5 mrad: minutes of sky) is not named at
all: 72 frames a second apart named an elevation zero of +50.57° ± 4.56° where the truth was
−0.4° (a tester's finding), the fit's linear standard error meaningless along a direction the
sky does not constrain.
Pure functions of the observations, except :func:`read_observations` (one SQL select of
the rows that carry all four values, so a range without a camera costs one index scan).
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from sqlalchemy import Connection, select

from backend.diagnosis.pointing_model import refraction_of
from backend.sites import SiteInfo
from backend.storage.tables import SOURCE_CODES, Measurement
from sim.pointing_model import (
    CORE_TERMS,
    MAX_DETERMINED_STD_DEG,
    MIN_OBSERVATIONS,
    PointingFit,
    fit_pointing_model_to_sun,
)
from sim.sun import solar_position

#: A term (or a step of one) is named when it exceeds this many standard errors (see the
#: module docstring for why 5 and not 3).
SIGNIFICANCE_SIGMAS = 5.0
#: … and this size [°]: 1 mrad of pointing (module docstring).
MIN_TERM_DEG = math.degrees(1e-3)
#: The smallest day-to-day step of a term that is a slip [°] (the same 1 mrad).
MIN_SLIP_DEG = MIN_TERM_DEG
#: A day is fitted on its own (for slips) with at least this many observations: an hour of
#: minutes, enough for the four core terms with a spread of the sun across the sky.
MIN_DAY_OBSERVATIONS = 60

#: The words for each term in a finding's sentence.
TERM_WORDS = {
    "azimuth_zero_deg": "pedestal yaw (azimuth zero)",
    "elevation_zero_deg": "elevation zero",
    "pedestal_tilt_north_deg": "pedestal tilt toward north",
    "pedestal_tilt_east_deg": "pedestal tilt toward east",
    "collimation_deg": "camera collimation",
    "nonperpendicularity_deg": "axis non-perpendicularity",
}

#: What a step of each core term is: the zeros are the encoders', a tilt is the pedestal's
#: (no encoder reads it: a tilt that stepped was "an encoder that slipped", a tester's finding).
STEP_CAUSES = {
    "azimuth_zero_deg": "an encoder that slipped (or the pedestal turned)",
    "elevation_zero_deg": "an encoder that slipped",
    "pedestal_tilt_north_deg": "the pedestal moved (its foundation settled or it was re-levelled)",
    "pedestal_tilt_east_deg": "the pedestal moved (its foundation settled or it was re-levelled)",
}

#: Fits kept by the digest of what they were fitted from (the sun, encoder angles and
#: offsets): a repeated diagnosis of a long range refits no day whose observations did not
#: change (a day's fit takes tens of ms; 400 of them seconds). Bounded, oldest out.
FITS_CACHED = 1024
_FITS: OrderedDict[bytes, PointingFit] = OrderedDict()
_FITS_LOCK = threading.Lock()


@dataclass(frozen=True)
class Observations:
    """Camera observations: Unix times [s], the true (apparent) sun and the encoder angles
    [°], the offsets [mrad]; sorted by time."""

    ts_s: np.ndarray
    sun_azimuth_deg: np.ndarray
    sun_elevation_deg: np.ndarray
    azimuth_deg: np.ndarray
    elevation_deg: np.ndarray
    offset_x_mrad: np.ndarray
    offset_y_mrad: np.ndarray

    def fit(self, part: slice = slice(None)) -> PointingFit:
        """The pointing-model fit of the observations ``part`` (core and supported terms);
        a fit of the same observations is taken from :data:`_FITS`."""
        cols = (self.sun_azimuth_deg[part], self.sun_elevation_deg[part],
                self.azimuth_deg[part], self.elevation_deg[part], self.offset_x_mrad[part],
                self.offset_y_mrad[part])
        digest = hashlib.blake2b(digest_size=16)
        for c in cols:
            digest.update(np.ascontiguousarray(c).tobytes())
        key = digest.digest()
        with _FITS_LOCK:
            if key in _FITS:
                _FITS.move_to_end(key)
                return _FITS[key]
        fit = fit_pointing_model_to_sun(*cols)
        with _FITS_LOCK:
            _FITS[key] = fit
            while len(_FITS) > FITS_CACHED:
                _FITS.popitem(last=False)
        return fit


def observations_from(info: SiteInfo, ts_s: np.ndarray, azimuth_deg: np.ndarray,
                      elevation_deg: np.ndarray, offset_x_mrad: np.ndarray,
                      offset_y_mrad: np.ndarray) -> Observations:
    """:class:`Observations` with the sun by SPA (apparent elevation, the site's pressure
    and air temperature: :func:`backend.diagnosis.pointing_model.refraction_of`)."""
    s = info.site
    pressure, temperature = refraction_of(info)
    times = pd.DatetimeIndex(pd.to_datetime(np.asarray(ts_s, np.int64), unit="s", utc=True))
    sun = solar_position(times, s.latitude, s.longitude, s.altitude, pressure, temperature)
    return Observations(np.asarray(ts_s, np.int64), sun["azimuth"].to_numpy(),
                        sun["apparent_elevation"].to_numpy(), *(np.asarray(v, float) for v in (
                            azimuth_deg, elevation_deg, offset_x_mrad, offset_y_mrad)))


def read_observations(conn: Connection, info: SiteInfo, t0_s: int, t1_s: int
                      ) -> Observations | None:
    """The tracker's measured readings in ``[t0_s, t1_s)`` that carry both encoder angles
    and both offsets, or None with fewer than :data:`sim.pointing_model.MIN_OBSERVATIONS`."""
    tracker = info.array_of_kind("tracker")
    if tracker is None or t1_s <= t0_s:
        return None
    m = Measurement
    cols = (m.azimuth_deg, m.elevation_deg, m.sun_offset_x_mrad, m.sun_offset_y_mrad)
    rows = conn.execute(select(m.ts_s, *cols).where(
        m.array_id == tracker.array_id, m.source == SOURCE_CODES["measured"],
        m.ts_s >= t0_s, m.ts_s < t1_s, *(c.is_not(None) for c in cols)).order_by(m.ts_s)).all()
    if len(rows) < MIN_OBSERVATIONS:
        return None
    a = np.array(rows, np.float64)
    return observations_from(info, a[:, 0].astype(np.int64), a[:, 1], a[:, 2], a[:, 3], a[:, 4])


def _decimals(std_deg: float) -> int:
    """Decimals that show a standard error to one significant figure (2 to 4)."""
    if not np.isfinite(std_deg) or std_deg <= 0:
        return 2
    return int(np.clip(-math.floor(math.log10(std_deg)), 2, 4))


def _significant(value: float, std: float, minimum: float) -> bool:
    return bool(np.isfinite(std) and abs(value) > max(SIGNIFICANCE_SIGMAS * std, minimum))


def _day_fits(obs: Observations, day_edges_s: list[int]
              ) -> list[tuple[int, PointingFit]]:
    """``(day index, fit)`` of each day with at least :data:`MIN_DAY_OBSERVATIONS`."""
    cut = np.searchsorted(obs.ts_s, day_edges_s)
    out = []
    for i in range(len(day_edges_s) - 1):
        a, b = int(cut[i]), int(cut[i + 1])
        if b - a >= MIN_DAY_OBSERVATIONS:
            out.append((i, obs.fit(slice(a, b))))
    return out


def slips(day_fits: list[tuple[int, PointingFit]], dates: list[str]) -> list[dict[str, Any]]:
    """``encoder_slip`` findings: steps of a core term between consecutive fitted days
    (module docstring); JSON-ready, oldest first."""
    out = []
    for (i, f1), (j, f2) in zip(day_fits, day_fits[1:], strict=False):
        gap = "" if j == i + 1 else (f"; no day between {dates[i]} and {dates[j]} had enough "
                                     "observations, so it may have slipped on one of them")
        for term in CORE_TERMS:
            v1, v2 = getattr(f1.model, term), getattr(f2.model, term)
            s1, s2 = f1.std.get(term, np.nan), f2.std.get(term, np.nan)
            step, std = v2 - v1, float(np.hypot(s1, s2))
            if term not in f1.identifiable or term not in f2.identifiable \
                    or not _significant(step, std, MIN_SLIP_DEG):
                continue
            d = _decimals(std)
            out.append({
                "kind": "encoder_slip", "term": term, "value_deg": round(step, 6),
                "std_deg": round(std, 6), "since": dates[j],
                "n_observations": f1.n_observations + f2.n_observations,
                "detail": f"{TERM_WORDS[term]} stepped by {step:+.{d}f}° ± {std:.{d}f}° on "
                          f"{dates[j]} (from {v1:+.{d}f}° to {v2:+.{d}f}°; "
                          f"{f1.n_observations} and {f2.n_observations} camera observations "
                          f"on the days either side): {STEP_CAUSES[term]}{gap}"})
    return out


def offsets(fit: PointingFit, since: str) -> list[dict[str, Any]]:
    """``mount_offset`` findings of the significant terms of ``fit`` that the observations
    determine (standard error at most :data:`sim.pointing_model.MAX_DETERMINED_STD_DEG`;
    module docstring)."""
    out = []
    for term in fit.fitted_terms:
        value, std = getattr(fit.model, term), fit.std.get(term, np.nan)
        if not (_significant(value, std, MIN_TERM_DEG) and std <= MAX_DETERMINED_STD_DEG):
            continue
        d = _decimals(std)
        detail = (f"{TERM_WORDS[term]} {value:+.{d}f}° ± {std:.{d}f}° (from "
                  f"{fit.n_observations} camera observations since {since})")
        if term not in fit.identifiable:
            others = sorted({b if a == term else a for a, b, _ in fit.correlated
                             if term in (a, b)})
            detail += (f"; not separated from {', '.join(others)} by these observations' "
                       "sky coverage")
        out.append({"kind": "mount_offset", "term": term, "value_deg": round(value, 6),
                    "std_deg": round(std, 6), "since": since,
                    "n_observations": fit.n_observations, "detail": detail})
    return out


def mount_faults(obs: Observations | None, day_edges_s: list[int], dates: list[str]
                 ) -> dict[str, Any] | None:
    """The diagnosis's ``mount`` answer for observations over local days (``day_edges_s``:
    the days' edges [Unix s], one more than ``dates``), or None without observations.

    Slips first (per-day fits); the offsets from the day of the last slip on (the whole
    range without one). ``faults``: slips, oldest first, then offsets; ``undetermined``: the
    fitted terms the observations do not determine (:func:`offsets` names none of them, and
    no fault named is not a mount found sound: 72 frames a second apart of a mount 2.5° off
    read "no significant term", a tester's finding)."""
    if obs is None:
        return None
    found = slips(_day_fits(obs, day_edges_s), dates)
    first = 0
    if found:
        k = dates.index(found[-1]["since"])
        first = int(np.searchsorted(obs.ts_s, day_edges_s[k]))
    if obs.ts_s.size - first < MIN_OBSERVATIONS:
        first = 0
    fit = obs.fit(slice(first, None))
    day = int(np.searchsorted(day_edges_s, obs.ts_s[first], side="right")) - 1
    since = dates[min(max(day, 0), len(dates) - 1)]
    return {"n_observations": fit.n_observations, "n_outliers": fit.n_outliers,
            "residual_rms_mrad": round(fit.residual_rms_mrad, 4), "since": since,
            "faults": found + offsets(fit, since),
            "undetermined": [t for t in fit.fitted_terms
                             if not fit.std.get(t, np.nan) <= MAX_DETERMINED_STD_DEG]}
