"""lumped.py - the lumped (one-state) electro-thermal cell of seed Ch. IV and its thermal current limit.

Seed eq. 4.1-4.3 (current + = discharge)::

    M c_p dT/dt = -h A_b (T - T_inf) + I^2 R_e - I T dS / (n F)
    dT/dt = alpha T + beta T u + gamma u^2 + eta                     (4.2)
    alpha = -A_b h / (M c_p), beta = -dS / (n F M c_p), gamma = R_e / (M c_p), eta = A_b h T_inf / (M c_p)

T in kelvin inside (the entropic term is in absolute temperature); inputs and outputs in degC.

The thermal current limit (4.10-4.13) uses the thesis's forward-Euler model ``A_T = 1 + alpha dt``:
the largest virtual input that puts T on ``T_max`` after N steps is
``v_bar = (T_max - A_T^N T_k) / sum_{i<N} A_T^i`` (4.12) and, with beta T and gamma held over the
horizon, ``gamma u^2 + beta_bar u + eta - v_bar/dt = 0`` gives the discharge and charge limits (4.13a/b).
If the discriminant is negative no current keeps T at the limit; both limits collapse to the
least-heating current ``-beta_bar / (2 gamma)``.

The electrical limits of Fig. 4.10 (4.16a/b) and the power capability (4.17a, 4.18a, 4.19a) are given here for an
OCV-R cell: the thesis's eq. 4.6 with its two RC branches left out (the lumped R_e above is the only resistance),
so the state is SOC alone and 4.19a loses its RC sums: ``V_{k+N} = V_oc(SOC_k - I N dt / (3600 C_b)) - R_e I``.

The plant (:func:`step_exact`) integrates 4.2 exactly over a step with the current held (the equation is
linear in T for a held current), so the limiter's Euler model and the plant differ as they would on a
real cell's controller.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shevsim.battery.cell import FARADAY_C_MOL
from shevsim.core.errors import ScenarioError

__all__ = ["LumpedCell", "OcvTable", "step_exact", "thermal_current_limits", "soc_current_limit",
           "voltage_current_limit", "predicted_voltage"]

KELVIN = 273.15


@dataclass(frozen=True)
class LumpedCell:
    """One cell of seed Ch. IV as a lumped thermal mass with a lumped internal resistance.

    Attributes
    ----------
    mass_kg : float
        M [kg].
    cp_j_kgk : float
        c_p [J/kg/K] (seed Sec. 4.2.2 identified 1248 for the e-Moli ICR18650J).
    area_m2 : float
        A_b, the convecting surface [m^2].
    r_e_ohm : float
        R_e, the lumped internal resistance (ohmic + polarisation) [ohm].
    ds_j_molk : float
        Entropy change dS of the cell reaction [J/mol/K] (n = 1).
    capacity_ah : float
        C_b [Ah].
    """

    mass_kg: float
    cp_j_kgk: float
    area_m2: float
    r_e_ohm: float
    ds_j_molk: float = 0.0
    capacity_ah: float = 2.3

    def __post_init__(self) -> None:
        for name in ("mass_kg", "cp_j_kgk", "area_m2", "r_e_ohm", "capacity_ah"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0):
                raise ScenarioError(f"LumpedCell: field '{name}' must be a finite positive number, got {v!r}")
        if not math.isfinite(self.ds_j_molk):
            raise ScenarioError(f"LumpedCell: field 'ds_j_molk' must be finite, got {self.ds_j_molk!r}")

    def coefficients(self, h_w_m2k: float, t_amb_c: float) -> tuple[float, float, float, float]:
        """(alpha [1/s], beta [1/(s A)], gamma [K/(s A^2)], eta [K/s]) of eq. 4.3."""
        mcp = self.mass_kg * self.cp_j_kgk
        alpha = -self.area_m2 * h_w_m2k / mcp
        beta = -self.ds_j_molk / (FARADAY_C_MOL * mcp)
        gamma = self.r_e_ohm / mcp
        eta = self.area_m2 * h_w_m2k * (t_amb_c + KELVIN) / mcp
        return alpha, beta, gamma, eta


def step_exact(cell: LumpedCell, t_c: float, i_a: float, dt_s: float, h_w_m2k: float, t_amb_c: float) -> float:
    """Temperature [degC] after ``dt_s`` with the current ``i_a`` held: exact solution of 4.2."""
    alpha, beta, gamma, eta = cell.coefficients(h_w_m2k, t_amb_c)
    a = alpha + beta * i_a                  # dT/dt = a T + b, T in K
    b = gamma * i_a * i_a + eta
    t_k = t_c + KELVIN
    if a == 0.0:
        return t_k + b * dt_s - KELVIN
    t_inf = -b / a
    return t_inf + (t_k - t_inf) * math.exp(a * dt_s) - KELVIN


def thermal_current_limits(cell: LumpedCell, t_c: float, t_max_c: float, horizon_steps: int, dt_s: float,
                           h_w_m2k: float, t_amb_c: float) -> tuple[float, float]:
    """(I_max discharge >= ..., I_min charge) [A] of eq. 4.13a/b for the horizon ``horizon_steps * dt_s``."""
    if horizon_steps < 1:
        raise ScenarioError(f"thermal_current_limits: horizon_steps must be >= 1, got {horizon_steps}")
    alpha, beta, gamma, eta = cell.coefficients(h_w_m2k, t_amb_c)
    a_t = 1.0 + alpha * dt_s
    t_k = t_c + KELVIN
    geo = float(horizon_steps) if a_t == 1.0 else (1.0 - a_t ** horizon_steps) / (1.0 - a_t)
    v_bar = (t_max_c + KELVIN - a_t ** horizon_steps * t_k) / geo        # 4.12
    beta_bar = beta * t_k
    disc = beta_bar * beta_bar - 4.0 * gamma * (eta - v_bar / dt_s)
    if disc < 0.0:
        least = -beta_bar / (2.0 * gamma)
        return least, least
    root = math.sqrt(disc)
    return (-beta_bar + root) / (2.0 * gamma), (-beta_bar - root) / (2.0 * gamma)   # 4.13a, 4.13b


class OcvTable:
    """OCV(SOC) as a piecewise-linear table read from a CSV with columns ``soc_frac``, ``ocv_v``.

    The SOC column must rise strictly and the OCV must not fall with SOC (a clear error names the file).
    Outside the table the end values are held.
    """

    def __init__(self, path: str | Path):
        from shevsim.battery.cell import read_csv_table
        from shevsim.core.errors import DataError
        rows = read_csv_table(Path(path), ("soc_frac", "ocv_v"))
        soc = np.array([r[0] for r in rows], dtype=float)
        ocv = np.array([r[1] for r in rows], dtype=float)
        if soc.size < 2 or np.any(np.diff(soc) <= 0.0):
            raise DataError(f"{path}: column 'soc_frac' must rise strictly over at least two rows")
        if np.any(np.diff(ocv) < 0.0):
            raise DataError(f"{path}: column 'ocv_v' must not fall as SOC rises")
        self.path = Path(path)
        self.soc_frac, self.ocv_v = soc, ocv

    def __call__(self, soc_frac: float) -> float:
        return float(np.interp(soc_frac, self.soc_frac, self.ocv_v))

    def slope(self, soc_frac: float) -> float:
        """dV_oc/dSOC [V] of the table segment that a discharge from ``soc_frac`` enters (the one below it)."""
        j = int(np.clip(np.searchsorted(self.soc_frac, soc_frac, side="left"), 1, self.soc_frac.size - 1))
        return float((self.ocv_v[j] - self.ocv_v[j - 1]) / (self.soc_frac[j] - self.soc_frac[j - 1]))

    def mean_v(self) -> float:
        """The table's mean OCV over its SOC range [V] (rest energy per charge)."""
        return float(np.trapezoid(self.ocv_v, self.soc_frac) / (self.soc_frac[-1] - self.soc_frac[0]))


