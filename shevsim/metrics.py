"""metrics.py - run metrics of a SHEV simulation (seed App. A), pure functions on a results DataFrame.

The DataFrame has a ``time_s`` column and one column per signal named
``component.port`` as in the SHEV signal table of ``docs/DEVELOPING.md``
(``vehicle.speed_mps``, ``engine_generator.fuel_mass_g``, ``battery.soc_pct``,
``battery.current_a``, ``cycle.speed_ref_mps`` ...). Cumulative quantities
(``*_energy_j``, ``fuel_mass_g``, ``soot_mass_mg``, ``distance_m``) are used as
differences last - first, so a run need not start them at zero.

Metrics
-------
* **Fuel economy, SOC-sustained (seed A.1)**:

      FE = 1/N_s sum_k  int_{t_k}^{t_k+T} v dt  /  int_{t_k}^{t_k+T} mdot_f dt

  over all window starts ``t_k`` with ``SOC(t_k) = SOC(t_k + T)`` (T = cycle
  duration; the seed runs two consecutive cycles). ``t_k`` are the roots of
  ``d(xi) = SOC(xi + T) - SOC(xi)`` on the sample grid (sign changes, located by
  linear interpolation, plus exact zeros), and, when ``soc_tolerance_pct > 0``,
  also every sample with ``|d| <= soc_tolerance_pct``. Fuel mass is converted to
  volume with `DIESEL_DENSITY_KG_PER_L`; L/100 km is ``100 / FE``.
* **Fuel economy, delta-SOC corrected** (whole run): the net battery energy
  drawn from the cells' OCV, ``E_b = delta(battery.chem_energy_j)`` (> 0 when the
  battery ends lower), is converted to the fuel the engine-generator would need
  to supply it at its average efficiency over the run,
  ``eta = E_gen,el / m_fuel`` (J of generator electrical output per g of fuel,
  ``E_gen,el = delta(fuel_energy_j - engine_loss_energy_j - gen_loss_energy_j)``):
  ``m_corr = m_fuel + E_b / eta``. The battery's own loss on refilling is not
  charged (so a deficit is slightly under-corrected; the term is small for
  small delta-SOC). Without ``chem_energy_j`` the SOC change times the pack
  energy (options ``pack_capacity_ah`` x ``pack_nominal_voltage_v``) is used;
  without the loss columns ``eta = eg_efficiency x LHV``.
* **Soot**: ``delta(soot_mass_mg) / 1000 / distance_km`` (g/km) over the run.
* **Effective Ah-processed (seed A.3)**: ``Ah_eff = int kappa(T, SOC, I) |I_cell| dt
  / 3600`` per cell (trapezoidal). Default ``kappa`` is a constant
  (``ah_severity_factor``, 1): the seed says the severity factor collapses to a
  constant for its narrow SOC window and perfect cooling. Option
  ``ah_weighting = "wang2011"``: Arrhenius / C-rate severity after Onori et al.
  (2012, seed ref. [141]) with the A123 26650 ageing law of Wang et al. (J. Power
  Sources 196, 2011): ``kappa = (exp(-(Ea - a c)/(R T)) / exp(-(Ea - a c0)/(R T0)))^(1/z)``,
  ``Ea = 31700 J/mol``, ``a = 370.3 J/mol``, ``z = 0.55``, reference ``c0 = 1 C``,
  ``T0 = 25 degC`` (Wang's prefactor B held constant - a simplification), T from
  ``battery.t_core_c``.
* **Battery-current histogram (Fig. A.8)**: cell current ``I_cell = battery.current_a /
  cells_parallel`` (+ discharge), sample counts per bin (default 5 A bins from
  -120 to 120 A/cell), fraction of samples, counts below/above the range.
* **Speed-trace miss**: ``(vehicle.speed_mps - cycle.speed_ref_mps) x 3.6``; RMS and
  max absolute (km/h) over the run.
* **Energy balance closure**: sources = fuel chemical energy
  (``*.fuel_energy_j``) + net battery energy drawn from the OCV
  (``*.chem_energy_j``); sinks = every loss (``*loss_energy_j``: engine, generator,
  battery, motors, ...) + auxiliary load (``*.aux_energy_j``) + road loads
  (``vehicle.aero_energy_j``, ``rolling_energy_j``, friction ``brake_energy_j``,
  ``grade_energy_j``) + change of kinetic energy (``vehicle.kinetic_energy_j``) + change of the
  engine-generator shaft's kinetic energy (``*.shaft_kinetic_energy_j``, when recorded; the
  engine-generator's own balance is fuel = elec + losses + shaft KE change).
  Residual = sources - sinks; closure error = residual / throughput, with
  throughput = fuel energy + gross battery energy (sum of |increments| of
  ``chem_energy_j``). Per-node residuals (engine-generator, bus, battery, motor,
  driveline, vehicle) are reported too when the bus/motor cumulative energies are
  recorded (`node_balances()`), to locate a closure error.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from shevsim.core.errors import DataError

#: Diesel density (kg/L): 3,167 g/gal (ANL GREET fuel specifications, conventional diesel) / 3.78541 L/gal.
DIESEL_DENSITY_KG_PER_L = 3.167 / 3.78541
#: Diesel lower heating value (J/kg): 128,450 Btu/gal (ANL GREET) x 1055.06 J/Btu / 3.167 kg/gal = 42.79 MJ/kg.
DIESEL_LHV_J_PER_KG = 128450.0 * 1055.06 / 3.167
#: Cells in parallel in the pack (SPEC 2.1: 130s10p).
CELLS_PARALLEL = 10
#: Default histogram edges of cell current (A/cell), 5 A bins (seed Fig. A.8 discusses 15-25 A/cell);
#: +/-120 A/cell covers the A123 26650's 10 s pulse rating (~120 A).
HIST_EDGES_A = tuple(float(x) for x in range(-120, 125, 5))
#: Gas constant (J/mol/K).
R_GAS = 8.314462618

_WANG_EA = 31700.0
_WANG_ALPHA = 370.3
_WANG_Z = 0.55


def _col(df, name: str) -> np.ndarray:
    if name not in df.columns:
        raise DataError(f"results: missing column '{name}' (have {sorted(df.columns)[:12]}...)")
    return np.asarray(df[name], dtype=float)


class ResultColumns:
    """A result's columns as [`compute_metrics()`][shevsim.metrics.compute_metrics] reads them (``columns``, ``[name]``), without building a
    DataFrame: ``time_s`` then the signals, each a read-only view of the result's own array."""

    def __init__(self, time_s, signals: Mapping[str, np.ndarray]):
        self._cols = {"time_s": time_s, **signals}
        self.columns = list(self._cols)

    def __getitem__(self, name: str) -> np.ndarray:
        v = np.asarray(self._cols[name]).view()
        v.flags.writeable = False
        return v


