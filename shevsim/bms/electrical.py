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

Table-scaled R_s, R1, C1 (``rs_model``, ``rc_model``; departure from the seed)
------------------------------------------------------------------------------
``"free"`` (both, the ``DEKFParams`` default) is the seed's filter above: x[2] = R_s [Ohm] and
theta = [R1, C1], one value each for both current directions and all temperatures, tracked by random
walks (5.19, 5.21).  Against a cell whose R_s differs between charge and discharge (the A123 tables:
charge ~5 % lower) and varies with SOC and temperature, one random walk can only sit between the
two tables and lag every current reversal.

``"table_scaled"`` (the BMS component's default for both) is the usual production-BMS form: the BMS
knows the cell type's nominal ECM maps R_s,nom, R1,nom, C1,nom(SOC, T, sign i) (the ``CellTables``
it already loads; R1, C1 = the first RC branch of the maps), and the filters estimate only
multiplicative factors for ageing and cell-to-cell spread::

    x     = [SOC, V1, kappa_s]                   (Omega_1, kappa_s a random walk as 5.19)
    theta = [kappa_1, kappa_2]                   (Omega_2, random walks as 5.21)
    R_s = kappa_s R_s,nom,  R1 = kappa_1 R1,nom,  C1 = kappa_2 C1,nom   at (SOC_k^-, T_k, sign i_k)
    C^x     = [dV_oc/dSOC, -1, -R_s,nom i_k]
    C^theta = [R1,nom dV_t/dR1, C1,nom dV_t/dC1]  (5.17d-e at the effective R1, C1)

- The maps are read once per step at the *predicted* SOC, with the discharge table for ``i >= 0`` and
  the charge table for ``i < 0`` (the plant's convention, here on the measured current), at ``T`` =
  the previous step's mean-temperature estimate of the thermal filter (``t_mean_c`` of
  :meth:`DEKF.step_heat`, which the sequential scheme of Sec. 5.3.2 already passes for the heat).
  They are known inputs: their SOC slopes are left out of C^x (as the seed leaves theta out of it).
- The factors start at 1 (a nominal cell) with variance ``factor_p0`` (1e-2) and random walk
  ``factor_q`` (1e-4 per step = the re-tuned free-R_s walk 1e-8 Ohm^2 relative to 0.01 Ohm).
- Published ``rs``, ``r1``, ``c1`` are the effective values of the step (used by the heat (5.16)
  and the power capability); the bounds ``rs_min_ohm``, ``r1_*``, ``c1_*`` apply to them.
- The state/parameter grouping, the 5.21-5.24 update sequence and the SOC/V1 tuning are unchanged;
  with both models ``"free"`` the arithmetic is the seed filter's, bit for bit.
- With the seed's parameter update (``rc_update = "seed"``) kappa_1 does not track ageing: see the next
  section.

Tracking the R1 factor (``rc_update = "tracking"``; departure from the seed)
----------------------------------------------------------------------------
Why the seed's update leaves kappa_1 at 1 (measured on the 2000 s drive profile of tests/unit/test_bms.py,
plant R_s and R1 x 1.2, BMS tuning, ``v2_model = "nominal_maps"``): kappa_1 ends at 1.002 (truth 1.2) while
kappa_s reaches 1.198, for two reasons that each suffice:

1. C^theta (5.17d) is the one-step partial derivative with V1_{k-1} held: about ``(dt/tau_1) V1``, median
   |dV_t/dkappa_1| 1.3e-4 V (tau_1 = R1 C1 ~ 20 s, dt = 0.1 s).  The predicted V1 depends on R1 through its
   whole recursion; that total derivative (Plett, J. Power Sources 134 (2004) 277, Part 3, the DEKF's
   ``dx/dtheta`` recursion) is ~1e-2 V open loop, and 1.9e-3 V once the state filter's corrections
   (``-K C^theta``: V1, SOC and kappa_s absorb ~80 % of an R1 error within a pulse) are accounted for.
2. The parameter filter divides by the same Sigma_v = 1 as the state filter.  That is a scaling only
   the state filter is tuned to (its Sigma_w are relative to it); the factor's S(0) = 1e-2 and walk are
   physical variances of kappa, so the gain S g / (g S g + 1) is ~1e-4 per volt: an innovation of
   1.2 mV RMS moves kappa_1 by ~1e-7 per step, and P_theta grows by the walk from 1e-2 to 2.0 over 2000 s,
   learning nothing.

