r"""mpc.py - linear MPC power split between engine-generator and battery (seed Sec. 5.2.2, App. C).

Model (seed 5.1-5.7, with the sign typo of 5.1b corrected: battery power ``u`` and current ``I``
positive = discharge)::

    dSOC/dt = -I / (3600 C_b),   I = (V_oc - sqrt(V_oc^2 - 4 R_s u)) / (2 R_s)          (5.1)
    v = P_d - u                                                                       (5.2)
    y = [SOC, sqrt(m_f(v))]                                                           (5.3)

linearised at the previous point (5.5-5.6): ``V_oc`` and ``R_s`` come from the BMS and are held,
so ``A = 0`` (``A_d = 1``); ``B = dphi/du = -(dI/du)/(3600 C_b)`` with ``dI/du = 1/sqrt(V_oc^2 - 4R_s u)``
at the linearisation power ``u_o = P_d,k - v_o`` (the battery power if the engine held its present
power ``v_o``), clipped to the BMS limits and to 90 % of the source's maximum-power point
``V_oc^2/(4 R_s)`` so the square root stays real; ``G_1`` follows from 5.6e.  ``H = d sqrt(m_f)/dv``
at the present engine power ``v_o`` (from the quasi-static curve, see :mod:`.fuel_curve`).
Discretised with ``dt`` (5.7).

Decision variables.  The seed optimises the battery-power moves ``Delta u`` (5.9).  With the demand
held over the horizon (5.10) the engine power is ``v_i = P_d - u_i``, so ``Delta v_i = -Delta u_i`` for
``i >= 1`` and ``Delta v_0 = (P_d - u_{k-1} - v_{k-1}) - Delta u_0``: an affine one-to-one change of
variables.  Here the engine-power moves ``z_j = Delta v_j`` (``j = 0..N_c-1``, held after ``N_c``) are
optimised directly, which gives the same optimum and makes the rate constraint (5.8d) simple
bounds.  The first move gives ``v_k = v_o + z_0`` (5.11).

Cost 5.8a over the prediction horizon (stage ``i = 0..N_p-1`` applies ``u_i, v_i`` and reaches
``SOC_{i+1}``)::

    J = sum_i eta1 (SOC_{i+1} - SOC_ref)^2 + eta2 (sqrt m_f(v_i))^2 + eta4 u_i^2  +  sum_j eta3 z_j^2
        + slack penalties

Units of the weights (Tables 5.2/A.1 give numbers without units): SOC as a *fraction*
(``y_1,ref = 0.5``), powers in *kW*, fuel rate in *kg/s*.  This is the only reading of the
published values in which the four terms are of comparable size (with W or g/s one term outweighs
the others by >= 10^3 and the split degenerates to "engine only" or "battery to its limit"); with
it the unconstrained fuel/battery balance ``eta2 dm_f/dv = 2 eta4 u`` gives ~24 kW of battery assist.

Constraints (5.8b-e) for ``j = 0..N_c-1`` (the input is held after ``N_c``), ``i = 1..N_p``:
``P_b,min <= u_j <= P_b,max`` (BMS limits), ``P_g,min <= v_j <= P_g,max``,
``Delta P_g,min dt <= z_j <= Delta P_g,max(v_o) dt`` (power-rate map at the present engine power,
held over the horizon as C.13), ``SOC_min <= SOC_i <= SOC_max``.
The SOC window is *soft*: one slack ``s_x >= 0`` [%] widens it, penalised ``rho1 s_x + rho2 s_x^2``
(exact penalty: when the window can be met the slack is zero).  The battery limits are soft in the
same way by default (``battery_limits_soft``), because when the demand exceeds what the rate-limited
engine plus the battery can deliver, no split meets them; with the setting off they are hard and
such a problem is infeasible -> fallback.  Engine limits and rates are always hard.

Scaling: SOC in %, power in kW, cost multiplied by ``kappa = 1/(eta3 + eta4 N_p)`` (Hessian entries
O(1)).  Because ``SOC_i`` is affine in ``i`` for ``i >= N_c`` (constant input), the SOC window
needs to be imposed only at ``i = 1..N_c`` and ``i = N_p``: the production QP has ``N_c + 2``
variables (moves, battery slack, SOC slack) and ``3 N_c + 2 (N_c + 1)`` rows.

Solve paths
-----------
``'daqp'`` (default) builds ``H, f`` and the bounds with one compiled (numba) function into
preallocated arrays, first solves the QP on the previous call's active set (one equality-constrained
solve, accepted only when it satisfies the QP's optimality conditions: 86 % of the calls on the UAC proxy;
``warm_active_set``) and otherwise calls DAQP with its active set warm-started from its previous call.  The whole
call is compiled (:func:`mpc_move`: build, DAQP's C library through :mod:`shevsim.supervisor.daqp_nb` - the
call sequence of ``daqp.Model`` -, first move, fallback); the compiled whole-vehicle loop calls the same
function.  ``compiled=False`` (or a DAQP build the binding does not know) runs the Python form
(``daqp.Model`` and the Python first move/fallback), the independent reference it equals bit for bit;
``'osqp'`` calls OSQP natively (eps 1e-6 + polish; measured 1-20 ms per call here and it can stop at its
iteration limit when a soft constraint is far from satisfied - that call then falls back; not
recommended, kept for comparison); ``'cvxpy'`` is the readable reference
(full horizon, every SOC constraint, built once with ``cp.Parameter``).  The paths agree to solver
precision (tests/unit/test_mpc.py); ``benchmarks/supervisor_call.py`` measures them.

Failures (non-finite inputs, infeasible QP, solver error): the call falls back - previous plan
shifted by one step (``fallback='shift'``) or the rule-based split (``'rule'``), projected onto the
engine limits and rate limits and, as far as possible, the battery limits - and
``fallback_count`` is incremented.  It never raises.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shevsim.core.errors import ScenarioError
from shevsim.core.lookup import py_max as _pmax
from shevsim.core.lookup import py_min as _pmin

from shevsim.core.compiled import field_index
from shevsim.supervisor import daqp_nb

from .fuel_curve import SqrtFuelCurve
from .rate_map import PowerRateMap
from .rule_based import rule_command

try:  # numba is a dependency; the pure-Python fallback keeps the module importable without it
    from numba import njit as _njit
except ImportError:  # pragma: no cover
    def _njit(*args, **kwargs):
        return lambda f: f

INF = 1e30          # "no bound" for DAQP and OSQP
SOLVERS = ("daqp", "osqp", "cvxpy")
FALLBACKS = ("shift", "rule")


@dataclass(frozen=True)
class MPCSettings:
    """Settings of the MPC supervisor (seed Table 5.2 / A.1 unless stated).

    Attributes
    ----------
    n_p, n_c : int
        Prediction and control horizons (Table 5.2: 40, 15).
    sample_time_s : float
        Sampling period [s] (Sec. 5.2.2: 0.2 s) = the supervisor component's step; also ``dt_s``.
    eta1_1, eta2_1, eta3_1, eta4_1 : float
        Weights of (SOC fraction - ref)^2, (sqrt(kg/s))^2, (Delta v per step in kW)^2, (u in kW)^2
        (Table 5.2: 4.17, 1, 2.5e-5, 1.25e-6; units: see the module docstring).
    soc_ref_pct, soc_min_pct, soc_max_pct : float
        SOC reference and window [%] (Table 5.2 y_1,ref = 0.5; Table A.1 SOC_min/max = 0.3/0.7).
    power_gen_min_w, power_gen_max_w : float
        Engine-generator electrical power limits [W].
    power_rate_min_wps : float
        Minimum (most negative) power rate [W/s] (Table 5.2: -60 kW/s).
    capacity_ah : float
        Pack capacity C_b [A.h] (10 parallel x 2.3 Ah, Table B.1).
    soc_slack_weight_1, soc_slack_weight_quad_1 : float
        Penalty of the SOC-window slack, per % and per %^2, in the units of J.
    battery_slack_weight_1, battery_slack_weight_quad_1 : float
        Penalty of the battery-limit slack, per kW and per kW^2, in the units of J.
    battery_limits_soft : bool
        Battery limits soft (exact penalty) or hard.
    solver : {'daqp', 'osqp', 'cvxpy'}
    cvxpy_solver : str
        Solver cvxpy uses for the reference path (default CLARABEL, interior point, tight).
    fallback : {'shift', 'rule'}
    warm_active_set : bool
        Solver 'daqp': try the previous call's active set first (:func:`solve_on_active_set`), DAQP when
        that is not the optimum (True, default); False: DAQP on every call.
    """

    n_p: int = 40
    n_c: int = 15
    sample_time_s: float = 0.2
    eta1_1: float = 4.17
    eta2_1: float = 1.0
    eta3_1: float = 2.5e-5
    eta4_1: float = 1.25e-6
    soc_ref_pct: float = 50.0
    soc_min_pct: float = 30.0
    soc_max_pct: float = 70.0
    power_gen_min_w: float = 0.0
    power_gen_max_w: float = 236e3
    power_rate_min_wps: float = -60e3
    capacity_ah: float = 23.0
    soc_slack_weight_1: float = 5.0
    soc_slack_weight_quad_1: float = 1.0
    battery_slack_weight_1: float = 5.0
    battery_slack_weight_quad_1: float = 0.1
    battery_limits_soft: bool = True
    solver: str = "daqp"
    cvxpy_solver: str = "CLARABEL"
    fallback: str = "shift"
    warm_active_set: bool = True

    @property
    def dt_s(self) -> float:
        """The sampling period [s] (``sample_time_s``)."""
        return self.sample_time_s

    def __post_init__(self) -> None:
        w = "MPC settings"
        if not (isinstance(self.n_c, int) and isinstance(self.n_p, int) and 1 <= self.n_c <= self.n_p):
            raise ScenarioError(f"{w}: need integers 1 <= n_c <= n_p, got n_c={self.n_c}, n_p={self.n_p}")
        for name in ("sample_time_s", "capacity_ah"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ScenarioError(f"{w}: {name} must be positive, got {v}")
        for name in ("eta1_1", "eta2_1", "eta3_1", "eta4_1", "soc_slack_weight_1", "soc_slack_weight_quad_1",
                     "battery_slack_weight_1", "battery_slack_weight_quad_1"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ScenarioError(f"{w}: {name} must be >= 0, got {v}")
        if self.eta3_1 <= 0 and self.eta4_1 <= 0:
            raise ScenarioError(f"{w}: eta3_1 or eta4_1 must be > 0 (strictly convex QP)")
        if self.soc_slack_weight_quad_1 <= 0 or self.battery_slack_weight_quad_1 <= 0:
            raise ScenarioError(f"{w}: the quadratic slack weights must be > 0 (strictly convex QP)")
        if not self.soc_min_pct < self.soc_ref_pct < self.soc_max_pct:
            raise ScenarioError(f"{w}: need soc_min_pct < soc_ref_pct < soc_max_pct, got {self.soc_min_pct}, "
                                f"{self.soc_ref_pct}, {self.soc_max_pct}")
        if not self.power_gen_min_w < self.power_gen_max_w:
            raise ScenarioError(f"{w}: power_gen_min_w must be < power_gen_max_w")
        if not (math.isfinite(self.power_rate_min_wps) and self.power_rate_min_wps < 0):
            raise ScenarioError(f"{w}: power_rate_min_wps must be negative, got {self.power_rate_min_wps}")
        if self.solver not in SOLVERS:
            raise ScenarioError(f"{w}: solver must be one of {SOLVERS}, got {self.solver!r}")
        if self.fallback not in FALLBACKS:
            raise ScenarioError(f"{w}: fallback must be one of {FALLBACKS}, got {self.fallback!r}")


# ---------------------------------------------------------------------------------------------
# the per-call vector build (compiled): state -> H, f, bounds
# ---------------------------------------------------------------------------------------------
# layout of the constant vector ``c`` passed to _build
_C_NAMES = ("dt", "cap_ah", "eta1f", "eta2", "eta3", "eta4", "kappa", "soc_ref", "soc_min", "soc_max",
            "pg_min", "pg_max", "dv_min", "rb1", "rb2", "rx1", "rx2", "soft_b")
_C = {n: i for i, n in enumerate(_C_NAMES)}
# layout of the auxiliary output vector
AUX_NAMES = ("beta", "d0", "u_lin", "hf", "s_o", "rate_up_dt", "phi_o", "b")


@_njit(cache=True, inline="always")
def _soc_linearisation(x, dt, cap):  # pragma: no cover - compiled
    """SOC model linearisation (5.1, 5.6) at ``u_lin`` inside the BMS limits and below the maximum-power point
    of the OCV-R source: ``(u_lin, phi_o [%/s], b [%/s per kW], beta [% per kW per step], d0 [% per step])``."""
    soc, pd, vo, voc, rs, pbmax, pbmin, rate_up = x
    u_lin = pd - vo
    if u_lin > pbmax:
        u_lin = pbmax
    if u_lin < pbmin:
        u_lin = pbmin
    u_mpp = 0.9 * voc * voc / (4.0 * rs) / 1000.0
    if u_lin > u_mpp:
        u_lin = u_mpp
    sq = math.sqrt(voc * voc - 4.0 * rs * u_lin * 1000.0)
    i_lin = (voc - sq) / (2.0 * rs)                  # A, + discharge
    phi_o = -100.0 * i_lin / (3600.0 * cap)          # %/s
    b = -100.0 * (1000.0 / sq) / (3600.0 * cap)      # %/s per kW (negative)
    beta = -dt * b                                   # % per kW per step (positive)
    d0 = dt * (phi_o + b * (pd - vo - u_lin))        # SOC change per step at held engine power
    return u_lin, phi_o, b, beta, d0


@_njit(cache=True, inline="always")
def _fuel_output(fp, fs, fsl, vo):  # pragma: no cover - compiled
    """Fuel output (5.3, 5.6d): ``(hf, s_o)``, the slope of sqrt(m_f) and its value at ``vo`` on the
    piecewise-linear curve ``fp -> fs`` (bisection: ``fp[lo] <= vo < fp[hi]``)."""
    lo = 0
    hi = fp.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if fp[mid] <= vo:
            lo = mid
        else:
            hi = mid
    hf = fsl[lo]
    return hf, fs[lo] + hf * (vo - fp[lo])


@_njit(cache=True, inline="always")
def _fill_objective(x, lin, fuel, qc, H, f):  # pragma: no cover - compiled
    """Hessian and gradient of the scaled QP (0.5 z'Hz + f'z, scaled by kappa), written into ``H, f``."""
    soc, pd, vo = x[0], x[1], x[2]
    beta, d0 = lin[3], lin[4]
    hf, s_o = fuel
    c, MtM, LtL, Mt1, Mtr, Lt1 = qc[0], qc[4], qc[5], qc[6], qc[7], qc[8]
    eta1f = c[2]
    eta2 = c[3]
    eta3 = c[4]
    eta4 = c[5]
    kap = c[6]
    nc = Lt1.shape[0]
    a1 = 2.0 * kap * eta1f * beta * beta
    a2 = 2.0 * kap * (eta2 * hf * hf + eta4)
    for r in range(nc):
        for q in range(nc):
            H[r, q] = a1 * MtM[r, q] + a2 * LtL[r, q]
        H[r, r] += 2.0 * kap * eta3
        H[r, nc] = 0.0
        H[r, nc + 1] = 0.0
        H[nc, r] = 0.0
        H[nc + 1, r] = 0.0
    H[nc, nc] = 2.0 * kap * c[14]
    H[nc, nc + 1] = 0.0
    H[nc + 1, nc] = 0.0
    sig = beta                                       # s_x [%] = beta * sigma_x
    H[nc + 1, nc + 1] = 2.0 * kap * c[16] * sig * sig
    e0 = soc - c[7]
    g1 = 2.0 * kap * eta1f * beta
    g2 = 2.0 * kap * (eta2 * hf * s_o - eta4 * (pd - vo))
    for r in range(nc):
        f[r] = g1 * (e0 * Mt1[r] + d0 * Mtr[r]) + g2 * Lt1[r]
    f[nc] = kap * c[13]
    f[nc + 1] = kap * c[15] * sig


@_njit(cache=True, inline="always")
def _fill_bounds(x, lin, qc, bu, bl):  # pragma: no cover - compiled
    """Bounds of the scaled QP, written into ``bu, bl``: simple bounds on the moves (5.8d) and the slacks, then
    the rows: engine limits (5.8c), battery limits (5.8b), SOC window (5.8e)."""
    soc, pd, vo, pbmax, pbmin, rate_up = x[0], x[1], x[2], x[5], x[6], x[7]
    beta, d0 = lin[3], lin[4]
    c, soc_idx = qc[0], qc[9]
    nc = qc[8].shape[0]
    n = nc + 2
    rate_up_dt = rate_up * c[0]
    dvmin = c[12]
    for r in range(nc):
        bl[r] = dvmin
        bu[r] = rate_up_dt
    bl[nc] = 0.0
    bu[nc] = 1e30 if c[17] > 0.5 else 0.0
    bl[nc + 1] = 0.0
    bu[nc + 1] = 1e30
    o = n
    for r in range(nc):
        bl[o + r] = c[10] - vo
        bu[o + r] = c[11] - vo
    o += nc
    for r in range(nc):
        bl[o + r] = pd - pbmax - vo
        bu[o + r] = 1e30
    o += nc
    for r in range(nc):
        bl[o + r] = -1e30
        bu[o + r] = pd - pbmin - vo
    o += nc
    ns = soc_idx.shape[0]
    for r in range(ns):
        i = soc_idx[r]
        bl[o + r] = (c[8] - soc - i * d0) / beta
        bu[o + r] = 1e30
        bl[o + ns + r] = -1e30
        bu[o + ns + r] = (c[9] - soc - i * d0) / beta
    return rate_up_dt


@_njit(cache=True)
def _build(x, qc, qw):  # pragma: no cover - compiled; the same code runs uncompiled in tests
    """Fill ``H, f, bu, bl`` of the scaled QP; return 0, or -1 for unusable inputs.

    ``x = (soc [%], pd [kW], vo [kW], voc [V], rs [Ohm], pbmax [kW], pbmin [kW], rate_up [kW/s])``: the
    operating point; ``qc`` = :attr:`MPCProblem.constants` (``c, fp, fs, fsl, MtM, LtL, Mt1, Mtr, Lt1,
    soc_idx``); ``qw`` = :attr:`MPCProblem.work` (``H, f, bu, bl, aux``, written).
    """
    soc, pd, vo, voc, rs, pbmax, pbmin, rate_up = x
    H, f, bu, bl, aux = qw
    if not (math.isfinite(soc) and math.isfinite(pd) and math.isfinite(vo) and math.isfinite(voc)
            and math.isfinite(rs) and math.isfinite(pbmax) and math.isfinite(pbmin) and math.isfinite(rate_up)):
        return -1
    if voc <= 0.0 or rs <= 0.0 or pbmax < pbmin:
        return -1
    c = qc[0]
    lin = _soc_linearisation(x, c[0], c[1])
    fuel = _fuel_output(qc[1], qc[2], qc[3], vo)
    _fill_objective(x, lin, fuel, qc, H, f)
    rate_up_dt = _fill_bounds(x, lin, qc, bu, bl)
    aux[0] = lin[3]
    aux[1] = lin[4]
    aux[2] = lin[0]
    aux[3] = fuel[0]
    aux[4] = fuel[1]
    aux[5] = rate_up_dt
    aux[6] = lin[1]
    aux[7] = lin[2]
    return 0


# ---------------------------------------------------------------------------------------------
# the whole call compiled (solver 'daqp'): build -> DAQP's C library -> first move or fallback
# ---------------------------------------------------------------------------------------------
# ``mp`` = [sample_time_s, n_c, pg_min_kw, pg_max_kw, fallback_shift, pg_min_w, pg_max_w, rate_min_wps, dt_s,
#           has_rule, rule_engine_on, warm_active_set];  ``x`` = [prev_cmd_w (the component's), fallback_count, plan_valid,
#           plan_age, battery_slack_w, soc_slack_pct, status]; status: 0 optimal, 1 unusable inputs, else the
#           DAQP exit flag (< 1) or -1000 (setup failed)
X_FIELDS = ("prev_cmd_w", "fallback_count", "plan_valid", "plan_age", "battery_slack_w", "soc_slack_pct", "status")


# ---------------------------------------------------------------------------------------------
# the previous call's active set tried first (both solve paths): one equality-constrained solve
# ---------------------------------------------------------------------------------------------
# Between two supervisor calls the QP changes a little (0.2 s of driving), and its optimal active set
# usually does not change at all (86 % of the calls over the UAC proxy x2).  So each call first solves
# the QP with the previous call's active constraints held as equalities (a KKT solve: Cholesky of H, the
# Schur complement of the active rows) and accepts that point when it is optimal for the whole QP - every
# constraint satisfied and every multiplier of the right sign, i.e. the KKT conditions of the strictly
# convex QP, whose minimiser is unique.  Otherwise (or when the active rows are dependent) DAQP solves the
# call as before, warm-started from its own working set, and its multipliers give the next active set.
# An accepted point is DAQP's own answer for that active set up to rounding (DAQP also ends with the
# equality-constrained solve of its final working set): 1e-13 kW apart over the UAC proxy x2
# (tests/unit/test_mpc.py checks it against DAQP on every call of a closed-loop sequence).
GUESS_PRIMAL_TOL = 1e-9     # constraint violation accepted, relative to 1 + |bound|
GUESS_DUAL_TOL = 1e-10      # multiplier of the wrong sign accepted, relative to 1 + max |multiplier|
GUESS_PIVOT_TOL = 1e-12     # Schur-complement pivot (relative to its diagonal) below which rows are dependent


def new_guess_state(n: int, m_total: int):
    """Buffers of the active-set guess for a QP with ``n`` variables and ``m_total`` bounds + rows:
    ``(wset, wsgn, kL, kY, kS, kv, kLU, kfac)``; ``wset[0]`` = number of active constraints (-1: none known),
    ``wset[1:]`` their indices, ``wsgn`` +1 (upper bound active) or -1 (lower); ``kLU``, ``kfac`` the LU
    factors of the last vertex set (``n`` active constraints) and ``[valid, its indices, row pivots]``."""
    wset = np.full(m_total + 1, -1, dtype=np.int64)
    return (wset, np.zeros(max(m_total, 1)), np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n)),
            np.zeros((3, n)), np.zeros((n, n)), np.zeros(2 * n + 1, dtype=np.int64))


@_njit(cache=True)
def set_active_from_lam(lam, m_total, wset, wsgn):
    """The active set of a DAQP solution: the constraints with a non-zero multiplier (DAQP's sign: > 0 the
    upper bound, < 0 the lower)."""
    cnt = 0
    for i in range(m_total):
        if lam[i] != 0.0:
            wset[1 + cnt] = i
            wsgn[cnt] = 1.0 if lam[i] > 0.0 else -1.0
            cnt += 1
    wset[0] = cnt


@_njit(cache=True)
def _primal_ok(A, bu, bl, z):
    """Every constraint ``bl <= [I; A] z <= bu`` holds (to :data:`GUESS_PRIMAL_TOL`) and ``z`` is finite."""
    n = z.shape[0]
    m_total = bu.shape[0]
    for i in range(n):
        if z[i] > bu[i] + GUESS_PRIMAL_TOL * (1.0 + abs(bu[i])) or z[i] < bl[i] - GUESS_PRIMAL_TOL * (1.0 + abs(bl[i])):
            return False
    for k in range(n):
        if not math.isfinite(z[k]):
            return False
    n4 = n - n % 4
    for i in range(n, m_total):
        a = A[i - n]
        s0 = 0.0                                  # four partial sums: independent chains (a check only:
        s1 = 0.0                                  # the answer z does not depend on their order)
        s2 = 0.0
        s3 = 0.0
        for k in range(0, n4, 4):
            s0 += a[k] * z[k]
            s1 += a[k + 1] * z[k + 1]
            s2 += a[k + 2] * z[k + 2]
            s3 += a[k + 3] * z[k + 3]
        for k in range(n4, n):
            s0 += a[k] * z[k]
        r = (s0 + s1) + (s2 + s3)
        if r > bu[i] + GUESS_PRIMAL_TOL * (1.0 + abs(bu[i])) or r < bl[i] - GUESS_PRIMAL_TOL * (1.0 + abs(bl[i])):
            return False
    return True


@_njit(cache=True)
def _signs_ok(mu, wset, wsgn, bu, bl, nw):
    """Every active inequality's multiplier has its sign (an equality, bl == bu, may take either)."""
    mmax = 0.0
    for c in range(nw):
        if not math.isfinite(mu[c]):
            return False
        if abs(mu[c]) > mmax:
            mmax = abs(mu[c])
    for c in range(nw):
        ic = wset[1 + c]
        if bu[ic] > bl[ic] and mu[c] * wsgn[c] < -GUESS_DUAL_TOL * (1.0 + mmax):
            return False
    return True


