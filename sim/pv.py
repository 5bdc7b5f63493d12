"""PV electrics: the Kyocera KD205GX-LP through the CEC single-diode model (pvlib).

- Module parameters come from pvlib's copy of the CEC module table (the file
  ``pvlib.pvsystem.retrieve_sam("CECMod")`` reads, the 2019-03-05 file; only the
  wanted row is parsed, once per process — :func:`cec_module_parameters` is
  cached; tests/sim/test_pv.py checks it against ``retrieve_sam``).
- The five single-diode parameters at operating conditions come from
  ``pvlib.pvsystem.calcparams_cec`` (Dobos 2012, doi:10.1115/1.4005759), the
  I–V curve and the maximum power point from ``pvlib.pvsystem.singlediode`` /
  ``i_from_v`` (Lambert-W, Jain & Kapoor 2004).
- Cell temperature: the SAPM cell-temperature model (King et al. 2004,
  ``pvlib.temperature.sapm_cell``), open rack, glass/polymer by default.
- :class:`ArrayConfig` holds N modules as ``modules_in_series`` ×
  ``strings_in_parallel`` (identical modules, no mismatch): the array current is
  the module current × strings, the voltage the module voltage × series count.

Seed 000 does not say how its four modules are wired; its ±30 A ACS712-30A
current sensor suggests **parallel** (4 × 7.71 A ≈ 31 A at the maximum power
point, 4 × 8.36 A ≈ 33 A short circuit, at 26.6 V): the default array is one
module in series × four strings in parallel.

Fast route (:class:`MppTable`): the maximum power point of the module is a
smooth function of two inputs only, effective irradiance and cell
temperature. The table solves the single-diode model exactly (pvlib) on a grid
of those two inputs once per module and interpolates bilinearly; points
outside the grid are solved exactly. Over real years of both arrays, through
the twin (clear sky at ``tehuantepec`` and pvlib's TMY3 year, 1-min steps), the
annual energy is 0.0002–0.0006 % below pvlib's full solution on the same
inputs and at most 0.04 W per module off at any step (``sim.mpp_*`` in
benchmarks/RESULTS.md; tests/sim/test_mpp_year.py asserts within 2× of them).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

KD205GX_LP = "Kyocera_Solar_KD205GX_LP"
"""Key of the Kyocera KD205GX-LP in pvlib's CEC module table."""

#: Datasheet values at STC (Kyocera KD205GX-LP; ../shared/reference/sites.json).
KD205GX_LP_DATASHEET_STC = {
    "pmax_w": 205.0,
    "vmp_v": 26.6,
    "imp_a": 7.71,
    "voc_v": 33.2,
    "isc_a": 8.36,
}

_CEC_KEYS = ("alpha_sc", "a_ref", "I_L_ref", "I_o_ref", "R_sh_ref", "R_s", "Adjust")


#: pvlib's copy of the CEC module table (what ``retrieve_sam("CECMod")`` reads).
CEC_TABLE_FILE = "sam-library-cec-modules-2019-03-05.csv"
_NAME_MAP = str.maketrans(' -.()[]:+/",', "____________")  # pvlib's name normalisation


@lru_cache(maxsize=8)
def _cec_row(module: str) -> tuple[tuple[str, Any], ...]:
    """One row of pvlib's CEC table, read with :mod:`csv` (the whole table via
    ``retrieve_sam`` costs ~0.1 s, a noticeable part of a CLI run)."""
    import csv

    import pvlib

    path = Path(pvlib.__file__).parent / "data" / CEC_TABLE_FILE
    with path.open(newline="", encoding="utf-8", errors="replace") as f:
        rows = csv.reader(f)
        header = next(rows)
        for row in rows:
            if row and row[0].translate(_NAME_MAP) == module:
                return tuple(
                    (k, _number_or_text(v)) for k, v in zip(header[1:], row[1:], strict=True)
                )
    raise ValueError(f"module {module!r} is not in pvlib's CEC module table")


def _number_or_text(value: str) -> Any:
    try:
        return float(value)
    except ValueError:
        return value


