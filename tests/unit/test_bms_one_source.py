"""The BMS physics is written once: every model is a numba-compatible pure function compiled from its
source, and ``f.py_func`` is the same source run by Python.

* compiled vs ``py_func`` agree (to 1e-12 relative; in practice bit for bit) on varied inputs, for every
  one-source function of :mod:`shevsim.bms.thermal_estimators`, :mod:`shevsim.bms.electrical` and
  :mod:`shevsim.bms.power_capability`;
* independent checks that do not compare the two forms: the thermal matrices against scipy's ``expm``
  of :func:`shevsim.battery.thermal.two_state_matrices`, the KF's steady-state gain against the DARE,
  the DKF / JEKF convection estimate on a plant simulated with scipy, the DEKF's SOC on a synthetic
  OCV-R-RC cell, and the power capability against step-by-step simulations of the cell over the horizon.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import expm, solve_discrete_are

from shevsim.battery.cell import default_tables
from shevsim.battery.thermal import ThermalParams, two_state_matrices
from shevsim.bms import electrical as el
from shevsim.bms import power_capability as pc_mod
from shevsim.bms import thermal_estimators as te
from shevsim.bms.electrical import DEKF, DEKFParams
from shevsim.bms.power_capability import PowerCapability, PowerCapabilityParams
from shevsim.bms.thermal_estimators import ThermalDKF, ThermalJEKF, ThermalKF, TwoStateDiscretiser

pytestmark = pytest.mark.skipif(not te.HAVE_NUMBA, reason="numba not installed")

P = ThermalParams()
R, K, ALPHA = P.radius_m, P.kt_w_mk, P.alpha_m2_s
BQ = ALPHA / (K * P.volume_m3)
RTOL = 1e-12


def _close(a, b, rtol=RTOL):
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    np.testing.assert_allclose(a, b, rtol=rtol, atol=1e-300)


def _both(f, *args):
    return f(*args), f.py_func(*args)


# ---------------------------------------------------------------------------------------------
# compiled vs py_func
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("h", [0.0, 0.5, 3.0, 20.0, 56.2, 400.0, 1000.0])
@pytest.mark.parametrize("dt", [0.1, 1.0, 10.0, 100.0])
@pytest.mark.parametrize("euler", [False, True])
def test_two_state_model_functions_compiled_equal_py_func(h, dt, euler):
    _close(*_both(te.two_state_a, h, R, K, ALPHA))
    _close(*_both(te.two_state_out, h, R, K))
    _close(*_both(te.two_state_dout, h, R, K, 2.0))
    _close(*_both(te.two_state_ad_bd, h, R, K, ALPHA, BQ, dt, euler))
    _close(*_both(te.two_state_d_ad_bd, h, R, K, ALPHA, BQ, dt, euler))


def _thermal_inputs(n, seed):
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    y = 25.0 + 3.0 * np.sin(k / 300.0) + 0.02 * rng.standard_normal(n)
    y[n // 2:] += np.linspace(0.0, 2.0, n - n // 2)      # a cooling fault: the surface warms
    ta = 25.0 + 0.02 * rng.standard_normal(n)
    q = 0.5 + 0.4 * np.sin(k / 37.0) + 0.1 * rng.standard_normal(n)
    return y, ta, q


@pytest.mark.parametrize("make", [
    lambda c: ThermalKF(h_w_m2k=20.0, dt_s=0.1, x0_c=(25.0, 0.0), compiled=c),
    lambda c: ThermalKF(h_w_m2k=20.0, dt_s=1.0, discretisation="euler", compiled=c),
    lambda c: ThermalDKF(h0_w_m2k=20.0, dt_s=0.1, x0_c=(25.0, 0.0), sigma_c=0.0158, beta2=0.03, s0=1e-2,
                         compiled=c),
    lambda c: ThermalDKF(h0_w_m2k=80.0, dt_s=1.0, total_derivative=False, compiled=c),
    lambda c: ThermalDKF(h0_w_m2k=20.0, dt_s=1.0, discretisation="euler", compiled=c),
    lambda c: ThermalJEKF(h0_w_m2k=20.0, dt_s=0.1, x0_c=(25.0, 0.0), sigma_c=0.0158, beta2=0.03, s0=1e-2,
                          compiled=c),
    lambda c: ThermalJEKF(h0_w_m2k=5.0, dt_s=1.0, discretisation="euler", compiled=c),
], ids=["kf", "kf-euler", "dkf", "dkf-partial", "dkf-euler", "jekf", "jekf-euler"])
def test_thermal_filter_steps_compiled_equal_py_func(make):
    fast, ref = make(True), make(False)
    assert fast.compiled and not ref.compiled
    assert ref._step is fast._step.py_func
    y, ta, q = _thermal_inputs(3000, 0)
    for a, b, c in zip(y, ta, q):
        _close(fast.update(a, b, c), ref.update(a, b, c))
    _close(fast._st, ref._st)
    assert abs(fast.h - make(True).h) > 0.01 or isinstance(fast, ThermalKF)   # the h estimate moved


@pytest.mark.parametrize("rs_model,rc_model,v2_model,rc_update", [
    ("free", "free", "none", "seed"), ("table_scaled", "free", "none", "seed"),
    ("table_scaled", "table_scaled", "none", "seed"), ("table_scaled", "table_scaled", "nominal_maps", "seed"),
    ("free", "free", "nominal_maps", "seed"), ("table_scaled", "table_scaled", "nominal_maps", "tracking")])
def test_dekf_step_compiled_equals_py_func(rs_model, rc_model, v2_model, rc_update):
    prm = DEKFParams(q_soc=1e-5, q_v1=2e-3, q_rs=1e-8, q_c1=1e4, rs_model=rs_model, rc_model=rc_model,
                     v2_model=v2_model, rc_update=rc_update)
    fast, ref = DEKF(prm), DEKF(prm, compiled=False)
    assert ref._step is el.dekf_step.py_func
    rng = np.random.default_rng(3)
    for k in range(3000):
        i = 20.0 * math.sin(k / 50.0) + rng.normal(0.0, 5.0)
        v = 3.3 - 0.012 * i + rng.normal(0.0, 0.01) - 0.1 * math.sin(k / 3000.0)
        tm = 25.0 + 5.0 * math.sin(k / 1000.0)
        _close(fast.step_heat(i, v, 0.1, tm), ref.step_heat(i, v, 0.1, tm))
        _close([fast.soc, fast.v1, fast.v2, fast.x2, fast.rs, fast.r1, fast.c1, fast.innovation, *fast.px,
                *fast.pth], [ref.soc, ref.v1, ref.v2, ref.x2, ref.rs, ref.r1, ref.c1, ref.innovation, *ref.px,
                             *ref.pth])
    _close(fast.xe, ref.xe)              # the whole state array (the tracking update's sensitivities too)
    if rc_update == "tracking":
        assert fast.th1 != 1.0 and fast.th2 == 1.0 and fast.xe[el.E.dv1_dk1] != 0.0
    if v2_model == "nominal_maps":
        assert abs(fast.v2) > 1e-4 and fast.r2 > 0.0      # the slow branch was propagated
    else:
        assert fast.v2 == 0.0
    for f in (fast, ref):      # the same error from both forms
        with pytest.raises(Exception, match="innovation"):
            f.step(1.0, math.nan, 0.1)


def test_dekf_helpers_compiled_equal_py_func():
    d, ix = default_tables().packed()
    rng = np.random.default_rng(4)
    for _ in range(500):
        soc, t, i = rng.uniform(-0.1, 1.1), rng.uniform(-20.0, 60.0), rng.uniform(-60.0, 60.0)
        _close(*_both(el._ecm_nom, d, ix, soc, t, i))
        _close(*_both(el.cell_heat, i, rng.uniform(0.005, 0.02), rng.uniform(-0.1, 0.1), rng.uniform(0.005, 0.03),
                      t, rng.uniform(-0.5, 0.5)))


def _pc_state(rng):
    return (rng.uniform(0.0, 1.0), rng.uniform(-0.1, 0.1), rng.uniform(0.005, 0.02), rng.uniform(0.005, 0.03),
            rng.uniform(100.0, 5000.0), rng.uniform(15.0, 50.0), rng.uniform(-100.0, 100.0), rng.uniform(1.0, 100.0),
            rng.uniform(15.0, 40.0))


@pytest.mark.parametrize("mode,v2_model", [("exact", "none"), ("seed", "none"), ("exact", "nominal_maps")])
def test_power_capability_functions_compiled_equal_py_func(mode, v2_model):
    prm = PowerCapabilityParams(polarisation_heat=mode, i_cell_max_a=60.0 if mode == "seed" else math.inf,
                                v2_model=v2_model)
    fast, ref = PowerCapability(prm), PowerCapability(prm, compiled=False)
    assert ref._limits is pc_mod.power_limits.py_func
    d, ix = fast._tabs
    k = fast._k
    rng = np.random.default_rng(5)
    bound = set()
    for _ in range(2000):
        s = _pc_state(rng)
        v2 = rng.uniform(-0.06, 0.06)
        a, b = fast.compute(*s, 0.0, v2), ref.compute(*s, 0.0, v2)
        _close(a, b)
        bound.add(min((b.i_soc_min_a, "soc"), (b.i_v_min_a, "v"), (b.i_t_dch_a, "t"))[1])
        soc, v1, rs, r1, c1, tm, gamma, h, ta = s
        th = fast._thermal_coeffs(h)
        last = (rng.uniform(-100.0, 100.0), rng.uniform(-100.0, 100.0))
        _close(*_both(pc_mod._electrical_limits, d, ix, k, soc, v1, rs, r1, c1, 0.0, v2, tm))
        _close(*_both(pc_mod._thermal_limits, d, ix, k, th, pc_mod.CellEstimate(soc, v1, rs, r1, c1, tm, gamma, ta),
                      *last))
        _close(*_both(pc_mod._voltage_after, d, ix, k, rng.uniform(-100.0, 100.0), soc, v1, rs, r1, c1, 0.0, v2,
                      tm))
        for rho in (math.exp(-0.1 / (r1 * c1)), math.exp(-0.2 / (r1 * c1)), th[11]):   # incl. rho = eig
            _close(*_both(pc_mod._pole_sum, rho, th, float(prm.horizon_steps)))
    assert bound == {"soc", "v", "t"}
    assert (fast.last_i_max_a, fast.last_i_min_a) == (ref.last_i_max_a, ref.last_i_min_a)


# ---------------------------------------------------------------------------------------------
# independent checks
# ---------------------------------------------------------------------------------------------
def _scipy_zoh(h, dt):
    """Ad, Bd, C, D of the two-state model from scipy's expm of the augmented matrix."""
    A, B, C, D = two_state_matrices(P, h)
    m = np.zeros((4, 4))
    m[:2, :2] = A
    m[:2, 2:] = B
    e = expm(m * dt)
    return e[:2, :2], e[:2, 2:], C, D


