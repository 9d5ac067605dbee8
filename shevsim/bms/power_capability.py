"""power_capability.py - battery power capability by Algebraic Propagation (seed 4.7-4.19, 5.26-5.36).

For a model ``x_{k+1} = A x_k + B u + G``, ``y = C x + D u + H`` the constant input that puts
the output exactly on its limit ``y_bar`` after N steps is (4.9)
``u_bar = (sum_{i<N} C A^i B + D)^{-1} (y_bar - C A^N x_k - sum_{i<N} C A^i G - H)``.

Electrical side (one cell, OCV-R-RC of the DEKF, current + discharge, 4.14-4.16 / 5.26-5.28)::

    SOC_{k+N} = SOC_k - N dt i / (3600 C_b)
    V_{k+N}   ~ V_oc(SOC_k) - a^N V1_k - i [R_s + R1 (1 - a^N) + V_oc'(SOC_k) N dt / (3600 C_b)]

(``a = exp(-dt/(R1 C1))``; V_oc linearised at SOC_k as in 4.15e - the seed's 5.27c writes
``V_t,k`` for ``V_oc(SOC_k)``, a typo) gives the currents that put SOC on SOC_min / SOC_max and
the terminal voltage on V_min / V_max after N steps.

Thermal side (5.29-5.33): the two-state model (T_mean, gamma) with heat input
``q = mu + V1^2/R1``, ``mu = i^2 R_s - i T_mean Delta S / F``.  With exact ZOH the N-step response
to a held input equals the one-step response over ``N dt``, so ``A^N`` and ``sum_{i<N} A^i B`` are
the ZOH matrices for the step ``N dt`` (closed form, :class:`TwoStateDiscretiser`).  The
polarisation heat is bounded over the horizon by 5.31: ``max(V1_k^2, V1_{k+N}^2)/R1`` with
``V1_{k+N}`` propagated under the previous step's current limit.  Solving ``T_core,k+N =
T_c,max`` for ``mu`` and then ``R_s i^2 - beta i - mu = 0`` (``beta = T_mean Delta S / F``, T in
kelvin) gives 5.33::

    i_T,dch = (beta + sqrt(beta^2 + 4 R_s mu_max)) / (2 R_s),
    i_T,chg = (beta - sqrt(beta^2 + 4 R_s mu_max)) / (2 R_s).

If ``beta^2 + 4 R_s mu_max < 0`` no current keeps T_core at or below the limit; both limits
collapse to the least-heating current ``beta / (2 R_s)``.

``polarisation_heat="exact"`` (the default; ``"seed"`` gives 5.31) replaces the 5.31 bound by the exact
polarisation heat along the horizon: under the held current ``V1_j = a^j V1_k + R1 (1 - a^j) i``,
so with the core-temperature weights ``w_j = C_c A^{N-1-j} B_q`` the predicted
``T_core,k+N`` is an exact quadratic in ``i``::

    [G R_s + R1 (G - 2 S(a) + S(a^2))] i^2 + [-G beta + 2 V1 (S(a) - S(a^2))] i
        + free + V1^2 S(a^2) / R1 = T_c,max,
    G = sum_j w_j,  S(rho) = sum_j w_j rho^j = C_c (A^N - rho^N I)(A - rho I)^{-1} B_q,

solved for its positive (discharge) and negative (charge) roots.  With it the predicted core
temperature lands on T_c,max instead of below it (the 5.31 bound is conservative by up to
~1 K for a 10 s horizon at tens of amperes).

Limits (4.17 / 5.34): ``i_max = min(SOC_min, V_min, thermal[, rating])``,
``i_min = max(SOC_max, V_max, thermal[, rating])``; power (4.18-4.19 / 5.35-5.36):
``P = i V_{k+N}`` with ``V_{k+N}`` from the (nonlinear) OCV at the predicted SOC, times the
pack's ``n_s n_p``; reported as ``p_max_w = max(P_dch, 0)`` and ``p_min_w = min(P_chg, 0)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from shevsim.battery.cell import FARADAY_C_MOL, CellTables, default_tables
from shevsim.battery.thermal import ThermalParams
from shevsim.core.lookup import HAVE_NUMBA, _njit, _t1_slope, _t1_value
from shevsim.bms.thermal_estimators import TwoStateDiscretiser
from shevsim.core.errors import ScenarioError

__all__ = ["PowerCapabilityParams", "PowerLimits", "PowerCapability", "electrical_current_limits"]


@dataclass(frozen=True)
class PowerCapabilityParams:
    """Constraints and horizon (seed Table A.1 limits, Sec. 4.4/5.4).

    Attributes
    ----------
    horizon_steps : int
        N (seed Ch. IV: 10 s at 10 Hz -> 100).
    dt_s : float
        BMS sample time [s].
    soc_min_frac, soc_max_frac : float
        SOC limits (Table A.1: 0.3, 0.7).
    v_min_v, v_max_v : float
        Cell voltage limits [V] (Table A.1: 2.0, 3.6).
    t_core_max_c : float
        Core temperature limit [degC] (Sec. 5.4: 45).
    i_cell_max_a : float
        Optional cell current rating [A] in both directions (default inf: not in the seed).
    polarisation_heat : str
        ``"seed"`` (5.31 bound) or ``"exact"`` (exact V1 trajectory, see module docstring).
    capacity_ah : float
        Cell capacity [A.h].
    n_series, n_parallel : int
        Pack configuration for the pack power.
    """

    horizon_steps: int = 100
    dt_s: float = 0.1
    soc_min_frac: float = 0.3
    soc_max_frac: float = 0.7
    v_min_v: float = 2.0
    v_max_v: float = 3.6
    t_core_max_c: float = 45.0
    i_cell_max_a: float = math.inf
    capacity_ah: float = 2.3
    n_series: int = 130
    n_parallel: int = 10
    polarisation_heat: str = "exact"

    def __post_init__(self) -> None:
        if self.polarisation_heat not in ("seed", "exact"):
            raise ScenarioError(f"power capability: polarisation_heat must be 'seed' or 'exact', "
                                f"got {self.polarisation_heat!r}")
        if self.horizon_steps < 1 or not self.dt_s > 0.0:
            raise ScenarioError("power capability: horizon_steps must be >= 1 and dt_s > 0")
        if not (self.soc_min_frac < self.soc_max_frac and self.v_min_v < self.v_max_v):
            raise ScenarioError("power capability: need soc_min < soc_max and v_min < v_max")


class PowerLimits(NamedTuple):
    """Result of one power-capability evaluation (cell currents [A], pack powers [W])."""

    i_max_a: float          # cell discharge current limit (overall, 5.34a)
    i_min_a: float          # cell charge current limit (overall, 5.34b)
    p_max_w: float          # pack discharge power limit >= 0
    p_min_w: float          # pack charge power limit <= 0
    i_soc_min_a: float
    i_soc_max_a: float
    i_v_min_a: float
    i_v_max_a: float
    i_t_dch_a: float
    i_t_chg_a: float
    v_dch_v: float          # predicted cell voltage after N steps at i_max
    v_chg_v: float          # predicted cell voltage after N steps at i_min


def electrical_current_limits(soc: float, v1: float, rs: float, r1: float, c1: float, p: PowerCapabilityParams,
                              tables: CellTables):
    """``(i_soc_min, i_soc_max, i_v_min, i_v_max)`` [A], seed 5.28 (cell, + discharge)."""
    n = p.horizon_steps
    ndt = n * p.dt_s
    q_as = 3600.0 * p.capacity_ah
    i_soc_min = (soc - p.soc_min_frac) * q_as / ndt
    i_soc_max = (soc - p.soc_max_frac) * q_as / ndt
    aN = math.exp(-ndt / (r1 * c1))
    gain = rs + r1 * (1.0 - aN) + tables.docv_dsoc(soc) * ndt / q_as
    free = tables.ocv(soc) - aN * v1
    return i_soc_min, i_soc_max, (free - p.v_min_v) / gain, (free - p.v_max_v) / gain


_CACHE_MAX = 16384
_CACHES: dict = {}


class _SharedCache(dict):
    """A memo of a pure function: shared, never copied with the owner's state."""

    def __deepcopy__(self, memo):
        return self

    def __copy__(self):
        return self


