"""models.py - fast calibration models with declared parameters and a library of candidate effects.

Each model (``cell``, ``vehicle``, ``engine`` soot - see :class:`EngineSootModel`) declares

* ``channels``: the measured channels it predicts (compared with the data);
* ``declared``: the parameters fitted from data (:class:`Param`: name with unit suffix, bounds, default);
* ``known``: parameters the data cannot determine (capacity, OCV curve, vehicle mass...) that come from
  ``--params`` (defaults below);
* ``effects``: named, physically meaningful extensions (:class:`Effect`), each with its own parameters.
  An effect that is not active takes its *neutral* parameter values, which make it vanish exactly.

``model.prepare(data)`` precomputes arrays once; ``model.simulate(ctx, values)`` returns the predicted
channels for a full parameter dictionary (declared + effect parameters; missing ones take defaults /
neutral values).  Simulations are a compiled tight loop (cell, numba) or vectorised NumPy (vehicle),
so a 1-hour, 10 Hz data set simulates in about a millisecond.

Cell model (equivalent circuit OCV-R-RC[-RC] + two-state or lumped thermal)
--------------------------------------------------------------------------
Current ``i`` positive = discharge, SI units, zero-order hold between samples (exact RC discretisation):

* SOC:        ``dz/dt = -i / (3600 * capacity_ah * capacity_scale)``
* RC pair k:  ``v_k[n+1] = v_k[n] exp(-dt/tau_k) + R_k s(T) (1 - exp(-dt/tau_k)) i[n]``
* terminal:   ``V = OCV(z) + dUdT (T_core - T_ref) - R0 s(T) i - sum v_k + M h``
* heat:       ``Q = i (OCV - V) - i T_core[K] dUdT``  (Bernardi: irreversible + reversible/entropic)
* two-state thermal (Lin/Kim; seed Ch. III):
  ``C_c dT_c/dt = Q + (T_s - T_c)/R_c``,  ``C_s dT_s/dt = (T_amb - T_s)/R_u - (T_s - T_c)/R_c``
  (integrated backward-Euler with Q explicit).  Lumped: ``C dT/dt = Q + (T_amb - T)/R_u``, T_s = T_c = T.

Cell effects: ``entropic_heat`` (dUdT != 0), ``arrhenius_resistance``
(``s(T) = exp(Ea/R (1/T - 1/T_ref))`` with the core temperature anchored to the measurement,
``T = T_s,measured + (T_c - T_s)_model``, so that errors of the thermal model do not enter the
resistance), ``cooling_change`` (convection coefficient multiplied by
``h_factor`` after an unknown time, smooth 20 s step: ``R_u -> R_u / (1 + (h_factor-1) sigmoid)``),
``ocv_hysteresis`` (one-state Plett: ``h[n+1] = e^{-g|i|dt/Q} h[n] - (1-e^{-g|i|dt/Q}) sign(i)``),
``capacity_fade`` (``capacity_scale``), ``current_offset`` (true current = measured - offset),
``low_soc_resistance`` (all resistances x ``1 + g exp(-SOC/s)``).

Vehicle model (road load, electrical power drawn from the bus)
-------------------------------------------------------------
``F = m (1 + f_rot) a + 1/2 rho CdA v^2 + m g Crr + m g theta(d)``, ``P_w = F v`` (v, a from the measured
speed, a by a centred difference over ``accel_window_s``), ``P = P_w / eta`` when ``P_w > 0`` else
``P_w eta regen_frac`` (one drive efficiency both ways: separate traction/regen efficiencies would make a
mass error indistinguishable from an aero error); regenerative power limited to ``-p_regen_max_w``;
plus auxiliary load.
Vehicle effects: ``road_grade`` (grade piecewise-linear in distance, 6 knots), ``aux_load``,
``mass_error``, ``rolling_error``, ``aero_error``, ``regen_limit``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

try:  # numba is a project dependency; fall back to plain Python if it is missing
    from numba import njit
except ImportError:  # pragma: no cover
    def njit(*args, **kwargs):
        if args and callable(args[0]):
            return args[0]
        return lambda f: f

from ..core.errors import DataError

T0_K = 273.15


@dataclass(frozen=True)
class Param:
    """A parameter: ``name`` (unit-suffixed), ``unit``, bounds ``lo..hi``, ``default``; ``log`` = fit in log space."""
    name: str
    unit: str
    lo: float
    hi: float
    default: float
    doc: str = ""
    log: bool = False


@dataclass(frozen=True)
class Effect:
    """A named model extension with its own parameters.

    ``neutral`` holds the parameter values that make the effect vanish; ``starts(ctx, base)`` returns extra
    starting points (dicts of parameter values; they may also move declared parameters, e.g. rescale R0
    so that a temperature law starts at the fitted mean resistance) for multi-start fits.
    """
    name: str
    description: str
    params: tuple[Param, ...]
    neutral: Mapping[str, float]
    channels: tuple[str, ...]
    starts: Any = None  # callable(ctx, base_values) -> list[dict] or None


# ----------------------------------------------------------------------------------------------- cell

# generic NCA 18650 open-circuit voltage (approximate shape; give the cell's own curve with --params)
DEFAULT_OCV_SOC = (0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
DEFAULT_OCV_V = (3.0, 3.3, 3.42, 3.52, 3.6, 3.66, 3.73, 3.81, 3.9, 3.99, 4.08, 4.19)
OCV_GRID_N = 401


@njit(cache=True)
def _cell_kernel(t, i_meas, t_amb, ts_meas, ocv_tab, soc0, tc0, ts0, cap_as, lumped,
                 r0, r1, tau1, r2, tau2, cc, cs, rc, ru,
                 dudt, ea_r, t_ref_k, t_chg, h_fac, chg_w, m_hyst, g_hyst, cap_scale, i_off,
                 ls_gain, ls_scale, anchor, out_v, out_tc, out_ts):  # pragma: no cover - compiled
    n = t.shape[0]
    ng = ocv_tab.shape[0]
    soc = soc0
    v1 = 0.0
    v2 = 0.0
    h = 0.0
    tc = tc0
    ts = ts0
    cap = cap_as * cap_scale
    t_ref_c = t_ref_k - 273.15
    for k in range(n):
        i = i_meas[k] - i_off
        x = soc * (ng - 1)
        if x <= 0.0:
            ocv = ocv_tab[0] + (ocv_tab[1] - ocv_tab[0]) * x
        elif x >= ng - 1:
            ocv = ocv_tab[ng - 1] + (ocv_tab[ng - 1] - ocv_tab[ng - 2]) * (x - (ng - 1))
        else:
            j = int(x)
            f = x - j
            ocv = ocv_tab[j] * (1.0 - f) + ocv_tab[j + 1] * f
        ocv += dudt * (tc - t_ref_c)
        tck = tc + 273.15
        if ea_r != 0.0:
            # core temperature anchored to the measured surface: T_s,meas + (T_c - T_s)_model
            tak = (ts_meas[k] + (tc - ts) + 273.15) if anchor else tck
            if tak < 200.0:
                tak = 200.0
            sr = math.exp(ea_r * (1.0 / tak - 1.0 / t_ref_k))
        else:
            sr = 1.0
        if ls_gain != 0.0:
            sr *= 1.0 + ls_gain * math.exp(-soc / ls_scale)
        v = ocv - r0 * sr * i - v1 - v2 + m_hyst * h
        out_v[k] = v
        out_tc[k] = tc
        out_ts[k] = ts
        if k == n - 1:
            break
        dt = t[k + 1] - t[k]
        q = i * (ocv - v) - i * tck * dudt
        # convection (possibly changed after t_chg)
        if h_fac != 1.0:
            z = (t[k] - t_chg) / chg_w
            if z > 40.0:
                sg = 1.0
            elif z < -40.0:
                sg = 0.0
            else:
                sg = 1.0 / (1.0 + math.exp(-z))
            ru_e = ru / (1.0 + (h_fac - 1.0) * sg)
        else:
            ru_e = ru
        ta = t_amb[k]
        if lumped:
            # C dT/dt = Q + (Ta - T)/Ru  (backward Euler)
            tc = (tc + dt / cc * (q + ta / ru_e)) / (1.0 + dt / (cc * ru_e))
            ts = tc
        else:
            # [cc/dt + 1/rc, -1/rc; -1/rc, cs/dt + 1/rc + 1/ru] [Tc; Ts] = [cc/dt Tc + Q; cs/dt Ts + Ta/ru]
            a11 = cc / dt + 1.0 / rc
            a12 = -1.0 / rc
            a22 = cs / dt + 1.0 / rc + 1.0 / ru_e
            b1 = cc / dt * tc + q
            b2 = cs / dt * ts + ta / ru_e
            det = a11 * a22 - a12 * a12
            tc = (b1 * a22 - a12 * b2) / det
            ts = (a11 * b2 - a12 * b1) / det
        e1 = math.exp(-dt / tau1)
        v1 = v1 * e1 + r1 * sr * (1.0 - e1) * i
        if r2 > 0.0:
            e2 = math.exp(-dt / tau2)
            v2 = v2 * e2 + r2 * sr * (1.0 - e2) * i
        soc -= dt * i / cap
        if g_hyst > 0.0 and m_hyst != 0.0:
            eh = math.exp(-abs(g_hyst * i * dt / cap_as))
            sgn = 1.0 if i > 0.0 else (-1.0 if i < 0.0 else 0.0)
            h = eh * h - (1.0 - eh) * sgn
    return 0


class CalibrationModel:
    """Base class: declared parameters, known parameters, effects, ``prepare`` and ``simulate``."""
    name = ""
    channels: tuple[str, ...] = ()
    optional_channels: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    declared: tuple[Param, ...] = ()
    known_defaults: dict = {}
    effects: dict

    def __init__(self, known: Mapping[str, Any] | None = None, where: str = "<params>"):
        known = dict(known or {})
        self.where = where
        self.known = dict(self.known_defaults)
        declared_names = {p.name for p in self._declared_for(self.known_defaults)}
        self.initial: dict[str, float] = {}
        for k, v in known.items():
            if k in self.known_defaults:
                self.known[k] = v
            elif k in declared_names:
                self.initial[k] = float(v)
            else:
                import difflib
                opts = list(self.known_defaults) + sorted(declared_names)
                best = difflib.get_close_matches(k, opts, n=1)
                hint = f" (did you mean '{best[0]}'?)" if best else ""
                raise DataError(f"{where}: unknown parameter '{k}' for model '{self.name}'{hint}; "
                                f"known: {', '.join(opts)}")
        self.declared = tuple(self._declared_for(self.known))
        for k, v in self.initial.items():
            p = next((q for q in self.declared if q.name == k), None)
            if p is not None and not (p.lo <= v <= p.hi):
                raise DataError(f"{where}: parameter '{k}' = {v} outside bounds [{p.lo}, {p.hi}] {p.unit}")
        self.effects = self._make_effects()

    # -- to override
    def _declared_for(self, known) -> tuple[Param, ...]:
        return self.declared

    def _make_effects(self) -> dict:
        return {}

    def prepare(self, data) -> dict:
        raise NotImplementedError

    def simulate(self, ctx: dict, values: Mapping[str, float]) -> dict:
        raise NotImplementedError

    def param_bounds(self, ctx: dict) -> dict:
        """Data-dependent bounds overriding the declared ones (name -> (lo, hi))."""
        return {}

    def regressors(self, ctx: dict) -> dict:
        """Candidate explanatory signals (name -> array) for residual correlation."""
        return {}

    # -- helpers
    def defaults(self) -> dict:
        d = {p.name: p.default for p in self.declared}
        d.update(self.initial)
        return d

    def full_values(self, values: Mapping[str, float]) -> dict:
        d = self.defaults()
        for e in self.effects.values():
            d.update(e.neutral)
        d.update(values)
        return d


class CellModel(CalibrationModel):
    """Cell OCV-R-RC (optional second RC) with two-state (default) or lumped thermal model.

    Channels: ``voltage_v`` [V], ``t_surface_c`` [degC], optional ``t_core_c`` [degC].
    Inputs: ``current_a`` [A, + discharge], ``t_ambient_c`` [degC].
    """
    name = "cell"
    channels = ("voltage_v", "t_surface_c")
    optional_channels = ("t_core_c",)
    inputs = ("current_a", "t_ambient_c")
    known_defaults = {
        "capacity_ah": 2.9,          # rated capacity [Ah]
        "soc0_frac": -1.0,           # initial SOC; < 0: from the first voltage sample by inverting the OCV
        "t_ref_c": 25.0,             # reference temperature of R and dU/dT [degC]
        "thermal": "two-state",      # or "lumped"
        "rc_pairs": 1,               # 1 or 2
        "change_width_s": 20.0,      # time scale of the smooth cooling_change step [s]
        "arrhenius_anchor": True,    # Arrhenius temperature = measured surface + modelled core-surface gradient
        "ocv_soc_frac": DEFAULT_OCV_SOC,
        "ocv_v": DEFAULT_OCV_V,
    }

    def _declared_for(self, known):
        ps = [Param("r0_ohm", "ohm", 1e-3, 0.5, 0.02, "series resistance at t_ref", log=True),
              Param("r1_ohm", "ohm", 1e-4, 0.5, 0.015, "RC pair 1 resistance", log=True),
              Param("tau1_s", "s", 0.5, 500.0, 20.0, "RC pair 1 time constant", log=True)]
        if int(known.get("rc_pairs", 1)) == 2:
            ps += [Param("r2_ohm", "ohm", 1e-4, 0.5, 0.01, "RC pair 2 resistance", log=True),
                   Param("tau2_s", "s", 10.0, 5000.0, 300.0, "RC pair 2 time constant", log=True)]
        if known.get("thermal", "two-state") == "lumped":
            ps += [Param("cc_j_k", "J/K", 5.0, 1000.0, 45.0, "lumped heat capacity", log=True),
                   Param("ru_k_w", "K/W", 0.5, 100.0, 10.0, "surface-to-ambient thermal resistance", log=True)]
        else:
            ps += [Param("cc_j_k", "J/K", 5.0, 1000.0, 40.0, "core heat capacity", log=True),
                   Param("cs_j_k", "J/K", 0.5, 200.0, 5.0, "surface (case) heat capacity", log=True),
                   Param("rc_k_w", "K/W", 0.05, 50.0, 2.0, "core-to-surface thermal resistance", log=True),
                   Param("ru_k_w", "K/W", 0.5, 100.0, 10.0, "surface-to-ambient thermal resistance", log=True)]
        return tuple(ps)

    def _make_effects(self):
        def arr_starts(ctx, base):
            # keep the mean resistance of the current fit: R_ref = R_fit / s(T_mean)
            tm = float(np.mean(ctx["df"]["t_surface_c"].to_numpy(float))) + T0_K
            tr = float(self.known["t_ref_c"]) + T0_K
            out = []
            for ea in (1500.0, 4000.0, 8000.0):
                sc = math.exp(ea * (1.0 / tm - 1.0 / tr))
                st = {"ea_r_k": ea}
                for name in ("r0_ohm", "r1_ohm", "r2_ohm"):
                    if name in base:
                        p = next(q for q in self.declared if q.name == name)
                        st[name] = min(max(base[name] / sc, p.lo * 1.01), p.hi * 0.99)
                out.append(st)
            return out

        def chg_starts(ctx, base):
            t = ctx["t"]
            return [{"t_change_s": t[0] + f * (t[-1] - t[0]), "h_factor": hf}
                    for f in (0.15, 0.35, 0.55, 0.75) for hf in (0.4, 2.5)]

        def hyst_starts(ctx, base):
            return [{"m_hyst_v": 0.01, "gamma_hyst": g} for g in (3.0, 30.0, 300.0)]

        effs = [
            Effect("entropic_heat", "reversible (entropic) heat -i T dU/dT and OCV temperature shift",
                   (Param("dudt_v_k", "V/K", -1e-3, 1e-3, 0.0, "entropic coefficient dOCV/dT"),),
                   {"dudt_v_k": 0.0}, ("t_surface_c", "voltage_v")),
            Effect("arrhenius_resistance", "R0, R1, R2 scale with exp(Ea/R (1/T - 1/T_ref)) of core temperature",
                   (Param("ea_r_k", "K", 0.0, 12000.0, 3000.0, "activation energy over gas constant"),),
                   {"ea_r_k": 0.0}, ("voltage_v", "t_surface_c"), arr_starts),
            Effect("cooling_change", "convection coefficient h multiplied by h_factor after an unknown time "
                   "(cooling fault or airflow change)",
                   (Param("t_change_s", "s", -1e12, 1e12, 0.0, "time of the change"),
                    Param("h_factor", "-", 0.1, 10.0, 1.0, "h after / h before", log=True)),
                   {"t_change_s": 0.0, "h_factor": 1.0}, ("t_surface_c",), chg_starts),
            Effect("ocv_hysteresis", "one-state OCV hysteresis M h, dh driven by |i| (Plett)",
                   (Param("m_hyst_v", "V", -0.1, 0.1, 0.01, "maximum hysteresis voltage"),
                    Param("gamma_hyst", "-", 0.1, 2000.0, 30.0, "hysteresis rate per unit charge", log=True)),
                   {"m_hyst_v": 0.0, "gamma_hyst": 0.0}, ("voltage_v",), hyst_starts),
            Effect("capacity_fade", "effective capacity differs from the rated one (aging)",
                   (Param("capacity_scale", "-", 0.3, 1.5, 1.0, "effective / rated capacity"),),
                   {"capacity_scale": 1.0}, ("voltage_v",)),
            Effect("current_offset", "current sensor offset: true current = measured - offset",
                   (Param("current_offset_a", "A", -1.0, 1.0, 0.0, "sensor offset"),),
                   {"current_offset_a": 0.0}, ("voltage_v",)),
            Effect("low_soc_resistance", "resistances rise at low SOC: R x (1 + g exp(-SOC / s)) "
                   "(electrode depletion / diffusion limitation near the end of discharge)",
                   (Param("r_lowsoc_gain", "-", 0.0, 50.0, 1.0, "gain g"),
                    Param("r_lowsoc_scale_frac", "-", 0.02, 0.3, 0.08, "SOC scale s")),
                   {"r_lowsoc_gain": 0.0, "r_lowsoc_scale_frac": 0.1}, ("voltage_v",)),
        ]
        return {e.name: e for e in effs}

    def prepare(self, data) -> dict:
        df = data.df
        t = df["time_s"].to_numpy(float)
        i = df["current_a"].to_numpy(float)
        ta = df["t_ambient_c"].to_numpy(float)
        soc_tab = np.asarray(self.known["ocv_soc_frac"], float)
        v_tab = np.asarray(self.known["ocv_v"], float)
        if soc_tab.shape != v_tab.shape or soc_tab.size < 2 or np.any(np.diff(soc_tab) <= 0):
            raise DataError(f"{self.where}: ocv_soc_frac must increase strictly and match ocv_v in length")
        grid = np.linspace(0.0, 1.0, OCV_GRID_N)
        # linear extrapolation outside the table
        ocv_tab = np.interp(grid, soc_tab, v_tab)
        lo, hi = soc_tab[0], soc_tab[-1]
        s_lo = (v_tab[1] - v_tab[0]) / (soc_tab[1] - soc_tab[0])
        s_hi = (v_tab[-1] - v_tab[-2]) / (soc_tab[-1] - soc_tab[-2])
        ocv_tab = np.where(grid < lo, v_tab[0] + s_lo * (grid - lo), ocv_tab)
        ocv_tab = np.where(grid > hi, v_tab[-1] + s_hi * (grid - hi), ocv_tab)
        soc0 = float(self.known["soc0_frac"])
        if soc0 < 0:
            # invert the OCV at the start (assumes the record starts at rest): mean voltage over the
            # initial low-current samples (at most 60 s) to average out sensor noise
            low = np.abs(i) <= 0.02 * max(float(np.abs(i).max()), 1e-9)
            n0 = int(np.argmin(low)) if not low.all() else low.size
            n0 = max(1, min(n0, int(np.searchsorted(t, t[0] + 60.0))))
            v0 = float(np.mean(df["voltage_v"].to_numpy(float)[:n0])) + float(np.mean(i[:n0])) * 0.02
            soc0 = float(np.interp(v0, ocv_tab, grid)) if np.all(np.diff(ocv_tab) > 0) else 0.5
        ts0 = float(df["t_surface_c"].iloc[0])
        return {"t": t, "i": i, "ta": ta, "ts_meas": df["t_surface_c"].to_numpy(float), "ocv_tab": ocv_tab, "soc0": soc0, "ts0": ts0,
                "tc0": float(df["t_core_c"].iloc[0]) if "t_core_c" in df else ts0,
                "has_core": "t_core_c" in df, "cap_as": float(self.known["capacity_ah"]) * 3600.0,
                "n": t.size, "df": df}

    def simulate(self, ctx, values):
        p = self.full_values(values)
        n = ctx["n"]
        ov, otc, ots = np.empty(n), np.empty(n), np.empty(n)
        lumped = self.known.get("thermal", "two-state") == "lumped"
        two = int(self.known.get("rc_pairs", 1)) == 2
        _cell_kernel(ctx["t"], ctx["i"], ctx["ta"], ctx["ts_meas"], ctx["ocv_tab"], ctx["soc0"], ctx["tc0"], ctx["ts0"],
                     ctx["cap_as"], lumped,
                     p["r0_ohm"], p["r1_ohm"], p["tau1_s"], p["r2_ohm"] if two else 0.0,
                     p["tau2_s"] if two else 1.0, p["cc_j_k"], p.get("cs_j_k", 1.0), p.get("rc_k_w", 1.0),
                     p["ru_k_w"], p["dudt_v_k"], p["ea_r_k"], float(self.known["t_ref_c"]) + T0_K,
                     p["t_change_s"], p["h_factor"], float(self.known["change_width_s"]), p["m_hyst_v"], p["gamma_hyst"],
                     p["capacity_scale"], p["current_offset_a"], p["r_lowsoc_gain"], p["r_lowsoc_scale_frac"],
                     bool(self.known["arrhenius_anchor"]), ov, otc, ots)
        out = {"voltage_v": ov, "t_surface_c": ots}
        if ctx["has_core"]:
            out["t_core_c"] = otc
        out["_t_core_c"] = otc
        return out

    def param_bounds(self, ctx):
        t = ctx["t"]
        return {"t_change_s": (float(t[0]), float(t[-1]))}

    def regressors(self, ctx):
        t, i = ctx["t"], ctx["i"]
        dt = np.diff(t, append=t[-1])
        ah = np.cumsum(i * dt) / 3600.0
        return {"time_s": t - t[0], "current_a": i, "abs_current_a": np.abs(i), "current_sq_a2": i * i,
                "discharged_ah": ah, "t_ambient_c": ctx["ta"],
                "t_surface_meas_c": ctx["df"]["t_surface_c"].to_numpy(float)}


class VehicleModel(CalibrationModel):
    """Road-load / electrical power model of a vehicle.

    Channel: ``power_w`` [W, + drawn from the bus, traction + auxiliaries].  Input: ``speed_mps``.
    """
    name = "vehicle"
    channels = ("power_w",)
    inputs = ("speed_mps",)
    known_defaults = {
        "mass_kg": 15554.0,          # nominal vehicle mass (M-ATV class SHEV)
        "cd_a_m2": 4.1,              # drag coefficient x frontal area
        "crr": 0.01,                 # rolling-resistance coefficient
        "rho_kg_m3": 1.2,
        "g_mps2": 9.81,
        "rot_inertia_frac": 0.05,    # equivalent rotating mass / mass
        "p_aux_w": 0.0,              # known auxiliary load
        "regen_frac": 1.0,           # fraction of braking wheel power the controller routes to the motor
        "accel_window_s": 2.0,       # centred-difference window for acceleration
    }
    N_GRADE = 6

    def _declared_for(self, known):
        return (Param("eta_drive_frac", "-", 0.4, 1.0, 0.85,
                      "motor + inverter + transmission efficiency (both directions)"),)

    def _make_effects(self):
        g = tuple(Param(f"grade_{k}_frac", "-", -0.15, 0.15, 0.0, f"road grade at distance knot {k}")
                  for k in range(self.N_GRADE))

        def regen_starts(ctx, base):
            pm = ctx["power_meas"]
            neg = -pm[pm < 0]
            if neg.size < 10:
                return []
            return [{"p_regen_max_w": float(np.quantile(neg, q))} for q in (0.5, 0.8, 0.95)]

        effs = [
            Effect("road_grade", f"road grade, piecewise linear in distance ({self.N_GRADE} knots)", g,
                   {p.name: 0.0 for p in g}, ("power_w",)),
            Effect("aux_load", "constant auxiliary electrical load (HVAC, cooling fans, electronics)",
                   (Param("p_aux_extra_w", "W", -2e4, 1e5, 1000.0, "extra auxiliary load"),),
                   {"p_aux_extra_w": 0.0}, ("power_w",)),
            Effect("mass_error", "vehicle mass differs from the nominal (payload)",
                   (Param("mass_scale", "-", 0.5, 2.0, 1.0, "actual / nominal mass"),),
                   {"mass_scale": 1.0}, ("power_w",)),
            Effect("rolling_error", "rolling-resistance coefficient differs from the nominal (tyres, surface)",
                   (Param("crr_scale", "-", 0.1, 5.0, 1.0, "actual / nominal Crr", log=True),),
                   {"crr_scale": 1.0}, ("power_w",)),
            Effect("aero_error", "aerodynamic drag area differs from the nominal (body, wind)",
                   (Param("cda_scale", "-", 0.2, 5.0, 1.0, "actual / nominal CdA", log=True),),
                   {"cda_scale": 1.0}, ("power_w",)),
            Effect("regen_limit", "regenerative braking power limited (machine/battery limit)",
                   (Param("p_regen_max_w", "W", 0.0, 2e6, 5e4, "maximum regenerative power"),),
                   {"p_regen_max_w": 1e12}, ("power_w",), regen_starts),
        ]
        return {e.name: e for e in effs}

    def prepare(self, data) -> dict:
        df = data.df
        t = df["time_s"].to_numpy(float)
        v = df["speed_mps"].to_numpy(float)
        w = float(self.known["accel_window_s"])
        a = (np.interp(t + w / 2, t, v) - np.interp(t - w / 2, t, v)) / w
        # at the ends the window is truncated by interp clamping: correct the divisor
        span = np.minimum(t + w / 2, t[-1]) - np.maximum(t - w / 2, t[0])
        a = a * w / np.maximum(span, 1e-9)
        dt = np.diff(t, prepend=t[0])
        d = np.cumsum(v * dt)
        dn = d / max(d[-1], 1e-9) * (self.N_GRADE - 1)
        knot = np.clip(np.floor(dn).astype(int), 0, self.N_GRADE - 2)
        frac = dn - knot
        return {"t": t, "v": v, "a": a, "d": d, "knot": knot, "frac": frac,
                "power_meas": df["power_w"].to_numpy(float), "n": t.size, "df": df}

    def simulate(self, ctx, values):
        p = self.full_values(values)
        k = self.known
        v, a = ctx["v"], ctx["a"]
        m = k["mass_kg"] * p["mass_scale"]
        gk = np.array([p[f"grade_{j}_frac"] for j in range(self.N_GRADE)])
        if np.any(gk != 0.0):
            grade = gk[ctx["knot"]] * (1 - ctx["frac"]) + gk[ctx["knot"] + 1] * ctx["frac"]
        else:
            grade = 0.0
        moving = v > 0.05
        f = (m * (1 + k["rot_inertia_frac"]) * a + 0.5 * k["rho_kg_m3"] * k["cd_a_m2"] * p["cda_scale"] * v * v
             + m * k["g_mps2"] * (k["crr"] * p["crr_scale"] * moving + grade))
        pw = f * v
        eta = p["eta_drive_frac"]
        pe = np.where(pw > 0, pw / eta, pw * eta * k["regen_frac"])
        pe = np.maximum(pe, -p["p_regen_max_w"])
        return {"power_w": pe + k["p_aux_w"] + p["p_aux_extra_w"]}

    def regressors(self, ctx):
        v, a = ctx["v"], ctx["a"]
        return {"time_s": ctx["t"] - ctx["t"][0], "speed_mps": v, "speed_sq": v * v, "speed_cube": v ** 3,
                "accel_mps2": a, "inertial_power": a * v, "distance_m": ctx["d"],
                "braking": (a * v < 0).astype(float) * np.abs(a * v)}


ENGINE_ON_KW = 0.5


@njit(cache=True)
def _lag(t, x, tau, y0):  # pragma: no cover - compiled
    """First-order lag dy/dt = (x - y)/tau, exact for x held between samples."""
    n = t.shape[0]
    y = np.empty(n)
    yk = y0
    for k in range(n):
        y[k] = yk
        if k < n - 1:
            e = math.exp(-(t[k + 1] - t[k]) / tau)
            yk = yk * e + (1.0 - e) * x[k]
    return y


class EngineSootModel(CalibrationModel):
    """Engine soot emission: quasi-static map plus (as effects) transient soot and analyzer behaviour.

    Channel: ``soot_rate_mgps`` [mg/s].  Input: ``power_w`` [W, engine brake power, >= 0].

    Quasi-static map (declared): ``s = a + b P + c P^2`` with P in kW while the engine runs
    (P > 0.5 kW; a series hybrid stops its engine at zero power command, so s = 0 then).  Effects:
    ``transient_soot`` (turbo lag: the air path follows power with a first-order lag tau_turbo; fuel
    injected without the matching boost makes extra soot ``k max(P - P_air, 0)``; seed App. A.2: more than
    half the soot of a transient cycle is transient), ``analyzer_lag`` (the measured rate is the true rate
    through a first-order lag), ``analyzer_offset`` (constant analyzer offset).
    """
    name = "engine"
    channels = ("soot_rate_mgps",)
    inputs = ("power_w",)
    known_defaults = {}

    def _declared_for(self, known):
        return (Param("soot_a_mgps", "mg/s", 0.0, 50.0, 0.5, "soot at zero power"),
                Param("soot_b_mgps_kw", "mg/s/kW", -1.0, 5.0, 0.03, "linear map coefficient"),
                Param("soot_c_mgps_kw2", "mg/s/kW^2", -0.01, 0.05, 2e-4, "quadratic map coefficient"))

    def _make_effects(self):
        def tr_starts(ctx, base):
            return [{"tau_turbo_s": tau} for tau in (0.5, 2.0, 6.0)]

        def lag_starts(ctx, base):
            return [{"tau_analyzer_s": tau} for tau in (0.5, 3.0, 15.0)]

        effs = [
            Effect("transient_soot", "turbo lag: extra soot k max(P - P_air, 0), P_air = lag(P, tau_turbo)",
                   (Param("k_transient_mgps_kw", "mg/s/kW", 0.0, 5.0, 0.05, "soot per kW of air deficit"),
                    Param("tau_turbo_s", "s", 0.1, 30.0, 2.0, "air-path time constant", log=True)),
                   {"k_transient_mgps_kw": 0.0, "tau_turbo_s": 1.0}, ("soot_rate_mgps",), tr_starts),
            Effect("analyzer_lag", "soot analyzer responds with a first-order lag",
                   (Param("tau_analyzer_s", "s", 0.05, 60.0, 2.0, "analyzer time constant", log=True),),
                   {"tau_analyzer_s": 0.0}, ("soot_rate_mgps",), lag_starts),
            Effect("analyzer_offset", "constant soot analyzer offset",
                   (Param("soot_offset_mgps", "mg/s", -20.0, 20.0, 0.0, "offset"),),
                   {"soot_offset_mgps": 0.0}, ("soot_rate_mgps",)),
        ]
        return {e.name: e for e in effs}

    def prepare(self, data) -> dict:
        df = data.df
        return {"t": df["time_s"].to_numpy(float), "p_kw": df["power_w"].to_numpy(float) / 1000.0,
                "n": len(df), "df": df}

    def simulate(self, ctx, values):
        p = self.full_values(values)
        t, pk = ctx["t"], ctx["p_kw"]
        s = (p["soot_a_mgps"] + p["soot_b_mgps_kw"] * pk + p["soot_c_mgps_kw2"] * pk * pk) * (pk > ENGINE_ON_KW)
        if p["k_transient_mgps_kw"] != 0.0:
            p_air = _lag(t, pk, p["tau_turbo_s"], pk[0])
            s = s + p["k_transient_mgps_kw"] * np.maximum(pk - p_air, 0.0)
        if p["tau_analyzer_s"] > 0.0:
            s = _lag(t, s, p["tau_analyzer_s"], s[0])
        return {"soot_rate_mgps": s + p["soot_offset_mgps"]}

    def regressors(self, ctx):
        t, pk = ctx["t"], ctx["p_kw"]
        dp = np.gradient(pk, t)
        return {"time_s": t - t[0], "power_kw": pk, "power_rate_kwps": dp, "power_rise_kwps": np.maximum(dp, 0.0)}


MODELS = {"cell": CellModel, "vehicle": VehicleModel, "engine": EngineSootModel}


def get_model(name: str, known: Mapping[str, Any] | None = None, where: str = "<params>") -> CalibrationModel:
    """Instantiate calibration model ``name`` (``cell`` or ``vehicle``) with known parameters."""
    if name not in MODELS:
        raise DataError(f"unknown calibration model '{name}'; available: {', '.join(MODELS)}")
    return MODELS[name](known, where)