@pytest.mark.parametrize("h", [0.0, 20.0, 56.2, 400.0])
def test_one_builder_matches_scipy_expm_of_the_battery_model(h):
    for dt in (0.1, 1.0, 10.0):
        Ad, Bd, C, D = _scipy_zoh(h, dt)
        np.testing.assert_allclose(te.two_state_ad_bd(h, R, K, ALPHA, BQ, dt, False), np.r_[Ad.ravel(), Bd.ravel()],
                                   rtol=1e-10, atol=1e-14)
        A, B, _, _ = two_state_matrices(P, h)
        np.testing.assert_allclose(te.two_state_a(h, R, K, ALPHA), A.ravel(), rtol=1e-14, atol=0.0)
        np.testing.assert_allclose(te.two_state_ad_bd(h, R, K, ALPHA, BQ, dt, True),
                                   np.r_[(np.eye(2) + A * dt).ravel(), (B * dt).ravel()], rtol=1e-13, atol=1e-16)
    cs0, cs1, ds, cc0, cc1, dc = te.two_state_out(h, R, K)
    np.testing.assert_allclose([cc0, cc1, dc, cs0, cs1, ds], [C[0, 0], C[0, 1], D[0, 1], C[1, 0], C[1, 1], D[1, 1]],
                               rtol=1e-13)