def _coeff_cache(key) -> _SharedCache:
    c = _CACHES.get(key)
    if c is None:
        c = _CACHES[key] = _SharedCache()
    return c


# ---------------------------------------------------------------------------------------------
# compiled compute(): the arithmetic of electrical_current_limits, thermal_current_limits,
# _exact_limits and voltage_after in the same order (bit-identical; pow via libm as CPython's **)
# ---------------------------------------------------------------------------------------------
def _pole_sum(rho, e00, e01, e10, e11, bq0, bq1, n00, n01, n10, n11, cc0, cc1, n):
    """``C_c (A^N - rho^N I) (A - rho I)^{-1} B_q`` of the 2x2 thermal model (``n`` = float(N));
    the removable singularity at ``rho = eig(A)`` is stepped around."""
    d00 = e00 - rho
    d11 = e11 - rho
    det = d00 * d11 - e01 * e10
    if abs(det) < 1e-13:
        rho *= 1.0 - 1e-6
        d00 = e00 - rho
        d11 = e11 - rho
        det = d00 * d11 - e01 * e10
    v0 = (d11 * bq0 - e01 * bq1) / det
    v1_ = (-e10 * bq0 + d00 * bq1) / det
    rn = math.pow(rho, n)
    return cc0 * (n00 * v0 + n01 * v1_ - rn * v0) + cc1 * (n10 * v0 + n11 * v1_ - rn * v1_)


