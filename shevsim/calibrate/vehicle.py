"""vehicle.py - calibration model of the vehicle: the simulator's own vehicle, motor and bus, speed-following.

The model is the replay arrangement itself (see :meth:`VehicleModel.replay`)::

    cycle (measured speed) -> vehicle (input_mode = "speed") -> motor -> bus.demand_power_w = power_w

The measured speed prescribes the motion; one master step of the chain is the components' own compiled
steps: :func:`shevsim.powertrain.vehicle.speed_follow_step` (the vehicle in speed mode: the works of the
step and the wheel force that drives the next one, :func:`~shevsim.powertrain.vehicle.traction_force_n`,
the exact inverse of the forward step, same :func:`~shevsim.powertrain.vehicle.road_forces` and road-grade
law), :func:`shevsim.powertrain.motor.motor_step` (efficiency map, heat-index torque limit, regenerative
limits) and :func:`shevsim.powertrain.motor.bus_balance` (the bus adds the auxiliary load).
:meth:`VehicleModel.simulate` runs exactly that chain in one compiled loop that only passes the state
between those functions, on the same input trace (the ``cycle`` component itself is stepped in
:meth:`~VehicleModel.prepare`), so the replay through :class:`~shevsim.core.master.Master` reproduces the
calibration bit for bit.

Parameters are the components' own (names, units, defaults from ``components/vehicle/matv.toml``,
``components/motor/default.toml``, ``components/bus/default.toml``): every parameter of those files is a
*known* parameter except ``input_mode``/``speed_init_mps`` (the record prescribes the motion; accepted and
ignored) and ``efficiency_scale_frac``, ``regen_efficiency_scale_frac`` (declared: a given value is the
starting value).  ``--params``
takes a parameter file of any of the three components (``[params]``; relative ``*_file`` paths resolved
against the file's folder), the short form (``[params]`` with any of those names), or an overlay with
tables ``[vehicle]``/``[motor]``/``[bus]`` - e.g. a previous calibration's ``params.toml``, so one
calibration's result seeds the next (its fitted mass, drag, ... become the nominal; the effects stay
candidates for a further change from it).  The vehicle's rotating inertia ``wheel_inertia_kg_m2`` (all
wheels, with ``wheel_radius_m``, which the vehicle and the motor share: one tyre) is a known parameter like
the others: the model's inertia is ``mass_kg + wheel_inertia_kg_m2 / wheel_radius_m^2`` and ``mass_kg`` (the
``mass_error`` effect's parameter) stays the translational mass.  A given road grade
(``grade_distance_m``/``grade_frac``) is the record's known grade; the ``road_grade`` effect adds its knots
to it.  Unknown names fail (with a suggestion), as do names in another component's table and missing map
files.  Fitted:

* declared: ``efficiency_scale_frac`` (motor: actual / map efficiency) and ``regen_efficiency_scale_frac``
  (motor: generating / motoring efficiency on top of it).  Both are always fitted: the drive's efficiency
  is never known exactly, and not the same in both directions (a published curve is often the motoring
  curve mirrored).  With one scale only, the model can raise traction power only by lowering the
  regenerated power, so an efficiency asymmetry of the record's drive was read as mass: the pair
  (``mass_kg``, ``efficiency_scale_frac``) is the only other way to scale traction and braking powers
  separately (``mass_error`` -3 % on a no-effect FASTSim record whose drive regenerates at a constant
  0.84, the first point of the curve it motors with; ``docs/calibration_independent.md``);
* effects (each a switchable term of a component, off at its parameter file's value):
  ``road_grade`` (vehicle ``grade_frac`` at 6 knots ``grade_distance_m`` spread evenly over the record's
  distance; reported as ``grade_frac[0]`` .. ``grade_frac[5]``), ``aux_load`` (bus ``aux_power_w``),
  ``mass_error`` (vehicle ``mass_kg``), ``rolling_error`` (vehicle ``rolling_coefficient``),
  ``aero_error`` (vehicle ``drag_coefficient``), ``regen_limit`` (motor ``regen_power_max_w``).

Time base.  The record's sampling grid (:func:`shevsim.calibrate.models.sampling_grid`, shared by every
calibration model: step ``dt`` = the median sample interval; an irregular record, e.g. logger jitter, is
interpolated onto it once, for the fit and the replay alike) is cut into ``n = ceil(dt / substep_s)``
steps ``h = dt / n`` (``substep_s`` = 0.1 s, known): the model and the replay step at ``h`` with the
cycle interpolating the speed on the grid linearly.  ``power_w`` at grid point ``k`` is the mean
electrical power over the grid period ending at it, ``(t_{k-1}, t_k]`` (an energy-integrating logger;
at 10 Hz with ``h = dt`` it is the power of that interval); the first is the bus power at the start;
the grid values are read back at the sample times by linear interpolation.
"""
from __future__ import annotations