@pytest.mark.parametrize("compiled", [True, False])
def test_kf_gain_converges_to_the_dare_steady_state_gain(compiled):
    h, dt, sigma, beta = 30.0, 1.0, 0.05, 5e-4
    kf = ThermalKF(P, h, dt, x0_c=(27.0, 0.0), sigma_c=sigma, beta1=beta, compiled=compiled)
    for _ in range(20000):
        kf.update(27.0, 27.0, 0.0)
    Ad, _, C, _ = _scipy_zoh(h, dt)
    c = C[1:2, :]                                             # the surface-temperature row
    Q, Rv = beta ** 2 * np.eye(2), np.array([[sigma ** 2]])
    X = solve_discrete_are(Ad.T, c.T, Q, Rv)                   # steady-state a-priori covariance
    k_dare = (X @ c.T / (c @ X @ c.T + Rv)).ravel()
    Pp = np.array([[kf.p00, kf.p01], [kf.p01, kf.p11]])        # the filter's a-posteriori covariance
    Pm = Ad @ Pp @ Ad.T + Q                                    # -> its next a-priori covariance
    k_kf = (Pm @ c.T / (c @ Pm @ c.T + Rv)).ravel()
    np.testing.assert_allclose(k_kf, k_dare, rtol=1e-6)
    np.testing.assert_allclose(Pm, X, rtol=1e-6)


