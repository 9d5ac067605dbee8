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

Nominal model
    The component's default parameters (``components/engine_generator/default.toml``), overridden by
    ``--params`` (any engine-generator parameter that is neither declared nor an effect parameter, plus the
    held inputs ``power_rate_max_wps`` and ``elec_power_max_w``), with every effect at its neutral value -
    in particular the transient soot term off (``transient_soot_mg_per_g = 0``: the quasi-static map only,
    as in the thesis simulation), whatever the component's default.

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
from typing import Mapping

import numpy as np

from ..components.engine_generator import EngineGeneratorParams
from ..core.errors import DataError
from ..powertrain import engine as eng
from .models import CalibrationModel, Effect, Param

_FIELDS = {f.name: f for f in dataclasses.fields(EngineGeneratorParams)}
_DEFAULT_PARAMS_FILE = eng.EG_DIR / "default.toml"
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

    def __init__(self, known: Mapping | None = None, where: str = "<params>"):
        # the nominal: every engine-generator parameter that is neither declared nor an effect parameter,
        # at the component's default, plus the held inputs
        fitted = {p.name for p in self._declared_for({})}
        fitted |= {p.name for f in self.effect_functions for p in f(self).params}
        base = _default_params()
        self.known_defaults = {k: getattr(base, k) for k in _FIELDS if k not in fitted}
        self.known_defaults.update(_INPUTS)
        super().__init__(known, where)
        try:
            self.base = dataclasses.replace(base, **{k: v for k, v in self.known.items() if k in _FIELDS})
        except (TypeError, ValueError) as exc:
            raise DataError(f"{where}: engine-generator parameters: {exc}") from exc

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
        maps = eng.EngineGenMaps(self.base.fuel_map_file, self.base.torque_map_file, self.base.max_torque_file,
                                 self.base.soot_map_file, self.base.generator_eff_file,
                                 self.base.generator_max_torque_file, self.base.ool_file)
        md, mi = eng.pack_maps(maps)
        return {"t": np.ascontiguousarray(t), "p_cmd": np.ascontiguousarray(p), "n": t.size, "df": df,
                "maps": maps, "md": md, "mi": mi, "p_max": float(maps.p_max_w)}

    def simulate(self, ctx, values):
        prm = self.params_for(values)
        st = eng.steady_state(ctx["maps"], float(ctx["p_cmd"][0]), soot_scale_frac=prm.soot_scale_frac)
        out = np.empty(ctx["n"])
        out[0] = eng.measured_soot_rate(st, prm)
        eng.run_record(ctx["md"], ctx["mi"], eng.pack_params(prm), ctx["p_max"], np.array(st.values()),
                   ctx["t"], ctx["p_cmd"], float(self.known["power_rate_max_wps"]),
                   float(self.known["elec_power_max_w"]), out)
        return {"soot_rate_mgps": out}

    def regressors(self, ctx):
        t, pk = ctx["t"], ctx["p_cmd"] / 1000.0
        dp = np.gradient(pk, t)
        return {"time_s": t - t[0], "power_kw": pk, "power_rate_kwps": dp, "power_rise_kwps": np.maximum(dp, 0.0)}

    # -- closing the loop in the simulator
    def overlay(self, values: Mapping[str, float], out_dir=None) -> dict:
        """``{"engine_generator": {...}}``: the fitted declared and effect parameters (neutral ones included,
        e.g. ``transient_soot_mg_per_g = 0`` when that effect was not selected) and the nominal parameters
        given with ``--params`` that differ from the component's defaults."""
        prm = self.params_for(values)
        dflt = _default_params()
        names = [p.name for p in self.declared] + [p.name for e in self.effects.values() for p in e.params]
        tab = {k: getattr(prm, k) for k in _FIELDS if k not in names and getattr(prm, k) != getattr(dflt, k)}
        tab.update({k: float(getattr(prm, k)) for k in dict.fromkeys(names)})
        return {self.component_name: tab}

    def replay(self, data, overlay_file) -> dict:
        """Step the ``engine_generator`` component (registry), parameters = its defaults with the overlay
        merged over them, through the master over the measured power command; ``{channel: array}``."""
        from ..components import get_component_class
        from ..core.master import Connection, Master, MasterSettings
        from ..core.params import load_params
        df = data.df
        t = df["time_s"].to_numpy(float)
        p = df["power_w"].to_numpy(float)
        cls = get_component_class(self.component)
        prm = load_params(cls.Params, _DEFAULT_PARAMS_FILE, _overlay_values(overlay_file, self.component_name))
        h = float(np.median(np.diff(t)))
        tg = t[0] + h * np.arange(int(round((t[-1] - t[0]) / h)) + 1)
        if not np.allclose(tg, t, rtol=0.0, atol=1e-9 * max(1.0, abs(t[-1]))):
            p = np.interp(tg, t, p)            # irregular record: replay on a regular grid, read back at t
        else:
            tg = t
        src = _power_source(tg, p)
        eg = cls(self.component_name, prm)
        eg.u["power_rate_max_wps"] = float(self.known["power_rate_max_wps"])
        eg.u["elec_power_max_w"] = float(self.known["elec_power_max_w"])
        m = Master([src, eg], [Connection(src.name, "power_w", eg.name, "power_cmd_w")],
                   MasterSettings(step_s=h), order=[src.name, eg.name])
        res = m.run(float(tg[-1]), t0=float(tg[0]))
        y = np.asarray(res[f"{eg.name}.soot_rate_meas_mgps"], float)
        return {"soot_rate_mgps": y if tg is t else np.interp(t, np.asarray(res.time_s), y)}


def _default_params() -> EngineGeneratorParams:
    from ..core.params import load_params
    return load_params(EngineGeneratorParams, _DEFAULT_PARAMS_FILE)


def _overlay_values(path, component: str) -> dict:
    """The overlay's values for ``component``, ``*_file`` paths resolved against the overlay's folder."""
    from ..core.overlay import overlay_values, resolve_files
    return resolve_files(overlay_values(path, component))


def _power_source(t: np.ndarray, p: np.ndarray):
    """The sample-and-hold ``profile`` source of ``power_w``."""
    from ..components.profile import ProfileParams, ProfileSource
    return ProfileSource("profile", ProfileParams(time_s=tuple(map(float, t)), power_w=tuple(map(float, p))))


# the old name of this model in shevsim.calibrate.models.MODELS
EngineSootModel = EngineModel
