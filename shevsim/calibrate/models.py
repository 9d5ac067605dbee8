"""models.py - the calibration-model interface: declared parameters, effects, simulate, overlay, replay.

A calibration model fits the simulator's OWN physics (the functions the components run) through the
components' own parameter names.  Each model (``cell`` -> :mod:`shevsim.calibrate.cell`, ``vehicle`` ->
:mod:`shevsim.calibrate.vehicle`, ``engine`` -> :mod:`shevsim.calibrate.engine`) declares

* ``channels``: the measured channels it predicts;
* ``declared``: the component parameters fitted on every run (:class:`Param`: name, unit, bounds, default);
* ``known``: what the data cannot determine, from ``--params`` (a component parameter file, or the
  model's short form);
* ``effects``: named model terms (:class:`Effect`), each a set of component parameters; the neutral
  values switch the term off (the component's default: today's behaviour).  Each model keeps its effect
  library as a list of functions ``f(model) -> Effect`` - one function and one entry per effect;

and implements ``prepare(data)`` (arrays once), ``simulate(ctx, values)`` (the compiled loop over the
component's one-source step, on :func:`sampling_grid`), ``overlay(values, out_dir)`` (the fit as a partial
component parameter set) and ``replay(data, overlay_file)`` (the component(s) with the overlay stepped by
:class:`shevsim.core.master.Master` over the record).
"""
from __future__ import annotations

from dataclasses import dataclass
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
    #: the range a physical value of this parameter falls in (None: the bounds); a selected effect whose
    #: parameter lands outside it (or on a bound) is reported as a model-form discrepancy, not as the cause
    plausible: tuple | None = None
    #: a declared parameter whose bounds are a plausibility guard inside a wider physical range: that range
    #: (``(lo, hi)``, e.g. the component's valid values).  The calibration may profile it past its bounds, up to
    #: these limits (``workflow._Run.screen_declared_bounds``); None: the bounds are the limits
    limits: tuple | None = None


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
    #: the channels on which the effect must show itself (its held-out gain >= MIN_GAIN there - unless it has
    #: a ``channel_claim``, which replaces that rule; None: all of ``channels``): a resistance's temperature
    #: law acts on the heat too, but it is seen in the voltage
    evidence: tuple[str, ...] | None = None
    #: ``(channels, fixed)``: the effect's claim is tested on ``channels`` alone - its parameters refitted with
    #: every other channel's weight 0 and the declared parameters named in ``fixed`` held at the candidate
    #: fit (the workflow's ``_Run.channel_claim``); it must be significant there and agree with the joint fit
    channel_claim: tuple | None = None
    #: ``((effect, {parameter: (lo, hi)}, ({parameter: start}, ...)), ...)``: the confounders of the channel
    #: claim - effects of the library refitted beside it in that test (when the model does not have them
    #: already), with these bounds, from each of these starts (the lowest cost kept): a law
    #: in a quantity that trends with another over the record (the cell's temperature with the SOC: both move
    #: with the charge passed) must show beside a law in the other, of either sign
    claim_nuisance: tuple = ()