import dataclasses
import math
import tempfile
import tomllib
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..core.errors import DataError, ShevsimError
from ..core.lookup import njit
from ..powertrain.motor import bus_balance, motor_step
from ..powertrain.vehicle import grade_total_rad, speed_follow_step
from .models import CalibrationModel, Effect, Param, resolve_known_files, sampling_grid, split_known
from shevsim.core.paths import DATA_ROOT

ROOT = DATA_ROOT
PARAM_FILES = {"vehicle": ROOT / "components" / "vehicle" / "matv.toml",
               "motor": ROOT / "components" / "motor" / "default.toml",
               "bus": ROOT / "components" / "bus" / "default.toml"}
N_GRADE = 6
SUBSTEP_S = 0.1
#: parameters of the files that are not known parameters of the calibration: the vehicle's mode and initial
#: speed (speed mode, the record prescribes both; accepted in ``--params`` and ignored) and the declared
#: efficiency scale (a ``--params`` value is its starting value)
_IGNORED = ("input_mode", "speed_init_mps")
_NOT_KNOWN = set(_IGNORED) | {"efficiency_scale_frac", "regen_efficiency_scale_frac"}


def _component_classes():
    from ..components import get_component_class
    return {n: get_component_class(n) for n in PARAM_FILES}


def _file_params() -> dict:
    """{component: params dataclass} loaded from the default parameter files."""
    from ..core.params import load_params
    return {n: load_params(cls.Params, PARAM_FILES[n]) for n, cls in _component_classes().items()}


def _owners(files: dict) -> dict:
    """parameter name -> the components that have it, in :data:`PARAM_FILES`' order.  One name is shared:
    ``wheel_radius_m`` (the vehicle's, for its wheels' equivalent mass ``J / r^2``, and the motor's, for its
    speed and torque at the wheel: the same tyre, one value, as the scenario's shared quantity)."""
    out: dict[str, tuple] = {}
    for comp, p in files.items():
        for f in dataclasses.fields(p):
            out[f.name] = out.get(f.name, ()) + (comp,)
    return out


_FILES = _file_params()
#: parameter name -> the components that take it (``wheel_radius_m``: vehicle and motor)
OWNERS = _owners(_FILES)
#: parameter name -> its first component (for messages)
OWNER = {k: v[0] for k, v in OWNERS.items()}


def _as_dict(p) -> dict:
    return {f.name: getattr(p, f.name) for f in dataclasses.fields(p)}


def _user_values(known: Mapping[str, Any] | None, where: str) -> dict:
    """The ``--params`` values as one flat dict of vehicle / motor / bus parameters (and ``substep_s``).

    ``known`` is the flat ``[params]`` dict of :func:`shevsim.calibrate.known.load_params_toml` (a component
    parameter file of any of the three components, or the short form), optionally with ``"__base_dir__"``
    (folder of the ``--params`` file: relative ``*_file`` paths are resolved against it) and
    ``"__tables__"`` (``{table: {param: value}}`` of an overlay with component tables, e.g. a previous
    calibration's ``params.toml``: ``[vehicle]``, ``[motor]``, ``[bus]`` are merged over ``[params]``;
    other components' tables are ignored).  ``input_mode`` and ``speed_init_mps`` are accepted and ignored
    (the record prescribes the motion).  A parameter in another component's table fails, as do unknown
    names (with a suggestion, by the base class).
    """
    known, base_dir, tables = split_known(known, where)
    ours = [n for n in PARAM_FILES if n in tables]
    if tables and not ours and not known:
        raise DataError(f"{where}: no [vehicle], [motor], [bus] or [params] table "
                        f"(tables: {', '.join(sorted(map(str, tables)))})")
    vals = dict(known)
    table_of: dict[str, str] = {}
    for comp in ours:
        tab = tables[comp]
        if not isinstance(tab, Mapping):
            raise DataError(f"{where}: [{comp}] must be a table of name = value")
        for k, v in tab.items():
            if k in OWNERS and comp not in OWNERS[k]:
                raise DataError(f"{where}: [{comp}] {k}: '{k}' is a {OWNER[k]} parameter (table [{OWNER[k]}])")
            if k in table_of and vals[k] != v:     # a parameter of two components (wheel_radius_m): one value
                raise DataError(f"{where}: [{comp}] {k} = {v!r} contradicts [{table_of[k]}] {k} = {vals[k]!r} "
                                f"(the {' and '.join(OWNERS[k])} share it: one tyre)")
            vals[k] = v
            table_of[k] = comp
    for k in _IGNORED:
        vals.pop(k, None)
    resolve_known_files(vals, OWNER, base_dir, where, "map file")
    return vals