def _plant_run(n, h_true, dt=1.0, seed=0, t0=30.0):
    """Noise-free two-state plant stepped with scipy's expm (not with the estimators' builder)."""
    rng = np.random.default_rng(seed)
    Ad, Bd, C, D = _scipy_zoh(h_true, dt)
    x = np.array([t0, 0.0])
    out = []
    for k in range(n):
        q = 1.0 + 0.8 * math.sin(k / 60.0) + 0.3 * rng.standard_normal()
        ta = 27.0 + math.sin(2.0 * math.pi * k / 1800.0)
        u = np.array([q, ta])
        tc, ts = C @ x + D @ u
        out.append((tc, ts, ta, q))
        x = Ad @ x + Bd @ u
    return out


@pytest.mark.parametrize("cls", [ThermalDKF, ThermalJEKF])
def test_dkf_and_jekf_find_the_convection_coefficient_of_an_independent_plant(cls):
    h_true = 40.0
    f = cls(P, 15.0, 1.0, x0_c=(30.0, 0.0), sigma_c=0.05)
    for tc, ts, ta, q in _plant_run(4000, h_true):
        e = f.update(ts, ta, q)
    assert e.h_w_m2k == pytest.approx(h_true, rel=0.05)
    assert e.t_core_c == pytest.approx(tc, abs=0.05)


def test_dekf_soc_converges_on_a_synthetic_ocv_r_rc_cell():
    tab = default_tables()
    cap, rs, r1, c1, dt = 2.3, 0.010, 0.014, 2000.0, 0.1
    a = math.exp(-dt / (r1 * c1))
    soc, v1 = 0.60, 0.0
    # seed Table 5.4 tuning; the flat LFP OCV makes SOC weakly observable at 45-60 %: it takes ~30 min
    f = DEKF(DEKFParams(capacity_ah=cap, soc0_frac=0.45, rs0_ohm=rs, r1_0_ohm=r1, c1_0_f=c1))
    rng = np.random.default_rng(6)
    errs = []
    for k in range(20000):
        i = 15.0 * math.sin(k / 200.0) + 5.0 * math.sin(k / 23.0) + 2.0
        soc -= dt * i / (3600.0 * cap)
        v1 = a * v1 + r1 * (1.0 - a) * i
        v = tab.ocv(soc) - v1 - rs * i + rng.normal(0.0, 0.002)
        f.step(i, v, dt)
        errs.append(f.soc - soc)
    assert abs(errs[0]) > 0.1                           # it started 15 % off
    assert max(abs(e) for e in errs[-2000:]) < 0.015     # and converged
    assert f.rs == pytest.approx(rs, rel=0.2)