def cec_module_parameters(module: str = KD205GX_LP) -> dict[str, Any]:
    """CEC module parameters from pvlib's table (the file ``retrieve_sam("CECMod")`` reads), cached.

    Parameters
    ----------
    module : str
        Column name in pvlib's CEC table, e.g. ``"Kyocera_Solar_KD205GX_LP"``.

    Returns
    -------
    dict
        The table's row (``I_L_ref`` [A], ``I_o_ref`` [A], ``R_s`` [Ω],
        ``R_sh_ref`` [Ω], ``a_ref`` [V], ``alpha_sc`` [A K⁻¹], ``Adjust`` [%], …).
    """
    return dict(_cec_row(module))


@dataclass(frozen=True)
class ArrayConfig:
    """One PV array: identical modules in series/parallel on one mount.

    Parameters
    ----------
    name : str
        Array id (``"tracker"``, ``"fixed"``).
    mount : {"tracker", "fixed"}
        Dual-axis tracker or fixed tilt.
    module : str
        Key in pvlib's CEC table.
    modules_in_series : int
        Modules per string.
    strings_in_parallel : int
        Strings in parallel.
    surface_tilt, surface_azimuth : float
        Orientation of a fixed array [°] (azimuth clockwise from north); ignored
        for a tracker.
    temperature_model : str
        Key of ``pvlib.temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"]``.
    albedo : float
        Ground reflectance [-].
    dc_loss_pct : float
        The array's DC losses the single-diode model does not see [%]: soiling, mismatch,
        wiring, the modules' nameplate tolerance, light-induced degradation and age. It
        scales the array's current at the maximum power point (:func:`array_mpp`), as
        PVWatts' system losses scale its power (Dobos 2014, PVWatts Version 5 Manual,
        NREL/TP-6A20-62641: 14.08 % by default, its ten categories compounded, the inverter
        apart; ``pvlib.pvsystem.pvwatts_losses``). 0 by default: the ideal array.
    inverter_limit_w : float or None
        The most power its inverter delivers [W] (its AC rating, where the logger reads AC
        power): above it the inverter leaves the maximum power point and clips
        (:func:`array_mpp`). A plant's DC/AC ratio is 1.1–1.4, so a tracker, which holds its
        peak for hours, clips on every clear day. None by default: no limit.
    """

    name: str
    mount: str = "fixed"
    module: str = KD205GX_LP
    modules_in_series: int = 1
    strings_in_parallel: int = 4
    surface_tilt: float = 0.0
    surface_azimuth: float = 180.0
    temperature_model: str = "open_rack_glass_polymer"
    albedo: float = 0.2
    dc_loss_pct: float = 0.0
    inverter_limit_w: float | None = None

    def __post_init__(self) -> None:
        if self.mount not in ("tracker", "fixed"):
            raise ValueError(f"array {self.name!r}: mount must be 'tracker' or 'fixed'")
        if self.modules_in_series < 1 or self.strings_in_parallel < 1:
            raise ValueError(
                f"array {self.name!r}: modules_in_series and strings_in_parallel must be >= 1"
            )
        if not 0.0 <= self.dc_loss_pct < 100.0:
            raise ValueError(f"array {self.name!r}: dc_loss_pct must be in 0..100 %")
        if self.inverter_limit_w is not None and not self.inverter_limit_w > 0.0:
            raise ValueError(f"array {self.name!r}: inverter_limit_w must be > 0 W")

    @property
    def modules(self) -> int:
        """Number of modules in the array."""
        return self.modules_in_series * self.strings_in_parallel

    @property
    def stc_power_w(self) -> float:
        """The array's rating: its modules' power at STC (the CEC table's ``STC``) [W]."""
        return float(cec_module_parameters(self.module)["STC"]) * self.modules

    def to_config(self) -> dict[str, Any]:
        """The array as a site file's entry (:func:`array_config_from_dict` reads it back)."""
        out = {key: getattr(self, name) for key, (name, _) in _SITE_FILE_KEYS.items()}
        if not self.dc_loss_pct:  # only when set: a stored config without it stays unchanged
            del out["dc_loss_pct"]
        if self.inverter_limit_w is None:
            del out["inverter_limit_w"]
        return out

    @property
    def wiring(self) -> str:
        """``"parallel"``, ``"series"`` or ``"<s>s<p>p"``."""
        if self.modules_in_series == 1:
            return "parallel"
        if self.strings_in_parallel == 1:
            return "series"
        return f"{self.modules_in_series}s{self.strings_in_parallel}p"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description with units in the keys."""
        out = {
            "name": self.name,
            "mount": self.mount,
            "module": self.module,
            "modules": self.modules,
            "modules_in_series": self.modules_in_series,
            "strings_in_parallel": self.strings_in_parallel,
            "wiring": self.wiring,
            "stc_power_w": self.stc_power_w,
            "temperature_model": self.temperature_model,
            "albedo": self.albedo,
        }
        if self.dc_loss_pct:  # only when set: a stored config without it stays unchanged
            out["dc_loss_pct"] = self.dc_loss_pct
        if self.inverter_limit_w is not None:
            out["inverter_limit_w"] = self.inverter_limit_w
        if self.mount == "fixed":
            out["surface_tilt_deg"] = self.surface_tilt
            out["surface_azimuth_deg"] = self.surface_azimuth
        return out


def cell_temperature(
    poa_global: np.ndarray,
    temp_air: np.ndarray | float,
    wind_speed: np.ndarray | float,
    model: str = "open_rack_glass_polymer",
) -> np.ndarray:
    """Cell temperature [°C]: SAPM model (King et al. 2004), ``pvlib.temperature.sapm_cell``.

    Parameters
    ----------
    poa_global : array_like
        Plane-of-array irradiance [W m⁻²].
    temp_air : array_like
        Air temperature [°C].
    wind_speed : array_like
        Wind speed at 10 m [m s⁻¹].
    model : str
        Mounting key of ``TEMPERATURE_MODEL_PARAMETERS["sapm"]``.
    """
    from pvlib import temperature

    p = temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"][model]
    return np.asarray(
        temperature.sapm_cell(poa_global, temp_air, wind_speed, p["a"], p["b"], p["deltaT"]),
        dtype=float,
    )


def air_temperature_from_module(
    temp_module: np.ndarray,
    poa_global: np.ndarray,
    wind_speed: np.ndarray | float,
    model: str = "open_rack_glass_polymer",
) -> np.ndarray:
    """The air temperature [°C] under which the SAPM module model (King et al. 2004, eq. 11:
    ``T_m = E · exp(a + b · WS) + T_a``) gives the measured back-of-module temperature
    ``temp_module`` at ``poa_global`` [W m⁻²] and ``wind_speed`` [m s⁻¹]: fed to
    :func:`cell_temperature`, the array's cells are then ``T_m + E / 1000 · ΔT`` (pvlib's
    ``sapm_cell_from_module``), and an array beside it under the same air gets the same
    correction of the model's mounting and wind."""
    from pvlib import temperature

    p = temperature.TEMPERATURE_MODEL_PARAMETERS["sapm"][model]
    e = np.asarray(poa_global, dtype=float)
    rise = e * np.exp(p["a"] + p["b"] * np.asarray(wind_speed, dtype=float))
    return np.asarray(temp_module, dtype=float) - rise