# ----------------------------------------------------------------------------------- the trace

def _trace(data, substep_s: float):
    """Speed trace of the record on its sampling grid (:func:`~shevsim.calibrate.models.sampling_grid`, as every
    calibration model; simulate and replay both use it): ``(t_grid, v_grid, dt, n_sub, h)``."""
    df = data.df
    t = df["time_s"].to_numpy(float)
    if t.size < 2 or not float(np.median(np.diff(t))) > 0:
        raise DataError(f"{data.path}: time_s must increase (at least two samples)")
    tg, (vg,), dt, _resampled = sampling_grid(t, df["speed_mps"].to_numpy(float))
    vg = np.maximum(vg, 0.0)
    n_sub = max(1, int(math.ceil(dt / substep_s - 1e-9)))
    return tg, vg, dt, n_sub, dt / n_sub


def _write_cycle(path: Path, vg: np.ndarray, dt: float) -> None:
    lines = ["# measured speed trace (calibration replay)", "time_s,speed_mps"]
    lines += [f"{k * dt!r},{float(x)!r}" for k, x in enumerate(vg)]
    path.write_text("\n".join(lines) + "\n")


def _sample(rec: np.ndarray, n_sub: int, n_g: int) -> np.ndarray:
    """Per-substep bus power (record j covers ``[j h, (j+1) h]``) -> per-sample mean over the period ending at it."""
    out = np.empty(n_g)
    out[0] = rec[0]
    out[1:] = rec[:(n_g - 1) * n_sub].reshape(n_g - 1, n_sub).mean(axis=1)
    return out


@njit(cache=True, error_model="numpy")
def _speed_following_power(vr, ar, h, vehicle, motor, aux):  # pragma: no cover - compiled
    """Bus power [W] at every master step of cycle -> vehicle (speed mode) -> motor -> bus (index 0 = initialise).

    ``vehicle = (grade knots' distance [m], grade [-], mass [kg], c_aero, rolling coefficient, g [m/s^2],
    rotating parts' equivalent mass J / r^2 [kg])``,
    ``motor = (maps md, mi, k_w, k_tau, extrapolate, regen speed min [m/s], regen power max [W], efficiency
    scale, heat rate [1/s], initial heat index, regenerating efficiency scale)``
    (:func:`~shevsim.powertrain.motor.motor_step`'s arguments),
    ``aux`` the bus's auxiliary power [W].

    The components' own steps in the master's order: :func:`~shevsim.powertrain.vehicle.speed_follow_step`
    (:class:`~shevsim.components.vehicle.Vehicle`, speed mode), :func:`~shevsim.powertrain.motor.motor_step`
    (:class:`~shevsim.components.motor.Motor`, bus limits unconnected) and
    :func:`~shevsim.powertrain.motor.bus_balance` (:class:`~shevsim.components.bus.PowerBus`, no generator,
    aux input 0); ``vr``/``ar`` are the cycle's outputs at each step.  Only the state passes between them here.
    """
    kd, kg, m, c, fr, g, m_rot = vehicle
    md, mi, k_w, k_tau, extrapolate, v_regen, p_regen, eff_scale, heat_rate, gamma0, regen_eff_scale = motor
    n = vr.shape[0] - 1
    rec = np.empty(n + 1)
    # initialise (grade input 0, at distance 0; the motor and bus start with 0 force / power)
    v = vr[0] if vr[0] > 0.0 else 0.0
    th = grade_total_rad(0.0, 0.0, kd, kg)
    dist = 0.0
    f_req = 0.0
    v_prev = v
    h_prev = 1.0
    gamma = gamma0
    rec[0] = bus_balance(0.0, 0.0, 0.0, aux)[1]
    vp = np.array([m, c, fr, g, m_rot])          # the vehicle's parameters (order of vehicle.VP)
    mp = np.array([k_w, k_tau, 1.0 if extrapolate else 0.0, v_regen, p_regen, eff_scale, heat_rate,
                   regen_eff_scale])             # the motor's (order of motor.P)
    for k in range(n):
        st = speed_follow_step(vp, kd, kg, v, th, dist, vr[k + 1], ar[k + 1], 0.0, h)
        v, dist, th, f_req = st[0], st[1], st[2], st[3]
        res = motor_step(md, mi, mp, f_req, v, 1e12, -1e12, h, v_prev, h_prev, gamma)
        gamma = res[6]
        v_prev = res[7]
        h_prev = h
        rec[k + 1] = bus_balance(res[2], 0.0, 0.0, aux)[1]
    return rec


