"""shevsim.fast - the compiled whole-vehicle path (issue 15).

:func:`runner_for` turns a scenario whose components are all native types this path knows into a
``runner(t_stop_s) -> Result`` that steps the whole system in one numba-compiled loop
(:func:`shevsim.fast.loop.run_loop`): the scenario's own execution order, step multiples and
connections (as index arrays), the components' own compiled physics (:mod:`shevsim.fast.kernels`),
the MPC's QP solved by DAQP's C library called from compiled code (:mod:`shevsim.supervisor.daqp_nb`), and
the outputs recorded into a preallocated array.  The result equals :meth:`Master.run
<shevsim.core.master.Master.run>` of the same scenario bit for bit (``tests/unit/test_fast_path.py``);
the Python master stays the reference and the path for FMUs and debugging.

How a run goes: the scenario is built and initialised by the Python master once (component
construction, initial state, initial outputs: the reference code itself); the components' states are
then copied into arrays (a template), and each call of the runner copies the template and runs the
compiled loop from ``t0``.  So one runner serves many runs (a study's evaluations) at the cost of
the loop alone.

A scenario the path cannot take is declined with the reason: FMUs or component types without a
kernel, the 30-node battery thermal model, an MPC solver other than DAQP (or a DAQP build whose C structs are not the
checked ones), uncompiled components, or ports that differ from the kernels' (a component changed
since).

Example::

    from shevsim.core.scenario import load_scenario
    from shevsim.fast import runner_for
    run, why = runner_for(load_scenario("hd_udds_mpc"))
    res = run(1060.0) if run is not None else None
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from shevsim.core.errors import FastPathError

__all__ = ["runner_for", "FastRunner", "FastPathError", "SUPPORTED_TYPES"]

SUPPORTED_TYPES = ("cycle", "driver", "vehicle", "motor", "bus", "engine_generator", "battery", "bms",
                   "rule_supervisor", "mpc_supervisor", "power_limits", "profile")
#: the kernels: one per type, the vehicle's speed mode its own
KINDS = SUPPORTED_TYPES + ("vehicle_speed",)


def _kind(c) -> str:
    return "vehicle_speed" if c.TYPE == "vehicle" and getattr(c, "_speed", False) else c.TYPE

# the ports each kernel reads/writes, in the components' declaration order (checked at build time)
def _engine_floor() -> tuple:
    import inspect
    from shevsim.powertrain.engine import step
    return ("elec_power_min_w",) if "elec_min_w" in inspect.signature(getattr(step, "py_func", step)).parameters else ()


_ENGINE_FLOOR = _engine_floor()
_PORTS = {
    "cycle": ((), ("speed_ref_mps", "accel_ref_mps2", "time_in_cycle_s")),
    "driver": (("speed_ref_mps", "accel_ref_mps2", "speed_mps"), ("force_req_n", "speed_error_mps", "feedforward_n")),
    "vehicle": (("traction_force_n", "brake_force_n", "grade_rad"),
                ("speed_mps", "accel_mps2", "distance_m", "traction_energy_j", "aero_energy_j", "rolling_energy_j",
                 "brake_energy_j", "grade_energy_j", "kinetic_energy_j")),
    "motor": (("force_req_n", "speed_mps", "elec_power_max_w", "elec_power_min_w"),
              ("traction_force_n", "brake_force_n", "elec_power_w", "torque_nm", "speed_radps", "torque_max_nm",
               "heat_index_frac", "loss_energy_j", "elec_energy_j", "mech_energy_j")),
    "bus": (("motor_power_w", "gen_power_w", "aux_power_w", "battery_power_max_w", "battery_power_min_w"),
            ("motor_power_max_w", "motor_power_min_w", "gen_power_max_w", "battery_power_w", "demand_power_w",
             "aux_energy_j", "motor_energy_j", "gen_energy_j", "battery_energy_j")),
    "engine_generator": (("power_cmd_w", "power_rate_max_wps", "elec_power_max_w") + _ENGINE_FLOOR,
                         ("elec_power_w", "engine_power_w", "engine_speed_radps", "engine_torque_nm", "rack_frac",
                          "fuel_rate_gps", "soot_rate_mgps", "power_limited_w", "elec_power_rated_w", "shed_count",
                          "shed_time_s", "fuel_mass_g", "fuel_energy_j", "soot_mass_mg", "soot_transient_mg",
                          "engine_loss_energy_j", "gen_loss_energy_j", "elec_energy_j", "shaft_kinetic_energy_j",
                          "soot_rate_meas_mgps")),
    "battery": (("power_w", "h_conv_w_m2k", "t_ambient_c", "current_cmd_a"),
                ("current_a", "voltage_v", "soc_pct", "ocv_v", "t_core_c", "t_surface_c", "t_mean_c", "heat_w",
                 "cell_current_meas_a", "cell_voltage_meas_v", "t_surface_meas_c", "t_ambient_meas_c",
                 "loss_energy_j", "chem_energy_j", "ah_throughput_ah", "clamp_count")),
    "bms": (("cell_current_meas_a", "cell_voltage_meas_v", "t_surface_meas_c", "t_ambient_meas_c"),
            ("soc_pct", "v1_v", "rs_ohm", "r1_ohm", "c1_f", "t_avg_c", "gamma_c", "t_core_c", "h_w_m2k", "heat_w",
             "ocv_v", "power_max_w", "power_min_w", "i_max_a", "i_min_a", "cell_rs_ohm")),
    "rule_supervisor": (("demand_power_w", "soc_pct", "gen_power_w", "power_max_w", "power_min_w", "ocv_v", "rs_ohm"),
                        ("power_cmd_w", "power_rate_max_wps", "battery_power_plan_w", "engine_on_1")),
    "mpc_supervisor": (("demand_power_w", "soc_pct", "gen_power_w", "power_max_w", "power_min_w", "ocv_v", "rs_ohm"),
                       ("power_cmd_w", "power_rate_max_wps", "battery_power_plan_w", "fallback_count",
                        "battery_slack_w", "soc_slack_pct")),
    "power_limits": (("motor_power_w", "gen_power_w", "aux_power_w", "battery_power_max_w", "battery_power_min_w"),
                     ("motor_power_max_w", "motor_power_min_w", "gen_power_max_w", "gen_power_min_w")),
    "vehicle_speed": (("speed_ref_mps", "accel_ref_mps2", "grade_rad"),
                      ("force_req_n", "speed_mps", "accel_mps2", "distance_m", "traction_energy_j", "aero_energy_j",
                       "rolling_energy_j", "brake_energy_j", "grade_energy_j", "kinetic_energy_j")),
    "profile": ((), ("current_a", "power_w", "speed_mps", "t_ambient_c", "h_conv_w_m2k")),
}


#: measurement-noise draws per (generator state, leftover block): shared by the runners of one process
_NOISE_CACHE: dict = {}


class Declined(Exception):
    """The scenario cannot take the fast path (the message says why)."""


def _f(*vals) -> np.ndarray:
    return np.array([float(v) for v in vals], dtype=np.float64)


# ------------------------------------------------------------------------------- packing per type
# each returns (data tuple, indices of the entries a run mutates (copied per run))
def _pack_cycle(c):
    return (c._va, c._sa, _f(c._dt, c._n, c._dur, c._repeat, c.t0)), ()


def _pack_driver(c):
    from shevsim.powertrain.vehicle import G_MPS2
    p = c.params
    return (_f(p.kp_n_per_mps, p.ki_n_per_m, p.mass_kg, c._c, p.rolling_coefficient, G_MPS2, p.force_brake_max_n,
               p.force_prop_max_n), _f(c.integ)), (1,)


def _pack_vehicle_speed(c):
    return (_f(c._m, c._c, c._fr, c._g), np.ascontiguousarray(c._kd, dtype=np.float64),
            np.ascontiguousarray(c._kg, dtype=np.float64), _f(c.v, c.dist, c.th, *c.e)), (3,)


def _pack_profile(c):
    from shevsim.components.profile import _PORTS as ports
    ts = np.array(c._t, dtype=np.float64)
    cols = np.zeros((len(ports), ts.size))
    has = np.zeros(len(ports))
    for q, name in enumerate(ports):
        if name in c._cols:
            cols[q] = c._cols[name]
            has[q] = 1.0
    return (ts, cols, has), ()


def _pack_vehicle(c):
    return (_f(c._m, c._c, c._fr, c._g, 1.0 if c._knots else 0.0), np.ascontiguousarray(c._kd, dtype=np.float64),
            np.ascontiguousarray(c._kg, dtype=np.float64), _f(c.v, c.dist, *c.e)), (3,)


def _pack_motor(c):
    return (c._md, c._mi, _f(c._k_w, c._k_tau, 1.0 if c.extrapolate else 0.0, c._v_regen, c._p_regen, c._eff_scale,
                             c._heat_rate),
            _f(c.gamma, c.e_loss, c.e_elec, c.e_mech, c.v_prev, c.h_prev)), (3,)


def _pack_bus(c):
    return (_f(c._aux_w, 1.0 if c.params.enforce_battery_limits else 0.0), _f(*c.e)), (1,)


def _pack_engine(c):
    from shevsim.powertrain.engine import step
    s = c._step
    if s.fn is not step:
        raise Declined(f"component '{c.name}': engine-generator built with compiled=False")
    return (s.md, s.mi, s.c, _f(s.p_max, c.maps.p_max_w), _f(*c.st.values())), (4,)


def _pack_battery(c):
    from shevsim.battery import model as bm
    if c._fd_w is not None:
        raise Declined(f"component '{c.name}': battery thermal_model 'fd30' has no fast-path kernel")
    if c._step is not bm.cell_step:
        raise Declined(f"component '{c.name}': battery built with compiled=False")
    p = c.params
    data = (c._d, c._ix, c._c, c.st.copy(), c._th.copy(), c.yv.copy(), np.zeros(0),
            _f(c._np, c._ns, c._npack, p.current_offset_a, p.sigma_current_a, p.sigma_voltage_v,
               p.sigma_temperature_c, 1.0 if p.input_mode == "current" else 0.0), np.zeros(1, dtype=np.int64))
    return data, (3, 4, 5, 8)


def _pack_bms(c, h):
    from shevsim.bms.electrical import dekf_step
    from shevsim.bms.power_capability import power_limits
    from shevsim.bms.thermal_estimators import ThermalDKF, ThermalJEKF, ThermalKF, dkf_step, jekf_step, kf_step
    if h != c.dt:                       # what do_step does first when its step differs from the built one
        c._build(h)
    d = c.dekf
    th = c.thermal
    kinds = {ThermalKF: (0, kf_step), ThermalDKF: (1, dkf_step), ThermalJEKF: (2, jekf_step)}
    if type(th) not in kinds:
        raise Declined(f"component '{c.name}': thermal estimator {type(th).__name__} has no fast-path kernel")
    code, fn = kinds[type(th)]
    if d._step is not dekf_step or th._step is not fn or c.pc._limits is not power_limits:
        raise Declined(f"component '{c.name}': BMS estimators built with compiled=False")
    a_n, a_1 = c.pc._discN._args, c.pc._disc1._args
    if a_n[5] or a_1[5] or a_n[:4] != a_1[:4]:
        raise Declined(f"component '{c.name}': power capability discretisation is not the ZOH of one cell")
    dd, dix = d._tabs
    xe = _f(d.soc, d.v1, d.x2, d.th1, d.th2, *d.px, *d.pth, d.rs, d.r1, d.c1, d.v2, d.r2)
    ckeys = np.full(4096, np.nan)          # memo of the thermal coefficients per rounded h (pure, shared by runs)
    cvals = np.zeros((4096, 17))
    pd_, pix = c.pc._tabs
    xb = _f(c.t_mean, c.gamma, c.t_core, c.h_est, c.q_est, c.pc.last_i_max_a, c.pc.last_i_min_a)
    data = (dd, dix, d._k, xe, th._st.copy(), th._c, pd_, pix, c.pc._k, _f(*a_n[:5], a_1[4]), ckeys,
            c.tables._d, c.tables._ix, xb, _f(c._ns, c._np, code), cvals)
    return data, (3, 4, 13)


def _rule_vec(rule, ts):
    s = rule.settings
    return _f(s.soc_min_pct, s.soc_max_pct, s.soc_ref_pct, s.soc_on_pct, s.soc_off_pct, s.charge_power_w,
              s.engine_on_min_power_w, s.engine_on_demand_w, s.power_gen_min_w, s.power_gen_max_w,
              s.power_rate_min_wps, rule.dt_s, ts)


def _rate_arrays(rate_map):
    return np.array(rate_map._inner, dtype=np.float64), np.array(rate_map.rates_wps, dtype=np.float64)


def _pack_rule(c):
    inner, rates = _rate_arrays(c.rule.rate_map)
    return (_rule_vec(c.rule, c.params.sample_time_s), inner, rates, _f(1.0 if c.engine_on else 0.0, c.prev_cmd)), (3,)


def _pack_mpc(c):
    from shevsim.supervisor import daqp_nb
    m = c.mpc
    if m.solver_name != "daqp":
        raise Declined(f"component '{c.name}': MPC solver '{m.solver_name}' (the fast path calls DAQP only)")
    ok, why = daqp_nb.available()
    if not ok:
        raise Declined(f"component '{c.name}': {why}")
    if not m.compiled_call:
        raise Declined(f"component '{c.name}': MPC built with compiled=False")
    a = list(m.arrays)
    a[0] = a[0].copy()
    a[0][10] = 1.0 if (m.rule is not None and m.rule.engine_on) else 0.0
    a[6] = a[6].copy()
    a[6][0] = c.prev_cmd                      # the component's previous command
    a[7] = a[7].copy()
    pr = m.prob
    for i in (18, 19, 21, 22, 23):            # the QP's work arrays: H, f, bu, bl, aux (the runner's own)
        a[i] = np.zeros_like(a[i])
    a[24:31] = daqp_nb.new_state(pr.n, pr.n + pr.m)
    from shevsim.supervisor.mpc import new_guess_state
    a[31:39] = new_guess_state(pr.n, pr.n + pr.m)
    return tuple(a), (6, 7, 30, 31)


def _pack_limits(c):
    return (_f(c._aux_w, 1.0 if c.params.enforce_battery_limits else 0.0),), ()


_PACK = {"vehicle_speed": _pack_vehicle_speed, "profile": _pack_profile, "power_limits": _pack_limits, "cycle": _pack_cycle, "driver": _pack_driver, "vehicle": _pack_vehicle, "motor": _pack_motor,
         "bus": _pack_bus, "engine_generator": _pack_engine, "battery": _pack_battery,
         "rule_supervisor": _pack_rule, "mpc_supervisor": _pack_mpc}

_DUMMY: dict = {}


def _dummies() -> dict:
    """Data of a default component of every type (the loop's argument for a type the scenario lacks:
    never stepped, but it keeps one compiled signature for every scenario)."""
    if not _DUMMY:
        from shevsim.components import get_component_class
        for kind in KINDS:
            if kind == "vehicle_speed":
                from shevsim.components.vehicle import Vehicle, VehicleParams
                comp = Vehicle(kind, VehicleParams(input_mode="speed"))
            else:
                comp = get_component_class(kind, "fast path")(kind)
            comp.initialize(0.0)
            _DUMMY[kind] = (_pack_bms(comp, 0.1) if kind == "bms" else _PACK[kind](comp))[0]
    return _DUMMY


class FastRunner:
    """``runner(t_stop_s) -> Result``: one scenario on the compiled loop (see the module docstring).

    Attributes
    ----------
    scenario : Scenario
    master : Master
        The initialised Python master the template was taken from (not stepped).
    last_wall_s : float
        Wall time of the last run's compiled loop [s].

    Notes
    -----
    A runner reuses its arrays from run to run: call it from one thread at a time (Dask workers run one
    task per process here); build one runner per thread otherwise.
    """

    def __init__(self, scenario, master):
        from .kernels import (T_BATTERY, T_BMS, T_BUS, T_CYCLE, T_DRIVER, T_ENGINE, T_LIMITS, T_MOTOR, T_MPC,
                              T_PROFILE, T_RULE, T_VEHICLE, T_VEHICLE_SPEED)
        codes = {"cycle": T_CYCLE, "driver": T_DRIVER, "vehicle": T_VEHICLE, "motor": T_MOTOR, "bus": T_BUS,
                 "engine_generator": T_ENGINE, "battery": T_BATTERY, "bms": T_BMS, "rule_supervisor": T_RULE,
                 "mpc_supervisor": T_MPC, "power_limits": T_LIMITS, "vehicle_speed": T_VEHICLE_SPEED,
                 "profile": T_PROFILE}
        self.scenario = scenario
        self.master = m = master
        self.h = float(m.settings.step_s)
        self._jacobi = m.settings.method == "jacobi"
        self.t0 = float(scenario.t0_s)
        m.initialize(self.t0)
        order = list(m.order)
        comps = [m.components[n] for n in order]
        types = {n: _kind(m.components[n]) for n in order}
        # port layout: outputs in the master's recording order, then inputs
        out_idx, in_idx = {}, {}
        obase, ibase = [], []
        k = 0
        for n, c in zip(order, comps):
            obase.append(k)
            for port in _PORTS[types[n]][1]:
                out_idx[(n, port)] = k
                k += 1
        self.nsig = k
        names = [f"{n}.{p}" for n in order for p in _PORTS[types[n]][1]]
        if names != list(m._signal_names):
            raise Declined("the recorded signals differ from the fast path's layout")
        for n, c in zip(order, comps):
            ibase.append(k)
            for port in _PORTS[types[n]][0]:
                in_idx[(n, port)] = k
                k += 1
        sig = np.zeros(k)
        for (n, port), i in out_idx.items():
            sig[i] = float(m.components[n].y[port])
        for (n, port), i in in_idx.items():
            sig[i] = float(m.components[n].u[port])
        self._sig0 = sig
        lptr, ldst, lsrc = [0], [], []
        for n in order:
            for cn in m.connections:
                if cn.dst == n:
                    ldst.append(in_idx[(cn.dst, cn.dst_port)])
                    lsrc.append(out_idx[(cn.src, cn.src_port)])
            lptr.append(len(ldst))
        i64 = lambda v: np.array(v, dtype=np.int64)  # noqa: E731
        self._typ = i64([codes[types[n]] for n in order])
        self._mult = i64([m.step_multiples[n] for n in order])
        self._ibase, self._obase = i64(ibase), i64(obase)
        self._lptr, self._ldst, self._lsrc = i64(lptr), i64(ldst), i64(lsrc)
        self._names = names
        self._units = dict(zip(m._signal_names, m._signal_units))
        # each component's position in its kind's instance list; the faults not yet applied at t0
        count: dict = {}
        inst = []
        for n in order:
            inst.append(count.get(types[n], 0))
            count[types[n]] = inst[-1] + 1
        self._inst = i64(inst)
        pending = m.faults[m._faults_done:]
        self._f_t = np.array([f.at_s for f in pending], dtype=np.float64)
        self._f_idx = i64([in_idx[(f.component, f.port)] for f in pending])
        self._f_val = np.array([f.value for f in pending], dtype=np.float64)
        self._forced0 = np.zeros(k, dtype=np.int8)
        for (cn, port) in m._forced:
            self._forced0[in_idx[(cn, port)]] = 1
        self._row0 = sig[:self.nsig].copy()
        # per-instance data (template) and which entries a run mutates; the loop gets one tuple per kind
        # holding one tuple per instance (execution order; a default component's data for a kind the scenario
        # lacks). Tuples, not numba typed lists: a typed list compiles its methods in every new process.
        dummies = _dummies()
        self._data = {typ: [] for typ in KINDS}
        self._mut = {typ: () for typ in KINDS}
        # [instance, step multiple, noise drawn so far, generator at build, key of (generator state, leftover
        # block), leftover of the component's current block]
        self._batteries = []
        for n, c in zip(order, comps):
            typ = types[n]
            if typ == "bms":
                data, mut = _pack_bms(c, m.step_multiples[n] * self.h)
            else:
                data, mut = _PACK[typ](c)
            if typ == "battery":
                import copy
                import pickle
                lead = np.array(c._buf[c._k:], dtype=np.float64)
                key = (pickle.dumps(c.rng.bit_generator.state), lead.tobytes())
                self._batteries.append([len(self._data[typ]), m.step_multiples[n], lead, copy.deepcopy(c.rng), key,
                                        lead])
            self._data[typ].append(data)
            self._mut[typ] = mut
        self._live = {}
        for typ in KINDS:
            if not self._data[typ]:
                self._live[typ] = (dummies[typ],)
            else:
                self._live[typ] = tuple(self._fresh(typ, i) for i in range(len(self._data[typ])))
        self._comp_names = order
        from shevsim.core.params import params_to_dict
        self._params = {}
        for n, c in m.components.items():
            try:
                self._params[n] = params_to_dict(getattr(c, "params", None))
            except TypeError:
                self._params[n] = {}
        self.last_wall_s = 0.0

    # ------------------------------------------------------------------------------------------
    def _noise_for(self, b, n_draws: int) -> np.ndarray:
        """The first ``n_draws`` measurement-noise draws of battery entry ``b``: the rest of the component's
        current block, then its generator's next blocks of standard normals, in order (what
        ``BatteryPack._noise`` draws).  A pure function of the generator's state: kept per process
        (:data:`_NOISE_CACHE`), so the runners of a study's evaluations share it (the loop only reads it)."""
        if b[2].size >= n_draws:
            return b[2]
        import copy
        from shevsim.components.battery import _NOISE_BLOCK
        hit = _NOISE_CACHE.get(b[4])
        if hit is None or hit.size < n_draws:
            rng = copy.deepcopy(b[3])
            nb = -(-(n_draws - b[5].size) // _NOISE_BLOCK)
            hit = np.concatenate([b[5]] + [rng.standard_normal(_NOISE_BLOCK) for _ in range(nb)])
            if len(_NOISE_CACHE) >= 16:
                _NOISE_CACHE.clear()
            _NOISE_CACHE[b[4]] = hit
        b[2] = hit
        return hit

    def n_steps(self, t_stop_s: float) -> int:
        """Communication steps to ``t_stop_s`` (the rule of :meth:`Master.run`)."""
        x = (t_stop_s - self.t0) / self.h
        n_total = round(x) if abs(x - round(x)) <= 1e-9 * max(1.0, abs(x)) else math.ceil(x)
        return max(int(n_total), 0)

    def _fresh(self, typ, i=0):
        """A copy of instance ``i``'s template data (the arrays a run mutates copied)."""
        data = self._data[typ][i]
        mut = self._mut[typ]
        return tuple(a.copy() if j in mut else a for j, a in enumerate(data))

    def _reset_live(self, n: int) -> None:
        """Bring the loop's data back to the template (in place) and give each battery its noise for ``n``
        steps."""
        for typ in KINDS:
            tmpl = self._data[typ]
            live = self._live[typ]
            for i in range(len(tmpl)):
                for j in self._mut[typ]:
                    np.copyto(live[i][j], tmpl[i][j])
        for b in self._batteries:
            i = b[0]
            need = 4 * (-(-n // b[1]))
            live = self._live["battery"]
            cur = live[i]
            if cur[6].size < need:
                self._live["battery"] = live[:i] + (cur[:6] + (self._noise_for(b, need),) + cur[7:],) + live[i + 1:]

    def __call__(self, t_stop_s: float):
        import time
        from shevsim.core.errors import ScenarioError, SimulationError
        from shevsim.core.results import Result
        from shevsim.supervisor import daqp_nb
        from .kernels import ERR_NONFINITE_OUTPUT, ERRORS
        from .loop import run_loop
        if not (isinstance(t_stop_s, (int, float)) and math.isfinite(t_stop_s)):
            raise ScenarioError(f"fast path: stop time must be a finite number, got {t_stop_s!r}")
        n = self.n_steps(float(t_stop_s))
        nsig = self.nsig
        rec = np.empty((nsig, n + 1))          # one row per signal: each signal's samples contiguous
        rec[:, 0] = self._row0
        sig = self._sig0.copy()
        self._reset_live(n)
        data = self._live
        out = np.zeros(3, dtype=np.int64)
        forced = self._forced0.copy()
        fstate = np.zeros(1, dtype=np.int64)
        wall = time.perf_counter()
        k0 = 0
        # the loop runs in chunks of about CHUNK_WALL_S of wall time: between two chunks Python handles a
        # pending signal (Ctrl-C, SIGTERM), so a stop request is honoured within a chunk, and the rows done so
        # far are returned as the partial result
        chunk = 256
        bar = None
        if getattr(self.master.settings, "progress", False) and n > 1000:
            try:
                from tqdm import tqdm
                bar = tqdm(total=n, unit="step", desc="simulating (compiled)", mininterval=0.5)
            except ImportError:  # pragma: no cover
                bar = None
        try:
            while True:
                todo = min(chunk, n - k0)
                tc = time.perf_counter()
                try:
                    run_loop(todo, k0, self.h, self.t0, self._typ, self._mult, self._ibase, self._obase,
                             self._lptr, self._ldst, self._lsrc, sig, rec, nsig, out, self._inst, self._f_t,
                             self._f_idx, self._f_val, forced, fstate, self._jacobi, data["cycle"], data["driver"],
                             data["vehicle"], data["motor"], data["bus"], data["engine_generator"], data["battery"],
                             data["bms"], data["rule_supervisor"], data["mpc_supervisor"], data["power_limits"],
                             data["vehicle_speed"], data["profile"])
                except (ArithmeticError, ValueError, IndexError) as exc:
                    # an exception raised inside compiled code carries no component or time: the caller
                    # (shevsim.run.simulate, engine 'auto') reruns on the Python master, which names them
                    raise FastPathError(f"the compiled loop raised {type(exc).__name__}: {exc} (between t="
                                        f"{self._time(k0):.6g} s and the stop; run with engine 'python' to name "
                                        f"the component and time)") from exc
                if out[0] == ERR_NONFINITE_OUTPUT:
                    row = int(out[1])
                    bad = [j for j in range(nsig) if not math.isfinite(rec[j, row])]
                    if bad:
                        comp, port = self._names[bad[0]].split(".", 1)
                        err = SimulationError(f"component '{comp}' output '{port}' is {float(rec[bad[0], row])!r} "
                                              f"at t={self._time(row):.6g} s (step {row})")
                        raise self._stopped(err, rec, row, comp, port, self._time(row))
                    k0 = row                # a row whose sum overflowed, every value finite: go on
                    if k0 >= n:
                        break
                    continue
                if out[0] != 0:
                    k = int(out[1])
                    comp = self._comp_names[int(out[2])]
                    err = SimulationError(f"component '{comp}' failed in do_step at t={self._time(k):.6g} s "
                                          f"(step {k}): {ERRORS.get(int(out[0]), 'error')}")
                    raise self._stopped(err, rec, k + 1, comp, None, self._time(k))
                k0 = int(out[1])
                if bar is not None:
                    bar.update(k0 - bar.n)
                if k0 >= n:
                    break
                dt = time.perf_counter() - tc
                chunk = int(min(max(chunk * CHUNK_WALL_S / max(dt, 1e-6), 16), 4 * chunk, 1_000_000))
        except KeyboardInterrupt as exc:    # Ctrl-C / SIGTERM between two chunks: the rows done so far
            from shevsim.core.results import Termination
            reason = getattr(exc, "reason", "interrupted (Ctrl-C)")
            exc.time_s = self._time(k0)
            exc.result = self._result(rec, k0 + 1, Termination("stopped", reason, None, None, exc.time_s))
            raise
        finally:
            if bar is not None:
                bar.close()
            if self._data["mpc_supervisor"]:
                for mpc in data["mpc_supervisor"]:
                    if mpc[30][0] != 0:
                        daqp_nb.drop_model(mpc[24], mpc[30])  # free DAQP's workspace (daqp.Model.__dealloc__)
            self.last_wall_s = time.perf_counter() - wall
        return self._result(rec, n + 1, "completed")

    def _stopped(self, err, rec, nrows, comp, port, t):
        """Attach where/when and the trajectory up to the stop (as the master's errors carry them)."""
        from shevsim.core.results import Termination
        err.component, err.port, err.time_s = comp, port, t
        err.result = self._result(rec, nrows, Termination("stopped", str(err), comp, port, t))
        return err

    def _time(self, k: int) -> float:
        return self.t0 + k * self.h

    def _result(self, rec, nrows, termination):
        from shevsim.core.results import Result
        times = np.empty(nrows)
        if nrows:
            times[0] = self.t0
            times[1:] = self.t0 + np.arange(1, nrows, dtype=np.int64) * self.h
        signals = {name: rec[j, :nrows] for j, name in enumerate(self._names)}
        return Result(times, signals, dict(self._units), {k: dict(v) for k, v in self._params.items()}, termination)


#: wall time of one chunk of the compiled loop (s): the longest wait for a stop request
CHUNK_WALL_S = 0.2


def runner_for(scenario, master=None) -> tuple[Callable | None, str]:
    """``(runner, why)``: a :class:`FastRunner` for ``scenario`` and ``""``, or ``None`` and the reason the
    scenario cannot take the fast path.

    ``runner(t_stop_s)`` returns a :class:`~shevsim.core.results.Result` equal to ``Master.run(t_stop_s,
    t0=scenario.t0_s)`` of the same scenario.  ``master``: a master already built from ``scenario``
    (``build_master``, not yet run) to take the components from instead of building them again; the
    runner initialises it (it must not be stepped by anyone else afterwards).
    """
    from shevsim.core.errors import ShevsimError
    why = _static_reason(scenario)
    if why:
        return None, why
    from shevsim.core.scenario import build_master
    if master is None:
        try:
            master = build_master(scenario)
        except ShevsimError as exc:
            return None, f"the scenario does not build: {exc}"
    why = _component_reason(master)
    if why:
        return None, why
    from shevsim.core.variables import units_compatible
    for c in master.connections:            # the loop copies values: a unit-converting link stays on the master
        su = master._vars[c.src][c.src_port].unit
        du = master._vars[c.dst][c.dst_port].unit
        if not units_compatible(su, du):
            return None, f"connection {c} converts '{su}' to '{du}' (unit conversion runs on the Python master)"
    try:
        return FastRunner(scenario, master), ""
    except Declined as exc:
        return None, str(exc)


def _static_reason(scenario) -> str:
    from numba.core import config as _nb_config
    if _nb_config.DISABLE_JIT:
        return "NUMBA_DISABLE_JIT is set (the fast path is compiled code)"
    seen = {}
    for spec in scenario.components:
        if spec.type == "fmu":
            return f"component '{spec.name}' is an FMU"
        if spec.type not in SUPPORTED_TYPES:
            return f"component '{spec.name}' has type '{spec.type}', which has no fast-path kernel"
    return ""


def _component_reason(master) -> str:
    from shevsim.components import get_component_class
    for n, c in master.components.items():
        typ = getattr(c, "TYPE", None)
        if typ not in SUPPORTED_TYPES or type(c) is not get_component_class(typ, "fast path"):
            return f"component '{n}' ({type(c).__name__}) is not the native '{typ}' class"
        ins = tuple(v.name for v in c.variables() if v.causality == "input")
        outs = tuple(v.name for v in c.variables() if v.causality == "output")
        if (ins, outs) != _PORTS[_kind(c)]:
            return f"component '{n}': its ports differ from the fast-path kernel's for type '{typ}'"
    return ""
