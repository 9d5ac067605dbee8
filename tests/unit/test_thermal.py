"""Tests of the cell thermal models against the PDE's exact solutions (steady state, Laplace domain),
energy conservation and each other."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import ss2tf
from scipy.special import j0, j1

from shevsim.battery.thermal import (FDThermal, ThermalParams, TwoStateThermal, analytical_tf, fd_matrices,
                                     state_space_tf, steady_state, two_state_matrices)
from shevsim.battery.verification import (divergence_frequency, fim_estimability, frequency_responses,
                                          identifiability_jacobian, kappa_coefficients, mag_phase_error)
from shevsim.core.errors import ScenarioError, SimulationError

P21 = ThermalParams.table_2_1()
P31 = ThermalParams()


def test_table_values():
    # Table 2.1 / 3.1 volume 3.4219e-5 m^3 from R and L
    assert P21.volume_m3 == pytest.approx(3.4219e-5, rel=2e-4)
    assert P31.volume_m3 == pytest.approx(3.4219e-5, rel=2e-4)
    assert P31.density_kg_m3 == 2047.0 and P21.kt_w_mk == 0.488


@pytest.mark.parametrize("p", [P21, P31])
@pytest.mark.parametrize("h", [1.0, 5.0, 56.2, 500.0])
def test_two_state_static_gain_equals_pde_steady_state(p, h):
    A, B, C, D = two_state_matrices(p, h)
    G = -C @ np.linalg.solve(A, B) + D
    ss = steady_state(p, 1.0, 0.0, h)
    # the parabolic steady profile lies in the polynomial family -> exact (1e-10 relative)
    assert G[0, 0] == pytest.approx(ss["t_core_c"], rel=1e-10)
    assert G[1, 0] == pytest.approx(ss["t_surface_c"], rel=1e-10)
    assert G[:, 1] == pytest.approx([1.0, 1.0], rel=1e-12)
    x = -np.linalg.solve(A, B @ np.array([1.0, 0.0]))
    assert x[0] == pytest.approx(ss["t_mean_c"], rel=1e-10)
    assert x[1] == pytest.approx(ss["gamma_c_per_m"], rel=1e-10)


@pytest.mark.parametrize("h", [5.0, 56.2])
def test_analytical_static_gain_and_printed_j0_sign(h):
    p = P21
    H = analytical_tf(p, h, np.array([1e-14j]))[0]
    ss = steady_state(p, 1.0, 0.0, h)
    H0 = analytical_tf(p, h, np.array([0.0]))[0]          # exactly s = 0
    assert H0[0, 0].real == pytest.approx(ss["t_core_c"], rel=1e-12)
    assert H0[1, 0].real == pytest.approx(ss["t_surface_c"], rel=1e-12)
    # series branch and Bessel branch agree where they meet (|zeta R| ~ 1e-3)
    s_edge = 1e-6 * p.alpha_m2_s / p.radius_m ** 2 * 1j      # |zeta R| = 1e-3
    Hb = analytical_tf(p, h, np.array([s_edge * 0.99, s_edge * 1.01]))
    assert np.allclose(Hb[0], Hb[1], rtol=1e-6)
    assert H[0, 0].real == pytest.approx(ss["t_core_c"], rel=1e-6)
    assert H[1, 0].real == pytest.approx(ss["t_surface_c"], rel=1e-6)
    assert H[0, 1].real == pytest.approx(1.0, rel=1e-6)
    # the printed (2.7c) with J0/J1 gives the wrong sign of the static gain of T_s/Q
    s = 1e-9
    z = math.sqrt(s / p.alpha_m2_s)
    hk = h / p.kt_w_mk
    h21_printed = (-z * j1(p.radius_m * z)) / (hk * j0(p.radius_m * z) - z * j1(p.radius_m * z)) \
        * p.alpha_m2_s / (p.kt_w_mk * p.volume_m3 * s)
    assert h21_printed < 0 < ss["t_surface_c"]


@pytest.mark.parametrize("h", [0.0, 5.0, 56.2])
def test_energy_conservation_two_state_and_fv(h):
    rng = np.random.default_rng(3)
    cap = P31.heat_capacity_j_k
    A, B, C, D = two_state_matrices(P31, h)
    An, Bn, Cn, Dn, w = fd_matrices(P31, h, 30, "fv")
    for _ in range(5):
        q, ta = rng.uniform(-2, 5), rng.uniform(-10, 40)
        x = np.array([rng.uniform(0, 50), rng.uniform(-500, 500)])
        ts = (C @ x + D @ [q, ta])[1]
        assert cap * (A @ x + B @ [q, ta])[0] == pytest.approx(q - h * P31.surface_m2 * (ts - ta), abs=1e-9)
        xn = rng.uniform(0, 50, 30)
        tsn = (Cn @ xn + Dn @ [q, ta])[1]
        assert cap * w @ (An @ xn + Bn @ [q, ta]) == pytest.approx(q - h * P31.surface_m2 * (tsn - ta), abs=1e-9)
    assert w.sum() == pytest.approx(1.0, abs=1e-14)


def test_step_is_exact_zoh_and_matches_ode_solver():
    m = TwoStateThermal(P31)
    A, B, C, D = two_state_matrices(P31, 20.0)
    u = np.array([2.0, 25.0])
    x0 = (30.0, -50.0)
    x = x0
    for _ in range(10):
        x = m.step(x, 2.0, 25.0, 20.0, 6.0)
    sol = solve_ivp(lambda t, y: A @ y + B @ u, (0, 60.0), list(x0), rtol=1e-11, atol=1e-11)
    assert x == pytest.approx(tuple(sol.y[:, -1]), rel=1e-8, abs=1e-7)
    x2 = m.step(x0, 2.0, 25.0, 20.0, 60.0)
    assert x2 == pytest.approx(x, rel=1e-12, abs=1e-9)
    yc, ys = m.outputs(x, 2.0, 25.0, 20.0)
    assert (yc, ys) == pytest.approx(tuple(C @ np.array(x) + D @ u), rel=1e-12)


def test_long_run_reaches_steady_state_all_models():
    h, q, ta = 20.0, 1.5, 25.0
    ss = steady_state(P31, q, ta, h)
    for m in (TwoStateThermal(P31), FDThermal(P31, 30, "fv")):
        x = m.initial_state(ta)
        for _ in range(100):
            x = m.step(x, q, ta, h, 200.0)
        tc, ts = m.outputs(x, q, ta, h)
        assert ts == pytest.approx(ss["t_surface_c"], abs=1e-9)
        assert tc == pytest.approx(ss["t_core_c"], abs=2e-3)   # FV core via quadratic extrapolation
    m = FDThermal(P31, 30, "fv")
    x = m.initial_state(ta)
    x = m.step(x, q, ta, h, 2e4)
    # second-order discretisation error: node values sit c*dr^2/4 high (half-cell surface resistance) and
    # the cell-centre mean of a parabola is c*dr^2/4 low of the cell average -> c*dr^2/2, c = q/(4 k V)
    c = q / (4 * P31.kt_w_mk * P31.volume_m3)
    dr = P31.radius_m / 30
    assert m.mean_temperature(x) - ss["t_mean_c"] == pytest.approx(c * dr ** 2 / 2, rel=1e-3)


F = np.logspace(-6, 0, 61)


@pytest.fixture(scope="module")
def fr():
    return frequency_responses(P21, 5.0, F, n_nodes=30)


def test_heat_input_responses_two_state_vs_analytical(fr):
    # seed Sec. 2.2.4: heat input -> core/surface accurate over the whole range; stated tolerance 0.2 dB, 1 deg
    for i in (0, 1):
        e_db, e_deg = mag_phase_error(fr["two_state"][:, i, 0], fr["analytical"][:, i, 0])
        assert np.max(np.abs(e_db)) < 0.2
        assert np.max(np.abs(e_deg)) < 1.0


def test_heat_input_high_frequency_asymptote():
    # s -> inf: uniform heating dominates, analytical H11 -> alpha/(k V s); the two-state model's
    # H11 -> C[0,0] alpha/(k V s), so the ratio tends to (24k - 3Rh)/(24k + Rh) (-0.193 dB for h = 5)
    p, h = P21, 5.0
    s = np.array([2j * np.pi * 10.0])
    A, B, C, D = two_state_matrices(p, h)
    r = state_space_tf(A, B, C, D, s)[0, 0, 0] / analytical_tf(p, h, s)[0, 0, 0]
    k, R = p.kt_w_mk, p.radius_m
    assert abs(r) == pytest.approx((24 * k - 3 * R * h) / (24 * k + R * h), rel=2e-3)


def test_ambient_responses_agree_at_low_frequency_and_diverge_above(fr):
    for i in (0, 1):
        Hp, Ha = fr["two_state"][:, i, 1], fr["analytical"][:, i, 1]
        e_db, e_deg = mag_phase_error(Hp, Ha)
        low = F <= 1e-3
        assert np.max(np.abs(e_db[low])) < 0.3 and np.max(np.abs(e_deg[low])) < 3.0
        fdiv = divergence_frequency(F, Hp, Ha, 0.5, 5.0)
        assert 1e-3 < fdiv < 2e-2          # measured: 2.4e-3 Hz (core), 7.1e-3 Hz (surface)
        assert np.max(np.abs(e_db[F >= 0.1])) > 3.0   # clearly different at high frequency


def test_fv_30_nodes_matches_analytical(fr):
    for i in (0, 1):
        e_db, e_deg = mag_phase_error(fr["fd"][:, i, 0], fr["analytical"][:, i, 0])
        assert np.max(np.abs(e_db)) < 0.02 and np.max(np.abs(e_deg)) < 0.1
    e_db, e_deg = mag_phase_error(fr["fd"][:, 1, 1], fr["analytical"][:, 1, 1])
    low = F <= 1e-2
    assert np.max(np.abs(e_db[low])) < 0.02 and np.max(np.abs(e_deg[low])) < 0.5  # measured 0.0023 dB, 0.24 deg


@pytest.mark.parametrize("scheme,order", [("fv", 1.8), ("fd", 0.9)])
def test_discretisation_converges_to_analytical(scheme, order):
    f = np.array([1e-5, 1e-4, 1e-3, 1e-2])
    s = 2j * np.pi * f
    Ha = analytical_tf(P21, 5.0, s)
    errs = []
    for n in (10, 20, 40):
        A, B, C, D, _ = fd_matrices(P21, 5.0, n, scheme)
        Hn = state_space_tf(A, B, C, D, s)
        errs.append(np.max(np.abs(Hn[:, :, 0] - Ha[:, :, 0]) / np.abs(Ha[:, :, 0])))
    rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(rates > order), (errs, rates)


def test_kappa_coefficients_reproduce_state_space_transfer_function():
    for p, h in ((P21, 5.0), (P31, 56.2)):
        A, B, C, D = two_state_matrices(p, h)
        k = kappa_coefficients(p, h)
        n0, d0 = ss2tf(A, B, C, D, input=0)
        n1, d1 = ss2tf(A, B, C, D, input=1)
        np.testing.assert_allclose(d0, k[:3] / k[0], rtol=1e-9)
        np.testing.assert_allclose(n0[0], np.r_[0, k[3:5]] / k[0], rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(n0[1], np.r_[0, k[5:7]] / k[0], rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(n1[0], np.r_[k[7], k[8], k[9]] / k[0], rtol=1e-9)
        np.testing.assert_allclose(n1[1], np.r_[k[10], k[11], k[9]] / k[0], rtol=1e-9)
        printed = kappa_coefficients(p, h, corrected=False)
        assert not np.isclose(printed[1] / printed[0], d0[1], rtol=1e-3)   # seed's kappa_2 typo
        assert not np.isclose(printed[7] / printed[0], n1[0][0], rtol=1e-3)  # seed's kappa_8 typo


def test_structural_identifiability_rank_three():
    for p, h in ((P21, 5.0), (P31, 56.2), (P31, 3.0)):
        J, sv, rank = identifiability_jacobian(p, h)
        assert rank == 3 and sv[-1] / sv[0] > 1e-3
        J2, sv2, rank2 = identifiability_jacobian(p, h, normalise=False)
        assert rank2 == 3


def test_fim_estimability_ranking():
    rng = np.random.default_rng(0)
    q = np.repeat(rng.uniform(0, 4, 60), 30)          # 1800 s of 30-s steps of heat
    r1 = fim_estimability(P31, 56.2, 1.0, q, 25.0, outputs=("surface",))
    r2 = fim_estimability(P31, 56.2, 1.0, q, 25.0, outputs=("surface", "core"))
    # seed 3.9: with T_s only k_t is least estimable, then c_p, then h; core measurement helps a lot
    assert r1["ranking"] == ["kt_w_mk", "cp_j_kgk", "h_w_m2k"]
    assert r1["condition_number"] > 10 * r2["condition_number"]
    assert r1["covariance"][0, 0] > 10 * r2["covariance"][0, 0]
    assert np.allclose(r1["fim"], r1["fim"].T)


def test_fd_and_two_state_time_domain_agree_on_drive_profile():
    from shevsim.battery.verification import drive_like_current
    q = drive_like_current(1800.0, 1.0, seed=2) ** 2 * 0.012
    m2, mf = TwoStateThermal(P31), FDThermal(P31)
    x2, xf = m2.initial_state(25.0), mf.initial_state(25.0)
    err = 0.0
    for qk in q:
        x2 = m2.step(x2, qk, 25.0, 30.0, 1.0)
        xf = mf.step(xf, qk, 25.0, 30.0, 1.0)
        a, b = m2.outputs(x2, qk, 25.0, 30.0), mf.outputs(xf, qk, 25.0, 30.0)
        err = max(err, abs(a[0] - b[0]), abs(a[1] - b[1]))
    tc = mf.outputs(xf, 0, 25.0, 30.0)[0]
    assert tc > 27.0           # the profile does heat the cell
    assert err < 0.15          # seed: polynomial model accurate for drive-cycle heat inputs


def test_bad_inputs_raise_named_errors():
    with pytest.raises(ScenarioError, match="kt_w_mk"):
        ThermalParams(kt_w_mk=-1.0)
    m = TwoStateThermal()
    with pytest.raises(SimulationError, match="h_w_m2k"):
        m.step((25.0, 0.0), 1.0, 25.0, -3.0, 1.0)
    with pytest.raises(SimulationError, match="dt"):
        m.step((25.0, 0.0), 1.0, 25.0, 3.0, 0.0)
    with pytest.raises(SimulationError, match="h_w_m2k"):
        FDThermal().step(np.zeros(30), 1.0, 25.0, float("nan"), 1.0)
    with pytest.raises(SimulationError, match="scheme"):
        FDThermal(scheme="fem")
