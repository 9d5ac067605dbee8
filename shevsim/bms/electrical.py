"""electrical.py - Dual Extended Kalman Filter for the cell's electrical side (seed 5.12-5.25).

Control-oriented model (OCV-R-RC, seed 5.12-5.13), one cell, current ``i`` + discharge::

    SOC_{k+1} = SOC_k - dt i_k / (3600 C_b)
    V1_{k+1}  = a V1_k + R1 (1 - a) i_k,        a = exp(-dt / (R1 C1))
    V_t,k     = V_oc(SOC_k) - V1_k - R_s i_k

Grouping (5.18): Omega_1 = {SOC, V1, R_s} is the augmented state x (R_s a random walk, 5.19),
Omega_2 = {R1, C1} the parameter theta of a second EKF.  One step k (5.21-5.24):

1. parameter time update ``theta^- = theta^+``, ``P_theta^- = P_theta^+ + Sigma_r``;
2. state time update ``x^- = f(x^+, i, theta^-)``, ``P_x^- = A P_x^+ A^T + Sigma_w`` with
   ``A = df/dx = diag(1, a, 1)``;
3. state measurement update with ``C^x = dg/dx = [dV_oc/dSOC, -1, -i]`` and the innovation
   ``e = y - g(x^-, i)``;
4. parameter measurement update with the same innovation and
   ``C^theta = dV_t/dtheta`` (5.17d-e, with the exponent's sign corrected: the seed prints
   ``e^{+dt/(R1 C1)}``; the derivative of ``a = e^{-dt/(R1 C1)}`` is
   ``da/dR1 = a dt/(R1^2 C1)``, ``da/dC1 = a dt/(R1 C1^2)``)::

       dV_t/dR1 = -(da/dR1) (V1_{k-1} - R1 i_{k-1}) - (1 - a) i_{k-1}
       dV_t/dC1 = -(da/dC1) (V1_{k-1} - R1 i_{k-1})

The input is sampled with the plant's zero-order hold: the current measured at k (the current
that flowed over [k-1, k]) drives the time update into k and the output at k, so
``u_{k-1} = u_k = i_k`` here.

Defaults are seed Table 5.4 (Sigma_w = diag(6e-3, 2e-2, 8e-6), Sigma_v = 1, P(0) = I,
S(0) = diag(0.1, 0.1)), SOC as a fraction.  Sigma_r is printed diag(2.5e8, 4e-1); a random
walk of variance 2.5e8 Ohm^2 per step on R1 is not physical, so the default reads it as
2.5e-8 (a dropped minus sign).  Only the ratios to Sigma_v matter to a Kalman filter, so
Sigma_v = 1 is a scaling, not the sensor's variance.

Everything is plain Python floats (3x3 and 2x2 symmetric covariances unrolled).  ``DEKF(compiled=True)``
(default) runs the same arithmetic as one numba kernel (:func:`_dekf_step_nb`, bit-identical);
:meth:`DEKF.step_heat` is the step followed by the heat estimate (5.16) in one call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from shevsim.battery.cell import FARADAY_C_MOL, CellTables, default_tables
from shevsim.battery.table_kernels import HAVE_NUMBA, _njit, _t1_slope, _t1_value
from shevsim.core.errors import SimulationError

__all__ = ["DEKFParams", "DEKF"]


@dataclass(frozen=True)
class DEKFParams:
    """Tuning and initial values of the electrical DEKF (seed Table 5.4 defaults).

    Attributes
    ----------
    capacity_ah : float
        Cell capacity C_b [A.h].
    soc0_frac, v1_0_v, rs0_ohm, r1_0_ohm, c1_0_f : float
        Initial estimates.
    q_soc, q_v1, q_rs : float
        Sigma_w diagonal (process noise of SOC [frac^2], V1 [V^2], R_s [Ohm^2] per step).
    r_v : float
        Sigma_v (output noise variance in the filter's scaling).
    q_r1, q_c1 : float
        Sigma_r diagonal (random walk of R1 [Ohm^2], C1 [F^2] per step).
    p0_soc, p0_v1, p0_rs : float
        P(0) diagonal.
    s0_r1, s0_c1 : float
        S(0) diagonal (initial parameter covariance).
    r1_min_ohm, r1_max_ohm, c1_min_f, c1_max_f, rs_min_ohm : float
        Physical bounds the estimates are kept in.
    """

    capacity_ah: float = 2.3
    soc0_frac: float = 0.5
    v1_0_v: float = 0.0
    rs0_ohm: float = 0.010
    r1_0_ohm: float = 0.014
    c1_0_f: float = 2000.0
    q_soc: float = 6e-3
    q_v1: float = 2e-2
    q_rs: float = 8e-6
    r_v: float = 1.0
    q_r1: float = 2.5e-8
    q_c1: float = 4e-1
    p0_soc: float = 1.0
    p0_v1: float = 1.0
    p0_rs: float = 1.0
    s0_r1: float = 1e-1
    s0_c1: float = 1e-1
    r1_min_ohm: float = 1e-4
    r1_max_ohm: float = 1.0
    c1_min_f: float = 10.0
    c1_max_f: float = 1e6
    rs_min_ohm: float = 1e-5


@_njit(cache=True)
def _dekf_step_nb(d, ix, k, soc0, v1_prev, rs, r1, c1, p00, p01, p02, p11, p12, p22, s00, s01, s11,
                  i_a, v_meas_v, dt_s, t_mean_c):  # pragma: no cover - compiled
    """DEKF.step (and DEKF.heat at the new estimates) with the same arithmetic; ``k = [capacity_ah,
    q_soc, q_v1, q_rs, r_v, q_r1, q_c1, r1_min, r1_max, c1_min, c1_max, rs_min, F]``.  Returns
    ``(ok, soc, v1, rs, r1, c1, p00, p01, p02, p11, p12, p22, s00, s01, s11, e, heat)``; ``ok = 0`` when
    the innovation variance is unusable (the caller re-runs the Python step, which raises)."""
    s00 += k[5]
    s11 += k[6]
    tau = r1 * c1
    a = math.exp(-dt_s / tau)
    soc = soc0 - dt_s * i_a / (3600.0 * k[0])
    v1 = a * v1_prev + r1 * (1.0 - a) * i_a
    p01 = p01 * a
    p11 = p11 * (a * a)
    p12 = p12 * a
    p00 += k[1]
    p11 += k[2]
    p22 += k[3]
    oo = ix[0]
    no = ix[1]
    c0 = _t1_slope(d, oo, no, soc)
    c2 = -i_a
    e = v_meas_v - (_t1_value(d, oo, no, soc) - v1 - rs * i_a)
    h0 = p00 * c0 - p01 + p02 * c2
    h1 = p01 * c0 - p11 + p12 * c2
    h2 = p02 * c0 - p12 + p22 * c2
    sden = c0 * h0 - h1 + c2 * h2 + k[4]
    if not (sden > 0.0 and math.isfinite(sden) and math.isfinite(e)):
        return (0, soc, v1, rs, r1, c1, p00, p01, p02, p11, p12, p22, s00, s01, s11, e, 0.0)
    k0 = h0 / sden
    k1 = h1 / sden
    k2 = h2 / sden
    soc += k0 * e
    v1 += k1 * e
    rs += k2 * e
    p00 -= k0 * h0
    p01 -= k0 * h1
    p02 -= k0 * h2
    p11 -= k1 * h1
    p12 -= k1 * h2
    p22 -= k2 * h2
    da_dr1 = a * dt_s / (r1 * tau)
    da_dc1 = a * dt_s / (c1 * tau)
    w = v1_prev - r1 * i_a
    g0 = -da_dr1 * w - (1.0 - a) * i_a
    g1 = -da_dc1 * w
    m0 = s00 * g0 + s01 * g1
    m1 = s01 * g0 + s11 * g1
    tden = g0 * m0 + g1 * m1 + k[4]
    l0 = m0 / tden
    l1 = m1 / tden
    r1 += l0 * e
    c1 += l1 * e
    s00 -= l0 * m0
    s01 -= l0 * m1
    s11 -= l1 * m1
    if soc < 0.0:
        soc = 0.0
    elif soc > 1.0:
        soc = 1.0
    if rs < k[11]:
        rs = k[11]
    r1 = min(max(r1, k[7]), k[8])
    c1 = min(max(c1, k[9]), k[10])
    ds = _t1_value(d, ix[2], ix[3], soc)
    heat = i_a * i_a * rs + v1 * v1 / r1 - i_a * (t_mean_c + 273.15) * ds / k[12]
    return (1, soc, v1, rs, r1, c1, p00, p01, p02, p11, p12, p22, s00, s01, s11, e, heat)


class DEKF:
    """Dual EKF over ``x = [SOC, V1, R_s]``, ``theta = [R1, C1]`` (see module docstring).

    Parameters
    ----------
    params : DEKFParams
    tables : CellTables, optional
        OCV and entropy tables the BMS knows (default: the A123 26650 tables).
    compiled : bool
        Compiled step (default; bit-identical to the Python step) or the Python reference.

    Attributes
    ----------
    soc, v1, rs, r1, c1 : float
        Current estimates (SOC as a fraction, V, Ohm, Ohm, F).
    """

    def __init__(self, params: DEKFParams | None = None, tables: CellTables | None = None, compiled: bool = True):
        self.params = params if params is not None else DEKFParams()
        self.tables = tables if tables is not None else default_tables()
        # compiled step (numba; same arithmetic, bit-identical); compiled=False for the Python path
        self.compiled = bool(compiled and HAVE_NUMBA)
        if self.compiled:
            import numpy as np
            p = self.params
            self._tabs = self.tables.packed()
            self._k = np.array([p.capacity_ah, p.q_soc, p.q_v1, p.q_rs, p.r_v, p.q_r1, p.q_c1, p.r1_min_ohm,
                                p.r1_max_ohm, p.c1_min_f, p.c1_max_f, p.rs_min_ohm, FARADAY_C_MOL])
        self.reset()

    def reset(self, soc0_frac: float | None = None) -> None:
        """Restore the initial estimates and covariances."""
        p = self.params
        self.soc = p.soc0_frac if soc0_frac is None else float(soc0_frac)
        self.v1 = p.v1_0_v
        self.rs = p.rs0_ohm
        self.r1 = p.r1_0_ohm
        self.c1 = p.c1_0_f
        # P_x symmetric 3x3: p00 p01 p02 / p11 p12 / p22
        self.px = [p.p0_soc, 0.0, 0.0, p.p0_v1, 0.0, p.p0_rs]
        # P_theta symmetric 2x2: s00 s01 / s11
        self.pth = [p.s0_r1, 0.0, p.s0_c1]
        self.innovation = 0.0

    # -- model ------------------------------------------------------------------------------
    def predict_voltage(self, i_a: float) -> float:
        """Terminal voltage g(x, i) of the current estimate [V]."""
        return self.tables.ocv(self.soc) - self.v1 - self.rs * i_a

    def heat(self, i_a: float, t_mean_c: float) -> float:
        """Heat generation estimate [W] (5.16 with the OCV-R-RC model): i^2 R_s + V1^2/R1 - i T dS/F."""
        ds = self.tables.entropy_change(self.soc)
        return i_a * i_a * self.rs + self.v1 * self.v1 / self.r1 - i_a * (t_mean_c + 273.15) * ds / FARADAY_C_MOL

    def step_heat(self, i_a: float, v_meas_v: float, dt_s: float, t_mean_c: float) -> float:
        """:meth:`step`, then :meth:`heat` at the new estimates; returns the heat [W]."""
        if self.compiled:
            px, pth = self.px, self.pth
            d, ix = self._tabs
            r = _dekf_step_nb(d, ix, self._k, self.soc, self.v1, self.rs, self.r1, self.c1, px[0], px[1], px[2],
                              px[3], px[4], px[5], pth[0], pth[1], pth[2], float(i_a), float(v_meas_v),
                              float(dt_s), float(t_mean_c))
            if r[0]:
                (_, self.soc, self.v1, self.rs, self.r1, self.c1, p00, p01, p02, p11, p12, p22, s00, s01, s11,
                 self.innovation, q) = r
                self.px = [p00, p01, p02, p11, p12, p22]
                self.pth = [s00, s01, s11]
                return q
        self._step_py(i_a, v_meas_v, dt_s)
        return self.heat(i_a, t_mean_c)

    def step(self, i_a: float, v_meas_v: float, dt_s: float) -> float:
        """One DEKF step with the measured cell current [A] (+ discharge) and voltage [V].

        Returns the innovation ``y - g(x^-, i)`` [V].
        """
        if self.compiled:
            self.step_heat(i_a, v_meas_v, dt_s, 25.0)
            return self.innovation
        return self._step_py(i_a, v_meas_v, dt_s)

    def _step_py(self, i_a: float, v_meas_v: float, dt_s: float) -> float:
        """The reference (Python) step; the compiled kernel runs the same arithmetic."""
        p = self.params
        tab = self.tables
        # 1. parameter time update (5.21)
        s00, s01, s11 = self.pth
        s00 += p.q_r1
        s11 += p.q_c1
        r1 = self.r1
        c1 = self.c1
        # 2. state time update (5.22) with i_{k-1} = i_k (ZOH)
        tau = r1 * c1
        a = math.exp(-dt_s / tau)
        v1_prev = self.v1
        soc = self.soc - dt_s * i_a / (3600.0 * p.capacity_ah)
        v1 = a * v1_prev + r1 * (1.0 - a) * i_a
        rs = self.rs
        p00, p01, p02, p11, p12, p22 = self.px
        # A = diag(1, a, 1): A P A^T
        p01 *= a
        p11 *= a * a
        p12 *= a
        p00 += p.q_soc
        p11 += p.q_v1
        p22 += p.q_rs
        # 3. state measurement update (5.23)
        c0 = tab.docv_dsoc(soc)
        c2 = -i_a
        e = v_meas_v - (tab.ocv(soc) - v1 - rs * i_a)
        # P C^T with C = [c0, -1, c2]
        h0 = p00 * c0 - p01 + p02 * c2
        h1 = p01 * c0 - p11 + p12 * c2
        h2 = p02 * c0 - p12 + p22 * c2
        sden = c0 * h0 - h1 + c2 * h2 + p.r_v
        if not (sden > 0.0 and math.isfinite(sden) and math.isfinite(e)):
            raise SimulationError(f"DEKF: non-finite or non-positive innovation variance "
                                  f"(innovation {e!r} V, variance {sden!r}; inputs i={i_a!r} A, v={v_meas_v!r} V)")
        k0 = h0 / sden
        k1 = h1 / sden
        k2 = h2 / sden
        soc += k0 * e
        v1 += k1 * e
        rs += k2 * e
        # P^+ = P - K (P C^T)^T   (symmetric form of (I - K C) P)
        p00 -= k0 * h0
        p01 -= k0 * h1
        p02 -= k0 * h2
        p11 -= k1 * h1
        p12 -= k1 * h2
        p22 -= k2 * h2
        # 4. parameter measurement update (5.24) with C^theta (5.17d-e, corrected)
        da_dr1 = a * dt_s / (r1 * tau)
        da_dc1 = a * dt_s / (c1 * tau)
        w = v1_prev - r1 * i_a
        g0 = -da_dr1 * w - (1.0 - a) * i_a
        g1 = -da_dc1 * w
        m0 = s00 * g0 + s01 * g1
        m1 = s01 * g0 + s11 * g1
        tden = g0 * m0 + g1 * m1 + p.r_v
        l0 = m0 / tden
        l1 = m1 / tden
        r1 += l0 * e
        c1 += l1 * e
        s00 -= l0 * m0
        s01 -= l0 * m1
        s11 -= l1 * m1
        # keep the estimates physical
        if soc < 0.0:
            soc = 0.0
        elif soc > 1.0:
            soc = 1.0
        if rs < p.rs_min_ohm:
            rs = p.rs_min_ohm
        r1 = min(max(r1, p.r1_min_ohm), p.r1_max_ohm)
        c1 = min(max(c1, p.c1_min_f), p.c1_max_f)
        self.soc, self.v1, self.rs, self.r1, self.c1 = soc, v1, rs, r1, c1
        self.px = [p00, p01, p02, p11, p12, p22]
        self.pth = [s00, s01, s11]
        self.innovation = e
        return e