_pole_sum_nb = _njit(cache=True)(_pole_sum)


@_njit(cache=True)
def _compute_nb(d, ix, k, th, soc, v1, rs, r1, c1, t_mean_c, gamma, t_amb_c, last_max, last_min):  # pragma: no cover
    """``k = [N, dt, soc_min, soc_max, v_min, v_max, t_core_max, i_cell_max, capacity_ah, n_pack,
    exact, F, float(N)]``; ``th`` = the 17 thermal coefficients of ``_thermal_coeffs``."""
    n = k[0]
    dt = k[1]
    oo = ix[0]
    no = ix[1]
    # electrical_current_limits
    ndt = n * dt
    q_as = 3600.0 * k[8]
    i_smin = (soc - k[2]) * q_as / ndt
    i_smax = (soc - k[3]) * q_as / ndt
    aN = math.exp(-ndt / (r1 * c1))
    gain = rs + r1 * (1.0 - aN) + _t1_slope(d, oo, no, soc) * ndt / q_as
    free = _t1_value(d, oo, no, soc) - aN * v1
    i_vmin = (free - k[4]) / gain
    i_vmax = (free - k[5]) / gain
    # thermal_current_limits
    a00 = th[0]
    a01 = th[1]
    a10 = th[2]
    a11 = th[3]
    b00 = th[4]
    b01 = th[5]
    b10 = th[6]
    b11 = th[7]
    cc0 = th[8]
    cc1 = th[9]
    dc = th[10]
    free = (cc0 * (a00 * t_mean_c + a01 * gamma + b01 * t_amb_c)
            + cc1 * (a10 * t_mean_c + a11 * gamma + b11 * t_amb_c) + dc * t_amb_c)
    gq = cc0 * b00 + cc1 * b10
    beta = (t_mean_c + 273.15) * _t1_value(d, ix[2], ix[3], soc) / k[11]
    if k[10] > 0.5:
        e00 = th[11]
        e01 = th[12]
        e10 = th[13]
        e11 = th[14]
        bq0 = th[15]
        bq1 = th[16]
        a = math.exp(-dt / (r1 * c1))
        s1 = _pole_sum_nb(a, e00, e01, e10, e11, bq0, bq1, a00, a01, a10, a11, cc0, cc1, k[12])
        s2 = _pole_sum_nb(a * a, e00, e01, e10, e11, bq0, bq1, a00, a01, a10, a11, cc0, cc1, k[12])
        qa = gq * rs + r1 * (gq - 2.0 * s1 + s2)
        qb = -gq * beta + 2.0 * v1 * (s1 - s2)
        qc = free + v1 * v1 * s2 / r1 - k[6]
        disc = qb * qb - 4.0 * qa * qc
        if disc < 0.0:
            i_td = -qb / (2.0 * qa)
            i_tc = i_td
        else:
            sq = math.sqrt(disc)
            i_td = (-qb + sq) / (2.0 * qa)
            i_tc = (-qb - sq) / (2.0 * qa)
    else:
        v1n = aN * v1 + r1 * (1.0 - aN) * last_max
        q_pol = max(v1 * v1, v1n * v1n) / r1
        mu_d = (k[6] - free - gq * q_pol) / gq
        v1n = aN * v1 + r1 * (1.0 - aN) * last_min
        q_pol = max(v1 * v1, v1n * v1n) / r1
        mu_c = (k[6] - free - gq * q_pol) / gq
        disc_d = beta * beta + 4.0 * rs * mu_d
        disc_c = beta * beta + 4.0 * rs * mu_c
        i_min_heat = beta / (2.0 * rs)
        i_td = (beta + math.sqrt(disc_d)) / (2.0 * rs) if disc_d >= 0.0 else i_min_heat
        i_tc = (beta - math.sqrt(disc_c)) / (2.0 * rs) if disc_c >= 0.0 else i_min_heat
    # compute()
    i_max = min(i_smin, i_vmin, i_td, k[7])
    i_min = max(i_smax, i_vmax, i_tc, -k[7])
    soc_n = soc - i_max * ndt / (3600.0 * k[8])
    v_d = _t1_value(d, oo, no, soc_n) - i_max * rs - aN * v1 - i_max * r1 * (1.0 - aN)
    soc_n = soc - i_min * ndt / (3600.0 * k[8])
    v_c = _t1_value(d, oo, no, soc_n) - i_min * rs - aN * v1 - i_min * r1 * (1.0 - aN)
    p_max = i_max * v_d * k[9]
    p_min = i_min * v_c * k[9]
    return (i_max, i_min, p_max if p_max > 0.0 else 0.0, p_min if p_min < 0.0 else 0.0,
            i_smin, i_smax, i_vmin, i_vmax, i_td, i_tc, v_d, v_c)


