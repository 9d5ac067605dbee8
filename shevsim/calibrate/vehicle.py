"""vehicle.py - calibration model of a vehicle (see models.py for the interface)."""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
from numba import njit

from ..core.errors import DataError
from .models import CalibrationModel, Effect, Param

T0_K = 273.15

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