@_njit(cache=True)
def _vertex_factor(A, wset, LU, fac):
    """LU factors (partial pivoting) of the ``n`` active rows of ``[I; A]`` into ``LU`` / ``fac``; False when
    a pivot is below :data:`GUESS_PIVOT_TOL` times the largest entry (dependent rows)."""
    n = LU.shape[0]
    fac[0] = 0
    big = 0.0
    for c in range(n):
        ic = wset[1 + c]
        for k in range(n):
            LU[c, k] = 0.0 if ic < n else A[ic - n, k]
        if ic < n:
            LU[c, ic] = 1.0
        for k in range(n):
            if abs(LU[c, k]) > big:
                big = abs(LU[c, k])
        fac[1 + c] = ic
        fac[1 + n + c] = c
    for j in range(n):
        p = j
        amax = abs(LU[j, j])
        for i in range(j + 1, n):
            if abs(LU[i, j]) > amax:
                amax = abs(LU[i, j])
                p = i
        if not amax > GUESS_PIVOT_TOL * big:
            return False
        if p != j:
            for k in range(n):
                tmp = LU[j, k]
                LU[j, k] = LU[p, k]
                LU[p, k] = tmp
            q = fac[1 + n + j]
            fac[1 + n + j] = fac[1 + n + p]
            fac[1 + n + p] = q
        d = LU[j, j]
        for i in range(j + 1, n):
            li = LU[i, j] / d
            LU[i, j] = li
            if li != 0.0:
                for k in range(j + 1, n):
                    LU[i, k] -= li * LU[j, k]
    fac[0] = 1
    return True


