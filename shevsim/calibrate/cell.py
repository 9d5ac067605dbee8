"""cell.py - calibration model of a cell (see models.py for the interface)."""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
from numba import njit

from ..core.errors import DataError
from .models import CalibrationModel, Effect, Param

T0_K = 273.15

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


