"""engine.py - calibration of the engine-generator component's own soot model against a measured record.

The model fitted here IS the ``engine_generator`` component's model: :func:`~shevsim.powertrain.engine.run_record` steps
:func:`shevsim.powertrain.engine.step` - the one function the component runs (compiled) - through the
measured power command, sample by sample, and compares the component's analyser reading
(``soot_rate_meas_mgps``) with the measured soot rate.  Every fitted quantity is a parameter of
:class:`shevsim.components.engine_generator.EngineGeneratorParams` (same name, unit, default file), so
what the calibration finds is a parameter overlay (:meth:`EngineModel.overlay`, table
``[engine_generator]``) that the simulator uses as it is, and :meth:`EngineModel.replay` steps the
component with that overlay through :class:`shevsim.core.master.Master` to show that it reproduces the fit.

Data (:data:`shevsim.calibrate.data.REQUIRED` ``["engine"]``)
    ``time_s``; ``power_w`` [W] read as the *electrical power command* of the engine-generator (its input
    ``power_cmd_w``: what the supervisor asked; the engine's brake power is an output of the model, not an
    input of it); ``soot_rate_mgps`` [mg/s] the soot analyser's reading.  Sample convention (that of the
    ``profile`` source under the Gauss-Seidel master): the step from ``t[k-1]`` to ``t[k]`` runs with the
    command ``power_w[k]`` and its result is the mean reading over that step, compared with
    ``soot_rate_mgps[k]``; the record starts in steady operation at ``power_w[0]``.

Sampling grid
    Fit and replay run on one fixed-step grid, :func:`shevsim.calibrate.models.sampling_grid`: step = the
    median sample interval, the power command interpolated onto it when the record is irregular (logger
    jitter), the analyser reading computed on the grid and interpolated back to the sample times.  A
    regular record is used as it is.  :meth:`EngineModel.simulate` (the compiled record loop) and
    :meth:`EngineModel.replay` (the component stepped by the master) are therefore one computation on
    any record.

Nominal model
    Default (no ``--params``): the component's default parameters
    (``components/engine_generator/default.toml``) with every effect at its neutral value - in
    particular the **quasi-static soot map only**: the transient soot term is off
    (``transient_soot_mg_per_g = 0``, as in the thesis's simulations), although the component's default
    file sets it to 10 mg/g.  The transient term is then a candidate effect the data must earn.

    ``--params FILE`` accepts

    * the component's own parameter file (``[params]`` with any
      :class:`~shevsim.components.engine_generator.EngineGeneratorParams` field; relative ``*_file``
      paths are resolved against the file's folder), e.g. ``components/engine_generator/default.toml``;
    * an overlay with an ``[engine_generator]`` table (e.g. a previous calibration's ``params.toml``,
      so that one calibration's result seeds the next; other component tables are ignored);
    * the held inputs ``power_rate_max_wps`` and ``elec_power_max_w`` (not parameters of the component:
      the supervisor's limits during the record; default 1e12 = none).

    What a value does depends on its kind: a declared parameter (``soot_scale_frac``) gives the fit's
    starting value; an effect parameter set to a **non-neutral** value puts that effect into the nominal
    model at that value - it is held there and **not** a candidate (listed under
    ``effects_in_nominal`` in the report's known parameters); an effect parameter at its neutral value
    changes nothing (the effect stays a candidate); every other parameter is part of the nominal.  So
    with the component's ``default.toml`` a user gets the simulator's default engine as it runs in a
    scenario: maps and dynamics as in the file, the transient soot term **on** at 10 mg/g (nominal, not
    refitted), ``soot_scale_frac`` fitted from 1.0, and the analyser lag and offset (0 in that file) as
    the candidate effects.  With a previous calibration's ``params.toml`` the effects it selected are
    nominal and its ``soot_scale_frac`` is the starting value.

Declared (fitted) parameter: ``soot_scale_frac`` (multiplier of the quasi-static soot map).

Effects (:data:`ENGINE_EFFECTS`, a list of functions ``f(model) -> Effect``; add an effect with one function
and one entry - its parameters must be engine-generator parameters, whose neutral value is the
component's "off"):

* ``transient_soot`` - ``transient_soot_mg_per_g``: soot of the turbo-lag fuel deficit (seed App. A.2);
* ``analyzer_lag`` - ``soot_analyzer_tau_s``: first-order lag of the analyser;
* ``analyzer_offset`` - ``soot_analyzer_offset_mgps``: constant analyser offset.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

from ..components.engine_generator import EngineGeneratorParams
from ..core.errors import DataError
from ..powertrain import engine as eng
from .models import CalibrationModel, Effect, Param, resolve_known_files, sampling_grid, split_known

_FIELDS = {f.name: f for f in dataclasses.fields(EngineGeneratorParams)}
DEFAULT_PARAMS_FILE = eng.EG_DIR / "default.toml"
_INPUTS = {"power_rate_max_wps": 1e12, "elec_power_max_w": 1e12}   # held inputs of the component


# ------------------------------------------------------------------------------------- effects

def transient_soot(model) -> Effect:
    """Soot of the fuel the rack demands but the lagging air path cannot burn (turbo lag; seed App. A.2)."""
    def starts(ctx, base):
        return [{"transient_soot_mg_per_g": v} for v in (2.0, 10.0, 40.0)]
    return Effect("transient_soot", "transient soot of the turbo-lag fuel deficit, c d^2 / m_fl "
                  "(engine_generator.transient_soot_mg_per_g)",
                  (Param("transient_soot_mg_per_g", "mg/g", 0.0, 200.0, 10.0,
                         "transient soot per gram of fuel deficit at a full-load relative deficit"),),
                  {"transient_soot_mg_per_g": 0.0}, ("soot_rate_mgps",), starts)


def analyzer_lag(model) -> Effect:
    """The analyser reads the soot rate through a first-order lag."""
    def starts(ctx, base):
        return [{"soot_analyzer_tau_s": v} for v in (0.5, 3.0, 15.0)]
    return Effect("analyzer_lag", "soot analyser responds with a first-order lag "
                  "(engine_generator.soot_analyzer_tau_s)",
                  (Param("soot_analyzer_tau_s", "s", 0.05, 60.0, 2.0, "analyser time constant", log=True),),
                  {"soot_analyzer_tau_s": 0.0}, ("soot_rate_mgps",), starts)


def analyzer_offset(model) -> Effect:
    """The analyser reads a constant offset."""
    return Effect("analyzer_offset", "constant soot analyser offset (engine_generator.soot_analyzer_offset_mgps)",
                  (Param("soot_analyzer_offset_mgps", "mg/s", -20.0, 20.0, 0.0, "analyser offset"),),
                  {"soot_analyzer_offset_mgps": 0.0}, ("soot_rate_mgps",))


ENGINE_EFFECTS = [transient_soot, analyzer_lag, analyzer_offset]
"""The effect library: one function ``f(model) -> Effect`` per effect."""


# --------------------------------------------------------------------------------------- model

class EngineModel(CalibrationModel):
    """The engine-generator component's soot model (module docstring).

    Channel: ``soot_rate_mgps`` [mg/s] (the analyser reading).  Input: ``power_w`` [W] (power command).
    """
    name = "engine"
    channels = ("soot_rate_mgps",)
    inputs = ("power_w",)
    component = "engine_generator"
    component_name = "engine_generator"
    effect_functions = ENGINE_EFFECTS

    def __init__(self, known: Mapping[str, Any] | None = None, where: str = "<params>"):
        vals = _user_values(known, where)
        # typed first (a string, a list or true/false for a number: an error naming the parameter)
        from .models import number_value, typed_values
        vals = typed_values(EngineGeneratorParams, vals, f"{where}: engine-generator parameters")
        for k in _INPUTS:
            if k in vals and not math.isfinite(number_value(vals[k], f"{where}: parameter '{k}'")):
                raise DataError(f"{where}: parameter '{k}' (a held input of the engine-generator) must be finite, "
                                f"got {vals[k]!r}")
        base = _default_params()
        self.base = base
        self.where = where
        declared = {p.name for p in self._declared_for({})}
        all_effects = [f(self) for f in self.effect_functions]
        effect_params = {p.name: e for e in all_effects for p in e.params}
        # the nominal: every engine-generator parameter that is neither declared nor an effect parameter,
        # at the component's default (or the user's value), plus the held inputs
        self.known_defaults = {k: getattr(base, k) for k in _FIELDS if k not in declared and k not in effect_params}
        self.known_defaults.update(_INPUTS)
        opts = [k for k in _FIELDS if k not in effect_params] + list(_INPUTS) + list(effect_params)
        for k, v in vals.items():
            if k not in opts:
                import difflib
                best = difflib.get_close_matches(k, opts, n=1)
                hint = f" (did you mean '{best[0]}'?)" if best else ""
                raise DataError(f"{where}: unknown parameter '{k}' for model 'engine'{hint}; "
                                f"expected an engine_generator parameter or {', '.join(_INPUTS)}")
            if k in effect_params and not (isinstance(v, (int, float)) and not isinstance(v, bool)):
                raise DataError(f"{where}: parameter '{k}' must be a number, got {v!r}")
        # an effect parameter set by the user away from its neutral value puts the effect into the nominal
        self.nominal_effects: dict[str, dict] = {}
        for e in all_effects:
            given = {p.name: float(vals[p.name]) for p in e.params if p.name in vals}
            if any(v != float(e.neutral[k]) for k, v in given.items()):
                self.nominal_effects[e.name] = {p.name: given.get(p.name, float(e.neutral[p.name])) for p in e.params}
        generic = {k: v for k, v in vals.items() if k not in effect_params}
        super().__init__(generic, where)
        if self.nominal_effects:
            self.known["effects_in_nominal"] = {
                n: {**v, "note": "set by --params: part of the nominal model (held), not a candidate effect"}
                for n, v in self.nominal_effects.items()}
        # the nominal's component parameters: known values, candidate effects neutral, nominal effects as given
        nominal = {k: v for k, v in self.known.items() if k in _FIELDS}
        for e in all_effects:
            nominal.update(self.nominal_effects.get(e.name, e.neutral))
        try:
            self.base = dataclasses.replace(base, **nominal)
        except (TypeError, ValueError) as exc:
            raise DataError(f"{where}: engine-generator parameters: {exc}") from exc
        self._effect_param_names = tuple(effect_params)

    def _declared_for(self, known):
        return (Param("soot_scale_frac", "-", 0.05, 20.0, 1.0, "multiplier of the quasi-static soot map",
                      log=True),)

    def _make_effects(self):
        effs = {}
        for f in self.effect_functions:
            e = f(self)
            bad = [p.name for p in e.params if p.name not in _FIELDS]
            if bad:
                raise DataError(f"engine effect '{e.name}': parameter(s) {bad} are not engine-generator parameters")
            if e.name not in getattr(self, "nominal_effects", {}):
                effs[e.name] = e
        return effs

    # -- the fit
    def params_for(self, values: Mapping[str, float]) -> EngineGeneratorParams:
        """The component's parameters for calibration values (declared + effects; others neutral)."""
        full = self.full_values(values)
        return dataclasses.replace(self.base, **{k: float(v) for k, v in full.items() if k in _FIELDS})

    def prepare(self, data) -> dict:
        df = data.df
        t = df["time_s"].to_numpy(float)
        p = df["power_w"].to_numpy(float)
        tg, (pg,), h, resampled = sampling_grid(t, p)
        maps = eng.EngineGenMaps(self.base.fuel_map_file, self.base.torque_map_file, self.base.max_torque_file,
                                 self.base.soot_map_file, self.base.generator_eff_file,
                                 self.base.generator_max_torque_file, self.base.ool_file)
        md, mi = eng.pack_maps(maps)
        return {"t": np.ascontiguousarray(t), "p_cmd": np.ascontiguousarray(p), "n": t.size, "df": df,
                "tg": np.ascontiguousarray(tg), "pg": np.ascontiguousarray(pg), "h": h, "resampled": resampled,
                "maps": maps, "md": md, "mi": mi, "p_max": float(maps.p_max_w)}

    def simulate(self, ctx, values):
        """The analyser reading at the sample times: the compiled record loop on the sampling grid."""
        prm = self.params_for(values)
        tg, pg = ctx["tg"], ctx["pg"]
        st = eng.steady_state(ctx["maps"], float(pg[0]), soot_scale_frac=prm.soot_scale_frac)
        out = np.empty(tg.size)
        out[0] = eng.measured_soot_rate(st, prm)
        eng.run_record(ctx["md"], ctx["mi"], eng.pack_params(prm), ctx["p_max"], np.array(st.values()),
                       tg, pg, float(self.known["power_rate_max_wps"]), float(self.known["elec_power_max_w"]), out)
        if ctx["resampled"]:
            out = np.interp(ctx["t"], tg, out)
        return {"soot_rate_mgps": out}

    def regressors(self, ctx):
        t, pk = ctx["t"], ctx["p_cmd"] / 1000.0
        dp = np.gradient(pk, t)
        return {"time_s": t - t[0], "power_kw": pk, "power_rate_kwps": dp, "power_rise_kwps": np.maximum(dp, 0.0)}

    # -- closing the loop in the simulator
    def overlay(self, values: Mapping[str, float], out_dir=None) -> dict:
        """``{"engine_generator": {...}}``: the declared and every effect parameter (candidate effects fitted
        or neutral, e.g. ``transient_soot_mg_per_g = 0`` when that effect was not selected; effects of the
        nominal at their given value) and the nominal parameters that differ from the component's
        defaults (e.g. given with ``--params``)."""
        prm = self.params_for(values)
        dflt = _default_params()
        names = [p.name for p in self.declared] + list(self._effect_param_names)
        tab = {k: getattr(prm, k) for k in _FIELDS if k not in names and getattr(prm, k) != getattr(dflt, k)}
        tab.update({k: float(getattr(prm, k)) for k in dict.fromkeys(names)})
        return {self.component_name: tab}

    def replay(self, data, overlay_file) -> dict:
        """Step the ``engine_generator`` component (registry), parameters = its defaults with the overlay
        merged over them, through the master over the measured power command on the sampling grid
        (:func:`~shevsim.calibrate.models.sampling_grid`, as :meth:`simulate`); ``{channel: array}`` at the
        sample times."""
        from ..components import get_component_class
        from ..core.master import Connection, Master, MasterSettings
        from ..core.params import load_params
        df = data.df
        t = df["time_s"].to_numpy(float)
        tg, (pg,), h, resampled = sampling_grid(t, df["power_w"].to_numpy(float))
        cls = get_component_class(self.component)
        prm = load_params(cls.Params, DEFAULT_PARAMS_FILE, _overlay_values(overlay_file, self.component_name))
        src = power_source(tg, pg)
        eg = cls(self.component_name, prm)
        eg.u["power_rate_max_wps"] = float(self.known["power_rate_max_wps"])
        eg.u["elec_power_max_w"] = float(self.known["elec_power_max_w"])
        m = Master([src, eg], [Connection(src.name, "power_w", eg.name, "power_cmd_w")],
                   MasterSettings(step_s=h), order=[src.name, eg.name])
        res = m.run(float(tg[-1]), t0=float(tg[0]))
        y = np.asarray(res[f"{eg.name}.soot_rate_meas_mgps"], float)
        return {"soot_rate_mgps": np.interp(t, np.asarray(res.time_s), y) if resampled else y}