def _has(df, *names) -> bool:
    return all(n in df.columns for n in names)


def _delta(df, name: str) -> float:
    x = _col(df, name)
    return float(x[-1] - x[0])


def _trapz(y: np.ndarray, t: np.ndarray) -> float:
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def _cumtrapz(y: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))])


def cumulative_distance_m(df) -> np.ndarray:
    """Distance travelled since the first sample (m): ``vehicle.distance_m`` or the integral of speed."""
    if "vehicle.distance_m" in df.columns:
        d = _col(df, "vehicle.distance_m")
        return d - d[0]
    return _cumtrapz(_col(df, "vehicle.speed_mps"), _col(df, "time_s"))


# ---------------------------------------------------------------- fuel economy
def sustainable_window_starts(time_s, soc_pct, cycle_duration_s: float, soc_tolerance_pct: float = 0.0) -> np.ndarray:
    """Window starts ``t_k`` with ``SOC(t_k) = SOC(t_k + T)`` (seed A.1), sorted.

    Parameters
    ----------
    time_s, soc_pct : array_like
        Time (s, increasing) and SOC (%).
    cycle_duration_s : float
        Window length T (s).
    soc_tolerance_pct : float
        Also accept samples with ``|SOC(xi + T) - SOC(xi)| <= tol``.
    """
    t = np.asarray(time_s, float)
    s = np.asarray(soc_pct, float)
    T = float(cycle_duration_s)
    if T <= 0:
        raise DataError(f"cycle duration must be > 0 s, got {T}")
    eps = 1e-9 * max(1.0, abs(t[-1]))
    xi = t[t + T <= t[-1] + eps]
    if xi.size == 0:
        return np.empty(0)
    d = np.interp(np.minimum(xi + T, t[-1]), t, s) - np.interp(xi, t, s)
    roots = list(xi[d == 0.0])
    sc = np.nonzero(d[:-1] * d[1:] < 0.0)[0]
    for i in sc:
        roots.append(xi[i] - d[i] * (xi[i + 1] - xi[i]) / (d[i + 1] - d[i]))
    if soc_tolerance_pct > 0:
        roots.extend(xi[np.abs(d) <= soc_tolerance_pct])
    if not roots:
        return np.empty(0)
    r = np.unique(np.round(np.asarray(roots, float), 9))
    return r