class CalibrationModel:
    """Base class: declared parameters, known parameters, effects, ``prepare`` and ``simulate``."""
    name = ""
    channels: tuple[str, ...] = ()
    optional_channels: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    declared: tuple[Param, ...] = ()
    known_defaults: dict = {}
    effects: dict
    #: the effect library when the model keeps it as one list of functions ``f(model) -> Effect | None`` (None:
    #: the effect does not apply to this nominal, e.g. the nominal has it already); () when built otherwise
    effect_functions: list | tuple = ()

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
                self.initial[k] = number_value(v, f"{where}: parameter '{k}'")
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

    #: what the model's predicted value at a sample stands for (:mod:`shevsim.calibrate.timing`)
    native_convention: str = "instantaneous"

    #: inputs the model differentiates (the vehicle's speed into acceleration): their noise reaches the prediction
    #: divided by the sample interval, so a fast record's floor is theirs (the report's ``--decimate`` advice)
    differentiated_inputs: tuple = ()

    def quiet_mask(self, ctx: dict):
        """Samples where the model's inputs are still (standstill, rest): for the sensor-noise floor; None = none."""
        return None

    #: correlated signal -> likely cause, for the baseline-failure report
    cause_hints: dict = {}

    def likely_causes(self, channel: str, diag: dict, data=None) -> list[str]:
        """Likely causes of a failing nominal model on ``channel`` from its held-out diagnostics; ``data`` (the
        loaded :class:`~shevsim.calibrate.data.MeasuredData`) keeps the list to what the loader did not
        already verify (a current sign checked against the voltage response is not suggested again)."""
        out = []
        used = self.defaults_used()
        if used:
            out.append(f"a nominal that is not this {self.name}'s: " + ", ".join(d["parameter"] for d in used)
                       + f" {'is' if len(used) == 1 else 'are'} not in --params (taken from {used[0]['default']}; "
                         f"give your own: docs/getting_started.md, 'Calibrating your own record')")
        if abs(diag["bias"]) > 0.5 * diag["rmse"]:
            out.append(f"a constant offset ({diag['bias']:+.4g}): sensor offset or a shifted curve/map")
        for c in diag["correlations"]:
            hint = self.cause_hints.get(c["signal"].replace("measured:", ""))
            if hint and abs(c["r"]) > 0.5 and hint not in out:
                out.append(f"{hint} (residual correlates with {c['signal']}, r = {c['r']:+.2f})")
        checks = getattr(data, "checks", None) or {}
        sign = checks.get("current_sign")
        corr = sign.get("corr_dI_dV") if sign else None
        if corr is not None and corr < -0.3:
            how = "as stated" if sign.get("how") == "stated" else "guessed from the data"
            out.append(f"an effect the model lacks, or wrong --params values (OCV curve, capacity, initial SOC) - not "
                       f"the inputs: the current sign ({sign.get('file')}, {how}) agrees with the voltage response "
                       f"(corr(dI, dV) = {corr:+.2f}) and the columns passed the unit checks")
        else:
            out.append("units or sign of an input column (check --map, --current-sign / --power-sign)")
        return out

    def effect_evidence(self, effect: str, ctx: dict, values: dict, meas: dict, base: dict | None = None) -> dict | None:
        """A check of what ``effect`` claims, on the record itself, beyond a better fit (None: no check).
        ``values``: the candidate fit's full values; ``base``: those of the model the effect is added to.
        Returns ``{"ok": bool, "statement": str, "evidence": {...}}``; a candidate that fits better but whose
        claim the record does not show (``ok`` False) is not selected, and the report says why."""
        return None

    def defaults_used(self) -> list[dict]:
        """The known quantities a user usually has of their own that the ``--params`` did not give, so that the
        model took the project's defaults (the M-ATV truck's motor map, the A123 26650 cell): ``[{"parameter",
        "value", "default"}]``, stated in the report - a result can be no better than the nominal it is given.
        Default: none."""
        return []

    def measurement_confirmed(self, effect: str, ctx: dict, values: dict, meas: dict) -> dict | None:
        """Whether the record confirms, beyond the direct measurement of its parameter, what ``effect`` claims
        (None: no check), in the form of :meth:`effect_evidence`.  A directly measured, significant parameter
        that the record's own check confirms is named even when the fit under load does not confirm it (the
        workflow's ``_Run.assess``): the model's form error had compensated for it."""
        return None

    def param_bounds(self, ctx: dict) -> dict:
        """Data-dependent bounds overriding the declared ones (name -> (lo, hi))."""
        return {}

    def regressors(self, ctx: dict) -> dict:
        """Candidate explanatory signals (name -> array) for residual correlation."""
        return {}

    #: channel -> the channels its model-form terms are computed from (an effect acting on one of those is
    #: judged on the plain residuals: fixing the source fixes the term)
    model_form_sources: dict = {}

    def model_form_terms(self, ctx: dict, values: dict, pred: dict, meas: dict) -> dict:
        """Model-form terms of one fit: ``{channel: (n, k) array}`` of signals that a structural discrepancy of
        the model's form (not a missing effect) puts into that channel's residual, given this fit's
        prediction ``pred`` and the measurements ``meas``.  The selection rule judges an effect that does not
        act on the ``model_form_sources`` of these terms on the residual with its least-squares fit by them
        (coefficients from the training part) removed, so that it must explain what the model's form cannot;
        the reported RMSE stays the plain one.  Default: none."""
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
          "engine": "shevsim.calibrate.engine:EngineModel"}


