"""engine.py - calibration model of engine soot (see models.py for the interface)."""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
from numba import njit

from ..core.errors import DataError
from .models import CalibrationModel, Effect, Param

T0_K = 273.15

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