def fuel_economy_soc_sustained(df, cycle_duration_s: float, soc_tolerance_pct: float = 0.0,
                               density_kg_per_l: float = DIESEL_DENSITY_KG_PER_L,
                               soc_col: str = "battery.soc_pct",
                               fuel_col: str = "engine_generator.fuel_mass_g") -> dict:
    """Seed A.1 fuel economy over windows of one cycle length with equal start/end SOC.

    Returns
    -------
    dict
        ``fuel_economy_kmpl`` (None when no window qualifies), ``fuel_consumption_l_per_100km``,
        ``n_windows`` (N_s), ``window_starts_s`` (first 20), ``window_kmpl_min``/``max``.
    """
    t = _col(df, "time_s")
    soc = _col(df, soc_col)
    fuel = _col(df, fuel_col)
    dist = cumulative_distance_m(df)
    tk = sustainable_window_starts(t, soc, cycle_duration_s, soc_tolerance_pct)
    T = float(cycle_duration_s)
    out: dict[str, Any] = {"n_windows": int(tk.size), "window_starts_s": [float(x) for x in tk[:20]],
                           "fuel_economy_kmpl": None, "fuel_consumption_l_per_100km": None,
                           "window_kmpl_min": None, "window_kmpl_max": None, "n_windows_no_fuel": 0}
    if tk.size == 0:
        return out
    end = np.minimum(tk + T, t[-1])
    dd_km = (np.interp(end, t, dist) - np.interp(tk, t, dist)) / 1000.0
    df_l = (np.interp(end, t, fuel) - np.interp(tk, t, fuel)) / 1000.0 / density_kg_per_l
    ok = df_l > 0
    out["n_windows_no_fuel"] = int(np.sum(~ok))
    if not np.any(ok):
        return out
    fe = dd_km[ok] / df_l[ok]
    m = float(np.mean(fe))
    out.update(fuel_economy_kmpl=m, fuel_consumption_l_per_100km=100.0 / m if m > 0 else None,
               window_kmpl_min=float(fe.min()), window_kmpl_max=float(fe.max()))
    return out


def per_cycle_summary(df, cycle_duration_s: float, density_kg_per_l: float = DIESEL_DENSITY_KG_PER_L,
                      soc_col: str = "battery.soc_pct", fuel_col: str = "engine_generator.fuel_mass_g") -> list[dict]:
    """Distance, fuel, km/L and SOC change of each complete repetition ``[k T, (k+1) T]`` of the cycle.

    The simpler reading of SOC sustainability (use the cycle whose end SOC returns to its
    start SOC) can be taken from here; the seed's A.1 figure is
    `fuel_economy_soc_sustained()`.
    """
    t = _col(df, "time_s")
    T = float(cycle_duration_s)
    dist = cumulative_distance_m(df)
    fuel = _col(df, fuel_col) if fuel_col in df.columns else None
    soc = _col(df, soc_col) if soc_col in df.columns else None
    eps = 1e-9 * max(1.0, abs(t[-1]))
    n = 0
    while t[0] + (n + 1) * T <= t[-1] + eps:
        n += 1
    if n == 0:
        return []
    # every boundary interpolated in one call per signal (np.interp on the whole record is O(len) per call:
    # a long run has thousands of cycles)
    a = t[0] + T * np.arange(n, dtype=float)
    b = np.minimum(t[0] + T * np.arange(1, n + 1, dtype=float), t[-1])
    d_a, d_b = np.interp(a, t, dist), np.interp(b, t, dist)
    f_a, f_b = (np.interp(a, t, fuel), np.interp(b, t, fuel)) if fuel is not None else (None, None)
    s_a, s_b = (np.interp(a, t, soc), np.interp(b, t, soc)) if soc is not None else (None, None)
    out = []
    for k in range(n):
        row: dict[str, Any] = {"index": k, "start_s": float(a[k]), "end_s": float(b[k]),
                               "distance_km": float(d_b[k] - d_a[k]) / 1000.0}
        if fuel is not None:
            fg = float(f_b[k] - f_a[k])
            row["fuel_mass_g"] = fg
            row["fuel_economy_kmpl"] = row["distance_km"] / (fg / 1000.0 / density_kg_per_l) if fg > 0 else None
        if soc is not None:
            row["soc_start_pct"] = float(s_a[k])
            row["delta_soc_pct"] = float(s_b[k]) - row["soc_start_pct"]
        out.append(row)
    return out