class PowerCapability:
    """Algebraic-Propagation power capability with electrical and thermal constraints.

    Parameters
    ----------
    params : PowerCapabilityParams
    thermal_params : ThermalParams
        Cell thermal parameters of the two-state model.
    tables : CellTables
        OCV and entropy tables.
    compiled : bool
        Run :meth:`compute` as one numba kernel (:func:`_compute_nb`, the same arithmetic, bit-identical;
        default) or in Python.

    Notes
    -----
    :meth:`compute` keeps the last current limits (for the 5.31 polarisation-heat bound), so one
    instance belongs to one BMS; ``last_i_max_a`` / ``last_i_min_a`` are part of its state.
    """

    def __init__(self, params: PowerCapabilityParams | None = None, thermal_params: ThermalParams | None = None,
                 tables: CellTables | None = None, compiled: bool = True):
        self.params = params if params is not None else PowerCapabilityParams()
        self.thermal_params = thermal_params if thermal_params is not None else ThermalParams()
        self.tables = tables if tables is not None else default_tables()
        p = self.params
        self._discN = TwoStateDiscretiser(self.thermal_params, p.horizon_steps * p.dt_s, "zoh")
        self._disc1 = TwoStateDiscretiser(self.thermal_params, p.dt_s, "zoh")
        # thermal coefficients per (rounded) h: a pure function of h and the constants, shared by
        # every instance with the same constants and not part of the state (not deep-copied)
        self._hcache = _coeff_cache((self.thermal_params, p.horizon_steps, p.dt_s))
        self._hcache_nb = _coeff_cache(("array", self.thermal_params, p.horizon_steps, p.dt_s))
        self._exact = p.polarisation_heat == "exact"
        self._npack = float(p.n_series * p.n_parallel)
        # compiled compute() (numba; same arithmetic, bit-identical); compiled=False for the Python path
        self.compiled = bool(compiled and HAVE_NUMBA)
        if self.compiled:
            import numpy as np
            self._tabs = self.tables.packed()
            self._k = np.array([p.horizon_steps, p.dt_s, p.soc_min_frac, p.soc_max_frac, p.v_min_v, p.v_max_v,
                                p.t_core_max_c, p.i_cell_max_a, p.capacity_ah, self._npack,
                                1.0 if self._exact else 0.0, FARADAY_C_MOL, float(p.horizon_steps)])
        self.last_i_max_a = 0.0
        self.last_i_min_a = 0.0

    def _thermal_coeffs(self, h_w_m2k: float) -> tuple:
        """``ZOH(N dt) (8), C_core/D_core (3), ZOH(dt) A and B_q (6)`` at ``h_w_m2k`` (cached)."""
        c = self._hcache.get(h_w_m2k)
        if c is None:
            _, _, _, cc0, cc1, dc = self._discN.out(h_w_m2k)
            e00, e01, e10, e11, bq0, _, bq1, _ = self._disc1._zoh(h_w_m2k)
            c = self._discN._zoh(h_w_m2k) + (cc0, cc1, dc, e00, e01, e10, e11, bq0, bq1)
            if len(self._hcache) >= _CACHE_MAX:
                self._hcache.clear()
            self._hcache[h_w_m2k] = c
        return c

    def thermal_current_limits(self, soc: float, v1: float, rs: float, r1: float, c1: float,
                               t_mean_c: float, gamma: float, h_w_m2k: float, t_amb_c: float):
        """``(i_t_dch, i_t_chg)`` [A] keeping the predicted core temperature <= T_c,max after N steps."""
        p = self.params
        ndt = p.horizon_steps * p.dt_s
        # the estimated h changes a little every step: evaluate the thermal matrices at h rounded to
        # 1e-3 W/m^2/K (closed-form ZOH, cached per rounded h; the effect on T_core is ~1e-5 K)
        h_w_m2k = round(h_w_m2k, 3)
        a00, a01, a10, a11, b00, b01, b10, b11, cc0, cc1, dc, e00, e01, e10, e11, bq0, bq1 = \
            self._thermal_coeffs(h_w_m2k)
        # free response of the core temperature (mu = 0, no polarisation heat)
        free = (cc0 * (a00 * t_mean_c + a01 * gamma + b01 * t_amb_c)
                + cc1 * (a10 * t_mean_c + a11 * gamma + b11 * t_amb_c) + dc * t_amb_c)
        gq = cc0 * b00 + cc1 * b10            # sum_i C A^i B_q  (> 0)
        beta = (t_mean_c + 273.15) * self.tables.entropy_change(soc) / FARADAY_C_MOL
        if self._exact:
            return self._exact_limits(v1, rs, r1, c1, beta, free, gq, h_w_m2k,
                                      (a00, a01, a10, a11), (cc0, cc1), (e00, e01, e10, e11, bq0, bq1))
        aN = math.exp(-ndt / (r1 * c1))
        out = []
        for i_prev in (self.last_i_max_a, self.last_i_min_a):
            v1n = aN * v1 + r1 * (1.0 - aN) * i_prev
            q_pol = max(v1 * v1, v1n * v1n) / r1          # 5.31
            mu = (p.t_core_max_c - free - gq * q_pol) / gq
            out.append(mu)
        mu_d, mu_c = out
        disc_d = beta * beta + 4.0 * rs * mu_d
        disc_c = beta * beta + 4.0 * rs * mu_c
        i_min_heat = beta / (2.0 * rs)
        i_t_dch = (beta + math.sqrt(disc_d)) / (2.0 * rs) if disc_d >= 0.0 else i_min_heat
        i_t_chg = (beta - math.sqrt(disc_c)) / (2.0 * rs) if disc_c >= 0.0 else i_min_heat
        return i_t_dch, i_t_chg

    def _exact_limits(self, v1, rs, r1, c1, beta, free, g, h_w_m2k, an, cc, e1=None):
        p = self.params
        n = p.horizon_steps
        e00, e01, e10, e11, bq0, bq1 = e1 if e1 is not None else self._thermal_coeffs(h_w_m2k)[11:]
        n00, n01, n10, n11 = an
        cc0, cc1 = cc
        a = math.exp(-p.dt_s / (r1 * c1))
        # S(rho) = C_c (A^N - rho^N I) (A - rho I)^{-1} B_q for rho = a and a^2
        s1 = _pole_sum(a, e00, e01, e10, e11, bq0, bq1, n00, n01, n10, n11, cc0, cc1, float(n))
        s2 = _pole_sum(a * a, e00, e01, e10, e11, bq0, bq1, n00, n01, n10, n11, cc0, cc1, float(n))
        qa = g * rs + r1 * (g - 2.0 * s1 + s2)
        qb = -g * beta + 2.0 * v1 * (s1 - s2)
        qc = free + v1 * v1 * s2 / r1 - p.t_core_max_c
        disc = qb * qb - 4.0 * qa * qc
        if disc < 0.0:
            i0 = -qb / (2.0 * qa)
            return i0, i0
        sq = math.sqrt(disc)
        return (-qb + sq) / (2.0 * qa), (-qb - sq) / (2.0 * qa)

    def voltage_after(self, i_a: float, soc: float, v1: float, rs: float, r1: float, c1: float) -> float:
        """Predicted cell terminal voltage after N steps at the held current (5.36) [V]."""
        p = self.params
        ndt = p.horizon_steps * p.dt_s
        aN = math.exp(-ndt / (r1 * c1))
        soc_n = soc - i_a * ndt / (3600.0 * p.capacity_ah)
        return self.tables.ocv(soc_n) - i_a * rs - aN * v1 - i_a * r1 * (1.0 - aN)

    def compute(self, soc: float, v1: float, rs: float, r1: float, c1: float, t_mean_c: float, gamma: float,
                h_w_m2k: float, t_amb_c: float) -> PowerLimits:
        """Current and power limits from the estimated states (SOC as a fraction, cell quantities)."""
        if self.compiled:
            hr = round(h_w_m2k, 3)
            th = self._hcache_nb.get(hr)
            if th is None:
                import numpy as np
                th = np.array(self._thermal_coeffs(hr))
                if len(self._hcache_nb) >= _CACHE_MAX:
                    self._hcache_nb.clear()
                self._hcache_nb[hr] = th
            d, ix = self._tabs
            r = _compute_nb(d, ix, self._k, th, float(soc), float(v1), float(rs), float(r1), float(c1),
                            float(t_mean_c), float(gamma), float(t_amb_c), self.last_i_max_a, self.last_i_min_a)
            self.last_i_max_a = r[0]
            self.last_i_min_a = r[1]
            return PowerLimits(*r)
        p = self.params
        i_smin, i_smax, i_vmin, i_vmax = electrical_current_limits(soc, v1, rs, r1, c1, p, self.tables)
        i_td, i_tc = self.thermal_current_limits(soc, v1, rs, r1, c1, t_mean_c, gamma, h_w_m2k, t_amb_c)
        i_max = min(i_smin, i_vmin, i_td, p.i_cell_max_a)
        i_min = max(i_smax, i_vmax, i_tc, -p.i_cell_max_a)
        v_d = self.voltage_after(i_max, soc, v1, rs, r1, c1)
        v_c = self.voltage_after(i_min, soc, v1, rs, r1, c1)
        p_max = i_max * v_d * self._npack
        p_min = i_min * v_c * self._npack
        self.last_i_max_a = i_max
        self.last_i_min_a = i_min
        return PowerLimits(i_max, i_min, p_max if p_max > 0.0 else 0.0, p_min if p_min < 0.0 else 0.0,
                           i_smin, i_smax, i_vmin, i_vmax, i_td, i_tc, v_d, v_c)
