"""cell.py - calibration of the battery component's own cell model against measured cell data.

The model fitted here IS the battery component's model: :func:`shevsim.battery.model.run_profile` steps
:func:`shevsim.battery.model.cell_step` - the function the ``battery`` component runs - through the
measured current profile (compiled).  Every fitted quantity is a parameter of
:class:`shevsim.components.battery.BatteryPackParams` (same name, unit and default), so what the
calibration finds is written as a parameter overlay (``params.toml``, table ``[battery]``) that
``shevsim run SCENARIO --params battery=DIR/params.toml`` uses, and :meth:`CellModel.replay` steps the
battery component with that overlay through :class:`shevsim.core.master.Master` to show that the simulator
reproduces the fit.

Nominal model
-------------
``--params`` gives either a battery parameter file (``[params]`` with BatteryPackParams names; its
``*_file`` tables are used) or the short form (``[params]`` ``capacity_ah``, ``soc0_frac``, ... and
``[ocv]`` ``soc_frac``/``ocv_v``).  In the short form the cell is foreign to the project's tables: the
OCV comes from ``[ocv]`` (written to ``ocv.csv`` beside the overlay), the ECM tables are the
project's A123 tables looked up at 25 degC (their SOC shape; magnitudes fitted through the scale
factors), no entropic heat and one RC branch (``rc_pairs = 2`` keeps the second).  Either way the data
fix the cell layout (1 s x 1 p), the input mode (current) and the initial temperature (first surface
sample); the initial SOC is ``soc0_frac`` or, when negative (default), the OCV inverse of the first
rest voltage.

Declared (fitted) parameters: ``rs_scale, r1_scale, c1_scale`` (and ``r2_scale, c2_scale`` when the
nominal has the second branch), ``kt_w_mk``, ``cp_j_kgk``, ``h_conv_factor``.

What the record resolves (:meth:`CellModel.record_resolution`, in the report): the slow branch's time
constant R2 C2 is limited to the record's longest rest after current when that rest is at least the
nominal slow branch's own time constant (a relaxation no rest shows decaying is a series capacitor - a
capacity); and the rests measure the current-sensor offset (:meth:`CellModel.measured_params`: the median
logged current at rest, its standard error from the rests' effective sample size; the calibration holds
``current_offset_a`` there).  A rest (:meth:`CellModel._rest_spans`) is where the cell carries no current: the
logged current at one level no larger than C/20 (absolute thresholds from the nominal capacity and the current
channel's own noise and resolution, not from the record's peak), without a trend, and the voltage relaxing
the way the nominal's RC branches relax after the current before it - a CV taper (current decaying, voltage held) or a small
constant charge is not a rest.

Effects: :data:`CELL_EFFECTS`, a list of functions ``f(model) -> Effect | None`` (None: does not apply
to this nominal model).  Add an effect with one function and one entry; its parameters must be
battery parameters (or ``name[k]`` elements of a list parameter).
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..battery import model as bm
from ..battery.cell import CellTables
from ..components.battery import BatteryPackParams
from ..core.errors import DataError
from .models import CalibrationModel, Effect, Param, sampling_grid

T0_K = 273.15
_FIELDS = {f.name for f in dataclasses.fields(BatteryPackParams)}
# legacy short-form keys of --params (the calibration's own keys before the one-source model)
_LEGACY = {"soc0_frac", "ocv_soc_frac", "ocv_v", "rc_pairs", "change_width_s", "h_conv_w_m2k", "t_ref_c"}
N_DUDT_KNOTS = 4


# ------------------------------------------------------------------------------------------ effects

def entropic_heat(model) -> Effect:
    """Reversible heat ``-i T dU/dT(SOC)``, dU/dT piecewise linear through knots over the SOC range visited."""
    ks = model.dudt_knots
    ps = tuple(Param(f"dudt_v_k[{k}]", "V/K", -2e-3, 2e-3, 0.0, f"dU/dT at SOC {s:.3f}") for k, s in enumerate(ks))
    return Effect("entropic_heat", "reversible (entropic) heat -i T dU/dT with dU/dT a function of SOC "
                  f"({len(ks)} knots; sign changes allowed)", ps, {p.name: 0.0 for p in ps}, ("t_surface_c",))


def arrhenius_resistance(model) -> Effect:
    def starts(ctx, base):
        return [{"arrhenius_ea_r_k": ea} for ea in (1500.0, 4000.0, 8000.0)]
    return Effect("arrhenius_resistance", "all resistances x exp(Ea/R (1/T - 1/T_ref)) of the cell mean "
                  "temperature (T_ref: the record's mean surface temperature)",
                  (Param("arrhenius_ea_r_k", "K", 0.0, 15000.0, 3000.0, "activation energy / gas constant"),),
                  {"arrhenius_ea_r_k": 0.0}, ("voltage_v", "t_surface_c"), starts,
                  # seen in the voltage (the resistances fall as the cell warms); its heat is the circuit's
                  # heat, whose form is uncertain (CellModel.model_form_terms): a temperature law fitted to
                  # bend the heat alone is not the explanation.  The claim is tested on the voltage alone
                  # (workflow _Run.channel_claim): Ea/R refitted with the temperature's weight 0 and the
                  # thermal parameters held at the candidate fit (the temperature the law reads stays the one
                  # the record's temperature channel made), the electrical ones free to trade against it
                  evidence=("voltage_v",), channel_claim=(("voltage_v",), ("kt_w_mk", "cp_j_kgk", "h_conv_factor")),
                  # over a drive the cell warms while its SOC falls, so a resistance that changes with the SOC
                  # (the nominal's tables rarely have the cell's own SOC shape) reads as a temperature law; the
                  # claim must hold beside the library's SOC law of the resistances, of either sign (a negative
                  # gain: falling towards low SOC; a long scale: nearly linear in SOC).  The PyBaMM no-effect
                  # drive with the heat of mixing (none_2_mixing: 25 -> 44 degC while the resistance falls 6 %
                  # from 80 to 60 % SOC) read 507 +- 300 K on the voltage alone without it, 181 +- 270 K with it.
                  # Started on each branch (g < 0 with a short scale, g > 0 with a long one, g = 0): from one
                  # start the fit stopped on the wrong branch (a reviewer's swing record: 3457 K at a cost above
                  # the branch with no law)
                  # And beside the particles' solid diffusion: its overpotential builds under current and relaxes
                  # at rest, as the cell's temperature rises and falls - a drive-and-park record moves the two
                  # together (a new user's PyBaMM DFN Ramadass2004 drives, no temperature law, warming 1.3-2.2 K
                  # over four 10-minute drives: 2466 +- 440 K on the voltage alone beside the SOC law, named at
                  # 1709 K; beside the diffusion too, 0 K.  Chen2020's true 1413 K: 1623 +- 530 K, still named)
                  claim_nuisance=(("low_soc_resistance", {"lowsoc_r_gain": (-0.95, 50.0),
                                                          "lowsoc_r_scale_frac": (0.02, 3.0)},
                                   ({"lowsoc_r_gain": 0.0, "lowsoc_r_scale_frac": 1.0},
                                    {"lowsoc_r_gain": -0.5, "lowsoc_r_scale_frac": 0.2},
                                    {"lowsoc_r_gain": 2.0, "lowsoc_r_scale_frac": 2.5})),
                                  ("solid_diffusion", {"diffusion_time_s": (0.0, 2.0e5)},
                                   ({"diffusion_time_s": 0.0}, {"diffusion_time_s": 300.0},
                                    {"diffusion_time_s": 3000.0}))))


def cooling_change(model) -> Effect:
    def starts(ctx, base):
        t = ctx["t"]
        return [{"h_change_time_s": t[0] + f * (t[-1] - t[0]), "h_change_factor": hf}
                for f in (0.15, 0.35, 0.55, 0.75) for hf in (0.4, 2.5)]
    return Effect("cooling_change", "convection coefficient multiplied by a factor after an unknown time "
                  "(cooling fault, airflow change)",
                  (Param("h_change_time_s", "s", -1e12, 1e12, 0.0, "time of the change"),
                   Param("h_change_factor", "1", 0.05, 20.0, 1.0, "h after / h before", log=True)),
                  {"h_change_time_s": 0.0, "h_change_factor": 1.0}, ("t_surface_c",), starts)


def ocv_hysteresis(model) -> Effect:
    def starts(ctx, base):
        return [{"hyst_max_v": 0.01, "hyst_rate": g} for g in (3.0, 30.0, 300.0)]
    return Effect("ocv_hysteresis", "one-state OCV hysteresis M h, h driven by the charge passed (Plett)",
                  (Param("hyst_max_v", "V", -0.1, 0.1, 0.01, "maximum hysteresis voltage",
                         plausible=(-0.05, 0.05)),     # Li-ion OCV hysteresis: a few mV (NMC) to some 40 mV (LFP)
                   Param("hyst_rate", "1", 0.1, 3000.0, 30.0, "rate per unit SOC", log=True)),
                  {"hyst_max_v": 0.0, "hyst_rate": 30.0}, ("voltage_v",), starts)


def capacity(model) -> Effect:
    rated = model.base.capacity_ah

    def starts(ctx, base):
        # from the rated capacity alone the fit can stall beside another freedom already fitted: on the trial's
        # Ramadass2004 record with 13 % lost, capacity on top of solid diffusion (1520 s) stopped at 1.711 A.h
        # (training cost 1471.5); from 0.85 or 1.15 x the rated one it reaches 1.5545 A.h with the diffusion at
        # 520 s (cost 1419.5; truth 1.5225 A.h, particles' R^2/D 103-400 s)
        return [{"capacity_ah": f * rated} for f in (0.85, 1.0, 1.15)]
    return Effect("capacity", "the cell's capacity differs from the rated one (ageing, rating)",
                  (Param("capacity_ah", "A.h", 0.3 * rated, 1.5 * rated, rated, "capacity"),),
                  {"capacity_ah": rated}, ("voltage_v",), starts)


def current_offset(model) -> Effect:
    return Effect("current_offset", "current-sensor offset: true current = logged current - offset",
                  (Param("current_offset_a", "A", -1.0, 1.0, 0.0, "sensor offset"),),
                  {"current_offset_a": 0.0}, ("voltage_v",))


def low_soc_resistance(model) -> Effect:
    return Effect("low_soc_resistance", "resistances rise at low SOC: R x (1 + g exp(-SOC / s))",
                  (Param("lowsoc_r_gain", "1", 0.0, 50.0, 1.0, "gain g"),
                   Param("lowsoc_r_scale_frac", "1", 0.02, 0.3, 0.08, "SOC scale s")),
                  {"lowsoc_r_gain": 0.0, "lowsoc_r_scale_frac": 0.1}, ("voltage_v",))


def second_rc_branch(model) -> Effect | None:
    if model.base.r2_scale > 0.0:
        return None     # the nominal model has it already
    def starts(ctx, base):
        return [{"r2_scale": r, "c2_scale": c} for r in (0.3, 1.0, 3.0) for c in (0.1, 1.0)]
    return Effect("second_rc_branch", "a second, slow RC branch (diffusion)",
                  (Param("r2_scale", "1", 0.01, 100.0, 1.0, "factor on the R2 table", log=True),
                   Param("c2_scale", "1", 0.01, 100.0, 1.0, "factor on the C2 table", log=True)),
                  {"r2_scale": 0.0, "c2_scale": 1.0}, ("voltage_v",), starts)


def initial_soc(model) -> Effect:
    """The initial SOC differs from the OCV inverse of the first rest voltage (a flat OCV - LFP - cannot give
    it, or the record does not start at rest): battery ``soc_init_pct`` fitted."""
    s0 = 100.0 * min(max(getattr(model, "soc0", 0.5), 0.0), 1.0)

    def starts(ctx, base):
        return [{"soc_init_pct": min(max(s0 + d, 2.0), 100.0)} for d in (-20.0, -8.0, 8.0, 20.0)]
    return Effect("initial_soc", "initial SOC other than the OCV inverse of the first rest voltage (flat OCV)",
                  (Param("soc_init_pct", "%", 2.0, 100.0, s0, "initial state of charge"),),
                  {"soc_init_pct": s0}, ("voltage_v",), starts)


def ocv_correction(model) -> Effect:
    """Corrections added to the given OCV curve at knots over the SOC range the record visits (a user's OCV
    table rarely belongs to the very cell measured); the corrected curve travels as ``ocv.csv``."""
    ks = model.ocv_knots
    ps = tuple(Param(f"ocv_delta_v[{k}]", "V", -0.05, 0.05, 0.0, f"OCV correction at SOC {s:.3f}")
               for k, s in enumerate(ks))
    return Effect("ocv_correction", f"the given OCV curve corrected at {len(ks)} knots (linear in between, held "
                  "beyond)", ps, {p.name: 0.0 for p in ps}, ("voltage_v",))


def solid_diffusion(model) -> Effect:
    """The OCV is read at the particles' surface SOC, which lags the bulk under current (solid diffusion,
    ``diffusion_time_s`` = R^2/D): its voltage is the OCV's slope times the lag, so it is large where the OCV
    is steep (graphite staging, the ends of an LFP plateau) and nothing on a plateau - a shape an RC branch
    has only if its tables follow the OCV's slope (a foreign cell's nominal takes the A123 tables' shape)."""
    if model.base.diffusion_time_s > 0.0:
        return None     # the nominal model has it already (a declared parameter)
    def starts(ctx, base):
        return [{"diffusion_time_s": tdv} for tdv in (300.0, 3000.0, 20000.0)]
    return Effect("solid_diffusion", "solid diffusion: the OCV read at the surface SOC, lagging the bulk under "
                  "current (diffusion time R^2/D)",
                  (Param("diffusion_time_s", "s", 0.0, 2.0e5, 0.0, "diffusion time R^2/D"),),
                  {"diffusion_time_s": 0.0}, ("voltage_v", "t_surface_c"), starts,
                  # a claim about the voltage (the lag, the OCV's slope); its heat is the diffusion overpotential's,
                  # whose timing is uncertain (dissipated at once here, in part on relaxation in a cell - PyBaMM's
                  # heat of mixing): a fit that gains on the temperature alone is not the explanation
                  evidence=("voltage_v",))