def get_model(name: str, known: Mapping[str, Any] | None = None, where: str = "<params>") -> CalibrationModel:
    """Instantiate calibration model ``name`` (``cell``, ``vehicle`` or ``engine``) with known parameters."""
    if name not in MODELS:
        raise DataError(f"unknown calibration model '{name}'; available: {', '.join(MODELS)}")
    import importlib
    mod, cls = MODELS[name].split(":")
    return getattr(importlib.import_module(mod), cls)(known, where)


def sampling_grid(t: np.ndarray, *columns: np.ndarray):
    """The fixed-step grid a record is simulated and replayed on, and its input columns on that grid.

    Step = the median sample interval; inputs by linear interpolation.  A record that is already regular
    (every time within 1e-9 of ``t0 + k h``) is returned as it is.  Every calibration model simulates on
    this grid and replays on it through the master, so fit and replay are one computation on any record
    (loggers jitter: the Panasonic records' 0.1 s steps vary by +-6 %).

    Returns ``(tg, [column on tg, ...], h, resampled)``.
    """
    t = np.asarray(t, float)
    h = float(np.median(np.diff(t)))
    tg = t[0] + h * np.arange(int(round((t[-1] - t[0]) / h)) + 1)
    if tg.size == t.size and np.allclose(tg, t, rtol=0.0, atol=1e-9 * max(1.0, abs(float(t[-1])))):
        return t, [np.asarray(c, float) for c in columns], h, False
    return tg, [np.interp(tg, t, np.asarray(c, float)) for c in columns], h, True


def number_value(v, where: str) -> float:
    """``v`` as a float when it is a number (an integer or a float, not true/false, a string, a list or a date);
    otherwise a DataError ``where: expected a number, got ...``."""
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise DataError(f"{where}: expected a number, got {v!r}")
    try:
        return float(v)
    except OverflowError:
        raise DataError(f"{where}: {v!r} is too large for a number") from None


def typed_values(cls, values: Mapping[str, Any], where: str) -> dict:
    """``values`` with each one that names a field of the parameter dataclass ``cls`` checked against the field's
    declared type (a number, an integer, true/false, a string, a list of numbers; :func:`shevsim.core.params._coerce`)
    - a DataError ``where: parameter 'NAME': expected ...`` otherwise; other names are left as they are."""
    from ..core.errors import ShevsimError
    from ..core.params import _coerce, _type_hints
    hints = _type_hints(cls)
    out = dict(values)
    for k, v in values.items():
        if k in hints:
            try:
                out[k] = _coerce(v, hints[k], f"{where}: parameter '{k}'")
            except ShevsimError as exc:
                raise DataError(str(exc)) from None
    return out


def resolve_known_files(vals: dict, fields, base_dir, where: str, what: str = "file") -> dict:
    """Make the ``*_file`` values among ``fields`` absolute (relative to ``base_dir``, the folder of the
    ``--params`` file) and check they exist; errors name the parameter and the path."""
    from pathlib import Path
    for k, v in list(vals.items()):
        if k.endswith("_file") and k in fields:
            if not isinstance(v, str) or not v:
                raise DataError(f"{where}: '{k}' must be a path string, got {v!r}")
            fp = Path(v)
            if not fp.is_absolute() and base_dir is not None:
                fp = Path(base_dir) / fp
            vals[k] = str(fp.resolve())
            if not fp.is_file():
                raise DataError(f"{where}: {k} = {v!r}: {what} not found ({fp})")
    return vals


def split_known(known, where: str):
    """``(known, base_dir, tables)`` from a ``--params`` dict of :func:`shevsim.calibrate.known.load_params_toml`:
    the flat values, the file's folder (``"__base_dir__"``) and its component tables (``"__tables__"``)."""
    from typing import Mapping as _Mapping
    known = dict(known or {})
    base_dir = known.pop("__base_dir__", None)
    tables = known.pop("__tables__", None) or {}
    known.pop("__component_file__", None)
    if not isinstance(tables, _Mapping):
        raise DataError(f"{where}: '__tables__' must map table names to tables")
    return known, base_dir, tables