def eg_energy_per_fuel_j_per_g(df, name: str = "engine_generator") -> float | None:
    """Average engine-generator electrical energy out per gram of fuel over the run (J/g)."""
    cols = [f"{name}.fuel_energy_j", f"{name}.engine_loss_energy_j", f"{name}.gen_loss_energy_j",
            f"{name}.fuel_mass_g"]
    if not _has(df, *cols):
        return None
    fuel_g = _delta(df, cols[3])
    if fuel_g <= 0:
        return None
    e_el = _delta(df, cols[0]) - _delta(df, cols[1]) - _delta(df, cols[2])
    return e_el / fuel_g


def fuel_economy_dsoc_corrected(df, density_kg_per_l: float = DIESEL_DENSITY_KG_PER_L,
                                pack_capacity_ah: float | None = None, pack_nominal_voltage_v: float | None = None,
                                eg_efficiency: float | None = None, lhv_j_per_kg: float = DIESEL_LHV_J_PER_KG,
                                eg: str = "engine_generator", battery: str = "battery") -> dict:
    """Whole-run fuel economy, raw and corrected for the battery's net energy (see module docstring)."""
    dist_km = float(cumulative_distance_m(df)[-1]) / 1000.0
    fuel_g = _delta(df, f"{eg}.fuel_mass_g")
    out: dict[str, Any] = {"distance_km": dist_km, "fuel_mass_g": fuel_g, "fuel_economy_raw_kmpl": None,
                           "battery_net_energy_j": None, "eg_elec_energy_per_fuel_j_per_g": None,
                           "fuel_equivalent_g": None, "fuel_economy_kmpl": None,
                           "fuel_consumption_l_per_100km": None, "method": None}
    if fuel_g > 0:
        out["fuel_economy_raw_kmpl"] = dist_km / (fuel_g / 1000.0 / density_kg_per_l)
    if f"{battery}.chem_energy_j" in df.columns:
        e_b = _delta(df, f"{battery}.chem_energy_j")
        out["method"] = "battery chem_energy_j"
    elif f"{battery}.soc_pct" in df.columns and pack_capacity_ah and pack_nominal_voltage_v:
        e_b = -_delta(df, f"{battery}.soc_pct") / 100.0 * pack_capacity_ah * 3600.0 * pack_nominal_voltage_v
        out["method"] = "delta SOC x pack capacity x nominal voltage"
    else:
        return out
    out["battery_net_energy_j"] = e_b
    eta = eg_energy_per_fuel_j_per_g(df, eg)
    if eta is None and eg_efficiency:
        eta = eg_efficiency * lhv_j_per_kg / 1000.0
    if eta is None or eta <= 0:
        return out
    out["eg_elec_energy_per_fuel_j_per_g"] = eta
    m_corr = fuel_g + e_b / eta
    out["fuel_equivalent_g"] = m_corr
    if m_corr > 0:
        fe = dist_km / (m_corr / 1000.0 / density_kg_per_l)
        out["fuel_economy_kmpl"] = fe
        # no distance (an idle cycle): fuel was burnt for nothing, consumption per distance is undefined
        out["fuel_consumption_l_per_100km"] = 100.0 / fe if fe > 0 else None
    return out


def soot_dsoc_corrected(soot_mg: float, fuel_g: float, fuel_equivalent_g: float | None,
                        distance_km: float) -> float | None:
    """Soot on the fuel economy's Delta-SOC-corrected basis [g/km] (issue 14).

    The battery's net energy is booked as ``fuel_equivalent_g - fuel_g`` grams of fuel (the same
    equivalent as `fuel_economy_dsoc_corrected()`); that fuel is charged with the run's mean soot per
    gram of fuel: ``soot_corr = soot x fuel_equivalent / fuel``.  A run that ends with a lower SOC thus
    no longer shows the soot it borrowed from the battery as a cut.  None when an input is missing or
    no fuel was burnt."""
    if fuel_equivalent_g is None or not fuel_g > 0 or not distance_km > 0:
        return None
    return soot_mg / 1000.0 * (fuel_equivalent_g / fuel_g) / distance_km


# ------------------------------------------------------------------ battery use
def severity_factor_wang2011(current_c_rate, temperature_c) -> np.ndarray:
    """Onori-style severity factor from the Wang et al. (2011) A123 ageing law (1 at 1 C, 25 degC)."""
    c = np.abs(np.asarray(current_c_rate, float))
    T = np.asarray(temperature_c, float) + 273.15
    T0 = 298.15
    expo = (-(_WANG_EA - _WANG_ALPHA * c) / (R_GAS * T) + (_WANG_EA - _WANG_ALPHA * 1.0) / (R_GAS * T0)) / _WANG_Z
    return np.exp(expo)