@_njit(cache=True)
def _solve_on_vertex(H, f, A, bu, bl, wset, wsgn, kv, LU, fac, z):
    """:func:`solve_on_active_set` when ``n`` constraints are active: the point is the one where they all
    hold (``C z = b``, ``C`` their rows, LU-factored once per set and kept while the set is unchanged) and the
    multipliers solve ``C' mu = -(H z + f)``; 1 when it is the optimum, else 0."""
    n = H.shape[0]
    same = fac[0] == 1
    if same:
        for c in range(n):
            if fac[1 + c] != wset[1 + c]:
                same = False
                break
    if not same and not _vertex_factor(A, wset, LU, fac):
        return 0
    y = kv[0]
    for j in range(n):                        # P C = L U:  L y = P b,  U z = y
        r = fac[1 + n + j]
        ic = wset[1 + r]
        s = bu[ic] if wsgn[r] > 0.0 else bl[ic]
        for k in range(j):
            s -= LU[j, k] * y[k]
        y[j] = s
    for j in range(n - 1, -1, -1):
        s = y[j]
        for k in range(j + 1, n):
            s -= LU[j, k] * z[k]
        z[j] = s / LU[j, j]
    g = kv[1]                                 # g = -(H z + f)
    for i in range(n):
        s = f[i]
        for k in range(n):
            s += H[i, k] * z[k]
        g[i] = -s
    for j in range(n):                        # C' = U' L' P:  U' s = g,  L' t = s,  mu = P' t
        s = g[j]
        for k in range(j):
            s -= LU[k, j] * g[k]
        g[j] = s / LU[j, j]
    for j in range(n - 1, -1, -1):
        s = g[j]
        for k in range(j + 1, n):
            s -= LU[k, j] * g[k]
        g[j] = s
    mu = kv[2]
    for j in range(n):
        mu[fac[1 + n + j]] = g[j]
    if not _signs_ok(mu, wset, wsgn, bu, bl, n):
        return 0
    return 1 if _primal_ok(A, bu, bl, z) else 0