#: the cell effect library: functions model -> Effect (or None when it does not apply); extend with one entry
CELL_EFFECTS = [entropic_heat, arrhenius_resistance, cooling_change, ocv_hysteresis, capacity, current_offset,
                low_soc_resistance, second_rc_branch, initial_soc, ocv_correction, solid_diffusion]
N_OCV_KNOTS = 5


def _lag(t: np.ndarray, u: np.ndarray, tau: float) -> np.ndarray:
    """First-order lag of ``u`` (time constant ``tau`` [s]) on the grid ``t``, starting from 0."""
    dts = np.diff(t, prepend=t[0])
    a = np.exp(-np.clip(dts, 0.0, None) / max(tau, 1e-9))
    if dts.size > 1 and np.allclose(dts[1:], dts[1]):
        from scipy.signal import lfilter
        return lfilter([1.0 - a[1]], [1.0, -a[1]], np.concatenate([[0.0], u[1:]]))
    y = np.empty(u.size)
    acc = 0.0
    for k in range(u.size):
        acc = a[k] * acc + (1.0 - a[k]) * u[k]
        y[k] = acc
    return y


# ------------------------------------------------------------------------------------------ model

def _ocv_csv_text(soc, v) -> str:
    lines = ["# OCV curve given to the calibration with --params [ocv] (written by shevsim calibrate)",
             "soc_frac,ocv_v"] + [f"{a:.10g},{b:.10g}" for a, b in zip(soc, v)]
    return "\n".join(lines) + "\n"