# ----------------------------------------------------------------------------------- the model

class VehicleModel(CalibrationModel):
    """Electrical power drawn from the bus by a vehicle following the measured speed (module docstring).

    Channel: ``power_w`` [W, + drawn from the bus, traction + auxiliaries].  Input: ``speed_mps``.
    """
    name = "vehicle"
    component = "vehicle"
    component_name = "vehicle"
    channels = ("power_w",)
    inputs = ("speed_mps",)
    known_defaults = dict({k: getattr(p, k) for p in _FILES.values() for k in (f.name for f in dataclasses.fields(p))
                           if k not in _NOT_KNOWN}, substep_s=SUBSTEP_S)

    #: the vehicle's own quantities a user should give; missing, the project's M-ATV (a 15.5 t truck) fills them in
    SALIENT_DEFAULTS = ("mass_kg", "frontal_area_m2", "drag_coefficient", "rolling_coefficient", "wheel_radius_m",
                        "wheel_inertia_kg_m2", "gear_ratio", "efficiency_map_file", "torque_curves_file",
                        "rated_power_w", "maps_rated_power_w", "aux_power_w")

    def __init__(self, known: Mapping[str, Any] | None = None, where: str = "<params>"):
        user = _user_values(known, where)
        # each component's values typed first (a list or a date for a number: an error naming it, not a TypeError
        # where the base class or an effect reads it)
        from .models import typed_values
        for comp, cls in _component_classes().items():
            user.update(typed_values(cls.Params, {k: v for k, v in user.items() if comp in OWNERS.get(k, ())},
                                     f"{where}: {comp} parameters"))
        self.given = set(user)
        super().__init__(user, where)
        # the known component parameters checked and typed (lists -> tuples, int -> float) by the components'
        # own parameter classes, once
        from ..core.params import make_params
        for comp, cls in _component_classes().items():
            given = {k: v for k, v in self.known.items() if comp in OWNERS.get(k, ())}
            try:
                prm = make_params(cls.Params, {**_as_dict(_FILES[comp]), **given}, f"{where}: {comp} parameters")
            except ShevsimError as exc:
                raise DataError(str(exc)) from exc
            for k in given:
                self.known[k] = getattr(prm, k)

    def defaults_used(self) -> list[dict]:
        """The vehicle, motor and bus quantities the ``--params`` did not give: the project's M-ATV (15.5 t
        series-hybrid truck; ``components/vehicle/matv.toml``, its 380 kW in-hub motor maps in
        ``components/motor/default.toml``) fills them in."""
        out = []
        for k in self.SALIENT_DEFAULTS:
            if k in self.given or k not in self.known:
                continue
            v = self.known[k]
            out.append({"parameter": k, "value": Path(v).name if k.endswith("_file") and isinstance(v, str) else v,
                        "default": "the project's M-ATV truck" + (" (its 380 kW in-hub motor)" if k in (
                            "efficiency_map_file", "torque_curves_file", "rated_power_w", "maps_rated_power_w")
                                                                                        else "")})
        return out

    def _declared_for(self, known):
        # the bounds are a plausibility guard (a given map within 8 % up, 20 % down); the motor takes (0, 2], capped
        # at an efficiency of 1: the calibration may profile them past the guard when a map is further off
        return (Param("efficiency_scale_frac", "-", 0.8, 1.08, _FILES["motor"].efficiency_scale_frac,
                      "motor: actual / map efficiency (motor + inverter)", limits=(0.0, 2.0)),
                Param("regen_efficiency_scale_frac", "-", 0.8, 1.08, _FILES["motor"].regen_efficiency_scale_frac,
                      "motor: generating / motoring efficiency on top of efficiency_scale_frac", limits=(0.0, 2.0)))

    def _make_effects(self):
        k = self.known
        g = tuple(Param(f"grade_frac[{j}]", "-", -0.15, 0.15, 0.0, f"vehicle: road grade tan(theta) at knot {j}")
                  for j in range(N_GRADE))

        def regen_starts(ctx, base):
            pm = ctx["power_meas"]
            neg = -pm[pm < 0]
            if neg.size < 10:
                return []
            return [{"regen_power_max_w": float(np.quantile(neg, q))} for q in (0.5, 0.8, 0.95)]

        m0 = float(k["mass_kg"])
        f0, cd0 = float(k["rolling_coefficient"]), float(k["drag_coefficient"])
        effs = [
            Effect("road_grade", f"road grade, piecewise linear in distance ({N_GRADE} knots; vehicle grade_frac)",
                   g, {p.name: 0.0 for p in g}, ("power_w",)),
            Effect("aux_load", "constant auxiliary electrical load (HVAC, cooling fans, electronics; bus aux_power_w)",
                   (Param("aux_power_w", "W", -2e4, 1e5, float(k["aux_power_w"]) + 1000.0, "constant auxiliary load"),),
                   {"aux_power_w": float(k["aux_power_w"])}, ("power_w",)),
            Effect("mass_error", "vehicle mass differs from the nominal (payload; vehicle mass_kg)",
                   (Param("mass_kg", "kg", 0.5 * m0, 2.0 * m0, m0, "vehicle mass", plausible=(0.8 * m0, 1.8 * m0)),),
                   {"mass_kg": m0}, ("power_w",)),
            Effect("rolling_error", "rolling-resistance coefficient differs from the nominal (tyres, surface)",
                   # plausible: within a factor 2 of the given f_r (one tyre class on paved roads spans about that,
                   # with pressure and temperature); a fit 3.6x the given one on a record with a constant grade (the
                   # same force while the vehicle moves) was the grade, not the tyres (a new-user trial's Leaf)
                   (Param("rolling_coefficient", "-", 0.002, 0.06, f0, "rolling coefficient f_r", log=True,
                          plausible=(0.5 * f0, 2.0 * f0)),),
                   {"rolling_coefficient": float(k["rolling_coefficient"])}, ("power_w",)),
            Effect("aero_error", "aerodynamic drag differs from the nominal (body, wind; vehicle drag_coefficient)",
                   # plausible: within a factor 2 of the given C_d (a spec-sheet value against a record's effective
                   # drag: roof loads, a trailer, a headwind's average add tens of percent; more is another body)
                   (Param("drag_coefficient", "-", 0.1, 3.0, cd0, "drag coefficient C_d", log=True,
                          plausible=(0.5 * cd0, 2.0 * cd0)),),
                   {"drag_coefficient": float(k["drag_coefficient"])}, ("power_w",)),
            Effect("regen_limit", "regenerative braking power limited (machine/inverter limit; motor regen_power_max_w)",
                   (Param("regen_power_max_w", "W", 1e3, 2e6, 5e4, "most regenerative electrical power"),),
                   {"regen_power_max_w": float(k["regen_power_max_w"])}, ("power_w",), regen_starts),
        ]
        return {e.name: e for e in effs}

    # -- the components' parameter sets for a full value dictionary
    def _params(self, values: Mapping[str, float] | None = None, grade_d=None) -> dict:
        """{component: params dataclass}: the files, the known parameters, then ``values`` (full)."""
        over = {n: {} for n in PARAM_FILES}
        for key, val in self.known.items():
            for comp in OWNERS.get(key, ()):
                if val != getattr(_FILES[comp], key):
                    over[comp][key] = val
        for key, val in (values or {}).items():
            for comp in OWNERS.get(key, ()):
                over[comp][key] = val
        gk = [float((values or {}).get(f"grade_frac[{j}]", 0.0)) for j in range(N_GRADE)]
        if any(x != 0.0 for x in gk) and grade_d is not None:
            d0, g0 = tuple(self.known["grade_distance_m"]), tuple(self.known["grade_frac"])
            if d0:   # a known grade profile (--params): the fitted knots add to it, on the union of the knots
                dd = np.union1d(np.asarray(d0, float), np.asarray(grade_d, float))
                gg = np.interp(dd, d0, g0) + np.interp(dd, grade_d, gk)
            else:
                dd, gg = grade_d, gk
            over["vehicle"]["grade_distance_m"] = tuple(float(x) for x in dd)
            over["vehicle"]["grade_frac"] = tuple(float(x) for x in gg)
        return over

    def _built(self, over: dict) -> dict:
        return {n: dataclasses.replace(_FILES[n], **over[n]) for n in PARAM_FILES}

    def prepare(self, data) -> dict:
        from ..components.cycle import CycleParams, CycleSource
        tg, vg, dt, n_sub, h = _trace(data, float(self.known["substep_s"]))
        n_steps = (tg.size - 1) * n_sub
        # the cycle component itself produces the input trace (same values as in the replay's master)
        with tempfile.TemporaryDirectory() as tmp:
            f = Path(tmp) / "trace.csv"
            _write_cycle(f, vg, dt)
            cyc = CycleSource("cycle", CycleParams(cycle_file=str(f)))
        cyc.initialize(0.0)
        vr = np.empty(n_steps + 1)
        ar = np.empty(n_steps + 1)
        vr[0], ar[0] = cyc.y["speed_ref_mps"], cyc.y["accel_ref_mps2"]
        for k in range(n_steps):
            cyc.do_step(0.0 + k * h, h)
            vr[k + 1], ar[k + 1] = cyc.y["speed_ref_mps"], cyc.y["accel_ref_mps2"]
        dist = float(np.sum(0.5 * (vr[1:] + vr[:-1]) * h))
        grade_d = np.linspace(0.0, max(dist, 1.0), N_GRADE)
        self._grade_d = grade_d          # knot distances of the last prepared record (used by overlay())
        # the motor's maps once (they do not depend on fitted parameters)
        base = self._built(self._params())
        motor = _component_classes()["motor"]("motor", base["motor"])
        df = data.df
        t = df["time_s"].to_numpy(float)
        v = df["speed_mps"].to_numpy(float)
        slope = np.diff(vg) / dt
        a = np.interp(t, tg[:-1] + 0.5 * dt, slope) if slope.size else np.zeros_like(t)
        return {"t": t, "tg": tg, "dt": dt, "n_sub": n_sub, "h": h, "vr": vr, "ar": ar, "grade_d": grade_d,
                "md": motor._md, "mi": motor._mi, "power_meas": df["power_w"].to_numpy(float), "v": v, "a": a,
                "d": np.interp(t, tg, np.concatenate([[0.0], np.cumsum(0.5 * (vg[1:] + vg[:-1]) * dt)])),
                "n": t.size, "df": df}

    def simulate(self, ctx, values):
        p = self.full_values(values)
        prm = self._built(self._params(p, ctx["grade_d"]))
        vp, mp, bp = prm["vehicle"], prm["motor"], prm["bus"]
        kd = np.array(vp.grade_distance_m, dtype=float)
        kg = np.array(vp.grade_frac, dtype=float)
        vehicle = (kd, kg, float(vp.mass_kg), float(vp.c_aero), float(vp.rolling_coefficient),
                   float(vp.gravity_mps2), float(vp.mass_rot_kg))
        motor = (ctx["md"], ctx["mi"], mp.gear_ratio / mp.wheel_radius_m, mp.wheel_radius_m / mp.gear_ratio,
                 bool(mp.extrapolate_speed), float(mp.regen_speed_min_mps), float(mp.regen_power_max_w),
                 float(mp.efficiency_scale_frac), float(mp.heat_rate_per_s), float(mp.heat_index_init_frac),
                 float(mp.regen_efficiency_scale_frac))
        rec = _speed_following_power(ctx["vr"], ctx["ar"], ctx["h"], vehicle, motor, float(bp.aux_power_w))
        pg = _sample(rec, ctx["n_sub"], ctx["tg"].size)
        return {"power_w": np.interp(ctx["t"], ctx["tg"], pg)}

    native_convention = "mean-ending"
    differentiated_inputs = ("speed_mps",)      # the acceleration of the road-load equation

    def quiet_mask(self, ctx):
        """Standstill: measured speed below 0.05 m/s."""
        return ctx["v"] < 0.05

    def param_bounds(self, ctx):
        pm = ctx["power_meas"]
        neg = float(np.max(-pm)) if pm.size else 0.0
        return {"regen_power_max_w": (1e3, max(2.0 * neg, 2e3))}

    def regressors(self, ctx):
        v, a = ctx["v"], ctx["a"]
        return {"time_s": ctx["t"] - ctx["t"][0], "speed_mps": v, "speed_sq": v * v, "speed_cube": v ** 3,
                "accel_mps2": a, "inertial_power": a * v, "distance_m": ctx["d"],
                "braking": (a * v < 0).astype(float) * np.abs(a * v)}

    # -- closing the loop in the simulator
    def overlay(self, values, out_dir=None) -> dict:
        """``{"vehicle": {...}, "motor": {...}, "bus": {...}}``: the fitted values (and known parameters that
        differ from the parameter files) in the components' own names; road-grade knots as the lists
        ``grade_distance_m`` (from the last :meth:`prepare`d record) / ``grade_frac``. Only values that
        differ from the parameter files are written; components without a change are left out."""
        over = self._params(values, getattr(self, "_grade_d", None))
        out = {}
        for comp, d in over.items():
            d = {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items() if v != getattr(_FILES[comp], k)}
            if d:
                out[comp] = d
        return out

    def replay(self, data, overlay_file) -> dict:
        """Replay the measured speed through the components stepped by the master (module docstring).

        ``overlay_file``: TOML with one table per component (``[vehicle]``, ``[motor]``, ``[bus]``) of
        parameters merged over the default parameter files.  Returns ``{"power_w": array}`` at the data's
        sample times and, for inspection, ``"result"`` (the master's :class:`~shevsim.core.results.Result`).
        """
        from ..core.master import Connection, Master, MasterSettings
        from ..core.overlay import Overlay, resolve_files
        from ..core.params import load_params
        doc = {}
        if overlay_file is not None:
            path = Path(overlay_file)
            from ..core.errors import toml_loads
            doc = toml_loads(path.read_text(encoding="utf-8-sig"), str(path), DataError, "invalid TOML")
            doc.pop("meta", None)
            unknown = set(doc) - set(PARAM_FILES)
            if unknown:
                raise DataError(f"{overlay_file}: unknown component table(s) {sorted(unknown)}; "
                                f"expected {sorted(PARAM_FILES)}")
            # relative *_file paths: against the overlay's folder
            doc = {n: resolve_files(Overlay(dict(d), path.parent.resolve(), path)) for n, d in doc.items()}
        tg, vg, dt, n_sub, h = _trace(data, float(self.known["substep_s"]))
        classes = _component_classes()
        from ..components import get_component_class
        cyc_cls = get_component_class("cycle")
        with tempfile.TemporaryDirectory() as tmp:
            f = Path(tmp) / "trace.csv"
            _write_cycle(f, vg, dt)
            comps = [cyc_cls("cycle", load_params(cyc_cls.Params, None, {"cycle_file": str(f)}))]
        for n in ("vehicle", "motor", "bus"):
            ov = dict(doc.get(n, {}))
            if n == "vehicle":
                ov["input_mode"] = "speed"
            comps.append(classes[n](n, load_params(classes[n].Params, PARAM_FILES[n], ov)))
        conns = [Connection.parse(a, b) for a, b in (
            ("vehicle.speed_ref_mps", "cycle.speed_ref_mps"), ("vehicle.accel_ref_mps2", "cycle.accel_ref_mps2"),
            ("motor.force_req_n", "vehicle.force_req_n"), ("motor.speed_mps", "vehicle.speed_mps"),
            ("bus.motor_power_w", "motor.elec_power_w"))]
        master = Master(comps, conns, MasterSettings(step_s=h), order=["cycle", "vehicle", "motor", "bus"])
        res = master.run((tg.size - 1) * n_sub * h)
        pg = _sample(np.asarray(res["bus.demand_power_w"], float), n_sub, tg.size)
        t = data.df["time_s"].to_numpy(float)
        return {"power_w": np.interp(t, tg, pg), "result": res}