@_njit(cache=True, inline="always")
def _cholesky_upper(H, kU, n):
    """``H = U'U`` (U upper, in ``kU``); False when ``H`` is not positive definite."""
    for j in range(n):
        d = H[j, j]
        for k in range(j):
            d -= kU[k, j] * kU[k, j]
        if not d > 0.0:
            return False
        d = math.sqrt(d)
        kU[j, j] = d
        for i in range(j + 1, n):
            s = H[j, i]
            for k in range(j):
                s -= kU[k, i] * kU[k, j]
            kU[j, i] = s / d
    return True


@_njit(cache=True, inline="always")
def _active_columns(kU, A, wset, nw, n, kY):
    """``Y[:, c] = L^-1 a_c`` for each active constraint ``c`` (row ``c`` of ``[I; A]``; ``L = U'``), all columns at
    once (the inner loops run over independent columns: no chain of dependent additions)."""
    for i in range(n):
        for c in range(nw):
            ic = wset[1 + c]
            if ic < n:
                kY[i, c] = 1.0 if i == ic else 0.0
            else:
                kY[i, c] = A[ic - n, i]
        for k in range(i):
            lik = kU[k, i]
            for c in range(nw):
                kY[i, c] -= lik * kY[k, c]
        d = kU[i, i]
        for c in range(nw):
            kY[i, c] /= d


@_njit(cache=True, inline="always")
def _multipliers(qp, wset, wsgn, kY, kS, g, mu, nw, n):
    """The multipliers ``mu`` of the active constraints: ``S mu = t`` with ``S = Y'Y`` (its Cholesky factor in
    ``kS``, lower) and ``t = -(b + Y'g)``; False when ``S`` is singular (dependent active rows)."""
    bu, bl = qp[3], qp[4]
    for c in range(nw):
        ic = wset[1 + c]
        mu[c] = -(bu[ic] if wsgn[c] > 0.0 else bl[ic])
        for q in range(c + 1):
            kS[c, q] = 0.0
    for i in range(n):
        gi = g[i]
        for c in range(nw):
            yc = kY[i, c]
            mu[c] -= yc * gi
            for q in range(c + 1):
                kS[c, q] += yc * kY[i, q]
    for j in range(nw):
        d0 = kS[j, j]
        d = d0
        for k in range(j):
            d -= kS[j, k] * kS[j, k]
        if not d > GUESS_PIVOT_TOL * d0:
            return False
        d = math.sqrt(d)
        kS[j, j] = d
        for i in range(j + 1, nw):
            s = kS[i, j]
            for k in range(j):
                s -= kS[i, k] * kS[j, k]
            kS[i, j] = s / d
    for i in range(nw):                       # S mu = t: forward then backward substitution
        s = mu[i]
        for k in range(i):
            s -= kS[i, k] * mu[k]
        mu[i] = s / kS[i, i]
    for i in range(nw - 1, -1, -1):
        s = mu[i]
        for k in range(i + 1, nw):
            s -= kS[k, i] * mu[k]
        mu[i] = s / kS[i, i]
    return True