class CellModel(CalibrationModel):
    """The battery component's cell model (see the module docstring).

    Channels: ``voltage_v`` [V], ``t_surface_c`` [degC], optional ``t_core_c`` [degC].
    Inputs: ``current_a`` [A, + discharge], ``t_ambient_c`` [degC].
    """
    name = "cell"
    component = "battery"
    component_name = "battery"
    channels = ("voltage_v", "t_surface_c")
    optional_channels = ("t_core_c",)
    inputs = ("current_a", "t_ambient_c")
    known_defaults = {"soc0_frac": -1.0, "h_conv_w_m2k": 20.0, "change_width_s": 20.0}
    effect_functions = CELL_EFFECTS
    #: the cell's voltage limits (data sheet / test record): not fitted, carried to the overlay's [shared]
    #: table (``cell_v_min_v``, ``cell_v_max_v``), where a scenario's BMS takes them
    limits = ("v_min_v", "v_max_v")
    cause_hints = {"discharged_ah": "capacity differs from the rated one, or the OCV curve is wrong",
                   "current_a": "resistance level wrong, or the current is in other units (mA?) or sign",
                   "current_sq_a2": "heat generation / resistance level wrong",
                   "abs_current_a": "resistance level or hysteresis",
                   "time_s": "a slow drift: temperature, ageing or a sensor drift",
                   "t_ambient_c": "ambient coupling (convection coefficient) wrong",
                   "t_surface_meas_c": "temperature dependence of the resistances (Arrhenius) missing"}

    def __init__(self, known: Mapping[str, Any] | None = None, where: str = "<params>"):
        known = dict(known or {})
        self.where = where
        self.known = dict(self.known_defaults)
        self.initial: dict[str, float] = {}
        comp: dict[str, Any] = {}
        base_dir = Path(known.pop("__base_dir__", "."))
        known.pop("__component_file__", None)
        tables = known.pop("__tables__", None) or {}
        for tname, vals in tables.items():     # an overlay / component file with a [battery] table
            if tname != self.component_name:
                raise DataError(f"{where}: table [{tname}] is not for the cell model (expected [battery] or [params])")
            known.update(vals)
        short_form = any(k in _LEGACY or k in ("thermal", "arrhenius_anchor") for k in known)
        self.given = set(known)
        # the battery's own parameters typed (a string, a list or true/false for a number: an error naming the
        # parameter), and the short form's numbers checked, before anything reads them
        from .models import number_value, typed_values
        known = typed_values(BatteryPackParams, known, f"{where}: battery parameters")
        for k in ("soc0_frac", "h_conv_w_m2k", "change_width_s", "t_ref_c", "rc_pairs"):
            if k in known and not math.isfinite(number_value(known[k], f"{where}: parameter '{k}'")):
                raise DataError(f"{where}: parameter '{k}' must be finite, got {known[k]!r}")
        if "rc_pairs" in known and known["rc_pairs"] not in (1, 2):
            raise DataError(f"{where}: rc_pairs = {known['rc_pairs']!r}: the cell has 1 or 2 RC branches")
        if "soc0_frac" in known and not (known["soc0_frac"] < 0 or 0.0 <= known["soc0_frac"] <= 1.0):
            raise DataError(f"{where}: soc0_frac = {known['soc0_frac']!r}: the initial SOC is a fraction in [0, 1] "
                            f"(or < 0: read from the record's first rest voltage)")
        for k in ("h_conv_w_m2k", "change_width_s"):
            if k in known and known[k] < 0:
                raise DataError(f"{where}: parameter '{k}' must be >= 0, got {known[k]!r}")
        self.cell_limits: dict[str, float] = {}
        for k, v in known.items():
            if k in self.limits:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                    raise DataError(f"{where}: '{k}' (the cell's voltage limit) must be a number > 0, got {v!r}")
                self.cell_limits[k] = float(v)
            elif k in _LEGACY or k in self.known_defaults:
                self.known[k] = v
            elif k in _FIELDS:
                comp[k] = v
            elif k == "thermal":
                if str(v).replace("_", "-") != "two-state":
                    raise DataError(f"{where}: thermal = {v!r}: the battery component's model is the two-state radial "
                                    f"model (the former lumped side model is gone)")
            elif k == "arrhenius_anchor":
                pass   # former side-model option: the component's Arrhenius law uses its own mean temperature
            elif k in ("r0_ohm", "r1_ohm", "tau1_s", "cc_j_k", "cs_j_k", "rc_k_w", "ru_k_w"):
                raise DataError(f"{where}: '{k}' belonged to the calibration's former side model; the cell is now "
                                f"the battery component's model - give battery parameters (e.g. rs_scale, "
                                f"kt_w_mk, cp_j_kgk, h_conv_factor) instead")
            else:
                import difflib
                opts = sorted(_FIELDS | set(self.known_defaults) | _LEGACY)
                best = difflib.get_close_matches(k, opts, n=1)
                hint = f" (did you mean '{best[0]}'?)" if best else ""
                raise DataError(f"{where}: unknown parameter '{k}' for the cell model{hint}")
        self.ocv_table = None
        if "ocv_soc_frac" in self.known:
            lists = {}
            for key, name in (("ocv_soc_frac", "soc_frac"), ("ocv_v", "ocv_v")):
                xs = self.known.get(key)
                if not isinstance(xs, (list, tuple)):
                    raise DataError(f"{where}: [ocv] {name} must be a list of numbers, got {xs!r}")
                lists[name] = tuple(number_value(x, f"{where}: [ocv] {name}") for x in xs)
            soc, v = lists["soc_frac"], lists["ocv_v"]
            for name, xs in (("soc_frac", soc), ("ocv_v", v)):
                bad = [j for j, x in enumerate(xs) if not math.isfinite(x)]
                if bad:
                    raise DataError(f"{where}: [ocv] {name}[{bad[0]}] = {xs[bad[0]]}: every value must be finite")
            if soc and not (0.0 <= min(soc) and max(soc) <= 1.0):
                raise DataError(f"{where}: [ocv] soc_frac must lie in [0, 1], got {min(soc):g}..{max(soc):g}"
                                + (" (in percent? give it as soc_pct)" if max(soc) > 1.0 and max(soc) <= 100.0 else ""))
            if v and float(np.median(v)) > 100.0:
                raise DataError(f"{where}: [ocv] ocv_v median {float(np.median(v)):g} looks like millivolts: the cell's "
                                f"open-circuit voltage in V is expected (divide by 1000)")
            if len(soc) != len(v) or len(soc) < 2 or any(b <= a for a, b in zip(soc, soc[1:])):
                raise DataError(f"{where}: [ocv] soc_frac must increase strictly and match ocv_v in length")
            if any(b <= a for a, b in zip(v, v[1:])):
                raise DataError(f"{where}: [ocv] ocv_v must increase strictly with soc_frac")
            self.ocv_table = (soc, v)
        defaults = {}
        if short_form:
            defaults = {"entropic_heat": False, "temperature_dependent": False,
                        "r2_scale": 1.0 if int(self.known.get("rc_pairs", 1)) == 2 else 0.0}
        for k, v in list(comp.items()):
            if k.endswith("_file") and isinstance(v, str) and v and not Path(v).is_absolute():
                comp[k] = str((base_dir / v).resolve())
        self.user_params = comp
        fixed = {"n_series": 1, "n_parallel": 1, "input_mode": "current", "sigma_current_a": 0.0,
                 "sigma_voltage_v": 0.0, "sigma_temperature_c": 0.0, "thermal_model": "two_state",
                 "h_change_width_s": float(self.known["change_width_s"])}
        try:
            self.base = dataclasses.replace(BatteryPackParams(), **{**defaults, **comp, **fixed})
        except (TypeError, ValueError, Exception) as exc:
            if isinstance(exc, DataError):
                raise
            raise DataError(f"{where}: {exc}") from exc
        self.dudt_knots = tuple(np.linspace(0.1, 0.9, N_DUDT_KNOTS))
        self.ocv_knots = tuple(np.linspace(0.1, 0.9, N_OCV_KNOTS))
        self.declared = self._declared_for(self.known)
        self.effects = self._make_effects()

    # -- declared parameters and effects
    def _declared_for(self, known):
        b = self.base
        ps = [Param("rs_scale", "1", 0.02, 50.0, 1.0, "factor on the R_s table", log=True),
              Param("r1_scale", "1", 0.02, 50.0, 1.0, "factor on the R_1 table", log=True),
              Param("c1_scale", "1", 0.01, 100.0, 1.0, "factor on the C_1 table", log=True)]
        if b.r2_scale > 0.0:
            ps += [Param("r2_scale", "1", 0.01, 100.0, b.r2_scale, "factor on the R_2 table", log=True),
                   Param("c2_scale", "1", 0.01, 100.0, b.c2_scale, "factor on the C_2 table", log=True)]
        if b.diffusion_time_s > 0.0:      # the nominal declares solid diffusion: its time is fitted
            ps += [Param("diffusion_time_s", "s", 10.0, 2.0e5, b.diffusion_time_s, "diffusion time R^2/D", log=True)]
        ps += [Param("kt_w_mk", "W/(m.K)", 0.05, 20.0, b.kt_w_mk, "radial thermal conductivity", log=True),
               Param("cp_j_kgk", "J/(kg.K)", 200.0, 5000.0, b.cp_j_kgk, "specific heat capacity", log=True),
               Param("h_conv_factor", "1", 0.05, 20.0, b.h_conv_factor, "factor on the convection coefficient",
                     log=True)]
        return tuple(ps)

    def _make_effects(self):
        out = {}
        for f in self.effect_functions:
            e = f(self)
            if e is not None:
                out[e.name] = e
        return out

    #: the cell's own quantities a user should give (alternative keys); missing, the project's A123 26650 fills them in
    SALIENT_DEFAULTS = ((("capacity_ah",), "capacity_ah"), (("ocv_file", "ocv_soc_frac"), "ocv_file"),
                        (("radius_m",), "radius_m"), (("length_m",), "length_m"), (("h_conv_w_m2k",), "h_conv_w_m2k"),
                        (("discharge_file", "charge_file"), "discharge_file"))

    def defaults_used(self) -> list[dict]:
        """The cell quantities the ``--params`` did not give: the project's A123 26650 (2.3 A.h LFP, 26 x 65 mm;
        ``components/battery``) fills them in - its OCV curve, its R/C tables' shape (their levels are fitted),
        its can - and the convection coefficient 20 W/(m2.K)."""
        out = []
        given = getattr(self, "given", set())
        for keys, name in self.SALIENT_DEFAULTS:
            if any(k in given for k in keys):
                continue
            if name == "h_conv_w_m2k":
                v = self.known.get("h_conv_w_m2k")
            else:
                v = getattr(self.base, name, None)
                if name.endswith("_file"):
                    v = Path(v).name if v else "(built in)"
            out.append({"parameter": name, "value": v,
                        "default": "the calibration's default convection coefficient" if name == "h_conv_w_m2k" else
                        "the project's A123 26650 LFP cell" + (" (the shape of its R/C tables; their levels are "
                                                               "fitted; your own: discharge_file and charge_file, CSV "
                                                               "soc_frac,t_c,rs_ohm,r1_ohm,c1_f,r2_ohm,c2_f - "
                                                               "docs/getting_started.md)"
                                                               if name == "discharge_file" else "")})
        return out

    # -- data
    def prepare(self, data) -> dict:
        df = data.df
        t = df["time_s"].to_numpy(float)
        i = df["current_a"].to_numpy(float)
        ta = df["t_ambient_c"].to_numpy(float)
        ts_meas = df["t_surface_c"].to_numpy(float)
        tables = self._tables()
        d, ix = tables.packed()
        soc0 = float(self.known["soc0_frac"])
        self.soc0_interval = None
        self.soc0_interval_wide = None
        self.first_rest_span = None
        if soc0 < 0:
            # invert the OCV at the start (the record starts at rest): mean voltage over the initial
            # low-current samples (at most 60 s)
            low = np.abs(i) <= 0.02 * max(float(np.abs(i).max()), 1e-9)
            n0 = int(np.argmin(low)) if not low.all() else low.size
            n0 = max(1, min(n0, int(np.searchsorted(t, t[0] + 60.0))))
            v0 = float(np.mean(df["voltage_v"].to_numpy(float)[:n0]))
            # the record's first rest, before any current: the cell is relaxed there (initial_soc's rest claim)
            self.first_rest_span = (0, n0 - 1) if n0 >= self.FIRST_REST_MIN_SAMPLES and not low.all() else None
            if self.first_rest_span is not None:
                # relaxed only if its voltage is still: a record that starts soon after current (its first "rest"
                # still relaxing) gives a biased reading, which is what initial_soc corrects - not a check on it
                vs = df["voltage_v"].to_numpy(float)[:n0]
                w = max(3, int(0.1 * vs.size))
                sd_v, q_v = self._noise(vs)
                moved = abs(float(np.mean(vs[-w:])) - float(np.mean(vs[:w])))
                if moved > max(self.REST_RELAX_SE * sd_v * math.sqrt(2.0 / w), q_v):
                    self.first_rest_span = None
            xs = np.linspace(0.0, 1.0, 2001)
            ocv = np.array([tables.ocv(x) for x in xs])
            soc0 = float(np.interp(v0, ocv, xs)) if np.all(np.diff(ocv) > 0) else 0.5
            # how well that reading holds: the SOC interval the table gives for the rest voltage +- the
            # voltage error a user's table carries (SOC0_TABLE_ERROR_V; on the edge of a plateau the local slope
            # misleads: a little lower is across the plateau)
            if np.all(np.diff(ocv) > 0) and ocv[0] < v0 < ocv[-1]:    # (outside the table: no reading to judge)
                dv = self.SOC0_TABLE_ERROR_V
                self.soc0_interval = (float(np.interp(v0 - dv, ocv, xs)), float(np.interp(v0 + dv, ocv, xs)))
                dw = self.FIRST_REST_MARGIN * dv
                self.soc0_interval_wide = (float(np.interp(v0 - dw, ocv, xs)), float(np.interp(v0 + dw, ocv, xs)))
        self.soc0 = soc0
        self.t_init_c = float(ts_meas[0])
        # Arrhenius reference: the record's mean temperature (decouples Ea from the resistance scales)
        self.t_ref_c = float(self.known["t_ref_c"]) if "t_ref_c" in self.known else float(np.mean(ts_meas))
        # entropic-heat knots over the SOC range the record visits (nominal capacity)
        dt = np.diff(t, prepend=t[0])
        soc = soc0 - np.cumsum(i * dt) / (3600.0 * self.base.capacity_ah)
        lo, hi = float(np.clip(soc.min(), 0.0, 1.0)), float(np.clip(soc.max(), 0.0, 1.0))
        if hi - lo < 0.05:
            lo, hi = max(0.0, lo - 0.025), min(1.0, hi + 0.025)
        self.dudt_knots = tuple(float(x) for x in np.linspace(lo, hi, N_DUDT_KNOTS))
        self.ocv_knots = tuple(float(x) for x in np.linspace(lo, hi, N_OCV_KNOTS))
        self.ocv_base = (np.array(tables._ocv.xs, float), np.array(tables._ocv.ys, float))
        # the record's rests after current has flowed: the slow time constant it resolves and the current a
        # sensor logs at zero current (record_resolution, measured_params)
        refused: list = []
        v_meas = df["voltage_v"].to_numpy(float)
        # the nominal's RC branches (R, tau) over the SOC range the record visits: which way a rest relaxes
        self.rc_branches = self._nominal_branches(tables, self.base, lo, hi)
        spans = self._rest_spans(t, i, v_meas, self.base.capacity_ah, min_s=self.SLOW_REST_MIN_S, why=refused,
                                 branches=self.rc_branches)
        self.rests_s = [float(t[b] - t[a]) for a, b in spans]
        self.rest_spans = list(spans)
        self._rest_t = t
        self.rests_refused = refused
        # the sensor offset is read in every rest long enough to be recognised as one (its relaxation tested), not
        # only in those long enough to show the slow branch: a drive's 20-90 s stops are rests too
        offset_spans = self._rest_spans(t, i, v_meas, self.base.capacity_ah, min_s=self.OFFSET_REST_MIN_S,
                                        branches=self.rc_branches)
        # the slow RC branch's time constant is limited to the longest rest: a relaxation that no rest shows
        # decaying cannot be told from a series capacitor - that is, from a capacity or a current offset
        # (over a swing where the OCV is near linear in the charge).  A record whose rests are all shorter than
        # the nominal slow branch's own time constant (the table's, x the declared scales) resolves no slow
        # relaxation at all: no limit then (the branch stays as declared), and a capacity or an offset is not
        # identifiable apart from it (record_resolution says so)
        xs = np.linspace(lo, hi, 21)
        self.tau2_table_s = float(np.mean([tables.params(x, 25.0, 1.0)[3] * tables.params(x, 25.0, 1.0)[4]
                                           for x in xs]))
        b = self.base
        self.tau2_nominal_s = self.tau2_table_s * (b.r2_scale if b.r2_scale > 0.0 else 1.0) * b.c2_scale
        longest = max(self.rests_s) if self.rests_s else 0.0
        self.tau2_max_s = longest if longest >= self.tau2_nominal_s else None
        self.soc_swing = hi - lo
        self.rest_current = self._offset_from_rests(t, i, offset_spans)
        self.effects = self._make_effects()
        tg, (ig, tag), _h, resampled = sampling_grid(t, i, ta)
        return {"t": t, "i": i, "ta": ta, "tg": tg, "ig": ig, "tag": tag, "resampled": resampled, "d": d, "ix": ix, "n": t.size, "df": df,
                "h_conv": float(self.known["h_conv_w_m2k"]), "has_core": "t_core_c" in df,
                "soc_range": (lo, hi)}

    def _tables(self) -> CellTables:
        b = self.base
        ocv_file = b.ocv_file or None
        tmp = None
        if self.ocv_table is not None:
            import os
            import tempfile
            fd, tmp = tempfile.mkstemp(suffix="_ocv.csv", prefix="shevsim_")
            with os.fdopen(fd, "w") as fh:
                fh.write(_ocv_csv_text(*self.ocv_table))
            ocv_file = tmp
        try:
            return CellTables(ocv_file, b.entropy_file or None, b.discharge_file or None, b.charge_file or None)
        except Exception as exc:
            raise DataError(f"{self.where}: {exc}") from exc
        finally:
            if tmp is not None:
                Path(tmp).unlink(missing_ok=True)    # our own temporary copy; the overlay writes ocv.csv

    # -- parameters of the component
    def _component_params(self, values: Mapping[str, float]) -> BatteryPackParams:
        """The battery parameters (nominal + ``values``) that the simulation of this record uses."""
        full = self.full_values(values)
        kw: dict[str, Any] = {"soc_init_pct": 100.0 * min(max(getattr(self, "soc0", 0.5), 0.0), 1.0),
                              "t_init_c": getattr(self, "t_init_c", self.base.t_init_c),
                              "arrhenius_t_ref_c": getattr(self, "t_ref_c", 25.0)}
        knots = [full.get(f"dudt_v_k[{k}]", 0.0) for k in range(len(self.dudt_knots))]
        if any(v != 0.0 for v in knots):
            kw["dudt_soc_frac"] = self.dudt_knots
            kw["dudt_v_k"] = tuple(knots)
        for k, v in full.items():
            if k in _FIELDS:
                kw[k] = v
        tmax = getattr(self, "tau2_max_s", None)
        if tmax and kw.get("r2_scale", self.base.r2_scale) > 0.0:
            r2s = kw.get("r2_scale", self.base.r2_scale)
            c2s = kw.get("c2_scale", self.base.c2_scale)
            kw["c2_scale"] = min(c2s, tmax / (r2s * self.tau2_table_s))
        return dataclasses.replace(self.base, **kw)

    def ocv_corrected(self, values):
        """The OCV table (soc, v) with the ``ocv_correction`` knots added, or None when they are all zero."""
        dv = [float(values.get(f"ocv_delta_v[{k}]", 0.0)) for k in range(len(getattr(self, "ocv_knots", ())))]
        if not any(dv):
            return None
        xs, ys = self.ocv_base
        return xs, ys + np.interp(xs, self.ocv_knots, dv)

    def _packed_tables(self, ctx, values):
        """The packed tables of ``ctx`` with the OCV part (xs, ys, slopes, cum) corrected when asked."""
        cor = self.ocv_corrected(values)
        if cor is None:
            return ctx["d"]
        xs, ys = cor
        o, n = int(ctx["ix"][0]), int(ctx["ix"][1])
        d = ctx["d"].copy()
        d[o + n:o + 2 * n] = ys
        d[o + 2 * n:o + 3 * n - 1] = np.diff(ys) / np.diff(xs)
        d[o + 3 * n - 1:o + 4 * n - 1] = np.concatenate([[0.0], np.cumsum(0.5 * (ys[1:] + ys[:-1]) * np.diff(xs))])
        return d

    def simulate(self, ctx, values):
        # the very parameter vector the component packs (every effect / declared parameter is a battery field)
        p = self._component_params(values)
        c = bm.pack_params(p)
        tg = ctx["tg"]
        n = tg.size
        st = np.zeros(bm.N_STATE)
        st[bm.S_SOC] = p.soc_init_pct / 100.0
        st[bm.S_X0] = p.t_init_c
        ov, ots, otc = np.empty(n), np.empty(n), np.empty(n)
        bm.run_profile(self._packed_tables(ctx, values), ctx["ix"], c, st, tg, ctx["ig"], ctx["tag"], ctx["h_conv"],
                       ov, ots, otc)
        if ctx["resampled"]:
            t = ctx["t"]
            ov, ots, otc = np.interp(t, tg, ov), np.interp(t, tg, ots), np.interp(t, tg, otc)
        out = {"voltage_v": ov, "t_surface_c": ots, "_t_core_c": otc}
        if ctx["has_core"]:
            out["t_core_c"] = otc
        return out

    #: the rests that limit the slow RC branch's time constant (record_resolution): at least this long
    SLOW_REST_MIN_S = 60.0
    #: the rests the current-sensor offset is read in (measured_params): at least this long - 20 samples at 1 Hz,
    #: enough for the relaxation test's first and last tenths (3 samples each) to tell a relaxing voltage
    OFFSET_REST_MIN_S = 20.0
    #: the first rest (before any current) joins initial_soc's rest claim when it has at least this many samples
    #: and its voltage is still (its last tenth within REST_RELAX_SE standard errors of its first)
    FIRST_REST_MIN_SAMPLES = 10
    #: a measured current offset is confirmed (measurement_confirmed) at no fewer rests after current than this
    CONFIRM_MIN_RESTS = 3
    #: an initial SOC is refused outside the relaxed first rest's reading widened by this factor on the table's
    #: error (effect_evidence, when no rest after current can check it): room for a C/20 table, hysteresis, the
    #: logger's resolution
    FIRST_REST_MARGIN = 2.0
    #: the slow branch counts as at its time-constant limit within this fraction of it (_capacity_pushes_slow_branch)
    SLOW_LIMIT_TOL = 1e-3
    #: the voltage error of a user's OCV table at a rest (record_resolution): a pseudo-OCV measured at C/50 or
    #: C/20 lies below the equilibrium by that current's overpotential, a few mV (PyBaMM's Prada2013 LFP at C/50:
    #: 1.8-3.3 mV; at C/20: 4.4-7.9 mV)
    SOC0_TABLE_ERROR_V = 2e-3
    #: record_resolution says the first rest's SOC reading is weak where that error spans more than +- this many
    #: points of SOC through the table
    FLAT_OCV_SOC_PCT = 2.0
    #: a rest's current level: at most this C-rate (A per A.h of the nominal capacity) - a sensor offset larger
    #: than C/20 is not an offset the rests are read for
    REST_LEVEL_C_RATE = 1.0 / 20.0
    #: the still band around a rest's level: this C-rate (or 6 noise standard deviations, or 2 resolution steps)
    REST_BAND_C_RATE = 1.0 / 100.0
    #: a rest's current has no trend (a CV taper decays): the change over the span within this many standard errors
    REST_TREND_SE = 4.0
    #: ... or a sensor's own drift: this C-rate over the span (a rest logged in 10 mA steps may step once)
    REST_DRIFT_C_RATE = 1.0 / 2000.0
    #: and its voltage relaxes: it moves in the relaxation's direction by more than this many standard errors
    REST_RELAX_SE = 4.0
    #: ... in either direction when the nominal's RC branches relax it both ways over the span, the smaller part at
    #: least this fraction of the larger (_relaxation_expected: a recent charge on the fast branch, an older net
    #: discharge on the slow one): the cell's split between its branches is not known to a factor of 10 before the
    #: fit (the default tables are another cell's), so the measured direction cannot be checked against it
    REST_MIXED_RATIO = 0.1

    @staticmethod
    def _noise(x) -> tuple[float, float]:
        """``(sd, q)``: the white-noise standard deviation of a smooth signal's samples (MAD of the second
        differences) and its resolution (the smallest nonzero step)."""
        x = np.asarray(x, float)
        d = np.abs(np.diff(x))
        q = float(d[d > 0].min()) if np.any(d > 0) else 0.0
        d2 = np.diff(x, 2)
        sd = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0) if d2.size else 0.0
        return sd, q

    @staticmethod
    def _tau_int(x) -> float:
        """Integrated autocorrelation time (in samples, >= 1) of ``x`` about its mean: ``1 + 2 sum rho_k``, the sum
        stopped at the first lag whose autocorrelation is no longer positive (Geyer's initial sequence): the
        factor by which correlated samples count less than independent ones (``n_eff = n / tau``)."""
        x = np.asarray(x, float) - float(np.mean(x))
        n = x.size
        c0 = float(x @ x)
        if n < 4 or c0 <= 0.0:
            return 1.0
        f = np.fft.rfft(x, 2 * n)
        ac = np.fft.irfft(f * np.conj(f))[:n] / c0
        tau = 1.0
        for k in range(1, n // 4):
            if ac[k] <= 0.0:
                break
            tau += 2.0 * float(ac[k])
        return max(tau, 1.0)

    @staticmethod
    def _nominal_branches(tables, base, lo: float = 0.0, hi: float = 1.0) -> tuple:
        """The nominal's RC branches ``((r_ohm, tau_s), ...)``: the discharge table's R_j and R_j C_j at 25 degC
        averaged over the SOC range ``lo..hi``, times the declared scales (the second branch only when the nominal
        has it)."""
        xs = np.linspace(lo, hi, 21) if hi > lo else np.array([lo])
        p = np.array([tables.params(float(x), 25.0, 1.0) for x in xs])
        out = [(float(np.mean(p[:, 1])) * base.r1_scale, float(np.mean(p[:, 1] * p[:, 2])) * base.r1_scale * base.c1_scale)]
        if base.r2_scale > 0.0:
            out.append((float(np.mean(p[:, 3])) * base.r2_scale,
                        float(np.mean(p[:, 3] * p[:, 4])) * base.r2_scale * base.c2_scale))
        return tuple(out)

    @classmethod
    def _relaxation_expected(cls, t, i, k: int, w_a: slice, w_c: slice, level: float, branches) -> list[float]:
        """Which way, and by how much, each of the nominal's RC branches ``branches`` (``((r_ohm, tau_s), ...)``)
        moves the voltage from the rest's window ``w_a`` (its first tenth) to ``w_c`` (its last), the rest starting
        at sample ``k`` [V per branch, > 0: up, the relaxation after a discharge].  Each branch holds the polarisation of the current
        before ``k`` (relative to the rest's level: a sensor offset is not current), a sample's current weighted
        by ``(1 - exp(-dt/tau))`` and by ``exp(-age/tau)``, how much of it is still there; during the rest it
        decays as ``exp(-s/tau)``, and the windows' mean decay tells what the span can show of it: a branch much
        faster than the first tenth has relaxed before it, a branch much slower than the span barely moves.  So
        a recent charge whose fast polarisation still decays over the span sets the direction even after a long
        net discharge, and an old discharge's slow polarisation sets it when nothing recent competes."""
        tk = float(t[k])
        sa, sc = t[w_a] - tk, t[w_c] - tk
        out = []
        for r, tau in branches:
            tau = max(float(tau), 1e-9)
            pre = (t >= tk - 20.0 * tau) & (np.arange(t.size) < k)
            if not pre.any():
                out.append(0.0)
                continue
            tp = t[pre]
            dt = np.diff(np.append(tp, tk))           # the current of a sample holds until the next one
            pol = float(np.sum((i[pre] - level) * (1.0 - np.exp(-dt / tau)) * np.exp(-(tk - tp - dt) / tau)))
            out.append(r * pol * (float(np.mean(np.exp(-sa / tau))) - float(np.mean(np.exp(-sc / tau)))))
        return out

    #: the RC branches ``_rest_spans`` assumes when the caller gives none: the default (A123 26650) tables' at
    #: SOC 0.5, 25 degC (filled on first use)
    _DEFAULT_BRANCHES: tuple | None = None

    @classmethod
    def _rest_spans(cls, t, i, v=None, capacity_ah: float | None = None, min_s: float = 60.0, why=None,
                    branches=None):
        """Index spans ``(first, last)`` of the record's rests after current has flowed (a rest before any
        current shows no relaxation).  A rest is where the cell carries no current, whatever its sensor logs:

        * the logged current stays at one level (within ``REST_BAND_C_RATE`` of the capacity, or 6 of the
          channel's own noise standard deviations, or 2 of its resolution steps; a 5-sample running median, so a
          lone spike does not end a rest) for at least ``min_s``, the level at most ``REST_LEVEL_C_RATE`` of the
          capacity (a sensor offset, not a charge or discharge);
        * with no trend: the current's linear change over the span is within ``REST_TREND_SE`` standard errors
          (autocorrelation counted), 2 resolution steps or ``REST_DRIFT_C_RATE`` of the capacity - a CV taper,
          whose current decays while the voltage is held at its limit, is not a rest;
        * and, given the voltage ``v``, the voltage relaxes: it moves, from the span's first tenth to its last,
          the way the nominal's RC branches relax after the current before it (:meth:`_relaxation_expected`: up when
          the polarisation still decaying over the span is a discharge's, down when it is a charge's; either way
          when the branches relax it both ways, within ``REST_MIXED_RATIO`` - a 20 s charge just before a rest
          after a long drive: the fast branch down, the slow one up), by more than ``REST_RELAX_SE`` standard
          errors of the voltage noise (a CV hold keeps the voltage flat; a small constant charge after a charge
          keeps it rising).

        ``capacity_ah`` (the nominal's) sets the absolute current scale; without it, 1 A h.  ``branches``: the
        nominal's RC branches ``((r_ohm, tau_s), ...)`` (:meth:`_nominal_branches`); without them, the default
        tables' at SOC 0.5, 25 degC.  ``why``: a list that receives ``(t_start_s, duration_s, reason)`` for each
        candidate span >= ``min_s`` refused."""
        from scipy.ndimage import median_filter
        t, i = np.asarray(t, float), np.asarray(i, float)
        n = i.size
        if n < 5:
            return []
        cap = float(capacity_ah) if capacity_ah and capacity_ah > 0 else 1.0
        if branches is None:
            if cls._DEFAULT_BRANCHES is None:
                from ..battery.cell import default_tables
                CellModel._DEFAULT_BRANCHES = cls._nominal_branches(default_tables(), BatteryPackParams(), 0.5, 0.5)
            branches = cls._DEFAULT_BRANCHES
        level_max = cls.REST_LEVEL_C_RATE * cap
        m = median_filter(i, size=5, mode="nearest")
        quiet = np.abs(m) <= level_max
        sd_i, q_i = cls._noise(i[quiet]) if quiet.sum() > 5 else (0.0, 0.0)
        band = max(cls.REST_BAND_C_RATE * cap, 6.0 * sd_i, 2.0 * q_i)
        moved = np.flatnonzero(~quiet)
        out, k = [], (int(moved[0]) + 1 if moved.size else n)
        while k < n:
            if not quiet[k]:
                k += 1
                continue
            j = k
            while j + 1 < n and quiet[j + 1] and abs(m[j + 1] - m[k]) <= band:
                j += 1
            if t[j] - t[k] >= min_s:
                reason = cls._not_a_rest(t, i, v, k, j, q_i, cap, branches)
                if reason is None:
                    out.append((k, j))
                elif why is not None:
                    why.append((float(t[k]), float(t[j] - t[k]), reason))
            k = j + 1
        return out

    @classmethod
    def _not_a_rest(cls, t, i, v, k, j, q_i, cap, branches=()):
        """Why the still span ``k..j`` is not a rest (None: it is one); see :meth:`_rest_spans`."""
        ts, xs = t[k:j + 1], i[k:j + 1]
        tc = ts - ts.mean()
        slope = float(tc @ (xs - xs.mean())) / max(float(tc @ tc), 1e-300)
        res = xs - xs.mean() - slope * tc
        dur = float(ts[-1] - ts[0])
        var_slope = float(res @ res) / max(xs.size - 2, 1) * cls._tau_int(res) / max(float(tc @ tc), 1e-300)
        se_change = math.sqrt(var_slope) * dur
        change = slope * dur
        if abs(change) > max(cls.REST_TREND_SE * se_change, 2.0 * q_i, cls.REST_DRIFT_C_RATE * cap):
            held = ""
            if v is not None:
                vs = np.asarray(v, float)[k:j + 1]
                sd_v, q_v = cls._noise(vs)
                if np.ptp(vs) <= max(6.0 * sd_v, 2.0 * q_v) and change * float(np.median(xs)) < 0.0:
                    held = " with the voltage held (a CV phase)"
            return f"the current {'decays' if change * float(np.median(xs)) < 0 else 'drifts'} by {change:+.4g} A{held}"
        if v is None:
            return None
        v = np.asarray(v, float)
        vs = v[k:j + 1]
        # which way the RC branches relax over the span after the current before it (relative to the span's level):
        # the polarisation still decaying between the span's first tenth and its last (_relaxation_expected)
        level = float(np.median(xs))
        w = max(3, int(0.1 * vs.size))
        if k == 0:
            return "no current before it"
        parts = cls._relaxation_expected(t, i, k, slice(k, k + w), slice(j + 1 - w, j + 1), level, branches)
        up, down = sum(x for x in parts if x > 0.0), -sum(x for x in parts if x < 0.0)
        if up == 0.0 and down == 0.0:
            return "no current before it"
        a, c = float(np.mean(vs[:w])), float(np.mean(vs[-w:]))
        sd_v, q_v = cls._noise(vs)
        se = sd_v * math.sqrt(2.0 / w)
        if min(up, down) >= cls.REST_MIXED_RATIO * max(up, down):
            # a recent current of one sign on the fast branch, an older one of the other on the slow: the direction
            # is the cell's split of its polarisation between them, which the nominal does not know: either way
            if abs(c - a) <= max(cls.REST_RELAX_SE * se, q_v):
                return (f"the voltage does not relax after the mixed current before it (a recent "
                        f"{'charge' if parts[0] < 0 else 'discharge'} and an older "
                        f"{'discharge' if parts[0] < 0 else 'charge'}; {1e3 * (c - a):+.2f} mV over "
                        f"{float(ts[-1] - ts[0]):.0f} s)")
            return None
        rise = (c - a) * (1.0 if up > down else -1.0)    # + : relaxes (up after a discharge, down after a charge)
        if rise <= max(cls.REST_RELAX_SE * se, q_v):
            side = "discharge" if up > down else "charge"
            return (f"the voltage does not relax after the {side} before it ({1e3 * (c - a):+.2f} mV over "
                    f"{float(ts[-1] - ts[0]):.0f} s)")
        return None

    #: a rest current beyond this many standard errors of its median is a measured sensor offset
    REST_OFFSET_SE = 5.0
    #: a rest whose level is more than this many of its standard errors from the rests' consensus carries a real
    #: current (a small pulse, a draw), not the offset: left out of the measurement and listed
    REST_AGREE_SE = 4.0
    #: the offset is measured only by at least this many agreeing rests (one or two cannot show their agreement)
    REST_MIN_AGREEING = 3

    def _rest_consensus(self, i, spans, q, pooled=False):
        """``(value, se, tau_int, chi2, agree, levels, level_se)`` of the offset from the rests ``spans`` (see
        :meth:`_offset_from_rests`); ``pooled``: one median over all of them (no consensus asked).  None when fewer
        than ``REST_MIN_AGREEING`` agree or the rests have < 30 samples."""
        segs = [i[a:b + 1] for a, b in spans]
        meds = np.array([float(np.median(x)) for x in segs])
        dev = np.concatenate([x - m for x, m in zip(segs, meds)])
        if dev.size < 30:
            return None
        # spread: the MAD's std, or the plain std when the logging is quantised (MAD 0)
        sd = 1.4826 * float(np.median(np.abs(dev))) or float(np.std(dev))
        tau = self._tau_int(dev)
        se_k = np.maximum(1.2533 * sd / np.sqrt(np.array([x.size for x in segs]) / tau), 1e-12)
        if pooled:
            allx = np.concatenate(segs)
            return (float(np.median(allx)), max(1.2533 * sd / math.sqrt(allx.size / tau), 0.5 * q), tau, 1.0,
                    np.ones(len(spans), bool), meds, se_k)
        centre = float(np.median(meds))
        for _ in range(3):
            agree = np.abs(meds - centre) <= self.REST_AGREE_SE * se_k
            if agree.sum() < self.REST_MIN_AGREEING:
                return None
            w = 1.0 / se_k[agree] ** 2
            centre = float(np.sum(w * meds[agree]) / np.sum(w))
        se_int = 1.0 / math.sqrt(float(np.sum(w)))
        chi2 = float(np.sum(w * (meds[agree] - centre) ** 2)) / max(int(agree.sum()) - 1, 1)
        return centre, max(se_int * math.sqrt(max(chi2, 1.0)), 0.5 * q), tau, chi2, agree, meds, se_k

    def _offset_from_rests(self, t, i, spans) -> dict | None:
        """The current the sensor logs at zero current, from the rests ``spans``: each rest is one measurement of
        the same offset - its median logged current, whose standard error counts the noise's autocorrelation (the
        integrated autocorrelation time of all the rests' deviations pooled: a 20-sample span alone underestimates
        its own).  A span that is a small real current (below C/20, after a larger one, its voltage relaxing) looks
        like a rest but does not agree with the others: rests further than ``REST_AGREE_SE`` of their standard errors
        from the consensus (the median of the rests' levels, then the inverse-variance mean of the agreeing ones) are
        left out and listed.  The estimate is that mean; its standard error the larger of the internal one and the
        agreeing rests' scatter (Birge ratio), and at least half the current channel's resolution (a quantised
        rest cannot be read finer).  When fewer than ``REST_MIN_AGREEING`` rests agree, only the rests of at least
        ``SLOW_REST_MIN_S`` are read, pooled (a real current does not relax the voltage for a minute like a rest:
        the former rule); None when there are none (or < 30 samples)."""
        steps = np.abs(np.diff(i))
        q = float(steps[steps > 0].min()) if np.any(steps > 0) else 0.0
        got = self._rest_consensus(i, spans, q) if len(spans) >= self.REST_MIN_AGREEING else None
        consensus = got is not None
        if got is None:
            spans = [(a, b) for a, b in spans if t[b] - t[a] >= self.SLOW_REST_MIN_S]
            if not spans:
                return None
            got = self._rest_consensus(i, spans, q, pooled=True)
            if got is None:
                return None
        centre, se, tau, chi2, agree, meds, se_k = got
        kept = [sp for sp, ok in zip(spans, agree) if ok]
        n = int(sum(b - a + 1 for a, b in kept))
        return {"value": centre, "se": se, "n": n, "n_eff": float(n / tau), "n_rests": len(kept),
                "duration_s": float(sum(t[b] - t[a] for a, b in kept)), "birge_ratio": math.sqrt(chi2),
                "consensus": consensus,
                "rests_left_out": [{"t_s": float(t[a]), "duration_s": float(t[b] - t[a]), "level_a": float(m),
                                    "se_a": float(e)}
                                   for (a, b), m, e, ok in zip(spans, meds, se_k, agree) if not ok]}

    def measured_params(self, ctx) -> dict:
        """Parameters this record measures directly: the current-sensor offset, whenever the record has rests
        after current (rests of at least ``OFFSET_REST_MIN_S``, >= 30 samples in all) - a cell at rest carries no current, so what the sensor logs there is
        its offset: the median logged current, with its standard error.  ``significant``: it differs from
        zero by more than ``REST_OFFSET_SE`` standard errors (else the rests measure the offset as zero, and
        the ``current_offset`` effect cannot be named)."""
        rc = getattr(self, "rest_current", None)
        if rc is None:
            return {}
        return {"current_offset_a": {"value": rc["value"], "se": rc["se"],
                                     "significant": bool(abs(rc["value"]) > self.REST_OFFSET_SE * rc["se"]),
                                     # a reviewer's PyBaMM records with a real standing current of C/100-C/25 in
                                     # the rests and no offset read the same levels (fifteenth session)
                                     "alternative": "a real current the cell carried at rest (a standing draw, a "
                                                    "charger's trickle, a balancing bleed) reads the same level: the "
                                                    "level alone does not tell it from a sensor offset; the fit under "
                                                    "load does (a held-out gain) or the relaxed rests do, where the "
                                                    "model and the rests allow",
                                     "how": f"the logged current in {rc.get('n_rests', '')} "
                                            + ("agreeing rests, " if rc.get("consensus", True)
                                               else f"rest(s) of >= {self.SLOW_REST_MIN_S:.0f} s, pooled, ")
                                            + f"{rc['duration_s']:.0f} s ({rc['n']} samples, "
                                            f"{rc.get('n_eff', rc['n']):.0f} effectively independent"
                                            + (f"; {len(rc['rests_left_out'])} low-current span(s) left out, their "
                                               f"level not the others' (a real current)"
                                               if rc.get("rests_left_out") else "") + ")"}}

    def record_resolution(self) -> dict:
        """What the record can resolve: its rests after current, the slow RC branch's time-constant limit,
        the SOC swing, and whether a capacity / a current offset can be told from the slow branch."""
        rests = list(getattr(self, "rests_s", []))
        tmax = getattr(self, "tau2_max_s", None)
        two = self.base.r2_scale > 0.0      # the nominal declares the slow branch (else: the effect's)
        out = {"rests_after_current_s": rests, "soc_swing_frac": float(getattr(self, "soc_swing", float("nan"))),
               "slow_branch_tau_max_s": tmax,
               "rest_current_a": getattr(self, "rest_current", None),
               "rests_refused": [{"t_s": a, "duration_s": d, "why": w}
                                 for a, d, w in getattr(self, "rests_refused", [])]}
        out["slow_branch_tau_nominal_s"] = float(getattr(self, "tau2_nominal_s", float("nan")))
        if tmax is None:
            what = (f"the record's longest rest after current ({max(rests):.0f} s) is shorter than the slow RC "
                    f"branch's time constant ({out['slow_branch_tau_nominal_s']:.0f} s)" if rests
                    else "the record has no rest (>= 60 s) after current")
            one = "" if two else " (the nominal has one RC branch: the time constant is the second_rc_branch effect's)"
            out["statement"] = (f"{what}: the slow relaxation is not resolved, so a capacity error or a current "
                                f"offset cannot be told apart from it{one}")
        else:
            out["statement"] = (f"the slow RC branch's time constant is limited to the longest rest, {tmax:.0f} s "
                                f"(longer relaxations are a series capacitor: a capacity); SOC swing "
                                f"{100 * out['soc_swing_frac']:.0f} %")
        if len(rests) < 3:
            # the open-circuit voltage shows only at rest (effect_evidence: _hysteresis_evidence, _rest_claim)
            out["statement"] += (f"; {len(rests)} rest(s) after current: OCV hysteresis (rests reached after charge "
                                 f"and after discharge) cannot be told from an OCV offset"
                                 + (", nor an OCV correction from the resistances' form under current" if len(rests) < 2
                                    else ""))
        iv = getattr(self, "soc0_interval", None)
        if iv is not None:
            # the initial SOC read through the user's OCV table at the first rest: on a flat OCV (an LFP
            # plateau) a small error of the voltage or of the table is many points of SOC
            dv_mv = 1e3 * self.SOC0_TABLE_ERROR_V
            half = 100.0 * (iv[1] - iv[0]) / 2.0
            out["initial_soc_from_first_rest"] = {"soc_pct": 100.0 * self.soc0, "voltage_error_v": self.SOC0_TABLE_ERROR_V,
                                                  "soc_pct_interval": [100.0 * iv[0], 100.0 * iv[1]]}
            if half > self.FLAT_OCV_SOC_PCT:
                out["statement"] += (f"; the initial SOC read at the first rest ({100.0 * self.soc0:.1f} %) lies on a "
                                     f"flat part of the OCV table: the rest voltage +-{dv_mv:.0f} mV (a pseudo-OCV's own "
                                     f"overpotential) gives {100.0 * iv[0]:.1f}-{100.0 * iv[1]:.1f} % (a relaxed rest "
                                     f"on a steep part of the OCV gives the SOC; a drive under load does not)")
        if out["rests_refused"]:
            r = out["rests_refused"][0]
            out["statement"] += (f"; {len(out['rests_refused'])} low-current span(s) of >= 60 s are not rests (the "
                                 f"first, at {r['t_s']:.0f} s for {r['duration_s']:.0f} s: {r['why']})")
        return out

    def quiet_mask(self, ctx):
        """Rest: |current| below 1 % of the record's largest."""
        i = ctx["i"]
        return np.abs(i) <= 0.01 * max(float(np.abs(i).max()), 1e-9)

    def param_bounds(self, ctx):
        t = ctx["t"]
        return {"h_change_time_s": (float(t[0]), float(t[-1]))}

    def regressors(self, ctx):
        t, i = ctx["t"], ctx["i"]
        dt = np.diff(t, prepend=t[0])
        ah = np.cumsum(i * dt) / 3600.0
        return {"time_s": t - t[0], "current_a": i, "abs_current_a": np.abs(i), "current_sq_a2": i * i,
                "discharged_ah": ah, "t_ambient_c": ctx["ta"],
                "t_surface_meas_c": ctx["df"]["t_surface_c"].to_numpy(float)}

    #: the temperature's model-form term is computed from the voltage residual
    model_form_sources = {"t_surface_c": ("voltage_v",)}

    def model_form_terms(self, ctx, values, pred, meas):
        """The heat that the fit's own voltage error carries into the temperature (Bernardi): the cell's
        irreversible heat is ``i (U - V)`` with the measured ``V``; the circuit's heat follows its predicted
        ``V``, so the model heats by ``-i (V_model - V_measured)`` too much whatever the thermal effects.
        The term is that heat error through the fitted cell's lumped thermal time constant ``m c_p / (h A)``;
        an effect on the temperature (reversible heat, cooling change) must explain what it does not.
        The reversible heat ``i T dU/dT`` is not in ``i (U - V)`` and stays an effect."""
        if "t_surface_c" not in pred or "voltage_v" not in pred:
            return {}
        i = ctx["i"]
        heat = -i * (np.asarray(pred["voltage_v"]) - meas["voltage_v"])
        b = self.base
        r, length = float(b.radius_m), float(b.length_m)
        mass = b.density_kg_m3 * math.pi * r * r * length
        area = 2.0 * math.pi * r * length + 2.0 * math.pi * r * r
        cp = float(values.get("cp_j_kgk", b.cp_j_kgk))
        h = float(self.known["h_conv_w_m2k"]) * float(values.get("h_conv_factor", b.h_conv_factor))
        tau = mass * cp / max(h * area, 1e-12)
        return {"t_surface_c": _lag(ctx["t"], heat, tau)[:, None]}

    def _irreversible_heat(self, ctx, values, meas):
        """``(soc, i (U(soc) - V_measured))`` per sample by coulomb counting from the fit's initial SOC and
        capacity (the given OCV, corrected when the fit corrects it); None without an OCV table."""
        base = getattr(self, "ocv_base", None)
        if base is None or "voltage_v" not in meas:
            return None
        t, i = ctx["t"], ctx["i"]
        cap = float(values.get("capacity_ah", self.base.capacity_ah))
        soc0 = float(values.get("soc_init_pct", 100.0 * min(max(getattr(self, "soc0", 0.5), 0.0), 1.0))) / 100.0
        i_true = i - float(values.get("current_offset_a", 0.0))
        dt = np.diff(t, prepend=t[0])
        soc = soc0 - np.cumsum(i_true * dt) / (3600.0 * max(cap, 1e-9))
        xs, ys = self.ocv_corrected(values) or base
        u = np.interp(soc, xs, ys)
        return soc, i_true * (u - np.asarray(meas["voltage_v"], float))

    #: the record's own energy balance (:meth:`_energy_balance`): its intervals [s]
    ENERGY_BALANCE_WINDOW_S = 30.0
    #: a term of the balance is seen when it differs from 0 (from 1 for a ratio), in the direction the fit
    #: claims, by this many standard errors (a one-sided test at the 5 % level)
    ENERGY_BALANCE_SIGMA = 1.645
    #: knots (over the record's time) of the heat loss per kelvin in the reversible-heat check
    ENERGY_BALANCE_LOSS_KNOTS = 5
    #: the record must carry at least this fraction of the fitted reversible heat (more is no evidence against it:
    #: a two-state model's surface lags a real cell's core differently, which takes the fitted size down)
    ENERGY_BALANCE_MIN_SHARE = 0.5

    def _slowest_branch_s(self, ctx, values) -> float:
        """Time constant [s] of the fitted circuit's slowest RC branch (mid SOC, 25 degC)."""
        from ..core.lookup import ecm_lookup
        _rs, r1, c1, r2, c2 = ecm_lookup(ctx["d"], ctx["ix"], 0.5, 25.0, 1.0)
        full = self.full_values(values)
        taus = [r1 * c1 * float(full.get("r1_scale", 1.0)) * float(full.get("c1_scale", 1.0))]
        if float(full.get("r2_scale", self.base.r2_scale)) > 0.0:
            taus.append(r2 * c2 * float(full.get("r2_scale", 1.0)) * float(full.get("c2_scale", 1.0)))
        return max(taus)

    def _after_change(self, ctx, values):
        """0 before the fitted cooling change, 1 after (the component's own logistic step)."""
        w = max(float(self.known["change_width_s"]), 1e-9)
        z = (ctx["t"] - float(values.get("h_change_time_s", 0.0))) / w
        return 1.0 / (1.0 + np.exp(-np.clip(z, -40.0, 40.0)))

    def _mixing_heat(self, ctx, values):
        """``i lag(i)`` [A2] with the time constant of the fitted circuit's slowest branch: the form of the heat of
        the diffusion overpotential, whose energy is released as heat of mixing later or, in a lumped
        electrochemical model, not at all (PyBaMM's SPMe heats by ``i (U_surface - V)``: 29 % less than
        ``i (U_bulk - V)`` on the Chen2020 drives); a term of free scale in the record's balance."""
        i = ctx["i"] - float(values.get("current_offset_a", 0.0))
        return i * _lag(ctx["t"], i, self._slowest_branch_s(ctx, values))

    def _energy_balance(self, ctx, values, meas, mask, extra=()):
        """The record's own lumped energy balance over the samples ``mask``, whatever the circuit, in integral
        form over consecutive intervals of at least ``ENERGY_BALANCE_WINDOW_S`` (any sampling):
        ``T(t1) - T(t0) = a int Q - b int (T - T_amb) + c (t1 - t0) + sum_k e_k int x_k`` with ``T`` the measured
        surface temperature, ``Q = i (U - V)`` the irreversible heat with the measured voltage (even in the
        current) and ``x_k`` the arrays of ``extra`` [W] (integrals by the trapezoidal rule).  Returns
        ``(coefficients a, b, c, e_1.., standard errors, covariance)`` (least squares, intervals discounted for
        the residual's lag-1 autocorrelation), or None when the record cannot give it."""
        irr = self._irreversible_heat(ctx, values, meas)
        if irr is None or "t_surface_c" not in meas:
            return None
        idx = np.flatnonzero(mask)
        if idx.size < 3:
            return None
        t = ctx["t"][idx]
        temp = np.asarray(meas["t_surface_c"], float)[idx]
        edges = [0]
        for k in range(1, t.size):
            if t[k] - t[edges[-1]] >= self.ENERGY_BALANCE_WINDOW_S:
                edges.append(k)
        e = np.asarray(edges)
        if e.size < 12 + 2 * len(extra):
            return None

        def integral(y):
            y = np.asarray(y, float)[idx]
            return np.diff(np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))])[e])
        x = np.column_stack([integral(irr[1]), -integral(np.asarray(meas["t_surface_c"], float) - ctx["ta"]),
                             np.diff(t[e])] + [integral(c) for c in extra])
        y = np.diff(temp[e])
        beta = np.linalg.lstsq(x, y, rcond=None)[0]
        res = y - x @ beta
        rho = float(np.clip(np.corrcoef(res[:-1], res[1:])[0, 1], 0.0, 0.999)) if np.std(res) > 0 else 0.0
        neff = max(res.size * (1.0 - rho) / (1.0 + rho), float(x.shape[1] + 2))
        cov = np.linalg.pinv(x.T @ x) * float(res @ res) / max(neff - x.shape[1], 1.0) * (res.size / neff)
        return beta, np.sqrt(np.clip(np.diag(cov), 0.0, None)), cov

    def effect_evidence(self, effect, ctx, values, meas, base=None):
        """What a thermal effect claims, checked on the record's own energy balance (:meth:`_energy_balance`),
        independently of the circuit, whose heat is uncertain by its form.

        * ``cooling_change`` claims that the cell's heat loss per kelvin above ambient changed by
          ``h_change_factor`` at ``h_change_time_s``: the balance with a loss per kelvin of its own after the
          change time (the model's step) gives ``b_after / b_before``, the change of the thermal time constant
          (a heat whose level differs goes into ``a``, a drift of the heat of mixing into its own term).
          Supported when that ratio differs from 1 by more than ``ENERGY_BALANCE_SIGMA`` standard errors and
          lies on the side of the fitted factor, nearer to it than to 1 (in logs).
        * ``entropic_heat`` claims a reversible heat ``-i T dU/dT(SOC)``, odd in the current: the fitted
          reversible heat enters the balance as a term of free scale, beside the heat of mixing
          (:meth:`_mixing_heat`; on a drive that discharges on average it is itself near ``i`` times a slowly
          varying number) and a heat loss per kelvin that may vary slowly over the record.  Its scale relative
          to the balance's ``a`` without the heat of mixing is the fraction of the fitted reversible heat the
          record carries: supported when it exceeds 0 by more than ``ENERGY_BALANCE_SIGMA`` standard errors and
          is at least ``ENERGY_BALANCE_MIN_SHARE``.

        A step in h at a free time, or an SOC-shaped reversible heat, that only bends the model to a thermal
        model-form error leaves the record's own balance without them.

        ``ocv_hysteresis`` claims that the open-circuit voltage depends on the direction the cell came from
        (:meth:`_hysteresis_evidence`): checked on the record's relaxed rest voltages, not on its voltage under
        current, where a resistance of another form (the Butler-Volmer overpotential's asymmetry and
        nonlinearity) bends the model the same way.  ``ocv_correction`` (the OCV itself differs from the given
        curve) and ``capacity`` (the SOC that the charge passed reaches differs) are claims about the relaxed
        voltage too: checked at the rests (:meth:`_rest_claim`); a record without rests after current cannot show
        an OCV correction (refused, what it lacks said); a capacity is then not checked there (a wide swing's
        voltage under current shows it, and :meth:`record_resolution` says when the record cannot tell it from
        the slow RC branch).  An initial SOC is checked at the rests after current and the relaxed first rest;
        with no rest after current as long as the slow relaxation, the relaxed first rest alone bounds it: its
        voltage +- ``FIRST_REST_MARGIN`` x the table's own error (``SOC0_TABLE_ERROR_V``) through the table."""
        if effect == "cooling_change":
            return self._cooling_evidence(ctx, values, meas)
        if effect == "entropic_heat":
            return self._entropic_evidence(ctx, values, meas)
        if effect == "ocv_hysteresis":
            return self._hysteresis_evidence(ctx, values, meas)
        if effect == "ocv_correction":
            k = len(getattr(self, "ocv_knots", ()))
            if not any(float(values.get(f"ocv_delta_v[{j}]", 0.0)) for j in range(k)):
                return None
            return self._rest_claim(ctx, values, meas, {f"ocv_delta_v[{j}]": 0.0 for j in range(k)},
                                    "the OCV correction", 2)
        if effect == "initial_soc":
            s0 = 100.0 * min(max(getattr(self, "soc0", 0.5), 0.0), 1.0)
            if float(values.get("soc_init_pct", s0)) == s0:
                return None
            claim = self._rest_claim(ctx, values, meas, {"soc_init_pct": s0}, "the initial SOC", 0, first_rest=True)
            if claim is None and self.first_rest_span is not None and self.soc0_interval is not None:
                # no rest after current to regress on: the relaxed first rest alone reads the initial SOC within the
                # interval its voltage +- FIRST_REST_MARGIN x the table's own error gives through the table; a value
                # outside it contradicts the one relaxed voltage the record has (the Ecker2015 drive: 77.58 %
                # fitted to the form error under current, first rest 78.1 %, truth 78.11 %)
                lo, hi = self.soc0_interval_wide or self.soc0_interval
                fit = float(values["soc_init_pct"])
                ok = 100.0 * lo <= fit <= 100.0 * hi
                claim = {"ok": ok, "evidence": {"first_rest_soc_interval_pct": [100.0 * lo, 100.0 * hi],
                                                "soc_init_pct": fit},
                         "statement": (f"the record's relaxed first rest (before any current) reads an initial SOC of "
                                       f"{100.0 * lo:.2f}-{100.0 * hi:.2f} % (its voltage +- "
                                       f"{1e3 * self.FIRST_REST_MARGIN * self.SOC0_TABLE_ERROR_V:.0f} mV through the "
                                       f"table: {self.FIRST_REST_MARGIN:g}x its own error) and the fit puts "
                                       f"it at {fit:.2f} %" + ("" if ok else ": outside, with no rest after current "
                                       "long enough to say otherwise; it bends the model to the voltage's form error "
                                       "under current"))}
            return claim
        if effect == "capacity":
            if float(values.get("capacity_ah", self.base.capacity_ah)) == self.base.capacity_ah:
                return None
            pushed = self._capacity_pushes_slow_branch(values, base)
            if pushed is not None:
                return pushed
            # the first rest (before any current, relaxed all through) is a rest too: the charge passed from it
            # reaches the later rests' SOC through the capacity (a drive-and-park record with one rest as long as
            # the slow relaxation: a capacity 8 % low named on PyBaMM ORegan2022 no-effect drives, unchecked)
            return self._rest_claim(ctx, values, meas, {"capacity_ah": self.base.capacity_ah}, "the capacity", 0,
                                    first_rest=True)
        return None

    def measurement_confirmed(self, effect, ctx, values, meas):
        """A current-sensor offset measured at the rests (the logged current where the cell carries none) claims
        that the charge the cell passed is the logged one less the offset: the relaxed rest voltages, read
        through the OCV, sit where the corrected charge puts them (:meth:`_rest_claim`, at least two rests as
        long as the slow relaxation).  Confirmed there, the offset is a fact about the logger whatever the fit
        under current says (the Ecker2015 offset record: measured 0.1501 +- 0.0003 A, truth 0.15; with it the
        rests' residuals go from -7.6, -9.2, -6.2, -16.8 mV to +5.1, -0.4, +1.4, -0.4 mV while the voltage under
        current, whose form error the baseline had fitted with the drifting SOC, gets worse)."""
        if effect != "current_offset" or not float(values.get("current_offset_a", 0.0)):
            return None
        # at least three rests (two degrees of freedom for the slope's scatter): with two, any drift of one sign
        # at the rest ends would do
        return self._rest_claim(ctx, values, meas, {"current_offset_a": 0.0}, "the current offset",
                                self.CONFIRM_MIN_RESTS)

    def _limited_tau_s(self, full) -> float:
        """The second (slow) RC branch's time constant [s] of the full values ``full``: the table's mean time
        constant times the scales, clipped at ``tau2_max_s`` as :meth:`_component_params` does (0 without it)."""
        b = self.base
        r2s = float(full.get("r2_scale", b.r2_scale))
        tau2 = r2s * float(full.get("c2_scale", b.c2_scale)) * self.tau2_table_s if r2s > 0.0 else 0.0
        tmax = getattr(self, "tau2_max_s", None)
        return min(tau2, tmax) if tmax else tau2

    def _capacity_pushes_slow_branch(self, values, base):
        """A capacity whose fit pushes the slow RC branch onto the record's time-constant limit is not separable
        from it; the refusal, or None.

        Beyond the limit (the longest rest after current, :meth:`prepare`) no rest shows a relaxation decay, and
        a branch is a series capacitor, which is what a capacity is to the voltage (the SOC that the charge
        passed reaches, at the OCV's slope).  When the model the capacity is added to (``base``: its full values)
        has its slow branch below the limit and the fit with the capacity needs it at the limit, the two
        are trading one capacitor-like response: the branch cancels the capacity's drift (a capacity above the
        rated one with a branch that pulls the voltage the other way; PyBaMM's no-effect swing drive with the
        heat of mixing: the pair low_soc_resistance + capacity 5.237 A.h moved the branch from 321 s to its
        620 s limit).  A true capacity error does not push it there: the model without it already stretches its
        slow branch towards the limit to stand in for it, and with it the branch comes back or stays
        (``capacity_swing``: 4811 -> 26 s against its 599 s limit; a reviewer's record with 8 % lost capacity and
        420 s rests: 3938 -> 5176 s against 419 s; none of the true capacities of the reviewer's 16 records).  The branch at the limit alone is not the sign: on records whose rests
        are barely longer than the cell's own slow relaxation (420 s rests; Chen2020's positive particle
        R^2/(pi^2 D) is 690 s) true capacities are fitted with it there.  The second branch only - the one the
        limit applies to: a fit may give the first branch a long time constant too, and a true capacity did (a
        reviewer's +8 % record: the first branch at 874 s with it, past the 614 s limit, the second 13 -> 18 s, the
        capacity 5.321 vs 5.4 A.h; counting the first branch refused it)."""
        tmax = getattr(self, "tau2_max_s", None)
        if not tmax or base is None:
            return None
        tol = 1.0 - self.SLOW_LIMIT_TOL
        full = self.full_values(values)
        tau, tau0 = self._limited_tau_s(full), self._limited_tau_s(self.full_values(base))
        if tau < tol * tmax or tau0 >= tol * tmax:
            return None
        cap = float(values.get("capacity_ah", self.base.capacity_ah))
        return {"ok": False, "evidence": {"slow_branch_tau_s": tau, "slow_branch_tau_before_s": tau0,
                                          "slow_branch_tau_max_s": tmax, "capacity_ah": cap},
                "statement": (f"the capacity ({cap:.4g} A.h) is fitted only by pushing the slow RC branch onto "
                              f"its time-constant limit ({tau0:.0f} s without it, {tmax:.0f} s with it: the record's "
                              f"longest rest after current, beyond which a branch is a series capacitor, as a "
                              f"capacity is): the two trade one response, and the record does not separate them (a "
                              f"rest long enough to show the slow relaxation decay can)")}

    def _cooling_evidence(self, ctx, values, meas):
        f = float(values.get("h_change_factor", 1.0))
        tc = float(values.get("h_change_time_s", 0.0))
        if f == 1.0:
            return None
        t = ctx["t"]
        rise = np.asarray(meas["t_surface_c"], float) - ctx["ta"]
        extra = (-rise * self._after_change(ctx, values), self._mixing_heat(ctx, values))
        rev = self._reversible_heat(ctx, values, meas)
        if rev is not None:            # fitted beside the cooling change: its form enters the balance too
            extra = extra + (rev,)
        ev = {"h_change_time_s": tc, "h_change_factor": f}
        n_side = min(int(np.sum(t < tc)), int(np.sum(t > tc)))
        fit = self._energy_balance(ctx, values, meas, np.ones(t.size, bool), extra=extra)
        if fit is None or n_side * float(np.median(np.diff(t))) < 10.0 * self.ENERGY_BALANCE_WINDOW_S:
            return {"ok": False, "evidence": ev, "statement": f"the record on one side of the cooling change at "
                    f"{tc:.0f} s is too short to show a change of the heat loss"}
        beta, _se, cov = fit
        b0, d = float(beta[1]), float(beta[3])       # loss per kelvin before; its change after
        b1 = b0 + d
        ev.update(loss_per_k_before_1_s=b0, loss_per_k_after_1_s=b1)
        if b0 <= 0.0 or b1 <= 0.0:
            return {"ok": False, "evidence": ev, "statement": f"the record's own energy balance gives no heat loss to "
                    f"ambient on one side of {tc:.0f} s (rate per kelvin {b0:.3g} / {b1:.3g} 1/s)"}
        ratio = b1 / b0
        # ln(b1 / b0) by the delta method: gradient (1/b1 - 1/b0, 1/b1) on (b0, d)
        g = np.array([1.0 / b1 - 1.0 / b0, 1.0 / b1])
        c2 = np.array([[cov[1, 1], cov[1, 3]], [cov[3, 1], cov[3, 3]]])
        se_ln = float(math.sqrt(max(float(g @ c2 @ g), 0.0)))
        lr, lf = math.log(ratio), math.log(f)
        ev.update(ratio=ratio, se_ln_ratio=se_ln)
        ok = abs(lr) > self.ENERGY_BALANCE_SIGMA * se_ln and lr * lf > 0 and abs(lr - lf) < abs(lr)
        why = (f"the record's own energy balance puts the heat loss per kelvin after {tc:.0f} s at {ratio:.2f}x the "
               f"loss before (+-{se_ln:.2f} in logs; fitted factor {f:.2f})")
        k = self.ENERGY_BALANCE_SIGMA
        if ok:
            tail = ""
        elif not abs(lr) > k * se_ln:        # a new user's trial: "no such change" beside a ratio of 2.57 +- 1.30
            tail = (f": within {k:g} standard errors of no change, so the record's own balance cannot show it (too "
                    f"little heating against the temperature's noise); the step is not named on the fit alone, where "
                    f"it may bend the model to a thermal model-form error (a record that heats the cell more can "
                    f"show it)")
        else:
            tail = (": the balance's change is not the fitted one (of the other sign, or nearer no change than the "
                    "fitted factor): the step bends the model to a thermal model-form error")
        return {"ok": ok, "evidence": ev, "statement": why + tail}

    def _reversible_heat(self, ctx, values, meas):
        """The fitted reversible heat ``-i T dU/dT(SOC)`` [W] (measured ``T``), or None when ``values`` have none."""
        knots = [float(values.get(f"dudt_v_k[{k}]", 0.0)) for k in range(len(self.dudt_knots))]
        irr = self._irreversible_heat(ctx, values, meas)
        if not any(knots) or irr is None:
            return None
        i_true = ctx["i"] - float(values.get("current_offset_a", 0.0))
        return -i_true * (np.asarray(meas["t_surface_c"], float) + T0_K) * np.interp(irr[0], self.dudt_knots, knots)

    def _entropic_evidence(self, ctx, values, meas):
        knots = [float(values.get(f"dudt_v_k[{k}]", 0.0)) for k in range(len(self.dudt_knots))]
        rev = self._reversible_heat(ctx, values, meas)
        if rev is None:
            return None
        # the heat loss per kelvin may vary slowly over the record (a cooling change, airflow): piecewise linear
        # in time (hat functions; the first is the balance's own constant term) - the reversible heat is odd in
        # the current, a heat loss is not
        t = ctx["t"]
        rise = np.asarray(meas["t_surface_c"], float) - ctx["ta"]
        knots_t = np.linspace(float(t[0]), float(t[-1]), self.ENERGY_BALANCE_LOSS_KNOTS)
        extra = (rev,) + tuple(-rise * np.interp(t, knots_t, np.eye(knots_t.size)[k])
                               for k in range(1, knots_t.size))
        if float(values.get("h_change_factor", 1.0)) != 1.0:      # and the cooling change fitted beside it
            extra = extra + (-rise * self._after_change(ctx, values),)
        every = np.ones(ctx["t"].size, bool)
        plain = self._energy_balance(ctx, values, meas, every, extra=extra)
        full = self._energy_balance(ctx, values, meas, every, extra=extra + (self._mixing_heat(ctx, values),))
        if plain is None or full is None:
            return None
        a = float(plain[0][0])
        if a <= 0.0:
            return {"ok": False, "evidence": {}, "statement": "the record's own energy balance finds no heating by "
                    "the irreversible heat"}
        scale, se = float(full[0][3]) / a, float(full[1][3]) / a
        k, share = self.ENERGY_BALANCE_SIGMA, self.ENERGY_BALANCE_MIN_SHARE
        ok = scale > k * se and scale >= share
        ev = {"reversible_heat_scale": scale, "se": se, "dudt_v_k_fitted": knots}
        why = (f"the record's own energy balance carries the fitted reversible heat (dU/dT "
               + ", ".join(f"{1e3 * x:+.2f}" for x in knots) + f" mV/K at the SOC knots) at {scale:.2f} +- {se:.2f} of "
               f"its size beside the heat of mixing")
        return {"ok": ok, "evidence": ev, "statement": why + ("" if ok else f" (needed: > {k:g} standard errors and "
                f"at least {share:g}): the reversible heat fitted is not the record's, it bends the model to a "
                f"thermal model-form error")}

    #: the checks at the rests (:meth:`_rest_claim`, :meth:`_hysteresis_evidence`): the rests' voltage must follow the
    #: fitted effect at this one-sided level (Student's t with the rests' degrees of freedom: a record has a handful of
    #: rests) ...
    REST_CLAIM_LEVEL = 0.95
    #: ... and with a slope within this factor of the fitted size (as :data:`workflow.CLAIM_FACTOR`)
    REST_CLAIM_FACTOR = 2.0
    #: the cell's hysteresis state at the record's start, which the record does not know (the fit assumes 0)
    HYSTERESIS_START_STATES = (-1.0, 0.0, 1.0)

    def _ocv_rest_spans(self):
        """The rests after current that show the open-circuit voltage: at least the slow RC branch's nominal time
        constant long (``tau2_nominal_s``).  A shorter rest ends with the slow relaxation still under way, so its
        voltage is the circuit's remaining polarisation as much as the OCV, and what it shows depends on the
        model's form (the PyBaMM Ecker2015 drive's 64-92 s stops against a 387 s slow branch passed an OCV
        correction fitted to the form error under current)."""
        tn = float(getattr(self, "tau2_nominal_s", 0.0) or 0.0)
        t = getattr(self, "_rest_t", None)
        return [(a, b) for a, b in getattr(self, "rest_spans", []) if t is None or t[b] - t[a] >= tn]

    def _rest_end_deviation(self, ctx, values, meas, neutral, first_rest: bool = False, spans=None, residual=False):
        """At the end (last tenth) of each rest after current: ``(fitted, measured)`` [V], the candidate fit's voltage
        and the measured one, each minus the fit's voltage with the parameters ``neutral`` (the effect switched off,
        the other parameters as fitted: the RC branches' remaining relaxation is the model's)."""
        v = np.asarray(meas["voltage_v"], float)
        with_e = np.asarray(self.simulate(ctx, values)["voltage_v"], float)
        without = np.asarray(self.simulate(ctx, dict(values, **neutral))["voltage_v"], float)
        fit, dev = [], []
        spans = list(getattr(self, "rest_spans", []) if spans is None else spans)
        if first_rest and getattr(self, "first_rest_span", None) is not None:
            spans = [self.first_rest_span] + spans
        for a, b in spans:
            sl = (slice(a, b + 1) if (a, b) == getattr(self, "first_rest_span", None)   # relaxed all through
                  else slice(b + 1 - max(3, int(0.1 * (b - a + 1))), b + 1))
            fit.append(float(np.mean(with_e[sl] - without[sl])))
            dev.append(float(np.mean(v[sl] - without[sl])))
        if residual:     # also the measured voltage less the fit without the effect, the whole record
            return np.array(fit), np.array(dev), v - without
        return np.array(fit), np.array(dev)

    #: :meth:`_unrelaxed` counts a rest's residual slope as relaxation still under way only beyond this many of its
    #: standard errors (the sensor's noise alone gives a slope too: 1 mV of noise on an 8-minute rest read 1.5 mV
    #: "still to come" at the median, 4.3 mV at the 90th percentile, before the slope had to be told from it)
    RELAXATION_SLOPE_SIGMA = 2.0

    def _unrelaxed(self, resid, spans) -> np.ndarray:
        """Per rest of ``spans``: the relaxation still to come after its end that the model does not make [V,
        signed], from ``resid`` (the measured voltage less the model's, which relaxes through its own RC branches:
        what the model follows needs no allowance).  The residual's tail is read
        as ``r = r_oc - c t^-a`` (t from the rest's start): its slope ``dV/dt`` on the last quarter and on the
        quarter before give ``a + 1 = ln(s_3 / s_4) / ln(t_4 / t_3)``, and what remains after the end ``T`` is
        ``c T^-a = T dV/dt / a``.  ``a`` is at least 1/2, solid diffusion's tail (``2 T dV/dt``, the slowest a cell
        relaxes); an exponential tail (an RC branch) steepens the slopes' fall, a larger ``a``, less to come.  Slopes
        of another sign or not falling: the diffusion bound.  Against the residual's noise (least-squares standard
        errors on the quarters' samples, counted ``n / tau`` with ``tau`` their residual's integrated
        autocorrelation time: a real logger's rest residual is not white, lag-1 correlation 0.4-0.7 on the
        Panasonic 18650PF, and white-noise errors there read noise as relaxation on half of the rests): the last
        quarter's slope within Student's quantile of its error (the normal's ``RELAXATION_SLOPE_SIGMA``, two-sided,
        with ``n / tau - 2`` degrees of freedom) is a relaxed rest (0 to come), and ``a`` is read from the slopes'
        ratio at its least within that quantile each (the allowance is a bound: noise on the ratio must not shrink
        it; 1 mV on a 10 mV diffusion tail put the plain ratio's ``a`` anywhere in 0.5-2.5).  Below its detection
        limit (about 5 mV still to come under 1 mV of noise on an 8-minute rest) a tail reads as relaxed.  A quarter is at least 3 samples.  The record's first rest, before any current, is
        relaxed (0)."""
        from scipy import stats
        v = np.asarray(resid, float)
        t = getattr(self, "_rest_t", None)
        level = float(stats.norm.cdf(self.RELAXATION_SLOPE_SIGMA))     # one-sided: the normal's 2 sigma, two-sided
        out = []
        for a, b in spans:
            if (a, b) == getattr(self, "first_rest_span", None) or t is None:
                out.append(0.0)
                continue
            k = max(3, (b - a + 1) // 4)
            if b + 1 - 2 * k < a:
                out.append(0.0)
                continue

            def slope(lo, hi):
                """Least-squares slope of the residual on ``[lo, hi)``, its standard error (the samples counted
                ``n / tau``, ``tau`` the integrated autocorrelation time of the fit's residual) and the quantile a
                slope must pass (Student's t with ``n / tau - 2`` degrees of freedom, at least 1)."""
                tt, vv = t[lo:hi] - t[lo], v[lo:hi]
                sxx = float(np.sum((tt - tt.mean()) ** 2))
                if sxx <= 0.0 or tt.size < 3:
                    return 0.0, float("inf"), float("inf")
                s = float(np.sum((tt - tt.mean()) * (vv - vv.mean()))) / sxx
                r = vv - vv.mean() - s * (tt - tt.mean())
                tau = CellModel._tau_int(r)
                se = math.sqrt(float(r @ r) / (tt.size - 2) / sxx * tau)
                return s, se, float(stats.t.ppf(level, max(1.0, tt.size / tau - 2.0)))
            (s4, e4, q4), (s3, e3, q3) = slope(b + 1 - k, b + 1), slope(b + 1 - 2 * k, b + 1 - k)
            if not abs(s4) > q4 * e4:
                out.append(0.0)
                continue
            t4 = float(np.mean(t[b + 1 - k:b + 1]) - t[a])
            t3 = float(np.mean(t[b + 1 - 2 * k:b + 1 - k]) - t[a])
            alpha = 0.5
            lo = (abs(s3) - q3 * e3) / (abs(s4) + q4 * e4)      # the slopes' fall, at its least within their errors
            if s3 * s4 > 0.0 and lo > 1.0 and t4 > t3 > 0.0:
                alpha = max(0.5, math.log(lo) / math.log(t4 / t3) - 1.0)
            out.append(float(t[b] - t[a]) * s4 / alpha)
        return np.array(out, float)

    def _rest_claim(self, ctx, values, meas, neutral: dict, what: str, min_rests: int, first_rest: bool = False):
        """Whether the record's own rests show what an effect fitted there claims about the open-circuit voltage.
        At rest the cell's voltage relaxes to its open-circuit voltage, where no resistance of any form acts: an
        effect on the OCV itself (a correction of the curve) or on the state it is read at (a capacity: the SOC the
        charge passed reaches) claims that the relaxed rest voltages sit where the fit puts them.  At each rest's
        end the measured voltage minus the fit's with ``neutral`` (the effect off, the other parameters as fitted)
        is regressed on the fit's own difference there, through the origin (the effect off is the alternative);
        supported when the slope exceeds 0 by Student's one-sided ``REST_CLAIM_LEVEL`` quantile (n - 1 degrees of
        freedom, the rests' scatter about the line: the OCV table's own error at their SOC) and is of the fitted
        size (within ``REST_CLAIM_FACTOR`` of 1, or 1 within the quantile's standard errors).  Fitted to the
        voltage under current, where it trades against the resistances' form (the Butler-Volmer overpotential's
        nonlinearity and asymmetry, which a linear circuit lacks), such an effect puts the rests where they are
        not.  With fewer than ``min_rests`` rests after current: not supported (``min_rests`` > 0: what the record
        lacks is said) or not checked (0).  ``first_rest``: the record's first rest, before any current (relaxed
        all through), is one of the rests (an effect on the initial state claims something there too)."""
        from scipy import stats
        after = self._ocv_rest_spans()
        spans = list(after)
        if first_rest and getattr(self, "first_rest_span", None) is not None:
            spans = [self.first_rest_span] + spans
        n = len(spans)
        ev = {"n_rests": n}
        if n < max(min_rests, 2):
            if min_rests <= 0:
                return None
            tn = float(getattr(self, "tau2_nominal_s", 0.0) or 0.0)
            return {"ok": False, "evidence": ev, "statement": (
                f"the record has {len(after)} rest(s) after current as long as the slow relaxation's time constant "
                f"({tn:.0f} s; {len(getattr(self, 'rest_spans', []))} of >= 60 s): the open-circuit voltage shows only "
                f"at a relaxed rest, and without such rests the record cannot tell {what} from the resistances' form "
                f"under current")}
        fit, dev_end, resid = self._rest_end_deviation(ctx, values, meas, neutral, first_rest, spans=after,
                                                       residual=True)
        # a rest's end voltage is the OCV only within the relaxation still under way there (_unrelaxed: at most
        # 2 T dV/dt, solid diffusion's tail): the relaxed voltage lies between the end voltage and that much
        # further, and the claim is judged at the point of that interval nearest to the effect's absence (a capacity 8 % low passed on PyBaMM ORegan2022 no-effect drives on a 483 s rest whose
        # voltage still rose 23 uV/s: -13.9 mV against the -14.6 mV the capacity put there, with 22 mV to go)
        rem = self._unrelaxed(resid, spans)
        lo, hi = np.minimum(dev_end, dev_end + rem), np.maximum(dev_end, dev_end + rem)
        dev = np.clip(0.0, lo, hi)
        q = float(stats.t.ppf(self.REST_CLAIM_LEVEL, n - 1))
        sxx = float(fit @ fit)
        slope = float(fit @ dev) / sxx if sxx > 0.0 else float("nan")
        se = math.sqrt(float((dev - slope * fit) @ (dev - slope * fit)) / (n - 1) / sxx) if sxx > 0.0 else float("inf")
        # the record's first rest, before any current: where an effect does not act there (a capacity: no charge
        # has passed; under 1 % of what it does at the rest after current) its point is (0, ~0) - the initial SOC was read there - and with one rest after current
        # beside it the scatter about the line is not measured: the t-test has nothing to test against, and the
        # claim is judged by its size alone (a reviewer's finding: its standard error came out of the first rest's
        # microvolts).  Where the effect acts there (an initial SOC) the first rest is evidence, and the t-test
        # keeps it (a fit that moves the first rest where the record does not is refused)
        scatter = not (first_rest and getattr(self, "first_rest_span", None) is not None and len(after) < 2
                       and abs(float(fit[0])) <= 0.01 * float(np.max(np.abs(fit[1:]), initial=0.0)))
        if scatter:
            ok = (math.isfinite(se) and slope > q * se and slope > 0.0
                  and (abs(math.log(slope)) <= math.log(self.REST_CLAIM_FACTOR) or abs(slope - 1.0) <= q * se))
        else:
            ok = math.isfinite(slope) and slope > 0.0 and abs(math.log(slope)) <= math.log(self.REST_CLAIM_FACTOR)
        ev.update(rest_end_t_s=[float(ctx["t"][b]) for _a, b in spans], fitted_at_rest_ends_v=[float(x) for x in fit],
                  rest_deviation_v=[float(x) for x in dev], rest_end_deviation_v=[float(x) for x in dev_end],
                  still_relaxing_v=[float(x) for x in rem], slope=slope, se=se if scatter else None,
                  t_test=scatter)
        why = (f"at the ends of the record's {n} rests {'(its first, before any current, and those after current)' if first_rest and getattr(self, 'first_rest_span', None) is not None else 'after current'} {what} moves the model's voltage by "
               + ", ".join(f"{1e3 * x:+.1f}" for x in fit) + " mV and the relaxed voltage differs from the model's "
               "without it by " + ", ".join(f"{1e3 * x:+.1f}" for x in dev) + " mV" + (
                   " (at the rest ends " + ", ".join(f"{1e3 * x:+.1f}" for x in dev_end) + " mV, still relaxing by up "
                   "to " + ", ".join(f"{1e3 * x:+.1f}" for x in rem) + " mV: the interval's point nearest to no effect)"
                   if np.any(dev != dev_end) else "") + (f": slope {slope:.2f} +- {se:.2f}" if scatter else (
                   f": slope {slope:.2f} (one rest after current: the rests' scatter is not measured, so the claim is "
                   f"judged by its size alone, no t-test)")))
        need = (f"> {q:.2f} standard errors, Student's t with {n - 1} degrees of freedom, and within a factor "
                f"{self.REST_CLAIM_FACTOR:g} of 1" if scatter else f"within a factor {self.REST_CLAIM_FACTOR:g} of 1")
        return {"ok": ok, "evidence": ev, "statement": why + ("" if ok else (
            f" (needed: {need}): the rests do not sit where it puts them; it bends the model to the "
            f"voltage's model-form error under current"))}

    def _hysteresis_evidence(self, ctx, values, meas):
        """Whether the record's own rests show the fitted OCV hysteresis ``M h``.

        Hysteresis claims that the voltage a cell relaxes to at rest depends on the direction it came from: rests
        reached after charge and after discharge sit apart by ``M`` times the difference of their hysteresis state
        ``h``.  Its evidence is the record's rests after current (:meth:`_rest_spans`): at each rest's end (its last
        tenth) the measured voltage minus the candidate fit's voltage without hysteresis (``hyst_max_v = 0``, the
        other parameters as fitted: the RC branches' remaining relaxation is the model's) is regressed on the fit's
        ``M h`` there, with an intercept - an OCV offset, which a record whose rests all share one ``h`` cannot
        tell from hysteresis (nor from an OCV correction, when ``h`` only builds up along a one-way discharge:
        then ``h`` is a function of the SOC).  ``h`` at each rest comes from the fit (the voltage with hysteresis
        minus the one without, over ``M``) for every start state of :data:`HYSTERESIS_START_STATES`: the
        recursion ``h+ = a h + b`` is affine, so a start state ``h0`` adds ``h0 exp(-g |charge passed| / Q)`` -
        evidence that rests on the fit's assumed start (0) is not the record's.  Supported when, for every start
        state, the slope exceeds 0 by Student's one-sided ``REST_CLAIM_LEVEL`` quantile (n - 2 degrees of
        freedom, the scatter of the rests about the line: the OCV table's own error at their SOC) and is of the
        fitted size (within ``REST_CLAIM_FACTOR`` of 1, or 1 within the quantile's standard errors).  A record
        with fewer than 3 rests after current cannot show it (a drive without rest stops: what it lacks is said)."""
        from scipy import stats
        m_h = float(values.get("hyst_max_v", 0.0))
        if m_h == 0.0:
            return None
        g = float(values.get("hyst_rate", 30.0))
        spans = list(getattr(self, "rest_spans", []))
        ev = {"hyst_max_v": m_h, "hyst_rate": g, "n_rests": len(spans)}
        if len(spans) < 3:
            return {"ok": False, "evidence": ev, "statement": (
                f"the record has {len(spans)} rest(s) after current (>= 60 s); hysteresis is the "
                "rest voltage depending on the direction the cell came from, and without rests reached after charge "
                "and after discharge the record cannot tell it from an OCV offset or correction: the fitted M h "
                "bends the model to the voltage's model-form error under current")}
        x0, dev = self._rest_end_deviation(ctx, values, meas, {"hyst_max_v": 0.0})
        t = ctx["t"]
        i_true = ctx["i"] - float(values.get("current_offset_a", 0.0))
        cap = float(values.get("capacity_ah", self.base.capacity_ah))
        memory = np.exp(-g * np.cumsum(np.abs(i_true) * np.diff(t, prepend=t[0])) / (3600.0 * max(cap, 1e-9)))
        mem = np.array([float(np.mean(memory[b + 1 - max(3, int(0.1 * (b - a + 1))):b + 1])) for a, b in spans])
        n = dev.size
        q = float(stats.t.ppf(self.REST_CLAIM_LEVEL, n - 2))
        ev.update(rest_end_t_s=[float(t[b]) for _a, b in spans], h_at_rest_ends=[float(x) for x in x0 / m_h],
                  start_memory_at_rest_ends=[float(x) for x in mem], rest_deviation_v=[float(x) for x in dev])
        fits, bad = [], []
        for h0 in self.HYSTERESIS_START_STATES:
            x = x0 + h0 * m_h * mem
            xc = x - x.mean()
            sxx = float(xc @ xc)
            if sxx <= 0.0:
                slope, se = float("nan"), float("inf")
            else:
                slope = float(xc @ (dev - dev.mean())) / sxx
                res = dev - dev.mean() - slope * xc
                se = math.sqrt(float(res @ res) / (n - 2) / sxx)
            sig = math.isfinite(se) and slope > q * se
            same = slope > 0.0 and (abs(math.log(slope)) <= math.log(self.REST_CLAIM_FACTOR)
                                    or abs(slope - 1.0) <= q * se)
            fits.append({"start_state": h0, "slope": slope, "se": se, "h_spread": float(np.ptp(x)) / abs(m_h)})
            if not (sig and same):
                bad.append((h0, slope, se, float(np.ptp(x)) / abs(m_h)))
        ev["regressions"] = fits
        ok = not bad
        h_txt = ", ".join(f"{x:+.2f}" for x in x0 / m_h)
        why = (f"at the ends of the record's {n} rests after current the fitted hysteresis state h is {h_txt} (start "
               f"state 0 as fitted; M = {1e3 * m_h:+.1f} mV); the rest voltages minus the model's without hysteresis "
               f"follow M h with slope "
               + ", ".join(f"{f['slope']:.2f} +- {f['se']:.2f} (start h {f['start_state']:+g})" for f in fits))
        if ok:
            return {"ok": True, "evidence": ev, "statement": why}
        h0, slope, se, spread = bad[0]
        what = (f"with start state {h0:+g} the rests' h spread is {spread:.2f}: they are reached from one side, and "
                "the record cannot tell hysteresis from an OCV offset / correction"
                if not math.isfinite(se) or spread < 0.1
                else f"with start state {h0:+g} the rests do not sit apart by M h")
        return {"ok": False, "evidence": ev, "statement": why + (
            f" (needed, whatever the cell's unknown state at the start: > {q:.2f} standard errors, Student's t with "
            f"{n - 2} degrees of freedom, and within a factor {self.REST_CLAIM_FACTOR:g} of 1): {what}; the fitted M h "
            f"bends the model to the voltage's model-form error under current")}

    # -- closing the loop
    def overlay(self, values, out_dir) -> dict:
        """Battery parameters that carry the fit into a scenario (``[battery]`` of ``params.toml``)."""
        p = self._component_params(values)
        ov: dict[str, Any] = {}
        for prm in self.declared:
            ov[prm.name] = getattr(p, prm.name)
        for name, e in self.effects.items():
            for prm in e.params:
                key = prm.name.split("[")[0]
                if key == "ocv_delta_v":
                    continue
                if key == "dudt_v_k":
                    if p.dudt_v_k:
                        ov["dudt_soc_frac"] = list(p.dudt_soc_frac)
                        ov["dudt_v_k"] = list(p.dudt_v_k)
                    continue
                val = getattr(p, key)
                # an effect at its neutral value is not in the model (initial_soc's neutral is the record's own
                # first-rest reading, not the component's default: a vehicle scenario given the overlay must not
                # start at the record's SOC - the Panasonic 25 degC overlay carried 100 % and stopped at t = 0)
                if prm.name in e.neutral and val == e.neutral[prm.name]:
                    continue
                if val != getattr(self.base, key):
                    ov[key] = val
        if p.arrhenius_ea_r_k != 0.0:
            ov["arrhenius_t_ref_c"] = p.arrhenius_t_ref_c
        if p.h_change_factor != 1.0:
            ov["h_change_width_s"] = p.h_change_width_s
        # what the nominal model fixed for this (foreign) cell travels with the overlay
        for k in ("entropic_heat", "temperature_dependent", "capacity_ah", "r2_scale", "radius_m", "length_m",
                  "density_kg_m3", "thermal_model"):
            ov.setdefault(k, getattr(p, k))
        for k in ("entropy_file", "discharge_file", "charge_file"):
            if k in self.user_params:
                ov[k] = self.user_params[k]
        cor = self.ocv_corrected(self.full_values(values))
        if cor is not None:          # the given curve with the fitted correction, as the component's table
            (Path(out_dir) / "ocv.csv").write_text(_ocv_csv_text(*(tuple(float(x) for x in a) for a in cor)))
            ov["ocv_file"] = "ocv.csv"
        elif self.ocv_table is not None:
            (Path(out_dir) / "ocv.csv").write_text(_ocv_csv_text(*self.ocv_table))
            ov["ocv_file"] = "ocv.csv"
        elif "ocv_file" in self.user_params:
            ov["ocv_file"] = self.user_params["ocv_file"]
        out = {self.component_name: ov}
        if self.cell_limits:      # the cell's voltage limits, for the BMS of a scenario with shared quantities
            out["shared"] = {f"cell_{k}": v for k, v in self.cell_limits.items()}
        return out

    def replay(self, data, overlay_file) -> dict:
        """Step the ``battery`` component, parameters = overlay, through the master over the record."""
        from ..components.battery import BatteryPack
        from ..components.profile import ProfileParams, ProfileSource
        from ..core.master import Connection, Master, MasterSettings
        from ..core.params import load_params
        from ..core.overlay import overlay_values, resolve_files
        df = data.df
        t = df["time_s"].to_numpy(float)
        ov = overlay_values(overlay_file, self.component_name)
        run_specific = {"n_series": 1, "n_parallel": 1, "input_mode": "current", "sigma_current_a": 0.0,
                        "sigma_voltage_v": 0.0, "sigma_temperature_c": 0.0,
                        "soc_init_pct": ov.values.get("soc_init_pct", 100.0 * min(max(self.soc0, 0.0), 1.0)),
                        "t_init_c": ov.values.get("t_init_c", self.t_init_c)}
        prm = load_params(BatteryPackParams, None, {**resolve_files(ov), **run_specific})
        tg, (ig, tag), h, _ = sampling_grid(t, df["current_a"].to_numpy(float), df["t_ambient_c"].to_numpy(float))
        src = ProfileSource("profile", ProfileParams(
            time_s=tuple(tg), current_a=tuple(ig), t_ambient_c=tuple(tag),
            h_conv_w_m2k=tuple(np.full(tg.size, float(self.known["h_conv_w_m2k"])))))
        bat = BatteryPack("battery", prm)
        conns = [Connection("profile", "current_a", "battery", "current_cmd_a"),
                 Connection("profile", "t_ambient_c", "battery", "t_ambient_c"),
                 Connection("profile", "h_conv_w_m2k", "battery", "h_conv_w_m2k")]
        m = Master([src, bat], conns, MasterSettings(step_s=h), order=["profile", "battery"])
        res = m.run(float(tg[-1]), t0=float(t[0]))
        rt = np.asarray(res.time_s)
        out = {}
        for ch, port in (("voltage_v", "battery.voltage_v"), ("t_surface_c", "battery.t_surface_c"),
                         ("t_core_c", "battery.t_core_c")):
            out[ch] = np.interp(t, rt, np.asarray(res[port], float))
        if "t_core_c" not in df:
            out.pop("t_core_c")
        return out