def single_diode_parameters(
    effective_irradiance: np.ndarray, temp_cell: np.ndarray, module: str = KD205GX_LP
) -> tuple[np.ndarray, ...]:
    """CEC single-diode parameters (photocurrent [A], saturation current [A],
    R_s [Ω], R_sh [Ω], nNsVth [V]) via ``pvlib.pvsystem.calcparams_cec``."""
    from pvlib import pvsystem

    p = cec_module_parameters(module)
    out = pvsystem.calcparams_cec(
        np.asarray(effective_irradiance, dtype=float),
        np.asarray(temp_cell, dtype=float),
        **{k: p[k] for k in _CEC_KEYS},
    )
    return tuple(np.asarray(x, dtype=float) for x in out)


def module_mpp_exact(
    effective_irradiance: np.ndarray, temp_cell: np.ndarray, module: str = KD205GX_LP
) -> dict[str, np.ndarray]:
    """Module operating points by the full CEC single-diode solution (pvlib, Lambert-W).

    Parameters
    ----------
    effective_irradiance : array_like
        Irradiance reaching the cells [W m⁻²].
    temp_cell : array_like
        Cell temperature [°C].

    Returns
    -------
    dict
        ``i_sc``, ``v_oc``, ``i_mp`` [A], ``v_mp`` [V], ``p_mp`` [W]; zero where
        the irradiance is zero or negative.
    """
    from pvlib import pvsystem

    e = np.asarray(effective_irradiance, dtype=float)
    t = np.broadcast_to(np.asarray(temp_cell, dtype=float), e.shape)
    lit = e > 0
    out = {k: np.zeros(e.shape) for k in ("i_sc", "v_oc", "i_mp", "v_mp", "p_mp")}
    if np.any(lit):
        params = single_diode_parameters(e[lit], t[lit], module)
        sd = pvsystem.singlediode(*params, method="lambertw")
        for k in out:
            out[k][lit] = np.asarray(sd[k], dtype=float)
    return out