@_njit(cache=True)
def solve_on_active_set(qp, guess, z):
    """Minimise ``0.5 z'Hz + f'z`` with the constraints of the active set held as equalities; return 1 and the
    minimiser in ``z`` when it satisfies every constraint ``bl <= [I; A] z <= bu`` and every multiplier has
    its sign (the point is then the QP's optimum), else 0 (``z`` then holds no answer).

    ``qp = (H, f, A, bu, bl)``: ``H`` symmetric positive definite (n x n), ``A`` the general rows (the first ``n``
    constraints are the simple bounds of ``bu, bl``).  ``guess`` = :func:`new_guess_state`'s ``(wset, wsgn, kU,
    kY, kS, kv, kLU, kfac)``: the active set and the work buffers ``kU, kY, kS, kLU`` (n x n), ``kv`` (3 x n) and
    ``kfac`` (``2 n + 1`` integers).  With ``n`` active constraints (a vertex: half the calls of the UAC proxy)
    the point is fixed by them alone (:func:`_solve_on_vertex`); otherwise the range-space solve below."""
    H, f, A, bu, bl = qp
    wset, wsgn, kU, kY, kS, kv, kLU, kfac = guess
    nw = wset[0]
    n = H.shape[0]
    if nw < 0 or nw > n:
        return 0
    if nw == n:
        return _solve_on_vertex(H, f, A, bu, bl, wset, wsgn, kv, kLU, kfac, z)
    if not _cholesky_upper(H, kU, n):
        return 0
    # g = L^-1 f
    g = kv[0]
    for i in range(n):
        s = f[i]
        for k in range(i):
            s -= kU[k, i] * g[k]
        g[i] = s / kU[i, i]
    _active_columns(kU, A, wset, nw, n, kY)
    mu = kv[1]
    if not _multipliers(qp, wset, wsgn, kY, kS, g, mu, nw, n):
        return 0
    if not _signs_ok(mu, wset, wsgn, bu, bl, nw):
        return 0
    # z = -L^-T (g + Y' mu)
    w = kv[2]
    for i in range(n):
        w[i] = g[i]
    for i in range(n):
        for c in range(nw):
            w[i] += kY[i, c] * mu[c]
    for i in range(n - 1, -1, -1):
        s = w[i]
        for k in range(i + 1, n):
            s += kU[i, k] * z[k]                # z = -u with L'u = w
        z[i] = -s / kU[i, i]
    return 1 if _primal_ok(A, bu, bl, z) else 0


@_njit(cache=True)
def _rate(inner, rates, pw):
    lo = 0
    hi = inner.shape[0]
    while lo < hi:                    # bisect.bisect_right
        mid = (lo + hi) // 2
        if pw < inner[mid]:
            hi = mid
        else:
            lo = mid + 1
    return rates[lo]


@_njit(cache=True)
def _fallback(mp, rp, rinner, rrates, plan, x, soc, demand, gen, pmax_w, pmin_w, rate):
    nc = int(mp[1])
    vo = gen if math.isfinite(gen) else 0.0
    cand = math.nan
    if mp[4] > 0.5 and x[2] > 0.5 and x[3] + 1 < nc:         # 'shift': the previous plan, one step on
        x[3] += 1
        cand = plan[int(x[3])] * 1e3
    elif mp[9] > 0.5:                                          # the rule-based split
        on, cand = rule_command(rp, rinner, rrates, mp[10] > 0.5, soc, demand, gen, pmax_w, pmin_w)
    if not math.isfinite(cand):
        cand = vo
    if math.isfinite(demand) and math.isfinite(pmax_w) and math.isfinite(pmin_w) and pmin_w <= pmax_w:
        cand = _pmin(_pmax(cand, demand - pmax_w), demand - pmin_w)
    cand = _pmin(_pmax(cand, mp[5]), mp[6])
    up = rate if (math.isfinite(rate) and rate > 0) else 0.0
    return _pmin(_pmax(cand, vo + mp[7] * mp[8]), vo + up * mp[8])


#: index constants of the move's state ``x`` (:data:`X_FIELDS`)
X = field_index(X_FIELDS, "X")


@_njit(cache=True)
def first_move(mv, z, soc_scale, ok, soc, demand, gen, pmax_w, pmin_w, rate):
    """The command [W] of one call from a QP solution ``z`` (``ok``) or, without one, the fallback
    (:func:`_fallback`); every solver's path ends here.  ``mv = (mp, rp, rinner, rrates, x, plan)``: settings,
    the rule-based split's settings and rate map, the state (:data:`X`) and the plan (absolute engine powers
    [kW] of the last optimal solution), updated in place; ``soc_scale`` = ``aux[0]`` (slack to %)."""
    mp, rp, rinner, rrates, x, plan = mv
    vo = gen * 1e-3
    nc = int(mp[1])
    if ok:
        # solver tolerance (~1e-9 kW) may put the move a hair outside the engine limits
        v_cmd = _pmin(_pmax(vo + z[0], mp[2]), mp[3])
        acc = 0.0
        for j in range(nc):                   # the plan: cumsum(z[:nc]) + vo
            acc += z[j]
            plan[j] = acc
        for j in range(nc):
            plan[j] += vo
        x[X.plan_valid] = 1.0
        x[X.plan_age] = 0.0
        x[X.battery_slack_w] = z[nc] * 1e3
        x[X.soc_slack_pct] = z[nc + 1] * soc_scale
    else:
        v_cmd = _fallback(mp, rp, rinner, rrates, plan, x, soc, demand, gen, pmax_w, pmin_w, rate) * 1e-3
        x[X.fallback_count] += 1.0
        x[X.battery_slack_w] = 0.0
        x[X.soc_slack_pct] = 0.0
    return v_cmd * 1e3


@_njit(cache=True)
def mpc_move(a, soc, demand, gen, pmax_w, pmin_w, ocv, rs):
    """One supervisor call with solver 'daqp' (:meth:`MPCSupervisor.step`): ``(command_w, rate_max_wps)``; ``a``
    = :attr:`MPCSupervisor.arrays`.  The QP is first solved on the previous call's active set
    (:func:`solve_on_active_set`), then by DAQP's C library when that is not optimal; :func:`first_move`
    turns the solution (or its absence) into the command."""
    (mp, rp, inner, rates, rinner, rrates, x, plan, c, fp, fs, fsl, MtM, LtL, Mt1, Mtr, Lt1, soc_idx, H, f, A, bu,
     bl, aux, ws, qp, res, sense, z, lam, flags, wset, wsgn, kL, kY, kS, kv, kLU, kfac) = a
    rate = _rate(inner, rates, gen)
    st = _build((soc, demand * 1e-3, gen * 1e-3, ocv, rs, pmax_w * 1e-3, pmin_w * 1e-3, rate * 1e-3),
                (c, fp, fs, fsl, MtM, LtL, Mt1, Mtr, Lt1, soc_idx), (H, f, bu, bl, aux))
    if st == 0:
        if mp[11] > 0.5 and solve_on_active_set((H, f, A, bu, bl), (wset, wsgn, kL, kY, kS, kv, kLU, kfac), z) == 1:
            x[X.status] = 0.0
        else:
            flag = daqp_nb.solve(ws, qp, res, sense, z, lam, flags, H, f, A, bu, bl)
            x[X.status] = 0.0 if flag >= 1 else float(flag)
            if flag >= 1:
                set_active_from_lam(lam, bu.shape[0], wset, wsgn)
            else:
                wset[0] = -1
    else:
        x[X.status] = 1.0
    cmd = first_move((mp, rp, rinner, rrates, x, plan), z, aux[0], x[X.status] == 0.0, soc, demand, gen, pmax_w,
                     pmin_w, rate)
    return cmd, rate


def daqp_move():
    """:func:`mpc_move`, or None when DAQP's C library cannot be bound (:mod:`shevsim.supervisor.daqp_nb`; it is
    then never compiled, its external symbols never linked)."""
    return mpc_move if daqp_nb.available()[0] else None


