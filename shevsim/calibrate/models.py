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

    # -- closing the loop in the simulator (every model implements these) -------------------
    #: registry TYPE of the component whose parameters this model fits (e.g. "battery", "vehicle")
    component: str = ""
    #: component instance name used in the overlay / replay scenario
    component_name: str = ""

    def overlay(self, values: Mapping[str, float], out_dir) -> dict:
        """The component parameters (the component's own names and units) that reproduce ``values``.

        Returns ``{component_name: {param: value}}``: a *partial* parameter set, merged over a scenario's
        parameter file by ``shevsim run SCENARIO --params COMPONENT=DIR/params.toml``.  Data that must
        live in a file (e.g. an OCV table) is written into ``out_dir`` and referenced by a path relative
        to it.
        """
        raise NotImplementedError

    def replay(self, data, overlay_file) -> dict:
        """Replay the measured inputs of ``data`` through the simulator itself.

        The component(s) are built from the registry with the overlay ``overlay_file`` merged over their
        defaults and stepped by :class:`shevsim.core.master.Master`; returns ``{channel: array}`` at the
        data's sample times (the same channels as :meth:`simulate`).
        """
        raise NotImplementedError

    #: correlated signal -> likely cause, for the baseline-failure report
    cause_hints: dict = {}

    def likely_causes(self, channel: str, diag: dict) -> list[str]:
        """Likely causes of a failing nominal model on ``channel`` from its held-out diagnostics."""
        out = []
        if abs(diag["bias"]) > 0.5 * diag["rmse"]:
            out.append(f"a constant offset ({diag['bias']:+.4g}): sensor offset or a shifted curve/map")
        for c in diag["correlations"][:3]:
            hint = self.cause_hints.get(c["signal"].replace("measured:", ""))
            if hint and abs(c["r"]) > 0.3 and hint not in out:
                out.append(f"{hint} (residual correlates with {c['signal']}, r = {c['r']:+.2f})")
        out.append("units or sign of an input column (check --map, --current-sign / --power-sign)")
        return out

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



MODELS = {"cell": "shevsim.calibrate.cell:CellModel", "vehicle": "shevsim.calibrate.vehicle:VehicleModel",
          "engine": "shevsim.calibrate.engine:EngineSootModel"}


def get_model(name: str, known: Mapping[str, Any] | None = None, where: str = "<params>") -> CalibrationModel:
    """Instantiate calibration model ``name`` (``cell``, ``vehicle`` or ``engine``) with known parameters."""
    if name not in MODELS:
        raise DataError(f"unknown calibration model '{name}'; available: {', '.join(MODELS)}")
    import importlib
    mod, cls = MODELS[name].split(":")
    return getattr(importlib.import_module(mod), cls)(known, where)
