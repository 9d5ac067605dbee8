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

Solid diffusion (``diffusion_time_s`` = tau_d > 0; departure from the seed): the cell shows the OCV of its
particles' surface SOC (:mod:`shevsim.battery.model`).  Under the held current ``i`` the plant's exact
propagation of the diffusion state w over ``N dt`` (e_N = exp(-30 N dt / tau_d), k_w = (2/35) tau_d / Q)
gives the surface SOC after N steps::

    s_{k+N} = SOC_k + w_k e_N - i [N dt / Q + k_w (1 - e_N) + tau_d / (105 Q)]

and ``V_{k+N}`` reads the OCV there.  Within a 10 s horizon the surface moves several times further than the
bulk SOC (tau_d = 3000 s, 2.3 A.h: 6.6e-3 per ampere against the bulk's 1.2e-3), so without it the discharge
limit is optimistic, and so far that the OCV's linearisation (4.15e) fails in its knee: the currents that put
``V_{k+N}`` on V_min / V_max are solved on the OCV table itself (Newton's iteration from the linearised
solution, :func:`_surface_voltage_current`).  ``diffusion_time_s = 0`` is the prediction above,
bit for bit.

Slow second branch (``v2_model = "nominal_maps"``, the BMS component's default with its DEKF's of that name;
departure from the seed): the plant is OCV-R-RC-RC and its second branch is slow (tau_2 = R2 C2 ~ 220-400 s)
and large (19 mV after 300 s of 2C on the default tables).  The DEKF propagates its voltage V2 open loop from the
nominal R2, C2 maps (:mod:`shevsim.bms.electrical`); the power capability carries that V2_k over the horizon with
the plant's exact discretisation (current held, R2, C2 held at their values now)::

    V2_{k+N} = a2^N V2_k + R2 (1 - a2^N) i,    a2^N = exp(-N dt / (R2 C2))
    V_{k+N}  = V_oc(s_{k+N}) - a^N V1_k - a2^N V2_k - i [R_s + R1 (1 - a^N) + R2 (1 - a2^N)]

(``s_{k+N}`` the SOC of the lines above: linearised at SOC_k without diffusion, the surface SOC on the OCV table
with it).  R2, C2 are the nominal maps' at SOC_k and the mean-temperature estimate, of the direction of the test
current as in the plant: the discharge table for the V_min limit, the charge table for the V_max limit, and for
the voltage after N steps (5.36) the table of the limit current's sign.  A charged V2 moves both voltage limits
by ``a2^N V2_k / gain``; from rest (V2_k = 0) a horizon short against R2 C2 adds only the branch's charge-up,
``R2 (1 - a2^N) ~ N dt / C2`` (its capacitor), to the horizon's resistance.  Measured against the battery plant
(tests/unit/test_bms_slow_branch.py): held at the predicted 10 s discharge limit after 300 s of 2C / 4C discharge
the plant ends +2.4 / +0.04 mV from V_min (without V2: -20 / -41 mV), at the charge limit after 2C charge
-0.06 mV from V_max (without: +23 mV).  ``v2_model = "none"`` (the :class:`PowerCapabilityParams` default) does
not read V2: the seed's prediction above, bit for bit.  The thermal limit still takes the polarisation heat of
V1 only (V2^2 / R2 is left out of its horizon).

Limits (4.17 / 5.34): ``i_max = min(SOC_min, V_min, thermal[, rating])``,
``i_min = max(SOC_max, V_max, thermal[, rating])``; power (4.18-4.19 / 5.35-5.36):
``P = i V_{k+N}`` with ``V_{k+N}`` from the (nonlinear) OCV at the predicted SOC, times the
pack's ``n_s n_p``; reported as ``p_max_w = max(P_dch, 0)`` and ``p_min_w = min(P_chg, 0)``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from collections import namedtuple
from typing import NamedTuple

from shevsim.battery.cell import FARADAY_C_MOL, CellTables, default_tables
from shevsim.battery.model import DIFF_INSTANT, DIFF_W_GAIN, DIFF_W_RATE
from shevsim.battery.thermal import ThermalParams, two_state_ad_bd, two_state_out
from shevsim.core.compiled import field_index
from shevsim.core.lookup import HAVE_NUMBA, ecm_lookup, njit, py_func, t1_slope, t1_value
from shevsim.bms.thermal_estimators import TwoStateDiscretiser
from shevsim.core.errors import ScenarioError
from shevsim.core.params import rng

__all__ = ["PowerCapabilityParams", "PowerLimits", "PowerCapability", "electrical_current_limits"]


@dataclass(frozen=True)
class CellLimits:
    """The pack and the cell limits the power capability keeps, declared once: :class:`PowerCapabilityParams`
    and the BMS component's parameters (:class:`shevsim.components.bms.BMSParams`) derive from it (fields: see
    :class:`PowerCapabilityParams`)."""

    v_min_v: float = 2.0
    v_max_v: float = 3.6
    t_core_max_c: float = 45.0
    i_cell_max_a: float = field(default=math.inf, metadata=rng(gt=0.0, allow_inf=True))
    n_series: int = 130
    n_parallel: int = 10
    polarisation_heat: str = "exact"

    def __post_init__(self) -> None:
        if self.polarisation_heat not in ("seed", "exact"):
            raise ScenarioError(f"power capability: polarisation_heat must be 'seed' or 'exact', "
                                f"got {self.polarisation_heat!r}")


@dataclass(frozen=True)
class PowerCapabilityParams(CellLimits):
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
    diffusion_time_s : float
        The cell's solid-diffusion time R^2/D [s] (0 = off, the seed's prediction bit for bit): the OCV is
        read at the surface SOC along the horizon (module docstring, "Solid diffusion").
    v2_model : str
        ``"none"`` (the seed's one-branch prediction, bit for bit) or ``"nominal_maps"``: the slow second RC
        branch V2 the DEKF propagates (its ``v2_model`` of that name) is carried over the horizon with the
        nominal R2, C2 maps (module docstring, "Slow second branch").
    """

    horizon_steps: int = 100
    dt_s: float = 0.1
    soc_min_frac: float = 0.3
    soc_max_frac: float = 0.7
    capacity_ah: float = 2.3
    diffusion_time_s: float = 0.0
    v2_model: str = "none"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.v2_model not in ("none", "nominal_maps"):
            raise ScenarioError(f"power capability: v2_model must be 'none' or 'nominal_maps', got {self.v2_model!r}")
        if not (math.isfinite(self.diffusion_time_s) and self.diffusion_time_s >= 0.0):
            raise ScenarioError(f"power capability: diffusion_time_s must be finite and >= 0, "
                                f"got {self.diffusion_time_s!r}")
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


#: the memos of the thermal coefficients, one per (thermal parameters, horizon, step)
_CACHES: dict = {}


# ---------------------------------------------------------------------------------------------
# the power capability written ONCE as numba-compatible pure functions (compiled from their source;
# ``f.py_func`` runs the same source in Python, the reference of ``compiled=False``).
# ``d, ix`` = ``CellTables.packed()``; ``k`` = :func:`_constants`; ``th`` = :func:`thermal_coeffs`.
# ---------------------------------------------------------------------------------------------
def _constants(p: PowerCapabilityParams):
    """``k = [N, dt, soc_min, soc_max, v_min, v_max, t_core_max, i_cell_max, capacity_ah, n_pack, exact, F,
    float(N), diffusion_time_s, slow branch (1.0 with v2_model = "nominal_maps", else 0.0)]`` of ``p``."""
    import numpy as np
    return np.array([p.horizon_steps, p.dt_s, p.soc_min_frac, p.soc_max_frac, p.v_min_v, p.v_max_v,
                     p.t_core_max_c, p.i_cell_max_a, p.capacity_ah, float(p.n_series * p.n_parallel),
                     1.0 if p.polarisation_heat == "exact" else 0.0, FARADAY_C_MOL, float(p.horizon_steps),
                     float(p.diffusion_time_s), 1.0 if p.v2_model == "nominal_maps" else 0.0])


#: a row ``th`` of the thermal coefficients (:func:`thermal_coeffs`): ``A_N, B_N = ZOH(N dt)`` of the two-state
#: model (``a``, ``b``: rows 0-1, columns [q, T_amb]), its core-temperature output ``C_core`` (``cc0``, ``cc1``) and
#: ``D_core`` (``dc``), and ``A, B_q = ZOH(dt)`` (``e``, ``bq``)
TH = field_index(("a00", "a01", "a10", "a11", "b00", "b01", "b10", "b11", "cc0", "cc1", "dc", "e00", "e01", "e10",
                  "e11", "bq0", "bq1"), "TH")

#: the estimates one power-capability evaluation starts from (cell quantities: SOC [-], V1 [V], R_s, R1 [Ohm],
#: C1 [F], T_mean, gamma, T_amb [degC]); a numba-compatible record
CellEstimate = namedtuple("CellEstimate", ("soc", "v1", "rs", "r1", "c1", "t_mean_c", "gamma", "t_amb_c"))


@njit(cache=True)
def _pole_sum(rho, th, n):
    """``C_c (A_N - rho^N I) (A - rho I)^{-1} B_q`` of the 2x2 thermal model of the coefficients ``th``
    (:data:`TH`; ``n`` = float(N)); the removable singularity at ``rho = eig(A)`` is stepped around."""
    e01 = th[TH.e01]
    e10 = th[TH.e10]
    d00 = th[TH.e00] - rho
    d11 = th[TH.e11] - rho
    det = d00 * d11 - e01 * e10
    if abs(det) < 1e-13:
        rho *= 1.0 - 1e-6
        d00 = th[TH.e00] - rho
        d11 = th[TH.e11] - rho
        det = d00 * d11 - e01 * e10
    bq0 = th[TH.bq0]
    bq1 = th[TH.bq1]
    v0 = (d11 * bq0 - e01 * bq1) / det
    v1_ = (-e10 * bq0 + d00 * bq1) / det
    rn = math.pow(rho, n)
    return (th[TH.cc0] * (th[TH.a00] * v0 + th[TH.a01] * v1_ - rn * v0)
            + th[TH.cc1] * (th[TH.a10] * v0 + th[TH.a11] * v1_ - rn * v1_))


@njit(cache=True)
def _diffusion_horizon(k, wd):
    """The surface SOC after N steps at a held current ``i`` is ``SOC + s0 - i g`` (diffusion state ``wd`` now,
    the plant's exact propagation of :mod:`shevsim.battery.model` over ``N dt``): ``(s0, g)`` =
    ``(wd e_N, N dt / Q + k_w (1 - e_N) + tau_d / (105 Q))``, ``e_N = exp(-30 N dt / tau_d)``."""
    ndt = k[0] * k[1]
    q_as = 3600.0 * k[8]
    td = k[13]
    exn = math.exp(-ndt * DIFF_W_RATE / td)
    return wd * exn, ndt / q_as + DIFF_W_GAIN * td / q_as * (1.0 - exn) + DIFF_INSTANT * td / q_as


@njit(cache=True)
def _surface_voltage_current(d, ix, sf, g, r, free_rc, v_lim, i0):
    """The held current ``i`` with ``OCV(sf - i g) - free_rc - i r = v_lim`` (the voltage after N steps with
    solid diffusion on its limit), by Newton's iteration on the OCV table from the linearised solution ``i0``
    (at most 30 steps, to 1e-9 V; the table is piecewise linear, so it ends in a segment exactly; the
    voltage falls with the current wherever the OCV rises with SOC, else the iteration stops)."""
    i = i0
    for _ in range(30):
        f = t1_value(d, ix[0], ix[1], sf - i * g) - free_rc - i * r - v_lim
        den = r + t1_slope(d, ix[0], ix[1], sf - i * g) * g
        if abs(f) < 1e-9 or not den > 0.0:     # on the limit, or an OCV table falling with SOC: keep i
            break
        i += f / den
    return i


@njit(cache=True)
def _slow_branch(d, ix, k, soc, t_c, v2, sign):
    """The slow second branch's part of the voltage after N steps at a held current ``i`` of the sign of ``sign``:
    ``V2_{k+N} = f2 + i r2`` with ``(f2, r2) = (a2^N V2_k, R2 (1 - a2^N))``, ``a2^N = exp(-N dt / (R2 C2))``, the
    nominal R2, C2 at ``soc``, ``t_c`` of the table of that direction (discharge for ``sign >= 0``, the plant's
    convention); ``(0, 0)`` without the slow branch (``k[14]`` = 0)."""
    if not k[14] > 0.5:
        return 0.0, 0.0
    _rs, _r1, _c1, r2, c2 = ecm_lookup(d, ix, soc, t_c, sign)
    a2n = math.exp(-(k[0] * k[1]) / (r2 * c2))
    return a2n * v2, r2 * (1.0 - a2n)


@njit(cache=True)
def _electrical_limits(d, ix, k, soc, v1, rs, r1, c1, wd=0.0, v2=0.0, t_c=25.0):
    """``(i_soc_min, i_soc_max, i_v_min, i_v_max)`` [A], seed 5.28 (cell, + discharge); with solid diffusion
    (``k[13]`` > 0, diffusion state ``wd``) the OCV is read at the surface SOC after N steps, solved on the
    OCV table itself; with the slow branch (``k[14]`` = 1, its voltage ``v2`` now, the maps at ``t_c`` [degC])
    ``V2_{k+N}`` of the discharge table for V_min, of the charge table for V_max (module docstring)."""
    ndt = k[0] * k[1]
    q_as = 3600.0 * k[8]
    aN = math.exp(-ndt / (r1 * c1))
    f2d, r2d = _slow_branch(d, ix, k, soc, t_c, v2, 1.0)
    f2c, r2c = _slow_branch(d, ix, k, soc, t_c, v2, -1.0)
    if k[13] > 0.0:
        s0, g = _diffusion_horizon(k, wd)
        r = rs + r1 * (1.0 - aN)
        slope = t1_slope(d, ix[0], ix[1], soc + s0)
        free = t1_value(d, ix[0], ix[1], soc + s0) - aN * v1
        if k[14] > 0.5:
            i_vmin = _surface_voltage_current(d, ix, soc + s0, g, r + r2d, aN * v1 + f2d, k[4],
                                              (free - f2d - k[4]) / (r + r2d + slope * g))
            i_vmax = _surface_voltage_current(d, ix, soc + s0, g, r + r2c, aN * v1 + f2c, k[5],
                                              (free - f2c - k[5]) / (r + r2c + slope * g))
        else:
            gain = r + slope * g
            i_vmin = _surface_voltage_current(d, ix, soc + s0, g, r, aN * v1, k[4], (free - k[4]) / gain)
            i_vmax = _surface_voltage_current(d, ix, soc + s0, g, r, aN * v1, k[5], (free - k[5]) / gain)
        return (soc - k[2]) * q_as / ndt, (soc - k[3]) * q_as / ndt, i_vmin, i_vmax
    gain = rs + r1 * (1.0 - aN) + t1_slope(d, ix[0], ix[1], soc) * ndt / q_as
    free = t1_value(d, ix[0], ix[1], soc) - aN * v1
    if k[14] > 0.5:
        return ((soc - k[2]) * q_as / ndt, (soc - k[3]) * q_as / ndt, (free - f2d - k[4]) / (gain + r2d),
                (free - f2c - k[5]) / (gain + r2c))
    return (soc - k[2]) * q_as / ndt, (soc - k[3]) * q_as / ndt, (free - k[4]) / gain, (free - k[5]) / gain


@njit(cache=True)
def _voltage_after(d, ix, k, i_a, soc, v1, rs, r1, c1, wd=0.0, v2=0.0, t_c=25.0):
    """Predicted cell terminal voltage after N steps at the held current ``i_a`` (5.36) [V]; with solid
    diffusion (``k[13]`` > 0) the OCV at the surface SOC; with the slow branch (``k[14]`` = 1) less
    ``V2_{k+N}`` of the table of the current's direction."""
    ndt = k[0] * k[1]
    aN = math.exp(-ndt / (r1 * c1))
    if k[13] > 0.0:
        s0, g = _diffusion_horizon(k, wd)
        soc_n = soc + s0 - i_a * g
    else:
        soc_n = soc - i_a * ndt / (3600.0 * k[8])
    v = t1_value(d, ix[0], ix[1], soc_n) - i_a * rs - aN * v1 - i_a * r1 * (1.0 - aN)
    if k[14] > 0.5:
        f2, r2 = _slow_branch(d, ix, k, soc, t_c, v2, i_a)
        v -= f2 + i_a * r2
    return v


@njit(cache=True)
def _thermal_limits(d, ix, k, th, s, last_max, last_min):
    """``(i_t_dch, i_t_chg)`` [A] keeping the predicted core temperature <= T_c,max after N steps from the
    estimates ``s`` (:data:`CellEstimate`): exact quadratic (``k[10]`` = 1, module docstring) or the 5.31 bound
    with the previous limits ``last_*``."""
    soc, v1, rs, r1, c1, t_mean_c, gamma, t_amb_c = s
    a00, a01, a10, a11, b00, b01, b10, b11, cc0, cc1, dc = (th[0], th[1], th[2], th[3], th[4], th[5], th[6],
                                                            th[7], th[8], th[9], th[10])
    # free response of the core temperature (mu = 0, no polarisation heat)
    free = (cc0 * (a00 * t_mean_c + a01 * gamma + b01 * t_amb_c)
            + cc1 * (a10 * t_mean_c + a11 * gamma + b11 * t_amb_c) + dc * t_amb_c)
    gq = cc0 * b00 + cc1 * b10            # sum_i C A^i B_q  (> 0)
    beta = (t_mean_c + 273.15) * t1_value(d, ix[2], ix[3], soc) / k[11]
    if k[10] > 0.5:
        # S(rho) = C_c (A^N - rho^N I) (A - rho I)^{-1} B_q for rho = a and a^2
        a = math.exp(-k[1] / (r1 * c1))
        s1 = _pole_sum(a, th, k[12])
        s2 = _pole_sum(a * a, th, k[12])
        qa = gq * rs + r1 * (gq - 2.0 * s1 + s2)
        qb = -gq * beta + 2.0 * v1 * (s1 - s2)
        qc = free + v1 * v1 * s2 / r1 - k[6]
        disc = qb * qb - 4.0 * qa * qc
        if disc < 0.0:
            return -qb / (2.0 * qa), -qb / (2.0 * qa)
        sq = math.sqrt(disc)
        return (-qb + sq) / (2.0 * qa), (-qb - sq) / (2.0 * qa)
    aN = math.exp(-(k[0] * k[1]) / (r1 * c1))
    v1n = aN * v1 + r1 * (1.0 - aN) * last_max
    q_pol = max(v1 * v1, v1n * v1n) / r1          # 5.31
    mu_d = (k[6] - free - gq * q_pol) / gq
    v1n = aN * v1 + r1 * (1.0 - aN) * last_min
    q_pol = max(v1 * v1, v1n * v1n) / r1
    mu_c = (k[6] - free - gq * q_pol) / gq
    disc_d = beta * beta + 4.0 * rs * mu_d
    disc_c = beta * beta + 4.0 * rs * mu_c
    i_min_heat = beta / (2.0 * rs)
    return ((beta + math.sqrt(disc_d)) / (2.0 * rs) if disc_d >= 0.0 else i_min_heat,
            (beta - math.sqrt(disc_c)) / (2.0 * rs) if disc_c >= 0.0 else i_min_heat)


@njit(cache=True)
def power_limits(d, ix, k, th, s, last_max, last_min, wd=0.0, v2=0.0):
    """One power-capability evaluation (4.17-4.19 / 5.34-5.36) from the estimates ``s`` (:data:`CellEstimate`)
    with the thermal coefficients ``th`` (:data:`TH`), the previous limits ``last_*`` [A], the solid-diffusion
    state ``wd`` (read only with ``k[13]`` = diffusion_time_s > 0) and the slow branch's voltage ``v2`` [V] (read
    only with ``k[14]`` = 1, v2_model = "nominal_maps"; its maps at ``s.t_mean_c``): the 12 fields of
    :class:`PowerLimits`."""
    soc, v1, rs, r1, c1, t_c = s.soc, s.v1, s.rs, s.r1, s.c1, s.t_mean_c
    i_smin, i_smax, i_vmin, i_vmax = _electrical_limits(d, ix, k, soc, v1, rs, r1, c1, wd, v2, t_c)
    i_td, i_tc = _thermal_limits(d, ix, k, th, s, last_max, last_min)
    i_max = min(i_smin, i_vmin, i_td, k[7])
    i_min = max(i_smax, i_vmax, i_tc, -k[7])
    v_d = _voltage_after(d, ix, k, i_max, soc, v1, rs, r1, c1, wd, v2, t_c)
    v_c = _voltage_after(d, ix, k, i_min, soc, v1, rs, r1, c1, wd, v2, t_c)
    p_max = i_max * v_d * k[9]
    p_min = i_min * v_c * k[9]
    return (i_max, i_min, p_max if p_max > 0.0 else 0.0, p_min if p_min < 0.0 else 0.0,
            i_smin, i_smax, i_vmin, i_vmax, i_td, i_tc, v_d, v_c)


@njit(cache=True)
def round3(x):
    """Python's ``round(x, 3)`` (correctly rounded: the decimal ``x`` rounded half-even to 3 places, then
    the nearest double), the thermal coefficients' key."""
    if not math.isfinite(x):
        return x
    p = x * 1000.0
    if abs(p) >= 4503599627370496.0:       # 2**52: already an integer number of thousandths
        return x
    # exact error of the product x * 1000 (Dekker's two-product; 1000 splits exactly)
    c = 134217729.0 * x
    xh = c - (c - x)
    xl = x - xh
    e = (xh * 1000.0 - p) + xl * 1000.0
    fl = math.floor(p)
    d = (p - fl) - 0.5
    s = d + e
    if s > 0.0:
        q = fl + 1.0
    elif s < 0.0:
        q = fl
    else:
        q = fl if (fl % 2.0) == 0.0 else fl + 1.0
    r = q / 1000.0
    if r == 0.0:
        r = math.copysign(0.0, x)
    return r


@njit(cache=True)
def thermal_coeffs(tp, h_w_m2k, keys, vals):
    """The thermal coefficients :func:`power_limits` reads (``ZOH(N dt)`` (8), ``C_core/D_core`` (3), ``ZOH(dt)``
    A and B_q (6)) at ``h_w_m2k`` rounded to 1e-3 W/m^2/K (the estimated h changes a little every step; the
    effect on T_core is ~1e-5 K): a pure function of the rounded h and ``tp = [R, k, alpha, bq, N dt, dt]``,
    memoised in the direct-mapped table ``keys`` / ``vals``; returns the row of ``vals`` holding them."""
    hh = round3(h_w_m2k)
    n = keys.shape[0]
    q = hh * 1000.0
    slot = int(abs(q)) % n if math.isfinite(q) else 0
    if keys[slot] == hh:
        return slot
    a = two_state_ad_bd(hh, tp[0], tp[1], tp[2], tp[3], tp[4], False)
    o = two_state_out(hh, tp[0], tp[1])
    b = two_state_ad_bd(hh, tp[0], tp[1], tp[2], tp[3], tp[5], False)
    out = vals[slot]
    for j in range(8):
        out[j] = a[j]
    out[8] = o[3]
    out[9] = o[4]
    out[10] = o[5]
    out[11] = b[0]
    out[12] = b[1]
    out[13] = b[2]
    out[14] = b[3]
    out[15] = b[4]
    out[16] = b[6]
    keys[slot] = hh
    return slot


class _Memo:
    """The memo of :func:`thermal_coeffs` (a pure function): shared, never copied with the owner's state."""

    def __init__(self, n: int = 4096):
        import numpy as np
        self.keys = np.full(n, np.nan)
        self.vals = np.zeros((n, 17))

    def __deepcopy__(self, memo):
        return self

    def __copy__(self):
        return self


def electrical_current_limits(soc: float, v1: float, rs: float, r1: float, c1: float, p: PowerCapabilityParams,
                              tables: CellTables):
    """``(i_soc_min, i_soc_max, i_v_min, i_v_max)`` [A], seed 5.28 (cell, + discharge)."""
    d, ix = tables.packed()
    return _electrical_limits(d, ix, _constants(p), float(soc), float(v1), float(rs), float(r1), float(c1))


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
        Run :func:`power_limits` compiled (default) or its ``py_func`` (the same source in Python).

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
        key = ("memo", self.thermal_params, p.horizon_steps, p.dt_s)
        self._memo = _CACHES.get(key)
        if self._memo is None:
            self._memo = _CACHES[key] = _Memo()
        import numpy as np
        a_n, a_1 = self._discN._args, self._disc1._args
        if a_n[5] or a_1[5] or a_n[:4] != a_1[:4]:
            raise ScenarioError("power capability: the discretisations must be the ZOH of one cell")
        #: ``[R, k, alpha, bq, N dt, dt]`` of :func:`thermal_coeffs`
        self.thermal_args = np.array(a_n[:5] + (a_1[4],), dtype=np.float64)
        self.compiled = bool(compiled and HAVE_NUMBA)
        self._limits = power_limits if self.compiled else py_func(power_limits)
        self._tabs = self.tables.packed()
        self._k = _constants(p)
        self.last_i_max_a = 0.0
        self.last_i_min_a = 0.0

    def _thermal_coeffs(self, h_w_m2k: float):
        """:func:`thermal_coeffs` at ``h_w_m2k`` (a row of the shared memo)."""
        m = self._memo
        return m.vals[thermal_coeffs(self.thermal_args, float(h_w_m2k), m.keys, m.vals)]

    def arrays(self) -> tuple:
        """``(d, ix, k, thermal_args, memo keys, memo values)``: what :func:`power_limits` and
        :func:`thermal_coeffs` take."""
        return self._tabs[0], self._tabs[1], self._k, self.thermal_args, self._memo.keys, self._memo.vals

    def thermal_current_limits(self, soc: float, v1: float, rs: float, r1: float, c1: float,
                               t_mean_c: float, gamma: float, h_w_m2k: float, t_amb_c: float):
        """``(i_t_dch, i_t_chg)`` [A] keeping the predicted core temperature <= T_c,max after N steps."""
        d, ix = self._tabs
        s = CellEstimate(float(soc), float(v1), float(rs), float(r1), float(c1), float(t_mean_c), float(gamma),
                         float(t_amb_c))
        return _thermal_limits(d, ix, self._k, self._thermal_coeffs(h_w_m2k), s, self.last_i_max_a, self.last_i_min_a)

    def voltage_after(self, i_a: float, soc: float, v1: float, rs: float, r1: float, c1: float,
                      wd: float = 0.0, v2: float = 0.0, t_mean_c: float = 25.0) -> float:
        """Predicted cell terminal voltage after N steps at the held current (5.36) [V] (``wd``: the
        solid-diffusion state, read with ``diffusion_time_s > 0``; ``v2`` [V]: the slow branch's voltage, read
        with ``v2_model = "nominal_maps"``, its maps at ``t_mean_c`` [degC])."""
        d, ix = self._tabs
        return _voltage_after(d, ix, self._k, float(i_a), float(soc), float(v1), float(rs), float(r1), float(c1),
                              float(wd), float(v2), float(t_mean_c))

    def compute(self, soc: float, v1: float, rs: float, r1: float, c1: float, t_mean_c: float, gamma: float,
                h_w_m2k: float, t_amb_c: float, wd: float = 0.0, v2: float = 0.0) -> PowerLimits:
        """Current and power limits from the estimated states (SOC as a fraction, cell quantities; ``wd`` the
        solid-diffusion state, read with ``diffusion_time_s > 0``; ``v2`` [V] the slow branch's voltage (the
        DEKF's), read with ``v2_model = "nominal_maps"``)."""
        d, ix = self._tabs
        s = CellEstimate(float(soc), float(v1), float(rs), float(r1), float(c1), float(t_mean_c), float(gamma),
                         float(t_amb_c))
        r = self._limits(d, ix, self._k, self._thermal_coeffs(h_w_m2k), s, self.last_i_max_a, self.last_i_min_a,
                         float(wd), float(v2))
        self.last_i_max_a = r[0]
        self.last_i_min_a = r[1]
        return PowerLimits(*r)