class MPCProblem:
    """Constant matrices of the MPC QP and the per-call build.

    Parameters
    ----------
    settings : MPCSettings
    fuel_curve : SqrtFuelCurve
    compiled : bool
        Use the numba-compiled build (default) or the same code in Python.
    """

    def __init__(self, settings: MPCSettings, fuel_curve: SqrtFuelCurve, compiled: bool = True):
        s = settings
        self.settings = s
        self.fuel_curve = fuel_curve
        npred, nc = s.n_p, s.n_c
        self.n = nc + 2
        # L: engine-power change held after N_c (rows i = 0..N_p-1): v_i = v_o + (L z)_i
        L = np.zeros((npred, nc))
        for i in range(npred):
            L[i, : min(i, nc - 1) + 1] = 1.0
        M = np.cumsum(L, axis=0)                    # (M z)_{i-1}: sum over steps before SOC_i
        self.L, self.M = L, M
        idx = list(range(1, nc + 1))
        if npred > nc:
            idx.append(npred)
        self.soc_idx = np.array(idx, dtype=np.float64)
        ns = len(idx)
        self.m = 3 * nc + 2 * ns
        K2 = np.tril(np.ones((nc, nc)))
        A = np.zeros((self.m, self.n))
        A[0:nc, :nc] = K2
        A[nc:2 * nc, :nc] = K2
        A[nc:2 * nc, nc] = 1.0
        A[2 * nc:3 * nc, :nc] = K2
        A[2 * nc:3 * nc, nc] = -1.0
        Ms = M[np.array(idx) - 1, :]
        A[3 * nc:3 * nc + ns, :nc] = Ms
        A[3 * nc:3 * nc + ns, nc + 1] = 1.0
        A[3 * nc + ns:, :nc] = Ms
        A[3 * nc + ns:, nc + 1] = -1.0
        self.A = A
        self.MtM = M.T @ M
        self.LtL = L.T @ L
        self.Mt1 = M.sum(axis=0)
        self.Mtr = M.T @ np.arange(1.0, npred + 1)
        self.Lt1 = L.sum(axis=0)
        self.kappa = 1.0 / (s.eta3_1 + s.eta4_1 * npred)
        self.c = np.zeros(len(_C_NAMES))
        vals = dict(dt=s.dt_s, cap_ah=s.capacity_ah, eta1f=s.eta1_1 / 1e4, eta2=s.eta2_1, eta3=s.eta3_1,
                    eta4=s.eta4_1, kappa=self.kappa, soc_ref=s.soc_ref_pct, soc_min=s.soc_min_pct,
                    soc_max=s.soc_max_pct, pg_min=s.power_gen_min_w / 1e3, pg_max=s.power_gen_max_w / 1e3,
                    dv_min=s.power_rate_min_wps / 1e3 * s.dt_s, rb1=s.battery_slack_weight_1,
                    rb2=s.battery_slack_weight_quad_1, rx1=s.soc_slack_weight_1, rx2=s.soc_slack_weight_quad_1,
                    soft_b=1.0 if s.battery_limits_soft else 0.0)
        for k, v in vals.items():
            self.c[_C[k]] = v
        self.fp = np.ascontiguousarray(fuel_curve.p_kw)
        self.fs = np.ascontiguousarray(fuel_curve.s)
        self.fsl = np.ascontiguousarray(fuel_curve.slope)
        # work arrays
        self.H = np.zeros((self.n, self.n))
        self.f = np.zeros(self.n)
        self.bu = np.zeros(self.n + self.m)
        self.bl = np.zeros(self.n + self.m)
        self.aux = np.zeros(len(AUX_NAMES))
        self._build = _build if compiled else getattr(_build, "py_func", _build)

    def build(self, soc_pct, demand_kw, gen_kw, pbmax_kw, pbmin_kw, ocv_v, rs_ohm, rate_up_kwps) -> int:
        """Fill ``self.H, self.f, self.bl, self.bu, self.aux``; 0 on success, -1 for unusable inputs."""
        x = tuple(float(v) for v in (soc_pct, demand_kw, gen_kw, ocv_v, rs_ohm, pbmax_kw, pbmin_kw, rate_up_kwps))
        return self._build(x, (self.c, self.fp, self.fs, self.fsl, self.MtM, self.LtL, self.Mt1, self.Mtr, self.Lt1,
                               self.soc_idx), (self.H, self.f, self.bu, self.bl, self.aux))

    def aux_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in zip(AUX_NAMES, self.aux)}

    def objective(self, z: np.ndarray) -> float:
        """Scaled QP objective ``0.5 z'Hz + f'z`` of the last build."""
        return float(0.5 * z @ self.H @ z + self.f @ z)


# ---------------------------------------------------------------------------------------------
# solvers
# ---------------------------------------------------------------------------------------------
class _DaqpSolver:
    """DAQP with the active set kept between calls (warm start)."""

    def __init__(self, prob: MPCProblem, compiled: bool = True):
        import daqp
        self._daqp = daqp
        self.prob = prob
        self.model = None
        self.guess = new_guess_state(prob.n, prob.n + prob.m)
        self._guess = solve_on_active_set if compiled else getattr(solve_on_active_set, "py_func", solve_on_active_set)

    def _setup(self) -> int:
        p = self.prob
        self.model = self._daqp.Model()
        flag, _ = self.model.setup(p.H, p.f, p.A, p.bu, p.bl)
        return flag

    def solve(self):
        """Return ``(z or None, status)``."""
        p = self.prob
        g = self.guess
        z = np.empty(p.n)
        if p.settings.warm_active_set and self._guess((p.H, p.f, p.A, p.bu, p.bl), g, z) == 1:   # see above
            return z, "optimal"
        if self.model is None:
            if self._setup() < 0:
                self.model = None
                g[0][0] = -1
                return None, "setup failed"
        else:
            self.model.update(H=p.H, f=p.f, bupper=p.bu, blower=p.bl)
        x, _, flag, info = self.model.solve()
        if flag < 1:
            self.model = None            # start the next call from a clean workspace
            g[0][0] = -1
            return None, f"daqp exitflag {flag}"
        set_active_from_lam(info["lam"], p.n + p.m, g[0], g[1])
        return x, "optimal"


class _OsqpSolver:
    """OSQP called natively; ``P`` values updated each call (structure fixed)."""

    def __init__(self, prob: MPCProblem, eps: float = 1e-6):
        import osqp
        from scipy import sparse
        self.prob = prob
        n = prob.n
        iu = np.triu_indices(n)
        order = np.lexsort((iu[0], iu[1]))              # column-major (CSC) order
        self._pr, self._pc = iu[0][order], iu[1][order]
        P = sparse.csc_matrix((prob.H[self._pr, self._pc] + 0.0, (self._pr, self._pc)), shape=(n, n))
        P.data[:] = 1.0                                # fixed pattern; values set per call
        self._P = P
        # row scaling: the SOC rows are in kW-steps (divided by beta ~ 6e-4 %/kW-step); OSQP converges
        # far better with them back in % (fixed nominal beta at 3.6 V/cell-ish pack values is enough)
        beta0 = prob.settings.dt_s * 100.0 / (3600.0 * prob.settings.capacity_ah) * 1000.0 / 430.0
        self._row = np.ones(n + prob.m)
        self._row[n + 3 * prob.settings.n_c:] = beta0
        self._A = sparse.csc_matrix(np.vstack([np.eye(n), prob.A]) * self._row[:, None])
        self._osqp = osqp
        self.eps = eps
        self.solver = None

    def _setup(self):
        p = self.prob
        P = self._P.copy()
        P.data = p.H[self._pr, self._pc].copy()
        self.solver = self._osqp.OSQP()
        self.solver.setup(P, p.f.copy(), self._A, self._scaled(p.bl), self._scaled(p.bu), verbose=False,
                          eps_abs=self.eps,
                          eps_rel=self.eps, polishing=True, max_iter=50000, warm_starting=True)

    def _scaled(self, b):
        out = b * self._row
        out[b >= INF] = INF                  # keep "no bound" infinite for OSQP (1e30 x 6e-4 is finite)
        out[b <= -INF] = -INF
        return out

    def solve(self):
        p = self.prob
        if self.solver is None:
            self._setup()
        else:
            self.solver.update(Px=p.H[self._pr, self._pc], q=p.f, l=self._scaled(p.bl), u=self._scaled(p.bu))
        res = self.solver.solve()
        st = res.info.status
        if st not in ("solved",) or res.x is None or not np.all(np.isfinite(res.x)):
            self.solver = None
            return None, f"osqp {st}"
        return res.x, "optimal"


