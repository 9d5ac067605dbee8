"""fuel_curve.py - the quasi-static fuel-rate vs engine-generator power curve used by the MPC (seed Fig. 5.2a).

The MPC's second output is ``y_2 = sqrt(m_f)`` (seed 5.3, App. C.1).  The curve is given as a table
``(power_w, fuel_rate_gps)``; the powertrain package derives the real one from the engine and
generator maps (``components/engine_generator/fuel_vs_power.csv``).  Here ``sqrt(m_f)`` is
interpolated linearly between the table points (in the QP's units: power in kW, ``m_f`` in kg/s),
so within a segment ``y_2`` is exactly affine in power and its slope ``H`` (seed 5.6d) is the
segment slope.  Outside the table the end segments are extended linearly.
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Sequence

import numpy as np

from shevsim.core.errors import ScenarioError


class SqrtFuelCurve:
    """Piecewise-linear ``sqrt(m_f)`` as a function of engine-generator electrical power.

    Parameters
    ----------
    power_w : sequence of float
        Engine-generator electrical power [W], strictly increasing, >= 2 points.
    fuel_rate_gps : sequence of float
        Steady-state fuel rate [g/s] at each power, >= 0 and finite.
    where : str
        Name used in error messages.

    Attributes
    ----------
    p_kw : ndarray
        Power axis [kW].
    s : ndarray
        ``sqrt(fuel rate in kg/s)`` at the table points [sqrt(kg/s)].
    slope : ndarray
        Segment slopes of ``s`` [sqrt(kg/s) per kW] (``len(p_kw) - 1``).
    """

    def __init__(self, power_w: Sequence[float], fuel_rate_gps: Sequence[float], where: str = "fuel curve"):
        p = np.asarray(power_w, dtype=float).ravel()
        f = np.asarray(fuel_rate_gps, dtype=float).ravel()
        if p.size != f.size:
            raise ScenarioError(f"{where}: fuel_curve_w has {p.size} points but fuel_rate_gps has {f.size}")
        if p.size < 2:
            raise ScenarioError(f"{where}: the fuel curve needs at least 2 points, got {p.size}")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(f))):
            raise ScenarioError(f"{where}: the fuel curve contains NaN or inf")
        if np.any(np.diff(p) <= 0.0):
            i = int(np.argmax(np.diff(p) <= 0.0))
            raise ScenarioError(f"{where}: fuel_curve_w must be strictly increasing (point {i + 1}: "
                                f"{p[i + 1]} after {p[i]})")
        if np.any(f < 0.0):
            raise ScenarioError(f"{where}: fuel_rate_gps must be >= 0 (point {int(np.argmax(f < 0))})")
        self.power_w = p
        self.fuel_rate_gps = f
        self.p_kw = p / 1e3
        self.s = np.sqrt(f / 1e3)
        self.slope = np.diff(self.s) / np.diff(self.p_kw)
        self.where = where

    @classmethod
    def from_csv(cls, path: str | Path) -> "SqrtFuelCurve":
        """Read a CSV with ``#`` comment lines and columns ``elec_power_w`` (or ``power_w``) and ``fuel_gps``
        (or ``fuel_rate_gps``)."""
        path = Path(path)
        if not path.is_file():
            raise ScenarioError(f"{path}: fuel curve file not found")
        with path.open(newline="") as fh:
            rows = [r for r in csv.reader(line for line in fh if line.strip() and not line.lstrip().startswith("#"))]
        if not rows:
            raise ScenarioError(f"{path}: empty fuel curve file")
        head = [h.strip() for h in rows[0]]
        pcol = next((c for c in ("elec_power_w", "power_w") if c in head), None)
        fcol = next((c for c in ("fuel_gps", "fuel_rate_gps") if c in head), None)
        if pcol is None or fcol is None:
            raise ScenarioError(f"{path}: needs columns elec_power_w (or power_w) and fuel_gps "
                                f"(or fuel_rate_gps), found {head}")
        ip, jf = head.index(pcol), head.index(fcol)
        pw, fg = [], []
        for n, r in enumerate(rows[1:], start=2):
            try:
                pw.append(float(r[ip]))
                fg.append(float(r[jf]))
            except (ValueError, IndexError) as exc:
                raise ScenarioError(f"{path}: data row {n}: cannot read {pcol}/{fcol} ({exc})") from exc
        return cls(pw, fg, where=str(path))

    def sqrt_and_slope(self, power_kw: float) -> tuple[float, float]:
        """``(sqrt(m_f) [sqrt(kg/s)], d sqrt(m_f)/dP [sqrt(kg/s)/kW])`` at ``power_kw``."""
        i = int(np.searchsorted(self.p_kw, power_kw, side="right")) - 1
        i = min(max(i, 0), self.p_kw.size - 2)
        return float(self.s[i] + self.slope[i] * (power_kw - self.p_kw[i])), float(self.slope[i])

    def fuel_rate_gps_at(self, power_w: float) -> float:
        """Fuel rate [g/s] of the interpolated curve (``(sqrt m_f)^2``)."""
        s, _ = self.sqrt_and_slope(power_w / 1e3)
        return 1e3 * s * s


def placeholder_fuel_curve() -> SqrtFuelCurve:
    """A documented *placeholder* convex curve for tests only (not a real engine).

    ``m_f = 0.25 + 0.055 P + 5e-5 P^2`` [g/s] with ``P`` in kW on 0..236 kW: idle 0.25 g/s, marginal
    198 g/kWh at zero load rising to 240 g/kWh at 236 kW - the shape and magnitude of a
    heavy-duty diesel's quasi-static curve (cf. seed Fig. 5.2a), chosen so tests need no data file.
    """
    p = np.linspace(0.0, 236.0, 60)
    return SqrtFuelCurve(p * 1e3, 0.25 + 0.055 * p + 5e-5 * p * p, where="placeholder fuel curve")


__all__ = ["SqrtFuelCurve", "placeholder_fuel_curve"]