def soc_current_limit(soc_frac: float, soc_min_frac: float, capacity_ah: float, horizon_steps: int,
                      dt_s: float) -> float:
    """Discharge limit [A] of 4.16a: the current that puts SOC on ``soc_min_frac`` after N steps."""
    return (soc_frac - soc_min_frac) * 3600.0 * capacity_ah / (horizon_steps * dt_s)


def voltage_current_limit(ocv: OcvTable, soc_frac: float, r_ohm: float, v_min_v: float, capacity_ah: float,
                          horizon_steps: int, dt_s: float) -> float:
    """Discharge limit [A] of 4.16b for an OCV-R cell, the OCV linearised at ``soc_frac``.

    ``V_{k+N} = V_oc(SOC_k) - (dV_oc/dSOC N dt / (3600 C_b) + R) I`` set equal to ``v_min_v``.
    """
    gain = ocv.slope(soc_frac) * horizon_steps * dt_s / (3600.0 * capacity_ah) + r_ohm
    return (ocv(soc_frac) - v_min_v) / gain


def predicted_voltage(ocv: OcvTable, soc_frac: float, i_a: float, r_ohm: float, capacity_ah: float,
                      horizon_steps: int, dt_s: float) -> float:
    """Terminal voltage [V] after N steps at the held current ``i_a``: 4.19a without the RC terms."""
    return ocv(soc_frac - i_a * horizon_steps * dt_s / (3600.0 * capacity_ah)) - i_a * r_ohm