The tracking update (factors only; the free R1, C1 always follow the seed's 5.24, bit for bit):

- C^theta = dV_t/dkappa_1 through the state estimate's recursion, with
  ``s^-_k = A s^+_{k-1} + df/dkappa_1`` (df/dkappa_1 = [0, R1,nom dV1/dR1 at V1_{k-1} held, 0]),
  ``C^theta_k = C^x_k s^-_k``, ``s^+_k = s^-_k - K_k C^theta_k`` (the gain's own dependence on kappa_1 is
  neglected, as in Plett's DEKF); three numbers carried in the state array;
- the parameter filter's output noise is in V^2: the innovation's running mean square (exponential window
  ``theta_window_s`` = 60 s, covariance matching, Mehra 1970), floored at ``theta_r_v2`` = (1 mV)^2, the
  voltage sensor's variance (seed Sec. 5.4).  The floor is what the measurement can give; the running
  mean square accounts for the state filter's errors, which cannot be put in V^2 from P_x (the state
  filter works in the Sigma_v = 1 scaling).  Without it (floor only) the parameter filter takes the 10 %
  SOC start error for an R1 error: over the first 1000 s kappa_1 spans 0.46-2.6 on the test's aged cell and
  hits its lower bound (R1 = 1e-4 Ohm) at 28 s on a second profile (with it: 1.00-1.91 and 0.90-1.80);
- kappa_1 starts at 1 with variance ``factor_p0`` (1e-2, physical now) and walks by ``r1_factor_q``
  (1e-7 per step: 1 % per 100 s at 10 Hz, steady gain time constant ~120 s);
- kappa_2 (C1) is held at 1: C1 = C1,nom.  Estimated jointly, the pair is well conditioned at the truth
  (Fisher correlation of the two sensitivities -0.06), but the start-up transient (10 % SOC error, kappa_s
  not yet converged) drives kappa_2 to 0.1-0.4; with a physical-units filter it had not come back after
  1000 s on two of five plants (kappa_1 then 15-21 % off).  A C1 that ages is left to the seed's update.

Measured (same profile, four plants R_s, R1 x {1, 1.2}^2 and three on a second profile and noise seed, 10 % SOC
start error, BMS tuning): kappa_1 within 3.2 % of the truth from 1000 s to 2000 s on all seven (1.4 % on the
test's aged cell, ends at 1.198), max SOC error 0.09 % there (seed update: kappa_1 1.002, SOC 1.7 %).

What R1 is observable against (measured, innovation RMS with kappa_1 held, second half): R_s and R1
scale the same current but are not collinear on this profile (2-15 s pulses; after 1000 s kappa_s stays in
1.187-1.204 whatever kappa_1 is held at in 0.8-1.5).  The limits are elsewhere:

- the slow branch: with ``v2_model = "none"`` the prediction error's minimum is at kappa_1 ~ 1.2 on the
  *nominal* plant and > 1.3 on the aged one (the one-branch V1 absorbs the plant's V2); the tracking update
  then estimates that effective value (+16-26 %), not R1.  Use it with ``v2_model = "nominal_maps"``;
- a slow SOC filter: with ``q_soc`` = 1e-5 (SOC converges over > 1000 s) kappa_1 absorbs the SOC error
  instead (up to 45 % off, SOC error up to 5.5 %); with the BMS tuning (1e-3) or Table 5.4 (6e-3) it does not.
  ``DEKFParams`` keeps ``rc_update = "seed"`` (its defaults are the seed's filter); the BMS component's
  default is ``"tracking"``.

Slow second branch (``v2_model``; departure from the seed)
-----------------------------------------------------------
The plant (:mod:`shevsim.battery.model`) is OCV-R-RC-RC; its second branch is slow (tau_2 = R2 C2 ~
220-400 s), larger than the first and direction dependent.  On LFP's flat OCV a few millivolts of it left
out of the filter's model become 2-3 % of SOC in closed loop (issue 14).  With ``v2_model =
"nominal_maps"`` (the BMS component's default) the filter propagates V2 open loop from the cell type's
nominal R2, C2(SOC, T, sign i) maps (the ``CellTables`` it already loads), read at the predicted SOC, the
previous mean-temperature estimate and the measured current's sign, with the current held over the step::

    V2_k = a2 V2_{k-1} + R2,nom (1 - a2) i_k,     a2 = exp(-dt / (R2,nom C2,nom))
    V_t,k = V_oc(SOC_k) - V1_k - V2_k - R_s i_k

V2 is a known input to the measurement (not a filter state; its error is not tracked by P_x), and the
heat (5.16) gains V2^2 / R2,nom.  ``"none"`` (the ``DEKFParams`` default) is the seed's one-branch filter,
bit for bit.  The power capability carries the V2 of the step over its horizon with the same maps
(:mod:`shevsim.bms.power_capability`, "Slow second branch").

Solid diffusion (``diffusion_time_s``; departure from the seed)
---------------------------------------------------------------
A cell with solid diffusion (the battery's ``diffusion_time_s`` = tau_d = R^2/D, :mod:`shevsim.battery.model`)
shows the OCV of its particles' *surface* SOC, which lags the bulk SOC under load.  A filter that reads the
OCV at the bulk SOC takes the lag for a SOC error and biases the estimate by the lag itself.  With
``diffusion_time_s > 0`` (0, the default, is the filter without it, bit for bit) the filter propagates the
diffusion state w open loop, as V2: a known input to the measurement, not a filter state, with the plant's
exact discretisation (current held over the step, Q = 3600 C_b)::

    w_k   = -k_w i_k + (w_{k-1} + k_w i_k) exp(-30 dt / tau_d),    k_w = (2/35) tau_d / Q
    s_k   = SOC_k + w_k - tau_d i_k / (105 Q)                       (the surface SOC)
    V_t,k = V_oc(s_k) - V1_k - V2_k - R_s i_k,    C^x = [dV_oc/dSOC at s_k, -1, -R_s,nom i_k]

(w does not depend on SOC: its error is not tracked by P_x.)  The heat (5.16) gains the diffusion
overpotential's ``i (V_oc(SOC) - V_oc(s))``, as the plant's, and the power capability reads the OCV at the
surface SOC along its horizon (:mod:`shevsim.bms.power_capability`).

The filter is written once, as the numba-compatible pure function :func:`dekf_step` (floats and the
packed tables in, a tuple out; 3x3 and 2x2 symmetric covariances unrolled), with the heat (5.16) in
:func:`cell_heat`.  ``DEKF(compiled=True)`` (default) runs it compiled; ``compiled=False`` runs
``dekf_step.py_func``, the same source in Python.  :meth:`DEKF.step_heat` is the step followed by the heat
estimate in one call.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shevsim.battery.cell import FARADAY_C_MOL, CellTables, default_tables
from shevsim.core.compiled import field_index, njit_step
from shevsim.core.lookup import HAVE_NUMBA, njit, t1_slope, t1_value, ecm_lookup
from shevsim.battery.model import DIFF_INSTANT, DIFF_W_GAIN, DIFF_W_RATE
from shevsim.core.errors import ScenarioError, SimulationError

__all__ = ["DEKFParams", "DEKF", "dekf_step", "cell_heat"]


@dataclass(frozen=True)
class DEKFTuning:
    """The DEKF's tuning and model choices, declared once: :class:`DEKFParams` and the BMS component's
    parameters (:class:`shevsim.components.bms.BMSParams`) both derive from it (fields: see
    :class:`DEKFParams`)."""

    capacity_ah: float = 2.3
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
    rs_model: str = "free"
    rc_model: str = "free"
    factor_p0: float = 1e-2
    factor_q: float = 1e-4
    v2_model: str = "none"
    rc_update: str = "seed"
    theta_r_v2: float = 1e-6
    theta_window_s: float = 60.0
    r1_factor_q: float = 1e-7
    diffusion_time_s: float = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.diffusion_time_s, (int, float)) and math.isfinite(self.diffusion_time_s)
                and self.diffusion_time_s >= 0.0):
            raise ScenarioError(f"{type(self).__name__}: diffusion_time_s (R^2/D of the cell's particles; 0 = off) "
                                f"must be finite and >= 0, got {self.diffusion_time_s!r}")
        for name in ("rs_model", "rc_model"):
            if getattr(self, name) not in ("free", "table_scaled"):
                raise ValueError(f"DEKFParams: {name} must be 'free' or 'table_scaled', got {getattr(self, name)!r}")
        if self.v2_model not in ("none", "nominal_maps"):
            raise ValueError(f"DEKFParams: v2_model must be 'none' or 'nominal_maps', got {self.v2_model!r}")
        if self.rc_update not in ("seed", "tracking"):
            raise ValueError(f"DEKFParams: rc_update must be 'seed' or 'tracking', got {self.rc_update!r}")
        for name in ("theta_r_v2", "theta_window_s"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0.0):
                raise ValueError(f"DEKFParams: {name} must be finite and > 0, got {getattr(self, name)!r}")
        if not (math.isfinite(self.r1_factor_q) and self.r1_factor_q >= 0.0):
            raise ValueError(f"DEKFParams: r1_factor_q must be finite and >= 0, got {self.r1_factor_q!r}")
        if not (self.factor_p0 >= 0.0 and self.factor_q >= 0.0):
            raise ValueError(f"DEKFParams: factor_p0 and factor_q must be >= 0, got {self.factor_p0!r}, "
                             f"{self.factor_q!r}")


@dataclass(frozen=True)
class DEKFParams(DEKFTuning):
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
    rs_model : str
        ``"free"`` (seed: R_s itself is the third state; tuned by ``q_rs``, ``p0_rs``, ``rs0_ohm``) or
        ``"table_scaled"`` (the third state is a factor kappa_s on the nominal map,
        ``R_s = kappa_s R_s,nom(SOC, T, sign i)``, starting at 1, tuned by ``factor_q``, ``factor_p0``).
    rc_model : str
        ``"free"`` (seed: theta = [R1, C1]; ``q_r1``, ``q_c1``, ``s0_r1``, ``s0_c1``, ``r1_0_ohm``,
        ``c1_0_f``) or ``"table_scaled"`` (theta = factors [kappa_1, kappa_2] on the nominal first-branch
        maps R1,nom, C1,nom(SOC, T, sign i), starting at 1, tuned by ``factor_q``, ``factor_p0``).
    factor_p0, factor_q : float
        Initial variance [-] and per-step random-walk variance [-] of every table factor: 1e-2
        (1-sigma 10 %: cell-to-cell spread plus ageing not yet seen) and 1e-4 (the re-tuned free R_s
        random walk, 1e-8 Ohm^2, relative to the nominal ~0.01 Ohm: the same relative walk).  See the
        module docstring.
    v2_model : str
        ``"none"`` (seed: one RC branch) or ``"nominal_maps"`` (the slow second branch V2 is propagated
        from the nominal R2, C2(SOC, T, sign i) maps and subtracted from the predicted voltage; see the
        module docstring, "Slow second branch").
    rc_update : str
        ``"seed"`` (5.24 with the one-step C^theta and Sigma_v) or ``"tracking"`` (``rc_model =
        "table_scaled"`` only: total-derivative C^theta for kappa_1, output noise in V^2, kappa_2 held at
        1; module docstring, "Tracking the R1 factor").  Ignored for ``rc_model = "free"``.
    theta_r_v2 : float
        Floor of the tracking update's output-noise variance [V^2]: the voltage sensor's, (1 mV)^2.
    theta_window_s : float
        Window [s] of the innovation's running mean square, the tracking update's output noise (60 s).
    r1_factor_q : float
        Random walk of kappa_1 per step in the tracking update [-] (1e-7).
    diffusion_time_s : float
        The cell's solid-diffusion time R^2/D [s] (the battery parameter of that name; 0 = off, the filter
        bit for bit as without it): the diffusion state w is propagated open loop with the plant's
        discretisation and the OCV read at the surface SOC (module docstring, "Solid diffusion").
    """

    soc0_frac: float = 0.5
    v1_0_v: float = 0.0
    r1_min_ohm: float = 1e-4
    r1_max_ohm: float = 1.0
    c1_min_f: float = 10.0
    c1_max_f: float = 1e6
    rs_min_ohm: float = 1e-5


@njit(cache=True)
def _ecm_nom(d, ix, soc, t_c, i_a):
    """``(R_s, R1, C1)`` of the nominal maps (``CellTables.params(soc, t_c, i_a)[:3]``; the one lookup)."""
    rs, r1, c1, _r2, _c2 = ecm_lookup(d, ix, soc, t_c, i_a)
    return rs, r1, c1


@njit(cache=True)
def cell_heat(i_a, rs, v1, r1, t_c, ds):
    """Heat generation [W] of the OCV-R-RC cell (5.16): ``i^2 R_s + V1^2 / R1 - i T dS / F`` (``ds`` = the
    entropy change dS [J/mol/K] at the SOC, ``t_c`` [degC])."""
    return i_a * i_a * rs + v1 * v1 / r1 - i_a * (t_c + 273.15) * ds / FARADAY_C_MOL


#: the filter's state array ``xe`` (:attr:`DEKF.xe`): estimates, the covariances ``P_x`` (p00 .. p22) and
#: ``P_theta`` (s00 .. s11), the effective R_s, R1, C1, the slow branch (v2, r2), the last innovation [V]
#: and, for ``rc_update = "tracking"``, the sensitivities d(SOC, V1, x2)/d(kappa_1) of the state estimate and the
#: parameter filter's output-noise variance [V^2] (module docstring), and the solid-diffusion state ``wd`` (surface
#: SOC - SOC without the instantaneous part, propagated open loop; 0 with ``diffusion_time_s = 0``)
E = field_index(("soc", "v1", "x2", "th1", "th2", "p00", "p01", "p02", "p11", "p12", "p22", "s00", "s01", "s11",
                 "rs", "r1", "c1", "v2", "r2", "innovation", "variance", "dsoc_dk1", "dv1_dk1", "dx2_dk1",
                 "r_theta", "wd"), "E")


@njit(cache=True, inline="always")
def _nominal_factors(d, ix, k, soc, t_mean_c, i_a, dt_s, v2_prev):
    """The nominal map factors at the predicted SOC and the slow branch: ``(rsn, r1n, c1n, v2, r2n)`` (1, 1, 1, 0,
    inf for the free filter); ``v2`` propagated from the nominal maps with the current held over ``dt_s`` when
    ``k[15] > 0.5`` (module docstring)."""
    rsn = 1.0
    r1n = 1.0
    c1n = 1.0
    v2 = 0.0
    r2n = math.inf
    if k[13] > 0.5 or k[14] > 0.5 or k[15] > 0.5:
        rsn_t, r1n_t, c1n_t, r2n_t, c2n_t = ecm_lookup(d, ix, soc, t_mean_c, i_a)
        if k[13] > 0.5:
            rsn = rsn_t
        if k[14] > 0.5:
            r1n = r1n_t
            c1n = c1n_t
        if k[15] > 0.5:
            r2n = r2n_t
            a2 = math.exp(-dt_s / (r2n_t * c2n_t))
            v2 = a2 * v2_prev + r2n_t * (1.0 - a2) * i_a
    return rsn, r1n, c1n, v2, r2n


@njit(cache=True, inline="always")
def _diffusion(k, w_prev, i_a, dt_s):
    """The solid-diffusion state after a step with the current ``i_a`` held over ``dt_s`` and the surface's
    offset from the bulk SOC: ``(w, surface SOC - SOC)``; ``(0, 0)`` with ``k[19]`` (diffusion_time_s) = 0.
    The plant's exact discretisation (:func:`shevsim.battery.model._cell_electrical`):
    ``w = -k_w i + (w_prev + k_w i) exp(-30 dt / tau_d)``, surface = SOC + w - tau_d i / (105 Q)."""
    td = k[19]
    if not td > 0.0:
        return 0.0, 0.0
    q_as = 3600.0 * k[0]
    exw = math.exp(-dt_s * DIFF_W_RATE / td)
    kw = DIFF_W_GAIN * td / q_as
    kd = DIFF_INSTANT * td / q_as
    w = -kw * i_a + (w_prev + kw * i_a) * exw
    return w, w - kd * i_a


@njit(cache=True, inline="always")
def _state_gain(p00, p01, p02, p11, p12, p22, c0, c2, r_v):
    """``P C^T`` with ``C = [c0, -1, c2]`` and the innovation variance ``C P C^T + r_v``: ``(h0, h1, h2, sden)``."""
    h0 = p00 * c0 - p01 + p02 * c2
    h1 = p01 * c0 - p11 + p12 * c2
    h2 = p02 * c0 - p12 + p22 * c2
    return h0, h1, h2, c0 * h0 - h1 + c2 * h2 + r_v


@njit(cache=True, inline="always")
def _parameter_jacobian(a, dt_s, r1, c1, r1n, c1n, v1_prev, i_a):
    """``C^theta`` (5.17d-e, corrected) of the parameters, times the nominal value for a factor
    (``dV/dkappa1 = R1,nom dV/dR1``, ``dV/dkappa2 = C1,nom dV/dC1``): ``(g0, g1)``."""
    tau = r1 * c1
    da_dr1 = a * dt_s / (r1 * tau)
    da_dc1 = a * dt_s / (c1 * tau)
    w = v1_prev - r1 * i_a
    return (-da_dr1 * w - (1.0 - a) * i_a) * r1n, -da_dc1 * w * c1n


@njit(cache=True, inline="always")
def _parameter_update(s00, s01, s11, th1, th2, g0, g1, e, r_v):
    """The parameter measurement update (5.24) with ``C^theta = [g0, g1]``: ``(th1, th2, s00, s01, s11)``."""
    m0 = s00 * g0 + s01 * g1
    m1 = s01 * g0 + s11 * g1
    tden = g0 * m0 + g1 * m1 + r_v
    l0 = m0 / tden
    l1 = m1 / tden
    return th1 + l0 * e, th2 + l1 * e, s00 - l0 * m0, s01 - l0 * m1, s11 - l1 * m1


@njit(cache=True, inline="always")
def _bounded(k, soc, x2, th1, th2, rsn, r1n, c1n):
    """The estimates kept physical (SOC in [0, 1], bounds on the effective R_s, R1, C1): ``(soc, x2, th1, th2,
    r1, c1)``."""
    if soc < 0.0:
        soc = 0.0
    elif soc > 1.0:
        soc = 1.0
    if x2 * rsn < k[11]:
        x2 = k[11] / rsn
    r1 = min(max(th1 * r1n, k[7]), k[8])
    c1 = min(max(th2 * c1n, k[9]), k[10])
    return soc, x2, r1 / r1n, c1 / c1n, r1, c1


@njit_step
def dekf_step(d, ix, k, xe, i_a, v_meas_v, dt_s, t_mean_c):
    """One DEKF step (5.21-5.24, module docstring) and the heat (5.16) at the new estimates.

    ``d, ix`` = ``CellTables.packed()``; ``k = [capacity_ah, q_soc, q_v1, q_x2, r_v, q_th1, q_th2, r1_min,
    r1_max, c1_min, c1_max, rs_min, F, rs_scaled, rc_scaled, v2_nominal, rc_tracking, theta_r_v2,
    theta_window_s, diffusion_time_s]``; ``xe`` the filter's state array
    (:data:`E`, read only): the estimates, the unrolled symmetric covariances ``P_x`` (p00 .. p22) and
    ``P_theta`` (s00 .. s11), the slow branch's voltage ``v2`` (propagated, not estimated, when
    ``k[15] > 0.5``; otherwise ignored and returned as 0).  Returns
    ``(ok, soc, v1, x2, rs, th1, th2, r1, c1, p00, p01, p02, p11, p12, p22, s00, s01, s11, e, var, heat, v2, r2)``
    (``x2``, ``th1``, ``th2`` the filter's states/parameters: R_s, R1, C1 or their factors; ``rs``, ``r1``,
    ``c1`` the effective values; ``e`` the innovation [V] and ``var`` its variance; ``v2`` the slow branch's
    voltage after the step and ``r2`` [Ohm] the nominal R2 it used, ``inf`` without it), then ``(dsoc_dk1,
    dv1_dk1, dx2_dk1, r_theta)`` (the tracking update's sensitivities and output-noise variance [V^2]; carried
    unchanged otherwise), then ``wd`` (the solid-diffusion state after the step, propagated open loop when
    ``k[19]`` = diffusion_time_s > 0, else 0); ``ok = 0`` when the innovation variance is unusable (the rest is
    then not an update).
    """
    v1_prev, x2, th1, th2 = xe[E.v1], xe[E.x2], xe[E.th1], xe[E.th2]
    p00, p01, p02, p11, p12, p22 = xe[E.p00], xe[E.p01], xe[E.p02], xe[E.p11], xe[E.p12], xe[E.p22]
    # 1. parameter time update (5.21); theta = [R1, C1] (free) or their factors (table_scaled)
    s00 = xe[E.s00] + k[5]
    s01 = xe[E.s01]
    s11 = xe[E.s11] + k[6]
    # SOC time update first: the nominal maps are read at the predicted SOC
    soc = xe[E.soc] - dt_s * i_a / (3600.0 * k[0])
    rsn, r1n, c1n, v2, r2n = _nominal_factors(d, ix, k, soc, t_mean_c, i_a, dt_s, xe[E.v2])
    r1 = th1 * r1n
    c1 = th2 * c1n
    # 2. state time update (5.22) with i_{k-1} = i_k (ZOH); A = diag(1, a, 1): A P A^T + Sigma_w
    a = math.exp(-dt_s / (r1 * c1))
    v1 = a * v1_prev + r1 * (1.0 - a) * i_a
    p01 = p01 * a
    p11 = p11 * (a * a)
    p12 = p12 * a
    p00 += k[1]
    p11 += k[2]
    p22 += k[3]
    # solid diffusion (open loop, a known input like V2): the OCV is read at the surface SOC
    wd, sd = _diffusion(k, xe[E.wd], i_a, dt_s)
    # 3. state measurement update (5.23); R_s = x2 * rsn (free: rsn = 1, x2 = R_s); dV/dSOC at the surface
    c0 = t1_slope(d, ix[0], ix[1], soc + sd)
    c2 = -i_a * rsn
    e = v_meas_v - (t1_value(d, ix[0], ix[1], soc + sd) - v1 - v2 - x2 * rsn * i_a)
    h0, h1, h2, sden = _state_gain(p00, p01, p02, p11, p12, p22, c0, c2, k[4])
    ds, dv, dx, r_theta = xe[E.dsoc_dk1], xe[E.dv1_dk1], xe[E.dx2_dk1], xe[E.r_theta]
    if not (sden > 0.0 and math.isfinite(sden) and math.isfinite(e)):
        return (0, soc, v1, x2, x2 * rsn, th1, th2, r1, c1, p00, p01, p02, p11, p12, p22, s00, s01, s11, e, sden,
                0.0, v2, r2n, ds, dv, dx, r_theta, wd)
    k0 = h0 / sden
    k1 = h1 / sden
    k2 = h2 / sden
    soc += k0 * e
    v1 += k1 * e
    x2 += k2 * e
    # P^+ = P - K (P C^T)^T   (symmetric form of (I - K C) P)
    p00 -= k0 * h0
    p01 -= k0 * h1
    p02 -= k0 * h2
    p11 -= k1 * h1
    p12 -= k1 * h2
    p22 -= k2 * h2
    # 4. parameter measurement update (5.24)
    g0, g1 = _parameter_jacobian(a, dt_s, r1, c1, r1n, c1n, v1_prev, i_a)
    if k[16] > 0.5:
        # tracking (module docstring): C^theta is the total derivative of the predicted voltage through the
        # state estimate's recursion, d x^-_k = A d x^+_{k-1} + df/dkappa_1, d x^+_k = d x^-_k - K C^theta
        # (-g0 = dV1^-/dkappa_1 with V1_{k-1} held); the output noise is in V^2
        dv = a * dv - g0
        g0 = c0 * ds - dv + c2 * dx
        g1 = 0.0
        ds -= k0 * g0
        dv -= k1 * g0
        dx -= k2 * g0
        w = min(dt_s / k[18], 1.0)
        r_theta += w * (e * e - r_theta)
        th1, th2, s00, s01, s11 = _parameter_update(s00, s01, s11, th1, th2, g0, g1, e, max(r_theta, k[17]))
    else:
        th1, th2, s00, s01, s11 = _parameter_update(s00, s01, s11, th1, th2, g0, g1, e, k[4])
    soc, x2, th1, th2, r1, c1 = _bounded(k, soc, x2, th1, th2, rsn, r1n, c1n)
    rs = x2 * rsn
    heat = cell_heat(i_a, rs, v1, r1, t_mean_c, t1_value(d, ix[2], ix[3], soc))
    if k[15] > 0.5:
        heat += v2 * v2 / r2n
    if k[19] > 0.0:
        # the diffusion overpotential dissipates i (OCV(SOC) - OCV(surface)) (the plant's heat term)
        heat += i_a * (t1_value(d, ix[0], ix[1], soc) - t1_value(d, ix[0], ix[1], soc + sd))
    return (1, soc, v1, x2, rs, th1, th2, r1, c1, p00, p01, p02, p11, p12, p22, s00, s01, s11, e, sden, heat, v2, r2n,
            ds, dv, dx, r_theta, wd)


@njit(cache=True, inline="always")
def store_update(xe, r):
    """Write a :func:`dekf_step` result ``r`` into the state array ``xe`` (:data:`E`); returns ``(ok, heat [W])``.
    When the innovation variance is unusable (``ok = 0``) only the innovation and its variance are written."""
    xe[E.innovation] = r[18]
    xe[E.variance] = r[19]
    if not r[0]:
        return 0, 0.0
    (xe[E.soc], xe[E.v1], xe[E.x2], xe[E.rs], xe[E.th1], xe[E.th2], xe[E.r1], xe[E.c1], xe[E.p00], xe[E.p01],
     xe[E.p02], xe[E.p11], xe[E.p12], xe[E.p22], xe[E.s00], xe[E.s01], xe[E.s11]) = r[1:18]
    xe[E.v2] = r[21]
    xe[E.r2] = r[22]
    xe[E.dsoc_dk1], xe[E.dv1_dk1], xe[E.dx2_dk1], xe[E.r_theta] = r[23:27]
    xe[E.wd] = r[27]
    return 1, r[20]


@njit(cache=True, inline="always")
def dekf_update(d, ix, k, xe, i_a, v_meas_v, dt_s, t_mean_c):
    """:func:`dekf_step` on the state array ``xe`` (:data:`E`), in place (:func:`store_update`); returns
    ``(ok, heat [W])``."""
    return store_update(xe, dekf_step(d, ix, k, xe, i_a, v_meas_v, dt_s, t_mean_c))


def _xe_property(name: str, doc: str):
    i = getattr(E, name)

    def get(self):
        return float(self.xe[i])

    def set_(self, v):
        self.xe[i] = v
    return property(get, set_, doc=doc)


class DEKF:
    """Dual EKF over ``x = [SOC, V1, R_s]``, ``theta = [R1, C1]`` (see module docstring).

    Parameters
    ----------
    params : DEKFParams
    tables : CellTables, optional
        OCV and entropy tables the BMS knows (default: the A123 26650 tables).
    compiled : bool
        Run :func:`dekf_step` compiled (default) or its ``py_func`` (the same source in Python).

    Attributes
    ----------
    soc, v1, rs, r1, c1 : float
        Current estimates (SOC as a fraction, V, Ohm, Ohm, F); ``rs`` is the effective R_s of the
        last step (``rs_factor * R_s,nom`` at that step's SOC, temperature and current direction
        for ``table_scaled``).
    x2 : float
        The third filter state: R_s [Ohm] (``free``) or the factor kappa [-] (``table_scaled``).
    v2, r2 : float
        Slow second-branch voltage [V] propagated from the nominal maps and the nominal R2 [Ohm] of the
        last step (``v2_model = "nominal_maps"``; 0 and ``inf`` otherwise).
    wd : float
        Solid-diffusion state w [1] after the last step (``diffusion_time_s > 0``; 0 otherwise): the surface
        SOC is ``SOC + w - tau_d i / (105 Q)`` (:meth:`surface_soc`).
    """

    soc = _xe_property("soc", "SOC estimate [1]")
    v1 = _xe_property("v1", "polarisation voltage V1 [V]")
    x2 = _xe_property("x2", "third state: R_s [Ohm] or its factor [1]")
    th1 = _xe_property("th1", "parameter: R1 [Ohm] or its factor [1]")
    th2 = _xe_property("th2", "parameter: C1 [F] or its factor [1]")
    rs = _xe_property("rs", "effective R_s of the last step [Ohm]")
    r1 = _xe_property("r1", "effective R1 [Ohm]")
    c1 = _xe_property("c1", "effective C1 [F]")
    v2 = _xe_property("v2", "slow branch voltage [V]")
    r2 = _xe_property("r2", "nominal R2 of the last step [Ohm]")
    innovation = _xe_property("innovation", "last innovation [V]")
    wd = _xe_property("wd", "solid-diffusion state w [1] (surface SOC - SOC without the instantaneous part)")

    @property
    def px(self) -> list:
        """P_x, symmetric 3x3: p00 p01 p02 / p11 p12 / p22."""
        return self.xe[E.p00:E.p22 + 1].tolist()

    @px.setter
    def px(self, v) -> None:
        self.xe[E.p00:E.p22 + 1] = v

    @property
    def pth(self) -> list:
        """P_theta, symmetric 2x2: s00 s01 / s11."""
        return self.xe[E.s00:E.s11 + 1].tolist()

    @pth.setter
    def pth(self, v) -> None:
        self.xe[E.s00:E.s11 + 1] = v

    def arrays(self) -> tuple:
        """``(d, ix, k, xe)``: what :func:`dekf_update` takes (tables, constants, the state array itself)."""
        return self._tabs[0], self._tabs[1], self._k, self.xe

    def __init__(self, params: DEKFParams | None = None, tables: CellTables | None = None, compiled: bool = True):
        self.xe = np.zeros(len(E))
        self.params = params if params is not None else DEKFParams()
        self.tables = tables if tables is not None else default_tables()
        p = self.params
        self.scaled = p.rs_model == "table_scaled"
        # third state x2: R_s [Ohm] (free) or the factor kappa [-] on R_s,nom (table_scaled)
        if self.scaled:
            self._q_x2, self._p0_x2, self._x2_0 = p.factor_q, p.factor_p0, 1.0
        else:
            self._q_x2, self._p0_x2, self._x2_0 = p.q_rs, p.p0_rs, p.rs0_ohm
        # theta = [R1 [Ohm], C1 [F]] (free) or [kappa_1, kappa_2] on R1,nom, C1,nom (table_scaled)
        self.rc_scaled = p.rc_model == "table_scaled"
        # the tracking update applies to the factors only (the free R1, C1 always follow the seed's 5.24)
        self.rc_tracking = self.rc_scaled and p.rc_update == "tracking"
        if self.rc_tracking:
            # kappa_1 in physical units (output noise in V^2); kappa_2 held at 1 (C1 = C1,nom; module docstring)
            self._q_th1, self._q_th2 = p.r1_factor_q, 0.0
            self._s0_th1, self._s0_th2 = p.factor_p0, 0.0
            self._th0 = (1.0, 1.0)
        elif self.rc_scaled:
            self._q_th1 = self._q_th2 = p.factor_q
            self._s0_th1 = self._s0_th2 = p.factor_p0
            self._th0 = (1.0, 1.0)
        else:
            self._q_th1, self._q_th2, self._s0_th1, self._s0_th2 = p.q_r1, p.q_c1, p.s0_r1, p.s0_c1
            self._th0 = (p.r1_0_ohm, p.c1_0_f)
        # the step is dekf_step, compiled (default) or its py_func (the same source run by Python)
        self.compiled = bool(compiled and HAVE_NUMBA)
        self._step = dekf_step if self.compiled else getattr(dekf_step, "py_func", dekf_step)
        self._tabs = self.tables.packed()
        self._k = np.array([p.capacity_ah, p.q_soc, p.q_v1, self._q_x2, p.r_v, self._q_th1, self._q_th2,
                            p.r1_min_ohm, p.r1_max_ohm, p.c1_min_f, p.c1_max_f, p.rs_min_ohm, FARADAY_C_MOL,
                            1.0 if self.scaled else 0.0, 1.0 if self.rc_scaled else 0.0,
                            1.0 if p.v2_model == "nominal_maps" else 0.0, 1.0 if self.rc_tracking else 0.0,
                            p.theta_r_v2, p.theta_window_s, float(p.diffusion_time_s)])
        self.reset()

    def reset(self, soc0_frac: float | None = None) -> None:
        """Restore the initial estimates and covariances."""
        p = self.params
        self.soc = p.soc0_frac if soc0_frac is None else float(soc0_frac)
        self.v1 = p.v1_0_v
        self.v2 = 0.0
        self.r2 = math.inf
        self.x2 = self._x2_0
        self.rs = p.rs0_ohm
        self.r1 = p.r1_0_ohm
        self.c1 = p.c1_0_f
        self.th1, self.th2 = self._th0
        # P_x symmetric 3x3: p00 p01 p02 / p11 p12 / p22
        self.px = [p.p0_soc, 0.0, 0.0, p.p0_v1, 0.0, self._p0_x2]
        # P_theta symmetric 2x2: s00 s01 / s11
        self.pth = [self._s0_th1, 0.0, self._s0_th2]
        self.innovation = 0.0
        self.xe[E.dsoc_dk1:E.dx2_dk1 + 1] = 0.0
        self.xe[E.r_theta] = p.theta_r_v2
        self.xe[E.wd] = 0.0

    # -- model ------------------------------------------------------------------------------
    def surface_soc(self, i_a: float) -> float:
        """SOC at the particles' surface with the current ``i_a`` flowing [1]: ``SOC + w - tau_d i / (105 Q)``
        (the SOC itself with ``diffusion_time_s = 0``)."""
        td = self.params.diffusion_time_s
        if not td > 0.0:
            return self.soc
        return self.soc + self.wd - DIFF_INSTANT * td * float(i_a) / (3600.0 * self.params.capacity_ah)

    def predict_voltage(self, i_a: float) -> float:
        """Terminal voltage g(x, i) of the current estimate [V] (the OCV at the surface SOC)."""
        return self.tables.ocv(self.surface_soc(i_a)) - self.v1 - self.v2 - self.rs * i_a

    def heat(self, i_a: float, t_mean_c: float) -> float:
        """Heat generation estimate [W] (5.16 with the OCV-R-RC model): i^2 R_s + V1^2/R1 - i T dS/F
        plus V2^2/R2,nom of the last step with ``v2_model = "nominal_maps"`` plus the diffusion overpotential's
        ``i (OCV(SOC) - OCV(surface))`` with ``diffusion_time_s > 0``."""
        q = cell_heat(float(i_a), self.rs, self.v1, self.r1, float(t_mean_c),
                      self.tables.entropy_change(self.soc)) + self.v2 * self.v2 / self.r2
        if self.params.diffusion_time_s > 0.0:
            q += float(i_a) * (self.tables.ocv(self.soc) - self.tables.ocv(self.surface_soc(i_a)))
        return q

    @property
    def rs_factor(self) -> float:
        """kappa = R_s / R_s,nom (``table_scaled``); ``nan`` for the free model."""
        return self.x2 if self.scaled else math.nan

    def step_heat(self, i_a: float, v_meas_v: float, dt_s: float, t_mean_c: float) -> float:
        """:meth:`step`, then :meth:`heat` at the new estimates; returns the heat [W].

        ``t_mean_c`` [degC] (the previous step's mean-temperature estimate) is used by the heat's
        entropic term and, for ``table_scaled``, by the R_s,nom lookup.
        """
        d, ix = self._tabs
        xe = self.xe
        ok, q = store_update(xe, self._step(d, ix, self._k, xe, float(i_a), float(v_meas_v), float(dt_s),
                                            float(t_mean_c)))
        if not ok:
            raise SimulationError(f"DEKF: non-finite or non-positive innovation variance "
                                  f"(innovation {self.xe[E.innovation]!r} V, variance {self.xe[E.variance]!r}; "
                                  f"inputs i={i_a!r} A, v={v_meas_v!r} V)")
        return q

    def step(self, i_a: float, v_meas_v: float, dt_s: float, t_c: float = 25.0) -> float:
        """One DEKF step with the measured cell current [A] (+ discharge) and voltage [V].

        ``t_c`` [degC]: cell temperature for the R_s,nom lookup (``table_scaled``; unused by ``free``).
        Returns the innovation ``y - g(x^-, i)`` [V].
        """
        self.step_heat(i_a, v_meas_v, dt_s, t_c)
        return self.innovation