def effective_ah_processed(df, cells_parallel: int = CELLS_PARALLEL, weighting: str = "constant",
                           severity_factor: float = 1.0, cell_capacity_ah: float = 2.3,
                           current_col: str = "battery.current_a", temp_col: str = "battery.t_core_c") -> dict:
    """Seed A.3 effective Ah-processed per cell (Ah) and the plain Ah throughput per cell."""
    t = _col(df, "time_s")
    i_cell = _col(df, current_col) / float(cells_parallel)
    plain = _trapz(np.abs(i_cell), t) / 3600.0
    if weighting == "constant":
        kappa = np.full_like(i_cell, float(severity_factor))
    elif weighting == "wang2011":
        kappa = severity_factor_wang2011(i_cell / cell_capacity_ah, _col(df, temp_col))
    else:
        raise DataError(f"metrics option 'ah_weighting': unknown weighting {weighting!r} "
                        "(use 'constant' or 'wang2011')")
    eff = _trapz(kappa * np.abs(i_cell), t) / 3600.0
    return {"ah_effective_cell_ah": eff, "ah_throughput_cell_ah": plain, "ah_weighting": weighting}


def current_histogram(df, cells_parallel: int = CELLS_PARALLEL, edges_a=HIST_EDGES_A,
                      current_col: str = "battery.current_a") -> dict:
    """Histogram of cell current (A/cell, + discharge): counts per bin ``[e_i, e_i+1)`` (last bin closed)."""
    i_cell = _col(df, current_col) / float(cells_parallel)
    edges = np.asarray(edges_a, float)
    if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise DataError("metrics option 'hist_edges_a': need >= 2 increasing bin edges")
    counts, _ = np.histogram(i_cell, bins=edges)
    n = i_cell.size
    return {"edges_a": [float(e) for e in edges], "counts": [int(c) for c in counts],
            "fraction": [float(c) / n for c in counts],
            "below_count": int(np.sum(i_cell < edges[0])), "above_count": int(np.sum(i_cell > edges[-1])),
            "n_samples": int(n)}


# ---------------------------------------------------------------- trace & soot
def speed_trace_miss(df, speed_col: str = "vehicle.speed_mps", ref_col: str = "cycle.speed_ref_mps") -> dict:
    """RMS and maximum absolute speed error (km/h) over the run."""
    e = (_col(df, speed_col) - _col(df, ref_col)) * 3.6
    return {"speed_miss_rms_kmh": float(math.sqrt(np.mean(e * e))), "speed_miss_max_kmh": float(np.max(np.abs(e)))}


def soot_g_per_km(df, soot_col: str = "engine_generator.soot_mass_mg") -> float | None:
    """Total soot over the run per distance (g/km)."""
    dist_km = float(cumulative_distance_m(df)[-1]) / 1000.0
    if dist_km <= 0:
        return None
    return _delta(df, soot_col) / 1000.0 / dist_km


# -------------------------------------------------------------- energy balance
ROAD_TERMS = ("aero_energy_j", "rolling_energy_j", "brake_energy_j", "grade_energy_j")


def energy_balance(df, vehicle: str = "vehicle") -> dict:
    """Closure of fuel + battery -> losses + aux + road loads + delta KE (see module docstring).

    Returns
    -------
    dict
        ``sources_j``, ``sinks_j`` (term -> J), ``residual_j``, ``throughput_j``,
        ``closure_error_frac`` (residual / throughput), ``missing`` (expected columns
        not found; the closure is None when any is missing) and ``nodes_j`` (per-node
        residuals, `node_balances()`).
    """
    cols = list(df.columns)
    fuel = [c for c in cols if c.endswith(".fuel_energy_j")]
    chem = [c for c in cols if c.endswith(".chem_energy_j")]
    losses = [c for c in cols if c.endswith("loss_energy_j")]
    aux = [c for c in cols if c.endswith(".aux_energy_j")]
    road = [f"{vehicle}.{n}" for n in ROAD_TERMS]
    ke = f"{vehicle}.kinetic_energy_j"
    missing = [c for c in road + [ke] if c not in cols]
    if not fuel:
        missing.append("*.fuel_energy_j")
    if not chem:
        missing.append("*.chem_energy_j")
    if not losses:
        missing.append("*loss_energy_j")
    out: dict[str, Any] = {"sources_j": {}, "sinks_j": {}, "residual_j": None, "throughput_j": None,
                           "closure_error_frac": None, "missing": missing, "nodes_j": node_balances(df, vehicle)}
    if missing:
        return out
    src = {c: _delta(df, c) for c in fuel + chem}
    sink = {c: _delta(df, c) for c in losses + aux + road}
    sink[ke + " (delta)"] = _delta(df, ke)
    for c in cols:
        if c.endswith(".shaft_kinetic_energy_j"):
            sink[c + " (delta)"] = _delta(df, c)
    residual = sum(src.values()) - sum(sink.values())
    throughput = sum(_delta(df, c) for c in fuel) + sum(float(np.sum(np.abs(np.diff(_col(df, c))))) for c in chem)
    out.update(sources_j=src, sinks_j=sink, residual_j=residual, throughput_j=throughput,
               closure_error_frac=residual / throughput if throughput > 0 else None)
    return out