class CvxpyReference:
    """Readable reference QP in cvxpy, built once with ``cp.Parameter`` (full horizon, all constraints).

    Variables: engine-power moves ``dv`` [kW] (``N_c``), battery slack ``s_b`` [kW], SOC slack ``s_x`` [%].
    """

    def __init__(self, prob: MPCProblem, solver: str = "CLARABEL"):
        import cvxpy as cp
        s = prob.settings
        self.prob, self.solver, self.cp = prob, solver, cp
        npred, nc = s.n_p, s.n_c
        L = prob.L
        self.soc0 = cp.Parameter(name="soc0_pct")
        self.v_o = cp.Parameter(name="v_o_kw")
        self.u_held = cp.Parameter(name="pd_minus_vo_kw")      # battery power if the engine held v_o
        self.d0 = cp.Parameter(name="soc_drift_pct_per_step")   # SOC change per step at held engine power
        self.beta = cp.Parameter(nonneg=True, name="beta_pct_per_kw_step")  # -dt*B
        self.s_o = cp.Parameter(name="sqrt_mf_o")
        self.hf = cp.Parameter(name="dsqrt_mf_dv")
        self.rate_up = cp.Parameter(name="dv_max_kw_per_step")
        self.pbmax = cp.Parameter(name="pb_max_kw")
        self.pbmin = cp.Parameter(name="pb_min_kw")
        self.dv = cp.Variable(nc, name="dv_kw")
        self.s_b = cp.Variable(nonneg=True, name="battery_slack_kw")
        self.s_x = cp.Variable(nonneg=True, name="soc_slack_pct")
        dv = self.dv
        v = self.v_o + L @ dv                                        # engine power over the horizon (C.5)
        u = self.u_held - L @ dv                                     # battery power (5.2)
        soc = self.soc0 + cp.cumsum(self.d0 + self.beta * (L @ dv))  # SOC_1..SOC_Np (5.7a)
        y2 = self.s_o + self.hf * (L @ dv)                           # sqrt(m_f) (5.7b)
        J = (s.eta1_1 / 1e4 * cp.sum_squares(soc - s.soc_ref_pct) + s.eta2_1 * cp.sum_squares(y2)
             + s.eta3_1 * cp.sum_squares(dv) + s.eta4_1 * cp.sum_squares(u)
             + s.soc_slack_weight_1 * self.s_x + s.soc_slack_weight_quad_1 * cp.square(self.s_x)
             + s.battery_slack_weight_1 * self.s_b + s.battery_slack_weight_quad_1 * cp.square(self.s_b))
        cons = [dv >= s.power_rate_min_wps / 1e3 * s.dt_s, dv <= self.rate_up,            # 5.8d
                v[:nc] >= s.power_gen_min_w / 1e3, v[:nc] <= s.power_gen_max_w / 1e3,    # 5.8c
                u[:nc] <= self.pbmax + self.s_b, u[:nc] >= self.pbmin - self.s_b,         # 5.8b
                soc >= s.soc_min_pct - self.s_x, soc <= s.soc_max_pct + self.s_x]         # 5.8e
        if not s.battery_limits_soft:
            cons.append(self.s_b == 0)
        self.problem = cp.Problem(cp.Minimize(prob.kappa * J), cons)
        assert self.problem.is_dpp()

    def set_from_build(self, soc_pct: float, demand_kw: float, gen_kw: float, pbmax_kw: float, pbmin_kw: float):
        """Copy the linearisation of the last :meth:`MPCProblem.build` into the parameters."""
        a = self.prob.aux_dict()
        self.soc0.value = soc_pct
        self.v_o.value = gen_kw
        self.u_held.value = demand_kw - gen_kw
        self.d0.value = a["d0"]
        self.beta.value = a["beta"]
        self.s_o.value = a["s_o"]
        self.hf.value = a["hf"]
        self.rate_up.value = a["rate_up_dt"]
        self.pbmax.value = pbmax_kw
        self.pbmin.value = pbmin_kw

    def solve(self):
        """Return ``(z or None, status)`` with ``z = [dv..., s_b, s_x / beta]`` (the fast path's variables)."""
        cp = self.cp
        try:
            self.problem.solve(solver=self.solver, warm_start=True)
        except (cp.error.SolverError, ValueError, ArithmeticError) as exc:
            return None, f"cvxpy error: {exc}"
        if self.problem.status not in (cp.OPTIMAL,) or self.dv.value is None:
            return None, f"cvxpy {self.problem.status}"
        z = np.concatenate([self.dv.value, [self.s_b.value, self.s_x.value / self.beta.value]])
        return z, "optimal"


# ---------------------------------------------------------------------------------------------
# the supervisor
# ---------------------------------------------------------------------------------------------
@dataclass
class MPCResult:
    """Details of the last call (for outputs and tests)."""

    power_cmd_w: float = 0.0
    ok: bool = False
    status: str = ""
    battery_slack_w: float = 0.0
    soc_slack_pct: float = 0.0
    rate_max_wps: float = 0.0


