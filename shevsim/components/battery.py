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
step) and compiled there; this class only packs the parameters, holds the state and publishes outputs.
``BatteryPack(name, params, compiled=False)`` runs the same functions uncompiled (``.py_func``).  The
``fd30`` thermal model steps the same electrical function and the 30-node model of
:mod:`shevsim.battery.thermal`.

Effects (model terms switched by parameters; the defaults reproduce the plain model): see the table in
:mod:`shevsim.battery.model` - ``dudt_soc_frac``/``dudt_v_k`` (entropic heat dU/dT(SOC)),
``arrhenius_ea_r_k``, ``h_change_time_s``/``h_change_factor``/``h_change_width_s`` (convection change),
``hyst_max_v``/``hyst_rate``, ``capacity_ah``, ``current_offset_a``, ``lowsoc_r_gain``/``lowsoc_r_scale_frac``,
``r2_scale`` (0 removes the second RC branch); scale factors ``rs_scale, r1_scale, c1_scale, r2_scale,
c2_scale`` on the ECM tables and ``h_conv_factor`` on the convection input.

The voltage/current pair reported at t + h is the left limit (current of the finished step,
state at t + h): the pair a BMS sampling at t + h sees.
"""
from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass

import numpy as np

from shevsim.battery import cell as _cell
from shevsim.battery import model as _m
from shevsim.battery.thermal import FDThermal, ThermalParams, TwoStateThermal, fd_matrices
from shevsim.core.component import Component
from shevsim.core.errors import ScenarioError, SimulationError
from shevsim.core.params import rng
from shevsim.core.variables import inp, out

_NOISE_BLOCK = 4096


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
        Low-SOC resistance rise ``x (1 + g exp(-SOC/s))`` [1], [1]; gain 0 = off.
    dudt_soc_frac, dudt_v_k : list of float
        Entropic coefficient dU/dT [V/K] at SOC knots [1] (piecewise linear, clamped); when given it
        replaces the entropy table (and acts whatever ``entropic_heat`` says); empty = off.
    h_conv_factor : float
        Factor [1] on the convection input ``h_conv_w_m2k``.
    h_change_time_s, h_change_factor, h_change_width_s : float
        Convection change: ``h`` times ``h_change_factor`` after ``h_change_time_s`` [s], logistic over
        ``h_change_width_s`` [s] (0: a step); factor 1 = off.
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
        for f in ("r2_scale", "arrhenius_ea_r_k", "hyst_rate", "lowsoc_r_gain", "h_change_width_s"):
            if getattr(self, f) < 0.0:
                raise ScenarioError(f"{where}: {f} must be >= 0, got {getattr(self, f)!r}")
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


class BatteryPack(Component):
    """Battery pack plant: OCV-R-RC-RC cells with a radial thermal model (see module docstring)."""

    TYPE = "battery"
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
    _static = ("name", "params", "tables", "thermal", "_fd_w", "_ns", "_np", "_npack", "_d", "_ix", "_c",
               "_step", "_elec", "_touts")

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
        # the one source, compiled (or its uncompiled reference)
        pick = (lambda f: f) if compiled else (lambda f: getattr(f, "py_func", f))
        self._step = pick(_m.cell_step)
        self._elec = pick(_m.cell_electrical)
        self._touts = pick(_m.thermal_outputs)
        self.initialize(0.0)

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

    def _noise(self) -> float:
        k = self._k
        if k >= _NOISE_BLOCK:
            self._buf = self.rng.standard_normal(_NOISE_BLOCK).tolist()
            k = 0
        self._k = k + 1
        return self._buf[k]

    def _noise4(self):
        """The next four draws of :meth:`_noise` (the same sequence, one slice when possible)."""
        k = self._k
        if k + 4 <= _NOISE_BLOCK:
            self._k = k + 4
            return self._buf[k:k + 4]
        return [self._noise(), self._noise(), self._noise(), self._noise()]

    def _publish(self, t_amb: float) -> None:
        yv = self.yv
        st = self.st
        y = self.y
        p = self.params
        i = float(yv[_m.Y_I])
        v = float(yv[_m.Y_V])
        ts = float(yv[_m.Y_TSURF])
        n0, n1, n2, n3 = self._noise4()
        y["current_a"] = i * self._np
        y["voltage_v"] = v * self._ns
        y["soc_pct"] = 100.0 * float(st[_m.S_SOC])
        y["ocv_v"] = float(yv[_m.Y_VOC]) * self._ns
        y["t_core_c"] = float(yv[_m.Y_TCORE])
        y["t_surface_c"] = ts
        y["t_mean_c"] = float(yv[_m.Y_TMEAN])
        y["heat_w"] = float(yv[_m.Y_Q])
        y["cell_current_meas_a"] = i + p.current_offset_a + p.sigma_current_a * n0
        y["cell_voltage_meas_v"] = v + p.sigma_voltage_v * n1
        y["t_surface_meas_c"] = ts + p.sigma_temperature_c * n2
        y["t_ambient_meas_c"] = t_amb + p.sigma_temperature_c * n3
        y["loss_energy_j"] = float(st[_m.S_ELOSS]) * self._npack
        y["chem_energy_j"] = float(st[_m.S_ECHEM]) * self._npack
        y["ah_throughput_ah"] = float(st[_m.S_AH]) * self._np
        y["clamp_count"] = float(st[_m.S_CLAMPS])

    # -- contract --------------------------------------------------------------------------
    def initialize(self, t0: float) -> None:
        p = self.params
        st = np.zeros(_m.N_STATE)
        st[_m.S_SOC] = p.soc_init_pct / 100.0
        st[_m.S_X0] = p.t_init_c
        self.st = st
        self._x_fd = self.thermal.initial_state(p.t_init_c) if self._fd_w is not None else None
        self.rng = np.random.default_rng(p.seed)
        self._buf = self.rng.standard_normal(_NOISE_BLOCK).tolist()
        self._k = 0
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
        self._th = np.full(16, np.nan)     # thermal-coefficient cache of the compiled step
        self._publish(t_amb)

    @property
    def i_cell(self) -> float:
        """Cell current of the last step [A], + discharge."""
        return float(self.yv[_m.Y_I])

    def do_step(self, t: float, h: float) -> None:
        u = self.u
        current_mode = self.params.input_mode == "current"
        p_pack = u["current_cmd_a"] if current_mode else u["power_w"]
        h_conv = u["h_conv_w_m2k"]
        t_amb = u["t_ambient_c"]
        if not (math.isfinite(p_pack) and math.isfinite(h_conv) and math.isfinite(t_amb)) or h_conv < 0.0:
            raise SimulationError(f"{self.name}: bad input at t={t:.6g} s "
                                  f"({'current_cmd_a' if current_mode else 'power_w'}={p_pack!r}, "
                                  f"h_conv_w_m2k={h_conv!r} (finite, >= 0), t_ambient_c={t_amb!r})")
        st = self.st
        saved = st.copy()
        if self._fd_w is None:
            self._step(self._d, self._ix, self._c, st, float(p_pack), float(t), float(h), float(t_amb),
                       float(h_conv), self._th, self.yv)
        else:
            x = self._x_fd
            t_mean = float(np.dot(self._fd_w, x))
            q = self._elec(self._d, self._ix, self._c, st, float(p_pack), float(h), t_mean, self.yv)
            h_eff = _py(_m.effective_h)(self._c, t + 0.5 * h, h_conv)
            self._x_fd = self.thermal.step(x, q, t_amb, h_eff, h)
            h_out = _py(_m.effective_h)(self._c, t + h, h_conv)
            self.yv[_m.Y_TCORE], self.yv[_m.Y_TSURF] = self.thermal.outputs(self._x_fd, q, t_amb, h_out)
            self.yv[_m.Y_TMEAN] = float(np.dot(self._fd_w, self._x_fd))
        soc_new = float(st[_m.S_SOC])
        if not (0.0 <= soc_new <= 1.0):
            i = float(self.yv[_m.Y_I])
            self.st = saved
            raise SimulationError(f"{self.name}: SOC left [0, 100] % at t={t + h:.6g} s "
                                  f"(soc_pct={100.0 * soc_new:.4g}, pack current {i * self._np:.6g} A)")
        self._publish(t_amb)