#: Per-node balances (name -> (+terms, -terms)); each residual should be ~0. Evaluated when all columns exist
#: (a term ending in ``?`` is optional: counted when recorded, else taken as 0).
NODE_BALANCES = {
    "engine_generator": (("engine_generator.fuel_energy_j",),
                         ("engine_generator.engine_loss_energy_j", "engine_generator.gen_loss_energy_j",
                          "bus.gen_energy_j", "engine_generator.shaft_kinetic_energy_j?")),
    "bus": (("bus.gen_energy_j", "bus.battery_energy_j"), ("bus.motor_energy_j", "bus.aux_energy_j")),
    "battery": (("battery.chem_energy_j",), ("battery.loss_energy_j", "bus.battery_energy_j")),
    "motor_electrical": (("bus.motor_energy_j",), ("motor.elec_energy_j",)),
    "motor": (("motor.elec_energy_j",), ("motor.loss_energy_j", "motor.mech_energy_j")),
    "driveline": (("motor.mech_energy_j",), ("{v}.traction_energy_j",)),
    "vehicle": (("{v}.traction_energy_j",),
                ("{v}.brake_energy_j", "{v}.aero_energy_j", "{v}.rolling_energy_j", "{v}.grade_energy_j",
                 "{v}.kinetic_energy_j")),
}


def node_balances(df, vehicle: str = "vehicle") -> dict:
    """Residual (J) of each node of `NODE_BALANCES` whose columns are all present.

    Locates where a whole-chain closure error comes from: e.g. ``motor`` =
    delta(elec_energy) - delta(loss_energy) - delta(mech_energy). Nodes with missing
    columns are omitted.
    """
    res = {}
    for node, (plus, minus) in NODE_BALANCES.items():
        plus = [c.format(v=vehicle) for c in plus]
        minus = [c.format(v=vehicle) for c in minus]
        minus = [c.rstrip("?") for c in minus if not c.endswith("?") or c.rstrip("?") in df.columns]
        if all(c in df.columns for c in plus + minus):
            res[node] = sum(_delta(df, c) for c in plus) - sum(_delta(df, c) for c in minus)
    return res


# ------------------------------------------------------------------- all in one
def _find_param(parameters: Mapping, comp: str, *keys):
    p = parameters.get(comp, {}) if isinstance(parameters, Mapping) else {}
    for k in keys:
        if k in p:
            return p[k]
    return None


def _cycle_duration(df, opts: Mapping, parameters: Mapping) -> tuple[float | None, str]:
    if opts.get("cycle_duration_s"):
        return float(opts["cycle_duration_s"]), "option cycle_duration_s"
    f = _find_param(parameters, "cycle", "cycle_file")
    if f and Path(f).is_file():
        from shevsim.cycles import load_cycle
        return load_cycle(f).duration_s, f"cycle_file {f}"
    if "cycle.time_in_cycle_s" in df.columns:
        tc = _col(df, "cycle.time_in_cycle_s")
        wraps = np.nonzero(np.diff(tc) < 0)[0]
        if wraps.size:
            return float(tc[wraps[0]] + (_col(df, "time_s")[wraps[0] + 1] - _col(df, "time_s")[wraps[0]])
                         - tc[wraps[0] + 1]), "cycle.time_in_cycle_s wrap"
    return None, "unknown"


def _clean(x):
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