class MPCSupervisor:
    """Linear MPC power split (seed 5.1-5.11) with a fast and a reference solve path.

    Parameters
    ----------
    settings : MPCSettings
    fuel_curve : SqrtFuelCurve
        Quasi-static fuel rate vs engine-generator electrical power.
    rate_map : PowerRateMap
        ``Delta P_g,max(P_g)`` [W/s]; evaluated at the present engine power.
    rule : object, optional
        A rule-based supervisor with ``split(...)`` used by ``fallback='rule'`` (and when no plan exists).

    Notes
    -----
    :meth:`step` takes SI inputs (W, %, V, Ohm) and returns the engine-generator electrical power
    command [W].  ``fallback_count`` counts calls that did not use a QP solution.
    """

    def __init__(self, settings: MPCSettings, fuel_curve: SqrtFuelCurve, rate_map: PowerRateMap,
                 rule=None, compiled: bool = True):
        self.settings = settings
        self.rate_map = rate_map
        self.prob = MPCProblem(settings, fuel_curve, compiled=compiled)
        self._compiled = compiled
        self.rule = rule
        self._nc = settings.n_c
        self._dv_min_kw = settings.power_rate_min_wps / 1e3 * settings.dt_s
        self._pg_min_kw = settings.power_gen_min_w / 1e3
        self._pg_max_kw = settings.power_gen_max_w / 1e3
        # solver 'daqp', compiled: the whole call is :func:`mpc_move` (the component's compiled step calls it too);
        # otherwise the solver object solves and :func:`first_move` makes the move.  Either way the state lives
        # in the arrays of ``self.arrays`` (X_FIELDS, the plan)
        self._move = daqp_move() if (compiled and settings.solver == "daqp") else None
        self._pack()
        if self._move is not None:
            self.solver_name = "daqp"
            self.solver = None
        else:
            self._make_solver(settings.solver)
        self.last = MPCResult()

    # -- the compiled call's state ------------------------------------------------------------------
    def _pack(self) -> None:
        s, p = self.settings, self.prob
        inner = np.array(self.rate_map._inner, dtype=np.float64)
        rates = np.array(self.rate_map.rates_wps, dtype=np.float64)
        r = self.rule
        if r is not None:
            rs = r.settings
            rp = np.array([rs.soc_min_pct, rs.soc_max_pct, rs.soc_ref_pct, rs.soc_on_pct, rs.soc_off_pct,
                           rs.charge_power_w, rs.engine_on_min_power_w, rs.engine_on_demand_w, rs.power_gen_min_w,
                           rs.power_gen_max_w, rs.power_rate_min_wps, r.dt_s], dtype=np.float64)
            rinner = np.array(r.rate_map._inner, dtype=np.float64)
            rrates = np.array(r.rate_map.rates_wps, dtype=np.float64)
        else:
            rp, rinner, rrates = np.zeros(12), np.zeros(0), np.ones(1)
        mp = np.array([s.dt_s, s.n_c, self._pg_min_kw, self._pg_max_kw, 1.0 if s.fallback == "shift" else 0.0,
                       s.power_gen_min_w, s.power_gen_max_w, s.power_rate_min_wps, s.dt_s,
                       1.0 if r is not None else 0.0, 0.0, 1.0 if s.warm_active_set else 0.0], dtype=np.float64)
        self._x = np.zeros(len(X_FIELDS))
        self._plan_arr = np.zeros(s.n_c)
        self._daqp = daqp_nb.new_state(p.n, p.n + p.m)
        self._guess = new_guess_state(p.n, p.n + p.m)
        self.arrays = (mp, rp, inner, rates, rinner, rrates, self._x, self._plan_arr, p.c, p.fp, p.fs, p.fsl, p.MtM,
                       p.LtL, p.Mt1, p.Mtr, p.Lt1, p.soc_idx, p.H, p.f, p.A, p.bu, p.bl, p.aux) + self._daqp + self._guess
        #: what :func:`first_move` takes
        self.move_state = (mp, rp, rinner, rrates, self._x, self._plan_arr)

    def __del__(self):
        d = getattr(self, "_daqp", None)
        if d is not None and d[6][0] != 0:
            try:
                daqp_nb.drop_model(d[0], d[6])
            except Exception:  # pragma: no cover - interpreter shutdown
                pass

    @property
    def compiled_call(self) -> bool:
        """True when :meth:`step` is the compiled :func:`mpc_move` (solver 'daqp', compiled)."""
        return self._move is not None

    @property
    def fallback_count(self) -> int:
        return int(self._x[X.fallback_count])

    @fallback_count.setter
    def fallback_count(self, v) -> None:
        self._x[X.fallback_count] = float(v)

    @property
    def _plan_age(self) -> int:
        return int(self._x[X.plan_age])

    @_plan_age.setter
    def _plan_age(self, v) -> None:
        self._x[X.plan_age] = float(v)

    @property
    def _plan_kw(self):
        """Absolute engine powers [kW] of the last optimal plan (a copy), None before the first solution."""
        return self._plan_arr.copy() if self._x[X.plan_valid] > 0.5 else None

    @_plan_kw.setter
    def _plan_kw(self, value) -> None:
        if value is None:
            self._x[X.plan_valid] = 0.0
        else:
            self._plan_arr[:] = value
            self._x[X.plan_valid] = 1.0

    def _make_solver(self, name: str) -> None:
        self.solver_name = name
        if name == "daqp":
            self.solver = _DaqpSolver(self.prob, compiled=self._compiled)
        elif name == "osqp":
            self.solver = _OsqpSolver(self.prob)
        else:
            self.solver = CvxpyReference(self.prob, self.settings.cvxpy_solver)

    def reset(self) -> None:
        """Forget the previous plan and the solver's warm start (not the fallback count)."""
        self._plan_kw = None
        self._plan_age = 0
        if self._move is not None:
            d = self._daqp
            daqp_nb.drop_model(d[0], d[6])    # next call sets DAQP up from scratch
            self._guess[0][0] = -1            # and no active set is known
        elif self.solver_name == "daqp":
            self.solver.model = None          # next call sets DAQP up from scratch
            self.solver.guess[0][0] = -1
        elif self.solver_name == "osqp":
            self.solver.solver = None

    @property
    def active_set(self):
        """The active set the next call tries first (:func:`solve_on_active_set`): ``(wset, wsgn)`` copies, or
        None (another solver).  Part of the supervisor's state: it decides which of two equal optima (to
        rounding) a call returns."""
        g = self._guess_state()
        return None if g is None else (g[0].copy(), g[1].copy())

    @active_set.setter
    def active_set(self, value) -> None:
        g = self._guess_state()
        if g is None:
            return
        if value is None:
            g[0][0] = -1
            return
        wset = np.asarray(value[0])
        wsgn = np.asarray(value[1])
        n, m_total = g[2].shape[0], g[0].shape[0] - 1
        k = int(wset[0]) if wset.shape == g[0].shape else -2
        # the compiled solve indexes A with these: refuse anything that is not a set of this QP's constraints
        if (wsgn.shape != g[1].shape or not -1 <= k <= n
                or (k > 0 and not (np.all((wset[1:1 + k] >= 0) & (wset[1:1 + k] < m_total))
                                   and np.all(np.abs(wsgn[:k]) == 1.0)))):
            raise ValueError(f"MPC active set: expected (indices of shape {g[0].shape} with a count in [-1, {n}] "
                             f"and indices in [0, {m_total}), signs of shape {g[1].shape} = +-1)")
        g[0][:] = wset
        g[1][:] = wsgn

    def _guess_state(self):
        if self._move is not None:
            return self._guess
        return self.solver.guess if self.solver_name == "daqp" else None

    def step(self, soc_pct: float, demand_w: float, gen_power_w: float, power_max_w: float,
             power_min_w: float, ocv_v: float, rs_ohm: float) -> float:
        """One supervisor call: state -> QP -> first move.  Returns the engine power command [W]."""
        self.arrays[0][10] = 1.0 if (self.rule is not None and self.rule.engine_on) else 0.0
        if self._move is not None:
            return self._step_compiled(soc_pct, demand_w, gen_power_w, power_max_w, power_min_w, ocv_v, rs_ohm)
        a = self.arrays
        rate = float(_rate(a[2], a[3], float(gen_power_w)))
        vo = gen_power_w * 1e-3
        st = self.prob.build(soc_pct, demand_w * 1e-3, vo, power_max_w * 1e-3, power_min_w * 1e-3, ocv_v,
                             rs_ohm, rate * 1e-3)
        if st == 0:
            if self.solver_name == "cvxpy":
                self.solver.set_from_build(soc_pct, demand_w * 1e-3, vo, power_max_w * 1e-3, power_min_w * 1e-3)
            try:
                z, status = self.solver.solve()
            except Exception as exc:  # a solver must never crash the run
                z, status = None, f"solver exception: {exc!r}"
        else:
            z, status = None, "unusable inputs (non-finite, V_oc <= 0, R_s <= 0 or P_b,max < P_b,min)"
        zz = self._daqp[4]                # the solution buffer of the compiled call, idle on this path
        if z is not None:
            zz[:] = z
        cmd = first_move(self.move_state, zz, float(self.prob.aux[0]), z is not None, float(soc_pct),
                         float(demand_w), float(gen_power_w), float(power_max_w), float(power_min_w), rate)
        self._x[X.status] = 0.0 if z is not None else 1.0
        return self._result(cmd, rate, status)

    _STATUS = {1.0: "unusable inputs (non-finite, V_oc <= 0, R_s <= 0 or P_b,max < P_b,min)",
               -1000.0: "daqp setup failed"}

    def _step_compiled(self, soc_pct, demand_w, gen_power_w, power_max_w, power_min_w, ocv_v, rs_ohm) -> float:
        cmd, rate = self._move(self.arrays, float(soc_pct), float(demand_w), float(gen_power_w), float(power_max_w),
                               float(power_min_w), float(ocv_v), float(rs_ohm))
        st = float(self._x[X.status])
        return self._result(cmd, rate, "optimal" if st == 0.0 else self._STATUS.get(st, f"daqp exitflag {int(st)}"))

    def _result(self, cmd: float, rate: float, status: str) -> float:
        """Fill :attr:`last` from the state the call left (every solver's path)."""
        x = self._x
        res = self.last
        res.rate_max_wps = rate
        res.ok = x[X.status] == 0.0
        res.status = status
        res.battery_slack_w = float(x[X.battery_slack_w])
        res.soc_slack_pct = float(x[X.soc_slack_pct])
        res.power_cmd_w = cmd
        return cmd

__all__ = ["MPCSettings", "MPCProblem", "MPCSupervisor", "CvxpyReference", "PowerRateMap", "SqrtFuelCurve",
           "AUX_NAMES", "INF"]