def _core_after_horizon(pc, h, soc, v1, rs, r1, c1, t_mean, gamma, ta, i):
    """Step-by-step simulation of the two-state model (scipy expm) over the horizon with the held
    current ``i``: heat ``i^2 R_s - i T_mean dS/F + V1_j^2 / R1`` with the RC branch stepped too."""
    p = pc.params
    Ad, Bd, C, D = _scipy_zoh(h, p.dt_s)
    ds = pc.tables.entropy_change(soc)
    mu = i * i * rs - i * (t_mean + 273.15) * ds / el.FARADAY_C_MOL
    a = math.exp(-p.dt_s / (r1 * c1))
    x = np.array([t_mean, gamma])
    for _ in range(p.horizon_steps):
        x = Ad @ x + Bd @ np.array([mu + v1 * v1 / r1, ta])
        v1 = a * v1 + r1 * (1.0 - a) * i
    return float(C[0] @ x + D[0] @ np.array([0.0, ta]))


@pytest.mark.parametrize("h,q0", [(20.0, 0.0), (4.0, 0.0), (56.2, 30.0)])
def test_exact_thermal_limit_puts_the_simulated_core_on_its_limit(h, q0):
    pc = PowerCapability(PowerCapabilityParams(polarisation_heat="exact"))
    soc, v1, rs, r1, c1, t_mean, gamma, ta = 0.5, 0.02, 0.012, 0.015, 1500.0, 38.0, -q0, 27.0
    i_d, i_c = pc.thermal_current_limits(soc, v1, rs, r1, c1, t_mean, gamma, h, ta)
    assert i_d > 0.0 > i_c
    for i in (i_d, i_c):
        assert _core_after_horizon(pc, h, soc, v1, rs, r1, c1, t_mean, gamma, ta, i) == \
            pytest.approx(pc.params.t_core_max_c, abs=1e-6)


@pytest.mark.parametrize("soc", [0.35, 0.5, 0.65])
def test_voltage_and_soc_limits_match_a_step_by_step_simulation(soc):
    pc = PowerCapability(PowerCapabilityParams())
    p, tab = pc.params, pc.tables
    v1, rs, r1, c1 = 0.03, 0.011, 0.014, 1800.0
    i_smin, i_smax, i_vmin, i_vmax = pc_mod.electrical_current_limits(soc, v1, rs, r1, c1, p, tab)
    a = math.exp(-p.dt_s / (r1 * c1))
    for i, v_lim in ((i_vmin, p.v_min_v), (i_vmax, p.v_max_v)):
        s, w = soc, v1
        for _ in range(p.horizon_steps):
            s -= p.dt_s * i / (3600.0 * p.capacity_ah)
            w = a * w + r1 * (1.0 - a) * i
        # the AP model: OCV linearised at SOC_k (4.15e)
        v = tab.ocv(soc) + tab.docv_dsoc(soc) * (s - soc) - w - rs * i
        assert v == pytest.approx(v_lim, abs=1e-9)
    for i, s_lim in ((i_smin, p.soc_min_frac), (i_smax, p.soc_max_frac)):
        s = soc
        for _ in range(p.horizon_steps):
            s -= p.dt_s * i / (3600.0 * p.capacity_ah)
        assert s == pytest.approx(s_lim, abs=1e-12)


def test_dkf_rejects_non_finite_measurements_in_both_forms():
    import math as _m

    from shevsim.bms.thermal_estimators import ThermalDKF
    from shevsim.core.errors import SimulationError
    for compiled in (True, False):
        f = ThermalDKF(dt_s=0.1, compiled=compiled)
        with pytest.raises(SimulationError, match="non-finite"):
            f.update(_m.nan, 25.0, 0.0)