def compute_metrics(df, params: Mapping | None = None) -> dict:
    """All run metrics as a JSON-serialisable dict (units in the keys).

    Parameters
    ----------
    df : pandas.DataFrame
        ``time_s`` + ``component.port`` columns. Metrics whose columns are absent are
        None and listed in ``notes``.
    params : mapping, optional
        Either flat options or ``{"scenario": options, "parameters": {component: params}}``
        (what [`shevsim.run`][shevsim.run] passes). Options: ``cycle_duration_s`` (else from the
        cycle component's ``cycle_file`` or from ``cycle.time_in_cycle_s``),
        ``soc_tolerance_pct`` (0), ``cells_parallel`` (battery parameter with
        'parallel' in its name, else 10), ``fuel_density_kg_per_l``, ``ah_weighting``
        ('constant' | 'wang2011'), ``ah_severity_factor`` (1), ``hist_edges_a``,
        ``pack_capacity_ah``, ``pack_nominal_voltage_v``, ``eg_efficiency``.
    """
    params = dict(params or {})
    parameters = params.pop("parameters", {}) or {}
    opts = dict(params.pop("scenario", {}) or {})
    opts.update(params)
    notes: list[str] = []
    m: dict[str, Any] = {}
    t = _col(df, "time_s")
    if t.size < 2:
        raise DataError("results: need at least 2 samples to compute metrics")
    m["duration_s"] = float(t[-1] - t[0])
    density = float(opts.get("fuel_density_kg_per_l", DIESEL_DENSITY_KG_PER_L))
    m["fuel_density_kg_per_l"] = density
    if "vehicle.speed_mps" in df.columns or "vehicle.distance_m" in df.columns:
        m["distance_km"] = float(cumulative_distance_m(df)[-1]) / 1000.0
    else:
        notes.append("no vehicle speed/distance: distance-based metrics skipped")
        m["distance_km"] = None
    if m["distance_km"] is not None and not m["distance_km"] > 0:
        notes.append(f"the vehicle did not move (distance {m['distance_km']:g} km): per-distance metrics "
                     f"(L/100 km, g/km) are null")

    cells_p = _cells_parallel(opts, parameters)
    m["cells_parallel"] = cells_p

    # fuel economy A.1
    T, t_src = _cycle_duration(df, opts, parameters)
    m["cycle_duration_s"] = T
    if T is not None:
        m["n_cycles"] = m["duration_s"] / T
    _fuel_metrics(m, df, opts, T, density, notes)
    if "battery.soc_pct" in df.columns:
        soc = _col(df, "battery.soc_pct")
        m.update(soc_start_pct=float(soc[0]), soc_end_pct=float(soc[-1]), delta_soc_pct=float(soc[-1] - soc[0]),
                 soc_min_pct=float(soc.min()), soc_max_pct=float(soc.max()))

    _soot_metrics(m, df)
    _battery_current_metrics(m, df, opts, cells_p, notes)

    if _has(df, "vehicle.speed_mps", "cycle.speed_ref_mps"):
        m.update(speed_trace_miss(df))
    else:
        notes.append("speed-trace miss skipped: needs vehicle.speed_mps and cycle.speed_ref_mps")

    eb = energy_balance(df)
    m["energy_balance"] = eb
    m["energy_closure_error_frac"] = eb["closure_error_frac"]
    if eb["missing"]:
        notes.append(f"energy balance incomplete: missing {eb['missing']}")
    m["notes"] = notes
    return _clean(m)


def _cells_parallel(opts: Mapping, parameters: Mapping) -> int:
    """Cells in parallel: the option, else the battery parameter with 'parallel' in its name, else the default."""
    cells_p = opts.get("cells_parallel")
    if cells_p is None:
        bp = parameters.get("battery", {}) if isinstance(parameters, Mapping) else {}
        for k, v in bp.items():
            if "parallel" in k and isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0:
                cells_p = v
                break
    cells_p = int(cells_p or CELLS_PARALLEL)
    return cells_p


def _fuel_metrics(m: dict, df, opts: Mapping, T: float | None, density: float, notes: list) -> None:
    """Fuel economy: SOC-sustained windows (A.1), per-cycle summary and the delta-SOC corrected figures."""
    if T is not None and m["distance_km"] is not None and _has(df, "battery.soc_pct", "engine_generator.fuel_mass_g"):
        fe = fuel_economy_soc_sustained(df, T, float(opts.get("soc_tolerance_pct", 0.0)), density)
        m["fuel_economy_soc_sustained_kmpl"] = fe["fuel_economy_kmpl"]
        m["fuel_consumption_soc_sustained_l_per_100km"] = fe["fuel_consumption_l_per_100km"]
        m["soc_sustained_windows_count"] = fe["n_windows"]
        m["soc_sustained_window_kmpl_min"] = fe["window_kmpl_min"]
        m["soc_sustained_window_kmpl_max"] = fe["window_kmpl_max"]
        if fe["fuel_economy_kmpl"] is None:
            notes.append("A.1: no window with SOC(t) = SOC(t + T_cycle) (run >= 2 cycles, or SOC never returns)")
    else:
        m["fuel_economy_soc_sustained_kmpl"] = None
        notes.append("A.1 fuel economy skipped: needs cycle duration, battery.soc_pct, engine_generator.fuel_mass_g")

    if T is not None and m["distance_km"] is not None:
        m["per_cycle"] = per_cycle_summary(df, T, density)

    if m["distance_km"] is not None and "engine_generator.fuel_mass_g" in df.columns:
        c = fuel_economy_dsoc_corrected(df, density, opts.get("pack_capacity_ah"), opts.get("pack_nominal_voltage_v"),
                                        opts.get("eg_efficiency"))
        m["fuel_mass_g"] = c["fuel_mass_g"]
        m["fuel_economy_raw_kmpl"] = c["fuel_economy_raw_kmpl"]
        m["fuel_economy_dsoc_corrected_kmpl"] = c["fuel_economy_kmpl"]
        m["fuel_consumption_dsoc_corrected_l_per_100km"] = c["fuel_consumption_l_per_100km"]
        m["battery_net_energy_j"] = c["battery_net_energy_j"]
        m["eg_elec_energy_per_fuel_j_per_g"] = c["eg_elec_energy_per_fuel_j_per_g"]
        m["fuel_equivalent_g"] = c["fuel_equivalent_g"]
        if c["fuel_economy_kmpl"] is None:
            notes.append("delta-SOC corrected fuel economy unavailable (battery energy or EG efficiency missing)")