class MppTable:
    """Exact-solution table of a module's maximum power point over (irradiance, temperature).

    The CEC single-diode model (pvlib, Lambert-W) is solved once on a grid —
    irradiance 0…1500 W m⁻² (1 W m⁻² steps up to 20, 5 up to 200, 10 above),
    cell temperature −30…100 °C in 1 °C steps — and ``i_mp``/``v_mp`` are
    interpolated bilinearly. Inputs outside the grid are solved exactly.
    """

    def __init__(self, module: str = KD205GX_LP) -> None:
        self.module = module
        self.irradiance = np.unique(
            np.concatenate(
                [
                    np.arange(0.0, 20.0, 1.0),
                    np.arange(20.0, 200.0, 5.0),
                    np.arange(200.0, 1501.0, 10.0),
                ]
            )
        )
        self.temperature = np.arange(-30.0, 100.5, 1.0)
        ee, tt = np.meshgrid(self.irradiance, self.temperature, indexing="ij")
        sol = module_mpp_exact(ee.ravel(), tt.ravel(), module)
        self.i_mp = sol["i_mp"].reshape(ee.shape)
        self.v_mp = sol["v_mp"].reshape(ee.shape)

    def lookup(
        self, effective_irradiance: np.ndarray, temp_cell: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Module ``(i_mp [A], v_mp [V])`` at irradiance [W m⁻²] and cell temperature [°C]."""
        e = np.asarray(effective_irradiance, dtype=float)
        t = np.broadcast_to(np.asarray(temp_cell, dtype=float), e.shape)
        g, tg = self.irradiance, self.temperature
        inside = (e >= g[0]) & (e <= g[-1]) & (t >= tg[0]) & (t <= tg[-1])
        i_mp = np.zeros(e.shape)
        v_mp = np.zeros(e.shape)
        ei, ti = e[inside], t[inside]
        k = np.clip(np.searchsorted(g, ei, side="right") - 1, 0, len(g) - 2)
        dt = tg[1] - tg[0]  # uniform temperature grid
        j = np.clip(np.floor((ti - tg[0]) / dt).astype(int), 0, len(tg) - 2)
        we = (ei - g[k]) / (g[k + 1] - g[k])
        wt = (ti - tg[j]) / dt
        for table, out in ((self.i_mp, i_mp), (self.v_mp, v_mp)):
            out[inside] = (
                table[k, j] * (1 - we) * (1 - wt)
                + table[k + 1, j] * we * (1 - wt)
                + table[k, j + 1] * (1 - we) * wt
                + table[k + 1, j + 1] * we * wt
            )
        outside = ~inside & (e > 0)
        if np.any(outside):
            sol = module_mpp_exact(e[outside], t[outside], self.module)
            i_mp[outside], v_mp[outside] = sol["i_mp"], sol["v_mp"]
        i_mp[e <= 0] = 0.0
        v_mp[e <= 0] = 0.0
        return i_mp, v_mp


@lru_cache(maxsize=8)
def mpp_table(module: str = KD205GX_LP) -> MppTable:
    """The (cached) :class:`MppTable` of a module; built once per process (~0.1 s)."""
    return MppTable(module)


def array_mpp(
    effective_irradiance: np.ndarray,
    temp_cell: np.ndarray,
    array: ArrayConfig,
    exact: bool = False,
) -> dict[str, np.ndarray]:
    """Array current, voltage and power at the maximum power point, its current reduced by
    the array's ``dc_loss_pct`` and its power cut at its ``inverter_limit_w`` (the one place
    the losses and the clipping enter: the twin, the sky read from an array's power and the
    diagnosis's fits all come through here). A clipping inverter moves the array's operating
    point from the maximum power point towards open circuit; that point is not modelled: the
    voltage stays the MPP's and the current takes the cut (a clipped minute's measured
    voltage reads above it).

    Parameters
    ----------
    effective_irradiance : array_like
        Irradiance reaching the cells [W m⁻²].
    temp_cell : array_like
        Cell temperature [°C].
    array : ArrayConfig
    exact : bool
        Solve the single-diode model at every point (pvlib) instead of the
        :class:`MppTable` route.

    Returns
    -------
    dict
        ``current_a`` [A], ``voltage_v`` [V], ``power_w`` [W].
    """
    if exact:
        sol = module_mpp_exact(effective_irradiance, temp_cell, array.module)
        i_mp, v_mp = sol["i_mp"], sol["v_mp"]
    else:
        i_mp, v_mp = mpp_table(array.module).lookup(effective_irradiance, temp_cell)
    current = i_mp * array.strings_in_parallel * (1.0 - array.dc_loss_pct / 100.0)
    voltage = v_mp * array.modules_in_series
    power = current * voltage
    if array.inverter_limit_w is not None:
        power = np.minimum(power, array.inverter_limit_w)
        current = np.divide(power, voltage, out=np.zeros_like(power), where=voltage > 0)
    return {"current_a": current, "voltage_v": voltage, "power_w": power}


def iv_curve(
    effective_irradiance: float, temp_cell: float, array: ArrayConfig, points: int = 100
) -> pd.DataFrame:
    """Full I–V curve of the array, from short circuit to open circuit.

    Uses ``pvlib.pvsystem.calcparams_cec`` and ``pvlib.pvsystem.i_from_v``
    (Lambert-W) on the module, scaled by the array's series/parallel wiring.

    Parameters
    ----------
    effective_irradiance : float
        Irradiance reaching the cells [W m⁻²], > 0.
    temp_cell : float
        Cell temperature [°C].
    array : ArrayConfig
    points : int
        Number of voltage points (≥ 2).

    Returns
    -------
    pandas.DataFrame
        Columns ``voltage_v``, ``current_a``, ``power_w``.
    """
    from pvlib import pvsystem

    if effective_irradiance <= 0:
        raise ValueError("effective_irradiance must be > 0 for an I-V curve")
    if points < 2:
        raise ValueError("points must be >= 2")
    params = single_diode_parameters(
        np.array([effective_irradiance]), np.array([temp_cell]), array.module
    )
    v_oc = float(pvsystem.singlediode(*params)["v_oc"][0])
    v_module = np.linspace(0.0, v_oc, points)
    i_module = np.asarray(pvsystem.i_from_v(v_module, *(float(p[0]) for p in params)), dtype=float)
    i_module = np.clip(i_module, 0.0, None)
    voltage = v_module * array.modules_in_series
    current = i_module * array.strings_in_parallel
    return pd.DataFrame({"voltage_v": voltage, "current_a": current, "power_w": voltage * current})


def _as_is(value: Any) -> Any:
    return value


#: Site-file key → (:class:`ArrayConfig` field, converter); units in the keys at the boundary.
_SITE_FILE_KEYS: dict[str, tuple[str, Any]] = {
    "mount": ("mount", _as_is),
    "module": ("module", _as_is),
    "modules_in_series": ("modules_in_series", int),
    "strings_in_parallel": ("strings_in_parallel", int),
    "surface_tilt_deg": ("surface_tilt", float),
    "surface_azimuth_deg": ("surface_azimuth", float),
    "temperature_model": ("temperature_model", _as_is),
    "albedo": ("albedo", float),
    "dc_loss_pct": ("dc_loss_pct", float),
    "inverter_limit_w": ("inverter_limit_w", float),
}


def array_config_from_dict(name: str, d: dict[str, Any]) -> ArrayConfig:
    """Build an :class:`ArrayConfig` from a site-file entry (units in the keys).

    A key left out takes the dataclass field's default (declared once, on
    :class:`ArrayConfig`).
    """
    known = set(_SITE_FILE_KEYS)
    unknown = sorted(set(d) - known)
    if unknown:
        raise ValueError(f"array {name!r}: unknown keys {unknown}; known: {sorted(known)}")
    kwargs = {  # a key set to null (a model's dump of an optional one) is left out
        field: convert(d[key]) for key, (field, convert) in _SITE_FILE_KEYS.items()
        if d.get(key) is not None
    }
    return ArrayConfig(name=name, **kwargs)
