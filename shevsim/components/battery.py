"""battery.py - battery pack plant component (TYPE ``battery``).

A pack of ``n_series`` x ``n_parallel`` identical A123 26650 LFP cells (seed Table B.1:
130 s x 10 p, 2.3 Ah).  Each cell is the OCV-R-RC-RC model of :mod:`shevsim.battery.cell`
(parameters in SOC and mean temperature, charge/discharge tables) coupled to a radial thermal
model of :mod:`shevsim.battery.thermal` (two-state, seed 2.24-2.25, or a 30-node control-volume
model) through the heat generation of seed 5.16.

Step (inputs held over [t, t+h], exact ZOH for the RC branches and the thermal model):

1. the cell power ``p = power_w / (n_s n_p)`` is held over the step; the current ``i`` is held
   and chosen so that the *step-averaged* terminal power equals ``p``:
   ``p h = i (a - b i)`` with ``a = int_0^h (V_oc - V_1 - V_2) dt`` at ``i = 0`` and
   ``b = h R_s + sum_j R_j (h - tau_j (1 - e^{-h/tau_j})) + h^2 (dV_oc/dSOC) / (2 Q)``, i.e. the
   quadratic of seed 5.1 with effective ``V`` and ``R``:
   ``i = (a - sqrt(a^2 - 4 b p h)) / (2 b)``.  When ``a^2 < 4 b p h`` the demand exceeds what the
   pack can deliver: the current is clamped at the maximum-power point ``a / (2 b)`` and
   ``clamp_count`` is incremented.
2. SOC, V_1, V_2 advance exactly; the heat (5.16 with both RC branches, exact step average of
   ``V_j^2 / R_j``) drives the thermal model.

Energy bookkeeping (pack, cumulative):
``chem_energy_j = int V_oc i dt`` (exact: ``Q * int V_oc dSOC`` over the step),
``loss_energy_j = int i (V_oc - V_t) dt = int (i^2 R_s + i (V_1 + V_2)) dt`` (the overpotential
loss; over an interval that starts and ends relaxed it equals the Joule heat
``int (i^2 R_s + sum V_j^2/R_j) dt``), so the terminal energy ``int P dt = chem - loss``.

Ports
-----
Inputs
    ``power_w`` [W]  pack power demand, + discharge.
    ``h_conv_w_m2k`` [W/(m2.K)]  cell convection coefficient (cooling fault input), start 20.
    ``t_ambient_c`` [degC]  coolant / ambient temperature, start 25.
    ``current_cmd_a`` [A]  pack current, + discharge; used instead of ``power_w`` when the
    parameter ``input_mode = "current"`` (cell tests, replay of measured current profiles).
Outputs (at t + h; none is direct feedthrough)
    ``current_a`` [A] pack current, + discharge; ``voltage_v`` [V] pack terminal voltage;
    ``soc_pct`` [%]; ``ocv_v`` [V] pack open-circuit voltage; ``t_core_c``, ``t_surface_c`` [degC]
    cell core / surface temperature; ``heat_w`` [W] heat generation per cell (step average);
    ``cell_current_meas_a`` [A], ``cell_voltage_meas_v`` [V], ``t_surface_meas_c``,
    ``t_ambient_meas_c`` [degC]: one cell's measurements with Gaussian noise
    (sigma 0.003 A, 0.001 V, 0.016 degC, seed Sec. 5.4) from a seeded numpy Generator;
    cumulative ``loss_energy_j``, ``chem_energy_j`` [J] (pack), ``ah_throughput_ah`` [A.h]
    (pack, int |i| dt); ``clamp_count`` [1] steps whose power demand was infeasible;
    ``t_mean_c`` [degC] volume-averaged cell temperature.

Physics: written once in :mod:`shevsim.battery.model` (electrical step with its effects, two-state thermal
step) and compiled there.  The component's one step, :func:`battery_step` (input check, the cell step, the
SOC check, publishing with the measurement noise), is what both the Python master (``do_step``) and the
compiled whole-vehicle loop call, on the component's arrays ``data`` (:data:`D`).
``BatteryPack(name, params, compiled=False)`` runs that step's Python form (``.py_func``).  The
``fd30`` thermal model steps the same electrical function and the 30-node model of
:mod:`shevsim.battery.thermal` in Python (it has no compiled step).

Measurement noise: a seeded ``numpy`` Generator draws standard normals in blocks of 4096; ``data`` holds
the draws not used yet (``noise`` from ``kn[0]`` on), four per step (current, voltage, surface and
ambient temperature, in that order).

Effects (model terms switched by parameters; the defaults reproduce the plain model): see the table in
:mod:`shevsim.battery.model` - ``dudt_soc_frac``/``dudt_v_k`` (entropic heat dU/dT(SOC)),
``arrhenius_ea_r_k``, ``h_change_time_s``/``h_change_factor``/``h_change_width_s`` (convection change),
``hyst_max_v``/``hyst_rate``, ``capacity_ah``, ``current_offset_a``, ``lowsoc_r_gain``/``lowsoc_r_scale_frac``,
``r2_scale`` (0 removes the second RC branch), ``diffusion_time_s`` (solid diffusion; 0 = off); scale factors ``rs_scale, r1_scale, c1_scale, r2_scale,
c2_scale`` on the ECM tables and ``h_conv_factor`` on the convection input.

The voltage/current pair reported at t + h is the left limit (current of the finished step,
state at t + h): the pair a BMS sampling at t + h sees.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import pickle
from dataclasses import dataclass

import numpy as np

from shevsim.battery import cell as _cell
from shevsim.battery import model as _m
from shevsim.battery.thermal import FDThermal, ThermalParams, TwoStateThermal, fd_matrices
from numba import njit

from shevsim.core.compiled import ERR_NAN_INPUT, CompiledStep, field_index, njit_step, port_index
from shevsim.core.component import Component
from shevsim.core.errors import ScenarioError, SimulationError
from shevsim.core.params import rng
from shevsim.core.variables import inp, out

_NOISE_BLOCK = 4096
ERR_SOC_RANGE = 16


def _py(f):
    """The Python form of a compiled function (itself when numba's JIT is disabled)."""
    return getattr(f, "py_func", f)


@dataclass(frozen=True)
class BatteryPackParams:
    """Parameters of the battery pack plant.

    Attributes
    ----------
    n_series, n_parallel : int
        Cells in series / parallel (Table B.1: 130, 10).
    capacity_ah : float
        Cell capacity [A.h] (Table B.1: 2.3).
    soc_init_pct : float
        Initial SOC [%].
    t_init_c : float
        Initial uniform cell temperature [degC].
    input_mode : str
        ``"power"`` (default: ``power_w`` drives the pack) or ``"current"`` (``current_cmd_a``).
    thermal_model : str
        ``"two_state"`` (seed 2.24-2.25) or ``"fd30"`` (30-node control-volume radial model).
    entropic_heat : bool
        Include the reversible heat ``-i T Delta S / F`` (seed 5.16).
    temperature_dependent : bool
        Look up the ECM parameters at the cell mean temperature (False: at 25 degC).
    seed : int
        Seed of the measurement-noise generator.
    sigma_current_a, sigma_voltage_v, sigma_temperature_c : float
        Measurement noise standard deviations (seed Sec. 5.4).
    ocv_file, entropy_file, discharge_file, charge_file : str
        Cell tables (empty: the representative A123 26650 tables in ``components/battery/``).
    radius_m, length_m, density_kg_m3, cp_j_kgk, kt_w_mk : float
        Cell thermal parameters (seed Table 3.1).
    rs_scale, r1_scale, c1_scale, r2_scale, c2_scale : float
        Factors [1] on the ECM tables' R_s, R_1, C_1, R_2, C_2 (calibration); ``r2_scale = 0`` removes the
        second RC branch.
    arrhenius_ea_r_k, arrhenius_t_ref_c : float
        Arrhenius law on all resistances, ``exp(Ea/R (1/T - 1/T_ref))`` [K], [degC]; 0 = off.
    hyst_max_v, hyst_rate : float
        One-state OCV hysteresis: maximum voltage M [V] (0 = off) and rate gamma [1 per unit charge].
    current_offset_a : float
        Current-sensor offset [A] per cell: the true cell current is the commanded (logged) current
        ``current_cmd_a / n_parallel`` minus this; ``cell_current_meas_a`` reads true + offset.
    lowsoc_r_gain, lowsoc_r_scale_frac : float
        Low-SOC resistance rise ``x (1 + g exp(-SOC/s))`` [1], [1]; gain 0 = off; a gain in (-1, 0)
        makes the resistances fall towards low SOC (the calibration's Arrhenius claim test refits it with
        either sign as the SOC trend a temperature law must show beside).
    dudt_soc_frac, dudt_v_k : list of float
        Entropic coefficient dU/dT [V/K] at SOC knots [1] (piecewise linear, clamped); when given it
        replaces the entropy table (and acts whatever ``entropic_heat`` says); empty = off.
    h_conv_factor : float
        Factor [1] on the convection input ``h_conv_w_m2k``.
    h_change_time_s, h_change_factor, h_change_width_s : float
        Convection change: ``h`` times ``h_change_factor`` after ``h_change_time_s`` [s], logistic over
        ``h_change_width_s`` [s] (0: a step); factor 1 = off.
    diffusion_time_s : float
        Solid diffusion time ``R^2/D`` [s] of the active particles (0 = off): the OCV is read at the surface
        SOC, which lags the bulk SOC under current (steady state ``-tau_d i / (15 Q)``) and relaxes at rest
        with the time constant ``tau_d / 30`` (:mod:`shevsim.battery.model`).
    """

    n_series: int = 130
    n_parallel: int = 10
    capacity_ah: float = 2.3
    soc_init_pct: float = 50.0
    t_init_c: float = 25.0
    thermal_model: str = "two_state"
    input_mode: str = "power"
    entropic_heat: bool = True
    temperature_dependent: bool = True
    seed: int = 0
    sigma_current_a: float = 0.003
    sigma_voltage_v: float = 0.001
    sigma_temperature_c: float = 0.016
    ocv_file: str = ""
    entropy_file: str = ""
    discharge_file: str = ""
    charge_file: str = ""
    radius_m: float = 12.93e-3
    length_m: float = 65.15e-3
    density_kg_m3: float = 2047.0
    cp_j_kgk: float = 1109.2
    kt_w_mk: float = 0.610
    rs_scale: float = 1.0
    r1_scale: float = 1.0
    c1_scale: float = 1.0
    r2_scale: float = 1.0
    c2_scale: float = 1.0
    arrhenius_ea_r_k: float = dataclasses.field(default=0.0, metadata=rng(lo=0.0, what="Ea/R; 0 = off"))
    arrhenius_t_ref_c: float = 25.0
    hyst_max_v: float = 0.0
    hyst_rate: float = 30.0
    current_offset_a: float = 0.0
    lowsoc_r_gain: float = 0.0
    lowsoc_r_scale_frac: float = 0.1
    dudt_soc_frac: tuple[float, ...] = ()
    dudt_v_k: tuple[float, ...] = dataclasses.field(default=(), metadata=rng(what="dU/dT in V/K, either sign"))
    h_conv_factor: float = 1.0
    h_change_time_s: float = 0.0
    h_change_factor: float = 1.0
    h_change_width_s: float = 0.0
    diffusion_time_s: float = dataclasses.field(default=0.0, metadata=rng(lo=0.0, what="R^2/D of the particles; 0 = off"))

    def __post_init__(self) -> None:
        where = "battery parameters"
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not math.isfinite(v):
                raise ScenarioError(f"{where}: {f.name} must be finite, got {v!r}")
        for f in ("rs_scale", "r1_scale", "c1_scale", "c2_scale", "h_conv_factor", "h_change_factor",
                  "lowsoc_r_scale_frac", "radius_m", "length_m", "density_kg_m3", "cp_j_kgk", "kt_w_mk"):
            if not getattr(self, f) > 0.0:
                raise ScenarioError(f"{where}: {f} must be > 0, got {getattr(self, f)!r}")
        for f in ("r2_scale", "arrhenius_ea_r_k", "hyst_rate", "h_change_width_s", "diffusion_time_s"):
            if getattr(self, f) < 0.0:
                raise ScenarioError(f"{where}: {f} must be >= 0, got {getattr(self, f)!r}")
        # (a negative gain: resistances that fall towards low SOC; > -1 keeps them positive at SOC 0)
        if not self.lowsoc_r_gain > -1.0:
            raise ScenarioError(f"{where}: lowsoc_r_gain must be > -1, got {self.lowsoc_r_gain!r}")
        if len(self.dudt_soc_frac) != len(self.dudt_v_k):
            raise ScenarioError(f"{where}: dudt_soc_frac and dudt_v_k must have the same length "
                                f"({len(self.dudt_soc_frac)} != {len(self.dudt_v_k)})")
        ks = list(self.dudt_soc_frac)
        if any(not (b > a) for a, b in zip(ks, ks[1:])) or any(not math.isfinite(v) for v in ks + list(self.dudt_v_k)):
            raise ScenarioError(f"{where}: dudt_soc_frac must be finite and strictly increasing, dudt_v_k finite")
        if self.n_series < 1 or self.n_parallel < 1:
            raise ScenarioError(f"{where}: n_series and n_parallel must be >= 1")
        if not self.capacity_ah > 0.0:
            raise ScenarioError(f"{where}: capacity_ah must be > 0, got {self.capacity_ah!r}")
        if not 0.0 <= self.soc_init_pct <= 100.0:
            raise ScenarioError(f"{where}: soc_init_pct must be in [0, 100], got {self.soc_init_pct!r}")
        if self.thermal_model not in ("two_state", "fd30"):
            raise ScenarioError(f"{where}: thermal_model must be 'two_state' or 'fd30', got {self.thermal_model!r}")
        if self.input_mode not in ("power", "current"):
            raise ScenarioError(f"{where}: input_mode must be 'power' or 'current', got {self.input_mode!r}")
        for f in ("sigma_current_a", "sigma_voltage_v", "sigma_temperature_c"):
            if getattr(self, f) < 0.0:
                raise ScenarioError(f"{where}: {f} must be >= 0")



#: the step's data (:attr:`BatteryPack.data`): cell tables, packed cell parameters, state, thermal-coefficient
#: workspace, cell outputs, noise draws and the index of the next one, publishing parameters, state before the step
D = field_index(("d", "ix", "c", "st", "th", "yv", "noise", "kn", "p", "st_prev"), "D")
#: publishing parameters ``data[D.p]``
P = field_index(("n_parallel", "n_series", "n_pack", "current_offset_a", "sigma_current_a", "sigma_voltage_v",
                 "sigma_temperature_c", "current_mode"), "P")


class BatteryPack(CompiledStep, Component):
    """Battery pack plant: OCV-R-RC-RC cells with a radial thermal model (see module docstring)."""

    TYPE = "battery"
    INPUT_DEFAULTS = ("h_conv_w_m2k", "t_ambient_c")   # 20 W/(m2 K), 25 degC; the unused drive input: defaulted_inputs
    Params = BatteryPackParams
    VARIABLES = (
        inp("power_w", "W", 0.0, "pack power demand, + discharge"),
        inp("h_conv_w_m2k", "W/(m2.K)", 20.0, "convection coefficient at the cell surface"),
        inp("t_ambient_c", "degC", 25.0, "ambient / coolant temperature"),
        inp("current_cmd_a", "A", 0.0, "pack current command, + discharge (input_mode 'current' only)"),
        out("current_a", "A", 0.0, "pack current, + discharge"),
        out("voltage_v", "V", 0.0, "pack terminal voltage"),
        out("soc_pct", "%", 50.0, "state of charge"),
        out("ocv_v", "V", 0.0, "pack open-circuit voltage"),
        out("t_core_c", "degC", 25.0, "cell core temperature"),
        out("t_surface_c", "degC", 25.0, "cell surface temperature"),
        out("t_mean_c", "degC", 25.0, "cell volume-averaged temperature"),
        out("heat_w", "W", 0.0, "heat generation per cell (5.16), + heating"),
        out("cell_current_meas_a", "A", 0.0, "measured cell current (noisy), + discharge"),
        out("cell_voltage_meas_v", "V", 0.0, "measured cell voltage (noisy)"),
        out("t_surface_meas_c", "degC", 25.0, "measured cell surface temperature (noisy)"),
        out("t_ambient_meas_c", "degC", 25.0, "measured ambient temperature (noisy)"),
        out("loss_energy_j", "J", 0.0, "cumulative overpotential loss int i (V_oc - V_t) dt, pack"),
        out("chem_energy_j", "J", 0.0, "cumulative energy drawn from the OCV int V_oc i dt, pack"),
        out("ah_throughput_ah", "A.h", 0.0, "cumulative int |i| dt, pack"),
        out("clamp_count", "1", 0.0, "steps whose power demand exceeded the pack's capability"),
    )
    STEP_ERRORS = {ERR_NAN_INPUT: "bad input (non-finite, or h_conv_w_m2k < 0)", ERR_SOC_RANGE: "SOC left [0, 100] %"}
    DATA_MUTABLE = (D.st, D.th, D.yv, D.kn, D.st_prev)
    _static = ("name", "params", "tables", "thermal", "_fd_w", "_ns", "_np", "_npack", "_d", "_ix", "_c",
               "_step", "_elec", "_touts", "_fn", "_u_names", "_y_names", "_compiled")

    def __init__(self, name: str = "battery", params: BatteryPackParams | None = None, compiled: bool = True):
        super().__init__(name, params)
        p = self.params
        self.tables = _cell.CellTables(p.ocv_file or None, p.entropy_file or None,
                                       p.discharge_file or None, p.charge_file or None)
        if self.tables._dch.nq != 5:
            raise ScenarioError(f"{name}: ECM tables must have the columns rs_ohm, r1_ohm, c1_f, r2_ohm, c2_f")
        tp = ThermalParams(radius_m=p.radius_m, length_m=p.length_m, density_kg_m3=p.density_kg_m3,
                           cp_j_kgk=p.cp_j_kgk, kt_w_mk=p.kt_w_mk)
        if p.thermal_model == "two_state":
            self.thermal = TwoStateThermal(tp)
            self._fd_w = None
        else:
            self.thermal = FDThermal(tp, n_nodes=30, scheme="fv")
            self._fd_w = np.array([float(v) for v in fd_matrices(tp, 1.0, 30, "fv")[4]])
        self._ns = float(p.n_series)
        self._np = float(p.n_parallel)
        self._npack = self._ns * self._np
        self._d, self._ix = self.tables.packed()
        self._c = _m.pack_params(p)
        self._compiled = compiled
        # the one source, compiled (or its uncompiled reference)
        pick = (lambda f: f) if compiled else (lambda f: getattr(f, "py_func", f))
        self._elec = pick(_m.cell_electrical)
        self._touts = pick(_m.thermal_outputs)
        self.initialize(0.0)

    def step_function(self):
        if self._fd_w is not None:
            return None
        return battery_step if self._compiled else _py(battery_step)

    def fast_reason(self) -> str:
        if self._fd_w is not None:
            return f"component '{self.name}': battery thermal_model 'fd30' has no compiled step"
        if not self._compiled:
            return f"component '{self.name}': battery built with compiled=False"
        return ""

    # -- helpers -------------------------------------------------------------------------
    @property
    def soc(self) -> float:
        """Cell state of charge [1]."""
        return float(self.st[_m.S_SOC])

    @property
    def v1(self) -> float:
        """First RC-branch voltage [V] (cell)."""
        return float(self.st[_m.S_V1])

    @property
    def v2(self) -> float:
        """Second RC-branch voltage [V] (cell)."""
        return float(self.st[_m.S_V2])

    @property
    def x_th(self):
        """Thermal state (two-state ``(T_mean, gamma)`` or the 30 node temperatures)."""
        return (float(self.st[_m.S_X0]), float(self.st[_m.S_X1])) if self._fd_w is None else self._x_fd

    @property
    def i_cell(self) -> float:
        """Cell current of the last step [A], + discharge."""
        return float(self.yv[_m.Y_I])

    def _refill(self, need: int) -> None:
        """Keep at least ``need`` unused draws in ``data`` (the generator's next blocks appended)."""
        noise, kn = self.data[D.noise], self.data[D.kn]
        left = noise.size - int(kn[0])
        if left >= need:
            return
        nb = -(-(need - left) // _NOISE_BLOCK)
        fresh = np.concatenate([noise[int(kn[0]):]] + [self.rng.standard_normal(_NOISE_BLOCK) for _ in range(nb)])
        kn[0] = 0
        self.data = self.data[:D.noise] + (fresh,) + self.data[D.noise + 1:]

    def fast_data(self, data: tuple, n_calls: int) -> tuple:
        """The data of a run of ``n_calls`` steps: the draws of the next ``4 n_calls`` noise values (a pure
        function of the generator's state, shared by the runs of one process)."""
        need = 4 * n_calls
        noise, kn = data[D.noise], data[D.kn]
        if noise.size - int(kn[0]) >= need:
            return data
        key = (pickle.dumps(self.rng.bit_generator.state), noise[int(kn[0]):].tobytes())
        hit = _NOISE_CACHE.get(key)
        if hit is None or hit.size < need:
            rng_ = copy.deepcopy(self.rng)
            left = noise[int(kn[0]):]
            nb = -(-(need - left.size) // _NOISE_BLOCK)
            hit = np.concatenate([left] + [rng_.standard_normal(_NOISE_BLOCK) for _ in range(nb)])
            if len(_NOISE_CACHE) >= 16:
                _NOISE_CACHE.clear()
            _NOISE_CACHE[key] = hit
        kn[0] = 0
        return data[:D.noise] + (hit,) + data[D.noise + 1:]

    # -- contract --------------------------------------------------------------------------
    def defaulted_inputs(self) -> set[str]:
        """The declared defaults plus the drive input the ``input_mode`` does not use."""
        unused = "current_cmd_a" if self.params.input_mode == "power" else "power_w"
        return super().defaulted_inputs() | {unused}

    def initialize(self, t0: float) -> None:
        p = self.params
        st = np.zeros(_m.N_STATE)
        st[_m.S_SOC] = p.soc_init_pct / 100.0
        st[_m.S_X0] = p.t_init_c
        self.st = st
        self._x_fd = self.thermal.initial_state(p.t_init_c) if self._fd_w is not None else None
        self.rng = np.random.default_rng(p.seed)
        yv = np.zeros(_m.N_OUT)
        t_amb, h_conv = self.u["t_ambient_c"], self.u["h_conv_w_m2k"]
        h_eff = _py(_m.effective_h)(self._c, t0, h_conv)     # factor and a convection change already due
        if self._fd_w is None:
            self._touts(self._c, st, t_amb, h_eff, yv)
        else:
            yv[_m.Y_TCORE], yv[_m.Y_TSURF] = self.thermal.outputs(self._x_fd, 0.0, t_amb, h_eff)
            yv[_m.Y_TMEAN] = float(np.dot(self._fd_w, self._x_fd))
        t_look = float(yv[_m.Y_TMEAN]) if p.temperature_dependent else 25.0
        yv[_m.Y_RS] = self.tables.params(float(st[_m.S_SOC]), t_look, 1.0)[0]
        yv[_m.Y_VOC] = self.tables.ocv(float(st[_m.S_SOC]))
        yv[_m.Y_V] = yv[_m.Y_VOC]
        self.yv = yv
        pub = np.array([self._np, self._ns, self._npack, p.current_offset_a, p.sigma_current_a, p.sigma_voltage_v,
                        p.sigma_temperature_c, 1.0 if p.input_mode == "current" else 0.0])
        self.data = (self._d, self._ix, self._c, st, np.full(16, np.nan), yv,
                     self.rng.standard_normal(_NOISE_BLOCK), np.zeros(1, dtype=np.int64), pub, st.copy())
        self._io()
        battery_publish(self.data, t_amb, self._y_arr)
        self.y.update(zip(self._y_names, self._y_arr.tolist()))

    def do_step(self, t: float, h: float) -> None:
        self._refill(4)
        if self._fd_w is None:
            return super().do_step(t, h)
        self._do_step_fd30(t, h)

    def _do_step_fd30(self, t: float, h: float) -> None:
        """The step with the 30-node thermal model (Python; no compiled step)."""
        u = self.u
        p_pack = u["current_cmd_a"] if self.params.input_mode == "current" else u["power_w"]
        h_conv = u["h_conv_w_m2k"]
        t_amb = u["t_ambient_c"]
        if not (math.isfinite(p_pack) and math.isfinite(h_conv) and math.isfinite(t_amb)) or h_conv < 0.0:
            raise SimulationError(self.step_error(ERR_NAN_INPUT, t, h))
        st = self.st
        saved = st.copy()
        x = self._x_fd
        t_mean = float(np.dot(self._fd_w, x))
        q = self._elec(self._d, self._ix, self._c, st, float(p_pack), float(h), t_mean, self.yv)
        h_eff = _py(_m.effective_h)(self._c, t + 0.5 * h, h_conv)
        self._x_fd = self.thermal.step(x, q, t_amb, h_eff, h)
        h_out = _py(_m.effective_h)(self._c, t + h, h_conv)
        self.yv[_m.Y_TCORE], self.yv[_m.Y_TSURF] = self.thermal.outputs(self._x_fd, q, t_amb, h_out)
        self.yv[_m.Y_TMEAN] = float(np.dot(self._fd_w, self._x_fd))
        if not (0.0 <= float(st[_m.S_SOC]) <= 1.0):
            self.data[D.st_prev][:] = st     # the rejected state (the message), the state as it was
            st[:] = saved
            raise SimulationError(self.step_error(ERR_SOC_RANGE, t, h))
        battery_publish(self.data, t_amb, self._y_arr)
        self.y.update(zip(self._y_names, self._y_arr.tolist()))

    def step_error(self, status: int, t: float, h: float) -> str:
        if status == ERR_SOC_RANGE:
            i = float(self.yv[_m.Y_I])
            return (f"{self.name}: SOC left [0, 100] % at t={t + h:.6g} s "
                    f"(soc_pct={100.0 * float(self.data[D.st_prev][_m.S_SOC]):.4g}, pack current {i * self._np:.6g} A)")
        return super().step_error(status, t, h)

U = port_index(BatteryPack.VARIABLES, "input")
Y = port_index(BatteryPack.VARIABLES, "output")


# ------------------------------------------------------------------------------------ the one step
@njit_step
def battery_publish(data, t_amb, y):
    """The outputs at the state in ``data`` (pack scaling, the next four noise draws)."""
    _d, _ix, _c, st, _th, yv, noise, kn, p, _prev = data      # the fields of D
    i = yv[_m.Y_I]
    v = yv[_m.Y_V]
    ts = yv[_m.Y_TSURF]
    k = kn[0]
    kn[0] = k + 4
    y[Y.current_a] = i * p[P.n_parallel]
    y[Y.voltage_v] = v * p[P.n_series]
    y[Y.soc_pct] = 100.0 * st[_m.S_SOC]
    y[Y.ocv_v] = yv[_m.Y_VOC] * p[P.n_series]
    y[Y.t_core_c] = yv[_m.Y_TCORE]
    y[Y.t_surface_c] = ts
    y[Y.t_mean_c] = yv[_m.Y_TMEAN]
    y[Y.heat_w] = yv[_m.Y_Q]
    y[Y.cell_current_meas_a] = i + p[P.current_offset_a] + p[P.sigma_current_a] * noise[k]
    y[Y.cell_voltage_meas_v] = v + p[P.sigma_voltage_v] * noise[k + 1]
    y[Y.t_surface_meas_c] = ts + p[P.sigma_temperature_c] * noise[k + 2]
    y[Y.t_ambient_meas_c] = t_amb + p[P.sigma_temperature_c] * noise[k + 3]
    y[Y.loss_energy_j] = st[_m.S_ELOSS] * p[P.n_pack]
    y[Y.chem_energy_j] = st[_m.S_ECHEM] * p[P.n_pack]
    y[Y.ah_throughput_ah] = st[_m.S_AH] * p[P.n_parallel]
    y[Y.clamp_count] = st[_m.S_CLAMPS]


@njit_step
def battery_step(data, u, y, t, h):
    """:class:`BatteryPack`'s step (two-state thermal model): input check, :func:`shevsim.battery.model.cell_step`,
    the SOC check (the state is left as it was on failure, the rejected one in ``st_prev``), the outputs at
    ``t + h``."""
    d, ix, c, st, th, yv, _noise, _kn, p, prev = data      # the fields of D
    p_pack = u[U.current_cmd_a] if p[P.current_mode] > 0.5 else u[U.power_w]
    h_conv = u[U.h_conv_w_m2k]
    t_amb = u[U.t_ambient_c]
    if not (math.isfinite(p_pack) and math.isfinite(h_conv) and math.isfinite(t_amb)) or h_conv < 0.0:
        return ERR_NAN_INPUT
    for j in range(st.shape[0]):          # element by element: a slice assignment may copy (allocate)
        prev[j] = st[j]
    _m.cell_step(d, ix, c, st, p_pack, t, h, t_amb, h_conv, th, yv)
    if not (0.0 <= st[_m.S_SOC] <= 1.0):
        for j in range(st.shape[0]):      # the state as it was; the rejected one kept in st_prev (the message)
            st[j], prev[j] = prev[j], st[j]
        return ERR_SOC_RANGE
    battery_publish(data, t_amb, y)
    return 0


#: measurement-noise draws per (generator state, unused draws): shared by the runs of one process
_NOISE_CACHE: dict = {}