def _soot_metrics(m: dict, df) -> None:
    """Soot per km, per fuel and delta-SOC corrected (needs distance and the soot counter)."""
    if m["distance_km"] and "engine_generator.soot_mass_mg" in df.columns:
        m["soot_g_per_km"] = soot_g_per_km(df)
        m["soot_mass_g"] = _delta(df, "engine_generator.soot_mass_mg") / 1000.0
        if m.get("fuel_mass_g"):
            m["soot_per_fuel_g_per_kg"] = m["soot_mass_g"] / (m["fuel_mass_g"] / 1000.0)
            m["soot_dsoc_corrected_g_per_km"] = soot_dsoc_corrected(
                1000.0 * m["soot_mass_g"], m["fuel_mass_g"], m.get("fuel_equivalent_g"), m["distance_km"])


def _battery_current_metrics(m: dict, df, opts: Mapping, cells_p: int, notes: list) -> None:
    """Effective Ah processed per cell, the current histogram, cell RMS and peak current."""
    if "battery.current_a" in df.columns:
        m.update(effective_ah_processed(df, cells_p, str(opts.get("ah_weighting", "constant")),
                                        float(opts.get("ah_severity_factor", 1.0))))
        m["battery_current_histogram"] = current_histogram(df, cells_p, opts.get("hist_edges_a", HIST_EDGES_A))
        i = _col(df, "battery.current_a") / cells_p
        m["cell_current_rms_a"] = float(math.sqrt(np.mean(i * i)))
        m["cell_current_max_abs_a"] = float(np.max(np.abs(i)))
    else:
        notes.append("no battery.current_a: Ah-processed and current histogram skipped")


# --------------------------------------------------------------- a result's metrics, never raising
#: cumulative counters reported as ``component.port``: final value
COUNTER_SUFFIXES = (".fallback_count", ".clamp_count", ".shed_count", ".shed_time_s")


def result_metrics(res, options: Mapping | None = None) -> dict:
    """Metrics of a [`Result`][shevsim.core.results.Result]; never raises.

    The final value of every robustness counter (``*.fallback_count``, ``*.clamp_count``,
    ``*.shed_count``, ``*.shed_time_s``), plus [`compute_metrics()`][shevsim.metrics.compute_metrics] when the vehicle's speed was
    recorded. A metric that cannot be computed (an idle cycle, no distance, a run stopped after one
    sample) is None and ``notes`` says why. ``options`` default to the scenario's ``[metrics]``
    table saved in ``res.meta["metrics_options"]``.
    """
    opts = dict(res.meta.get("metrics_options") or {}) if options is None else dict(options)
    out: dict[str, Any] = {}
    notes: list[str] = []
    for name, values in res.signals.items():
        if name.endswith(COUNTER_SUFFIXES) and len(values):
            out[name] = float(values[-1])
    term = getattr(res, "termination", "completed")
    if str(term) != "completed":
        notes.append(f"the run did not complete ({term}): metrics cover what was simulated")
    if "vehicle.speed_mps" in res.signals:
        try:
            with np.errstate(divide="ignore", invalid="ignore"):
                m = compute_metrics(ResultColumns(res.time_s, res.signals),
                                    {"scenario": opts, "parameters": res.parameters})
            notes = notes + list(m.pop("notes", []))
            out.update(m)
        except Exception as exc:  # noqa: BLE001 - a metric never costs the run: null and the reason
            notes.append(f"SHEV metrics could not be computed: {type(exc).__name__}: {exc}")
    out["notes"] = notes
    return _clean(out)
