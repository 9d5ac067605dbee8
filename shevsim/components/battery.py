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

Speed: with the two-state thermal model the step runs as one numba kernel (:func:`_pack_step_nb`, the
arithmetic of the Python step and of the CellTables lookups in the same order - bit-identical);
``BatteryPack(name, params, compiled=False)`` and the ``fd30`` model use the Python step.

The voltage/current pair reported at t + h is the left limit (current of the finished step,
state at t + h): the pair a BMS sampling at t + h sees.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shevsim.battery import cell as _cell
from shevsim.battery.thermal import FDThermal, ThermalParams, TwoStateThermal, fd_matrices
from shevsim.core.component import Component
from shevsim.core.errors import ScenarioError, SimulationError
from shevsim.core.variables import inp, out

_NOISE_BLOCK = 4096

from shevsim.core.lookup import HAVE_NUMBA, _g2_locate, _njit, _t1_integral, _t1_slope, _t1_value


# ------------------------------------------------------------------------------------------------
# compiled step of the two-state pack (the arithmetic of BatteryPack.do_step and of the CellTables
# lookups in the same order: bit-identical, see tests/unit/test_compiled_kernels.py)
# ------------------------------------------------------------------------------------------------
@_njit(cache=True)
def _pack_step_nb(d, ix, c, thc, soc, v1, v2, x0, x1, p_pack, h, t_amb):  # pragma: no cover - compiled
    """One two-state pack step; ``c = [n_p, n_pack, q_as, current_mode, temperature_dependent,
    entropic_heat, F]``, ``thc`` = ZOH (a00..b11) and output (c00, c01, d0, c10, c11, d1) coefficients.
    Returns ``(i, soc_new, v1n, v2n, x0n, x1n, e_chem, e_loss, q, rs, clamped, voc, v, t_core, t_surf)``."""
    q_as = c[2]
    current_mode = c[3] > 0.5
    p_cell = (p_pack / c[0]) if current_mode else (p_pack / c[1])
    t_mean = x0
    t_look = t_mean if c[4] > 0.5 else 25.0
    # ECM parameters (discharge table for p_cell >= 0)
    if p_cell >= 0.0:
        og, ns, nt = ix[4], ix[5], ix[6]
    else:
        og, ns, nt = ix[7], ix[8], ix[9]
    nq = ix[10]
    i_s, ws = _g2_locate(d, og, ns, soc)
    j_t, wt = _g2_locate(d, og + ns, nt, t_look)
    ov = og + ns + nt
    pa = ov + (j_t * ns + i_s) * nq
    pb = pa + nq
    pc = ov + ((j_t + 1) * ns + i_s) * nq
    pd = pc + nq
    w00 = (1.0 - ws) * (1.0 - wt)
    w01 = ws * (1.0 - wt)
    w10 = (1.0 - ws) * wt
    w11 = ws * wt
    rs = w00 * d[pa] + w01 * d[pb] + w10 * d[pc] + w11 * d[pd]
    r1 = w00 * d[pa + 1] + w01 * d[pb + 1] + w10 * d[pc + 1] + w11 * d[pd + 1]
    c1 = w00 * d[pa + 2] + w01 * d[pb + 2] + w10 * d[pc + 2] + w11 * d[pd + 2]
    r2 = w00 * d[pa + 3] + w01 * d[pb + 3] + w10 * d[pc + 3] + w11 * d[pd + 3]
    c2 = w00 * d[pa + 4] + w01 * d[pb + 4] + w10 * d[pc + 4] + w11 * d[pd + 4]
    oo, no = ix[0], ix[1]
    tau1 = r1 * c1
    tau2 = r2 * c2
    ex1 = math.exp(-h / tau1)
    ex2 = math.exp(-h / tau2)
    g1 = tau1 * (1.0 - ex1)
    g2 = tau2 * (1.0 - ex2)
    a = h * _t1_value(d, oo, no, soc) - v1 * g1 - v2 * g2
    b = h * rs + r1 * (h - g1) + r2 * (h - g2) + 0.5 * h * h * _t1_slope(d, oo, no, soc) / q_as
    clamped = 0
    if current_mode:
        i = p_cell
    else:
        ph = p_cell * h
        disc = a * a - 4.0 * b * ph
        if disc >= 0.0 and a > 0.0:
            i = 2.0 * ph / (a + math.sqrt(disc))
        else:
            i = 0.5 * a / b if a > 0.0 else 0.0
            clamped = 1
    soc_new = soc - i * h / q_as
    vinf = r1 * i
    dd = v1 - vinf
    v1n = vinf + dd * ex1
    iv1 = vinf * h + dd * g1
    iv1s = vinf * vinf * h + 2.0 * vinf * dd * g1 + dd * dd * 0.5 * tau1 * (1.0 - ex1 * ex1)
    vinf = r2 * i
    dd = v2 - vinf
    v2n = vinf + dd * ex2
    iv2 = vinf * h + dd * g2
    iv2s = vinf * vinf * h + 2.0 * vinf * dd * g2 + dd * dd * 0.5 * tau2 * (1.0 - ex2 * ex2)
    e_chem = q_as * (_t1_integral(d, oo, no, soc) - _t1_integral(d, oo, no, soc_new))
    e_loss = i * i * rs * h + i * (iv1 + iv2)
    q = i * i * rs + (iv1s / r1 + iv2s / r2) / h
    if c[5] > 0.5:
        ds = _t1_value(d, ix[2], ix[3], 0.5 * (soc + soc_new))
        q -= i * (t_mean + 273.15) * ds / c[6]
    x0n = thc[0] * x0 + thc[1] * x1 + thc[4] * q + thc[5] * t_amb
    x1n = thc[2] * x0 + thc[3] * x1 + thc[6] * q + thc[7] * t_amb
    voc = _t1_value(d, oo, no, soc_new)
    v = voc - rs * i - v1n - v2n
    t_core = thc[8] * x0n + thc[9] * x1n + thc[10] * t_amb
    t_surf = thc[11] * x0n + thc[12] * x1n + thc[13] * t_amb
    return i, soc_new, v1n, v2n, x0n, x1n, e_chem, e_loss, q, rs, clamped, voc, v, t_core, t_surf


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

    def __post_init__(self) -> None:
        where = "battery parameters"
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
    _static = ("name", "params", "tables", "thermal", "_fd_w", "_ns", "_np", "_npack", "_q_as", "_nb", "_thkey",
               "_thc")

    def __init__(self, name: str = "battery", params: BatteryPackParams | None = None, compiled: bool = True):
        super().__init__(name, params)
        p = self.params
        self.tables = _cell.CellTables(p.ocv_file or None, p.entropy_file or None,
                                       p.discharge_file or None, p.charge_file or None)
        tp = ThermalParams(radius_m=p.radius_m, length_m=p.length_m, density_kg_m3=p.density_kg_m3,
                           cp_j_kgk=p.cp_j_kgk, kt_w_mk=p.kt_w_mk)
        if p.thermal_model == "two_state":
            self.thermal = TwoStateThermal(tp)
            self._fd_w = None
        else:
            self.thermal = FDThermal(tp, n_nodes=30, scheme="fv")
            self._fd_w = [float(v) for v in fd_matrices(tp, 1.0, 30, "fv")[4]]
        self._ns = float(p.n_series)
        self._np = float(p.n_parallel)
        self._npack = self._ns * self._np
        self._q_as = 3600.0 * p.capacity_ah
        # compiled step (numba; two-state thermal model only; bit-identical to the Python step)
        self._nb = None
        if compiled and HAVE_NUMBA and self._fd_w is None and self.tables._dch.nq == 5:
            d, ix = self.tables.packed()
            c = np.array([self._np, self._npack, self._q_as, 1.0 if p.input_mode == "current" else 0.0,
                          1.0 if p.temperature_dependent else 0.0, 1.0 if p.entropic_heat else 0.0,
                          _cell.FARADAY_C_MOL])
            self._nb = (d, ix, c)
        self._thkey = None
        self._thc = None
        self.initialize(0.0)

    # -- helpers -------------------------------------------------------------------------
    def _t_mean(self, x) -> float:
        if self._fd_w is None:
            return x[0]
        return float(np.dot(self._fd_w, x))

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

    def _write_outputs(self, i: float, rs: float, q: float) -> None:
        y = self.y
        p = self.params
        u = self.u
        voc = self.tables.ocv(self.soc)
        v = voc - rs * i - self.v1 - self.v2
        t_amb = u["t_ambient_c"]
        tc, ts = self.thermal.outputs(self.x_th, q, t_amb, u["h_conv_w_m2k"])
        n0, n1, n2, n3 = self._noise4()
        y["current_a"] = i * self._np
        y["voltage_v"] = v * self._ns
        y["soc_pct"] = 100.0 * self.soc
        y["ocv_v"] = voc * self._ns
        y["t_core_c"] = tc
        y["t_surface_c"] = ts
        y["t_mean_c"] = self._t_mean(self.x_th)
        y["heat_w"] = q
        y["cell_current_meas_a"] = i + p.sigma_current_a * n0
        y["cell_voltage_meas_v"] = v + p.sigma_voltage_v * n1
        y["t_surface_meas_c"] = ts + p.sigma_temperature_c * n2
        y["t_ambient_meas_c"] = t_amb + p.sigma_temperature_c * n3
        y["loss_energy_j"] = self.e_loss * self._npack
        y["chem_energy_j"] = self.e_chem * self._npack
        y["ah_throughput_ah"] = self.ah * self._np
        y["clamp_count"] = float(self.clamps)

    # -- contract --------------------------------------------------------------------------
    def initialize(self, t0: float) -> None:
        p = self.params
        self.soc = p.soc_init_pct / 100.0
        self.v1 = 0.0
        self.v2 = 0.0
        self.x_th = self.thermal.initial_state(p.t_init_c)
        self.e_loss = 0.0   # per cell [J]
        self.e_chem = 0.0   # per cell [J]
        self.ah = 0.0       # per cell [A.h]
        self.clamps = 0
        self.i_cell = 0.0
        self.rng = np.random.default_rng(p.seed)
        self._buf = self.rng.standard_normal(_NOISE_BLOCK).tolist()
        self._k = 0
        rs = self.tables.params(self.soc, self._t_lookup(), 1.0)[0]
        self._write_outputs(0.0, rs, 0.0)

    def _t_lookup(self) -> float:
        return self._t_mean(self.x_th) if self.params.temperature_dependent else 25.0

    def _do_step_compiled(self, t: float, h: float, p_pack: float, h_conv: float, t_amb: float) -> None:
        d, ix, c = self._nb
        x0, x1 = self.x_th
        (i, soc_new, v1n, v2n, x0n, x1n, e_chem, e_loss, q, rs, clamped, voc, v, tc, ts) = _pack_step_nb(
            d, ix, c, self._thermal_coeffs(h_conv, h), self.soc, self.v1, self.v2, x0, x1, p_pack, h, t_amb)
        if clamped:
            self.clamps += 1
        if not (0.0 <= soc_new <= 1.0):
            raise SimulationError(f"{self.name}: SOC left [0, 100] % at t={t + h:.6g} s "
                                  f"(soc_pct={100.0 * soc_new:.4g}, pack current {i * self._np:.6g} A)")
        self.x_th = (x0n, x1n)
        self.soc = soc_new
        self.v1 = v1n
        self.v2 = v2n
        self.i_cell = i
        self.e_chem += e_chem
        self.e_loss += e_loss
        self.ah += abs(i) * h / 3600.0
        # outputs (as _write_outputs, with voc, v, t_core, t_surface from the kernel)
        y = self.y
        p = self.params
        n0, n1, n2, n3 = self._noise4()
        y["current_a"] = i * self._np
        y["voltage_v"] = v * self._ns
        y["soc_pct"] = 100.0 * soc_new
        y["ocv_v"] = voc * self._ns
        y["t_core_c"] = tc
        y["t_surface_c"] = ts
        y["t_mean_c"] = x0n
        y["heat_w"] = q
        y["cell_current_meas_a"] = i + p.sigma_current_a * n0
        y["cell_voltage_meas_v"] = v + p.sigma_voltage_v * n1
        y["t_surface_meas_c"] = ts + p.sigma_temperature_c * n2
        y["t_ambient_meas_c"] = t_amb + p.sigma_temperature_c * n3
        y["loss_energy_j"] = self.e_loss * self._npack
        y["chem_energy_j"] = self.e_chem * self._npack
        y["ah_throughput_ah"] = self.ah * self._np
        y["clamp_count"] = float(self.clamps)

    def _thermal_coeffs(self, h_conv: float, h: float):
        """ZOH and output coefficients of the two-state model as one array (kept while h_conv, h hold)."""
        key = (h_conv, h)
        if key != self._thkey:
            self._thc = np.array(self.thermal._coeffs(h_conv, h) + self.thermal._ocoeffs(h_conv))
            self._thkey = key
        return self._thc

    def do_step(self, t: float, h: float) -> None:
        u = self.u
        prm = self.params
        current_mode = prm.input_mode == "current"
        p_pack = u["current_cmd_a"] if current_mode else u["power_w"]
        h_conv = u["h_conv_w_m2k"]
        t_amb = u["t_ambient_c"]
        if not (math.isfinite(p_pack) and math.isfinite(h_conv) and math.isfinite(t_amb)):
            raise SimulationError(f"{self.name}: non-finite input at t={t:.6g} s "
                                  f"({'current_cmd_a' if current_mode else 'power_w'}={p_pack!r}, h_conv_w_m2k={h_conv!r}, t_ambient_c={t_amb!r})")
        if self._nb is not None:
            self._do_step_compiled(t, float(h), float(p_pack), float(h_conv), float(t_amb))
            return
        tab = self.tables
        soc = self.soc
        v1 = self.v1
        v2 = self.v2
        q_as = self._q_as
        p_cell = (p_pack / self._np) if current_mode else (p_pack / self._npack)  # cell current or power
        t_mean = self.x_th[0] if self._fd_w is None else self._t_mean(self.x_th)
        t_look = t_mean if prm.temperature_dependent else 25.0
        rs, r1, c1, r2, c2 = tab.params(soc, t_look, p_cell)
        tau1 = r1 * c1
        tau2 = r2 * c2
        ex1 = math.exp(-h / tau1)
        ex2 = math.exp(-h / tau2)
        g1 = tau1 * (1.0 - ex1)
        g2 = tau2 * (1.0 - ex2)
        a = h * tab.ocv(soc) - v1 * g1 - v2 * g2
        b = h * rs + r1 * (h - g1) + r2 * (h - g2) + 0.5 * h * h * tab.docv_dsoc(soc) / q_as
        if current_mode:
            i = p_cell
        else:
            ph = p_cell * h
            disc = a * a - 4.0 * b * ph
            if disc >= 0.0 and a > 0.0:
                i = 2.0 * ph / (a + math.sqrt(disc))
            else:
                i = 0.5 * a / b if a > 0.0 else 0.0
                self.clamps += 1
        soc_new = soc - i * h / q_as
        if not (0.0 <= soc_new <= 1.0):
            raise SimulationError(f"{self.name}: SOC left [0, 100] % at t={t + h:.6g} s "
                                  f"(soc_pct={100.0 * soc_new:.4g}, pack current {i * self._np:.6g} A)")
        # exact RC-branch integrals over the step (cell.rc_integrals written out, reusing e^{-h/tau})
        vinf = r1 * i
        d = v1 - vinf
        v1n = vinf + d * ex1
        iv1 = vinf * h + d * g1
        iv1s = vinf * vinf * h + 2.0 * vinf * d * g1 + d * d * 0.5 * tau1 * (1.0 - ex1 * ex1)
        vinf = r2 * i
        d = v2 - vinf
        v2n = vinf + d * ex2
        iv2 = vinf * h + d * g2
        iv2s = vinf * vinf * h + 2.0 * vinf * d * g2 + d * d * 0.5 * tau2 * (1.0 - ex2 * ex2)
        e_chem = q_as * (tab.ocv_integral(soc) - tab.ocv_integral(soc_new))
        e_loss = i * i * rs * h + i * (iv1 + iv2)
        q = i * i * rs + (iv1s / r1 + iv2s / r2) / h
        if prm.entropic_heat:
            ds = tab.entropy_change(0.5 * (soc + soc_new))
            q -= i * (t_mean + 273.15) * ds / _cell.FARADAY_C_MOL
        self.x_th = self.thermal.step(self.x_th, q, t_amb, h_conv, h)
        self.soc = soc_new
        self.v1 = v1n
        self.v2 = v2n
        self.i_cell = i
        self.e_chem += e_chem
        self.e_loss += e_loss
        self.ah += abs(i) * h / 3600.0
        self._write_outputs(i, rs, q)