def _default_params() -> EngineGeneratorParams:
    from ..core.params import load_params
    return load_params(EngineGeneratorParams, DEFAULT_PARAMS_FILE)


def _user_values(known: Mapping[str, Any] | None, where: str) -> dict:
    """The ``--params`` values as one flat dict of engine-generator parameters and held inputs.

    ``known`` is the flat ``[params]`` dict of :func:`shevsim.calibrate.known.load_params_toml`, optionally
    with ``"__base_dir__"`` (folder of the ``--params`` file: relative ``*_file`` paths are resolved
    against it) and ``"__tables__"`` (``{table: {param: value}}`` of a file with component tables; the
    ``[engine_generator]`` table is merged over ``[params]``, other components' tables are ignored).
    """
    known, base_dir, tables = split_known(known, where)
    if tables and "engine_generator" not in tables and not known:
        raise DataError(f"{where}: no [engine_generator] or [params] table "
                        f"(tables: {', '.join(sorted(map(str, tables)))})")
    tab = tables.get("engine_generator", {})
    if not isinstance(tab, Mapping):
        raise DataError(f"{where}: [engine_generator] must be a table of name = value")
    vals = {**known, **tab}
    resolve_known_files(vals, _FIELDS, base_dir, where, "file")
    return vals


def _overlay_values(path, component: str) -> dict:
    """The overlay's values for ``component``, ``*_file`` paths resolved against the overlay's folder."""
    from ..core.overlay import overlay_values, resolve_files
    return resolve_files(overlay_values(path, component))


def power_source(t: np.ndarray, p: np.ndarray):
    """The sample-and-hold ``profile`` source of ``power_w``."""
    from ..components.profile import ProfileParams, ProfileSource
    return ProfileSource("profile", ProfileParams(time_s=tuple(map(float, t)), power_w=tuple(map(float, p))))


