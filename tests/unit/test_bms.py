"""BMS: DEKF against the richer OCV-R-RC-RC plant, Algebraic-Propagation power capability checked
by simulating the models it inverts, and the BMS component in closed loop with the plant."""
from __future__ import annotations

import math

import numpy as np
import pytest

from shevsim.battery import cell
from shevsim.battery.thermal import ThermalParams, TwoStateThermal, steady_state
from shevsim.bms.electrical import DEKF, DEKFParams
from shevsim.bms.power_capability import PowerCapability, PowerCapabilityParams
from shevsim.components.battery import BatteryPack, BatteryPackParams
from shevsim.components.bms import BMS, BMSParams
from shevsim.core.errors import SimulationError

DT = 0.1
NS, NP = 130, 10
RETUNED = dict(q_soc=1e-5, q_v1=2e-3, q_rs=1e-8, q_c1=1e4)


def drive_profile(n, dt, seed=1, scale=1.0):
    """Pack-power profile with drive-cycle-like pulses (2-15 s holds, -60..+80 kW, 20 % idle)."""
    rng = np.random.default_rng(seed)
    p = np.zeros(n)
    k = 0
    while k < n:
        m = int(rng.uniform(2.0, 15.0) / dt)
        p[k:k + m] = rng.uniform(-60e3, 80e3) if rng.random() > 0.2 else 0.0
        k += m
    p -= 0.9 * p.mean()          # keep SOC in the usable window
    return scale * p


@pytest.fixture(scope="module")
def plant_run():
    """2000 s of the OCV-R-RC-RC plant (true SOC 60 %) with noisy measurements."""
    n = 20000
    prof = drive_profile(n, DT)
    b = BatteryPack("battery", BatteryPackParams(soc_init_pct=60.0, seed=3))
    rows = []
    for k in range(n):
        b.u["power_w"] = prof[k]
        t_mean = b.y["t_mean_c"]
        soc0 = b.soc
        b.do_step(k * DT, DT)
        y = b.y
        rs_true = b.tables.params(b.soc, t_mean, b.i_cell)[0]
        _, r1, _, r2, _ = b.tables.params(soc0, t_mean, b.i_cell)
        rows.append((y["cell_current_meas_a"], y["cell_voltage_meas_v"], y["soc_pct"] / 100.0, rs_true,
                     y["heat_w"], t_mean, b.v1 + b.v2, b.v1 ** 2 / r1 + b.v2 ** 2 / r2))
    return np.array(rows)


def run_dekf(data, **kw):
    f = DEKF(DEKFParams(soc0_frac=0.5, **kw))     # 10 % initial SOC error
    out = np.empty((len(data), 4))
    for k, (i, v, _, _, _, t_mean, _, _) in enumerate(data):
        f.step(i, v, DT, t_mean)        # t_mean: plant mean temperature at the start of the step (the BMS's
        out[k] = (f.soc, f.rs, f.heat(i, t_mean), f.x2)      # previous-step estimate; its lookup temperature)
    return out


# (rs_model, rc_model): the seed's free R_s, R1, C1 and the BMS default (factors on the nominal maps)
MODELS = [("free", "free"), ("table_scaled", "table_scaled")]


# -- DEKF ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("rs_model, rc_model", MODELS)
def test_dekf_soc_converges_from_10pct_error_and_stays(plant_run, rs_model, rc_model):
    est = run_dekf(plant_run, rs_model=rs_model, rc_model=rc_model, **RETUNED)
    err = np.abs(est[:, 0] - plant_run[:, 2])
    assert err[0] > 0.09
    half = len(err) // 2
    assert err[half:].max() < 0.02, f"max |SOC error| after 1000 s: {err[half:].max():.4f}"


@pytest.mark.parametrize("rs_model, rc_model", MODELS)
def test_dekf_rs_tracks_plant_within_5pct(plant_run, rs_model, rc_model):
    est = run_dekf(plant_run, rs_model=rs_model, rc_model=rc_model, **RETUNED)
    rel = np.abs(est[:, 1] / plant_run[:, 3] - 1.0)
    half = len(rel) // 2
    assert rel[half:].max() < 0.05, f"max R_s error after 1000 s: {rel[half:].max():.4f}"


def test_dekf_table_5_4_tuning_reduces_soc_error(plant_run):
    # seed Table 5.4 as printed (Sigma_r(R1) read as 2.5e-8): converges, but more slowly and
    # less precisely than the re-tuned set against this plant's slow second RC branch
    est = run_dekf(plant_run)
    err = np.abs(est[:, 0] - plant_run[:, 2])
    assert err[-2000:].max() < 0.05


@pytest.mark.parametrize("rs_model, rc_model", [
    MODELS[0],
    pytest.param(*MODELS[1], marks=pytest.mark.xfail(
        strict=True, reason="R1, C1 from the first-branch map on this high-current profile: the 1-RC V1 "
                            "absorbs part of the plant's slow V2 and V1^2/R1,nom over-estimates: mean "
                            "+2.3 % (free R1, C1: +1.5 %); on the UAC proxy +0.5 % (integration test)"))])
def test_dekf_heat_estimate_mean_within_2pct(plant_run, rs_model, rc_model):
    # the thermal filter low-passes the heat: its mean (energy) is what drives the temperature
    est = run_dekf(plant_run, rs_model=rs_model, rc_model=rc_model, **RETUNED)
    half = len(est) // 2
    q_true, q_est = plant_run[half:, 4], est[half:, 2]
    assert abs(q_est.mean() / q_true.mean() - 1.0) < 0.02


def _oracle_heat_rmse(data, half):
    """RMSE of the best any OCV-R-RC heat estimate can do: the plant's own heat with its two-branch
    polarisation heat replaced by (V1 + V2)^2 / R with the least-squares constant R (true states)."""
    v, pol, q = data[half:, 6], data[half:, 7], data[half:, 4]
    r_best = np.sum(v ** 4) / np.sum(v * v * pol)
    return math.sqrt(np.mean((v * v / r_best - pol) ** 2)), q.mean()


@pytest.mark.parametrize("rs_model, rc_model", MODELS)
def test_dekf_heat_rmse_close_to_the_one_rc_structural_floor(plant_run, rs_model, rc_model):
    est = run_dekf(plant_run, rs_model=rs_model, rc_model=rc_model, **RETUNED)
    half = len(est) // 2
    floor, q_mean = _oracle_heat_rmse(plant_run, half)
    rmse = math.sqrt(np.mean((est[half:, 2] - plant_run[half:, 4]) ** 2))
    assert floor > 0.02 * q_mean            # the 2 % target is out of reach of any OCV-R-RC estimate here
    assert rmse < 1.5 * floor, (rmse / q_mean, floor / q_mean)


@pytest.mark.xfail(strict=True, reason="1-RC DEKF vs 2-RC plant: instantaneous polarisation heat V1^2/R1 "
                                       "cannot match V1^2/R1 + V2^2/R2 of the plant; measured RMSE 5.4 % "
                                       "(free) / 5.3 % (table-scaled) of the mean heat, the best constant-R "
                                       "OCV-R-RC estimate with true states 4.5 % on this profile (target 2 %; "
                                       "met on the UAC proxy, tests/integration/test_bms_study.py)")
@pytest.mark.parametrize("rs_model, rc_model", MODELS)
def test_dekf_heat_estimate_rmse_below_2pct_of_mean(plant_run, rs_model, rc_model):
    est = run_dekf(plant_run, rs_model=rs_model, rc_model=rc_model, **RETUNED)
    half = len(est) // 2
    q_true, q_est = plant_run[half:, 4], est[half:, 2]
    assert math.sqrt(np.mean((q_est - q_true) ** 2)) < 0.02 * q_true.mean()


@pytest.fixture(scope="module")
def aged_plant(tmp_path_factory):
    """The plant of :func:`plant_run` built from tables with R_s and R1 x 1.2 (an aged cell), 2000 s: rows of
    (measured current, measured voltage, T_mean at the start of the step, true SOC, true R_s, true current)."""
    tmp = tmp_path_factory.mktemp("aged")
    files = {}
    for kind in ("discharge", "charge"):
        lines = (cell.DATA_DIR / f"a123_26650_ecm_{kind}.csv").read_text().splitlines()
        out = []
        for ln in lines:
            if ln.startswith("#") or ln.startswith("soc_frac"):
                out.append(ln)
                continue
            v = ln.split(",")
            v[2] = repr(1.2 * float(v[2]))        # rs_ohm
            v[3] = repr(1.2 * float(v[3]))        # r1_ohm
            out.append(",".join(v))
        files[kind] = tmp / f"aged_{kind}.csv"
        files[kind].write_text("\n".join(out) + "\n")
    n = 20000
    prof = drive_profile(n, DT)
    b = BatteryPack("battery", BatteryPackParams(soc_init_pct=60.0, seed=3, discharge_file=str(files["discharge"]),
                                                 charge_file=str(files["charge"])))
    rows = []
    for k in range(n):
        b.u["power_w"] = prof[k]
        t_mean = b.y["t_mean_c"]
        b.do_step(k * DT, DT)
        rs_true = b.tables.params(b.soc, t_mean, b.i_cell)[0]
        rows.append((b.y["cell_current_meas_a"], b.y["cell_voltage_meas_v"], t_mean, b.y["soc_pct"] / 100.0, rs_true,
                     b.i_cell))
    return np.array(rows)


@pytest.fixture(scope="module")
def aged_run(aged_plant):
    """The one-branch table-scaled DEKF (``RETUNED``, the seed's parameter update) on :func:`aged_plant`."""
    f = DEKF(DEKFParams(soc0_frac=0.5, rs_model="table_scaled", rc_model="table_scaled", **RETUNED))
    rows = []
    for i, v, t_mean, soc, rs_true, i_cell in aged_plant:
        f.step(i, v, DT, t_mean)
        rows.append((f.soc - soc, f.x2, f.th1, f.rs / rs_true - 1.0, i_cell))
    return np.array(rows)


def test_dekf_table_scaled_tracks_an_aged_cell(aged_run):
    # the BMS knows only the nominal maps; the plant's R_s and R1 are 20 % above them
    half = len(aged_run) // 2
    soc_err, kappa_s, rel = aged_run[half:, 0], aged_run[half:, 1], aged_run[half:, 3]
    assert np.abs(soc_err).max() < 0.02
    assert np.abs(kappa_s / 1.2 - 1.0).max() < 0.05, (kappa_s.min(), kappa_s.max())
    loaded = np.abs(aged_run[half:, 4]) > 1.0
    assert np.abs(rel[loaded]).max() < 0.05


def run_bms_dekf(data, kappa_1=None, **overrides):
    """The BMS component's DEKF (``BMSParams.retuned()``: table-scaled factors, V2 from the nominal maps, the
    tracking R1-factor update, q_soc 1e-3) from a 10 % SOC error on plant rows (current, voltage, T_mean, true
    SOC, ...); ``kappa_1`` given: the R1 factor held there.  Rows of (SOC error, kappa_s, kappa_1, kappa_2,
    innovation [V])."""
    import dataclasses

    from shevsim.bms.electrical import DEKFTuning
    p = BMSParams.retuned(**overrides)
    f = DEKF(DEKFParams(soc0_frac=0.5, **{fl.name: getattr(p, fl.name) for fl in dataclasses.fields(DEKFTuning)}))
    if kappa_1 is not None:
        assert p.r1_factor_q == 0.0
        f.th1 = kappa_1
        f.pth = [0.0, 0.0, 0.0]
    out = np.empty((len(data), 5))
    for k, row in enumerate(data):
        f.step(row[0], row[1], DT, row[2])
        out[k] = (f.soc - row[3], f.x2, f.th1, f.th2, f.innovation)
    return out


def test_dekf_table_scaled_r1_factor_tracks_an_aged_cell(aged_plant):
    """The BMS's DEKF tracks the R1 factor of a cell aged by 20 % (module docstring of shevsim.bms.electrical,
    "Tracking the R1 factor"; measured: within 1.4 % after 1000 s, ends at 1.198, SOC error 0.09 %); the seed's
    parameter update, which left the R1 factor at ~1.00 (the strict xfail this replaces), keeps it there and
    leaves a larger SOC error (measured 1.7 %)."""
    half = len(aged_plant) // 2
    trk = run_bms_dekf(aged_plant)
    assert np.abs(trk[half:, 2] / 1.2 - 1.0).max() < 0.05, (trk[half:, 2].min(), trk[half:, 2].max())
    assert np.abs(trk[half:, 1] / 1.2 - 1.0).max() < 0.05
    assert np.all(trk[:, 3] == 1.0)                       # C1 = C1,nom in the tracking update
    assert np.abs(trk[half:, 0]).max() < 0.005
    seed = run_bms_dekf(aged_plant, rc_update="seed")
    assert np.abs(seed[half:, 2] - 1.0).max() < 0.01      # the defect: the seed's gain is ~1e-4 per volt
    assert np.abs(seed[half:, 0]).max() > 2.0 * np.abs(trk[half:, 0]).max()


def test_dekf_r1_factor_stays_nominal_on_a_nominal_cell(plant_run):
    # the same filter on the un-aged plant: no drift of the R1 factor (measured within 1 %)
    est = run_bms_dekf(plant_run[:, [0, 1, 5, 2]])      # current, voltage, T_mean, true SOC
    half = len(est) // 2
    assert np.abs(est[half:, 2] - 1.0).max() < 0.05
    assert np.abs(est[half:, 0]).max() < 0.005


@pytest.mark.parametrize("v2_model, best", [("nominal_maps", 1.2), ("none", 1.4)])
def test_r1_factor_is_observable_only_with_the_slow_branch_modelled(aged_plant, v2_model, best):
    """Prediction-error check of what the R1 factor means (module docstring): with kappa_1 held, the innovation
    RMS after 1000 s is smallest at the truth (1.2) when V2 is modelled; the one-branch filter's V1 absorbs the
    plant's V2, so its best kappa_1 lies above the truth (measured innovation RMS [mV] at kappa_1 = 1.0 / 1.2 /
    1.4 / 1.5: with V2 1.17 / 1.02 / 1.10 / 1.18, without 1.55 / 1.20 / 1.09 / 1.10)."""
    half = len(aged_plant) // 2
    rms = {}
    for k1 in (1.0, 1.2, 1.4):
        e = run_bms_dekf(aged_plant, kappa_1=k1, v2_model=v2_model, r1_factor_q=0.0)[half:, 4]
        rms[k1] = math.sqrt(np.mean(e ** 2))
    assert min(rms, key=rms.get) == best, rms


def test_dekf_exact_on_its_own_model_noise_free():
    # on data from its own OCV-R-RC model with the true parameters, the filter stays on the truth
    rs, r1, c1 = 0.011, 0.009, 3000.0
    f = DEKF(DEKFParams(soc0_frac=0.55, rs0_ohm=rs, r1_0_ohm=r1, c1_0_f=c1, q_r1=0.0, q_c1=0.0,
                        s0_r1=0.0, s0_c1=0.0))
    soc, v1 = 0.55, 0.0
    a = math.exp(-DT / (r1 * c1))
    rng = np.random.default_rng(0)
    for k in range(3000):
        i = 15.0 * math.sin(0.01 * k) + rng.normal(0, 3.0)
        soc -= DT * i / (3600 * 2.3)
        v1 = a * v1 + r1 * (1 - a) * i
        f.step(i, cell.ocv(soc) - v1 - rs * i, DT)
    assert abs(f.soc - soc) < 1e-4 and abs(f.v1 - v1) < 1e-4 and abs(f.rs / rs - 1) < 1e-3


# -- power capability ---------------------------------------------------------------------------
def _thermal_state(t_amb, q, h):
    ss = steady_state(ThermalParams(), q, t_amb, h)
    return ss["t_mean_c"], ss["gamma_c_per_m"]


@pytest.mark.parametrize("mode", ["exact", "seed"])
@pytest.mark.parametrize("h, q0", [(20.0, 0.9), (3.0, 0.12)])
def test_thermal_limit_reaches_but_does_not_exceed_45(h, q0, mode):
    tp = ThermalParams()
    pc = PowerCapability(PowerCapabilityParams(soc_min_frac=0.0, soc_max_frac=1.0, v_min_v=0.0, v_max_v=10.0,
                                               polarisation_heat=mode))
    soc, v1, rs, r1, c1 = 0.5, 0.02, 0.008, 0.006, 2500.0
    t_amb = 30.0
    t_mean, gamma = _thermal_state(t_amb, q0, h)          # warm cell, core ~38 degC
    th = TwoStateThermal(tp)
    assert 36.0 < th.outputs((t_mean, gamma), 0.0, t_amb, h)[0] < 41.0
    for _ in range(3):           # let the 5.31 bound use this step's own limit as "previous"
        lim = pc.compute(soc, v1, rs, r1, c1, t_mean, gamma, h, t_amb)
    # gain from a heat held over the horizon to the core temperature (unit heat from rest)
    x = (0.0, 0.0)
    for _ in range(100):
        x = th.step(x, 1.0, 0.0, h, DT)
    gain = th.outputs(x, 0.0, 0.0, h)[0]
    for i_lim in (lim.i_t_dch_a, lim.i_t_chg_a):
        # simulate the plant's two-state thermal model (exact ZOH, dt steps), heat re-evaluated each step
        x = (t_mean, gamma)
        v = v1
        a = math.exp(-DT / (r1 * c1))
        q_pol = []
        for _ in range(100):
            q_pol.append(v * v / r1)
            q = (i_lim ** 2 * rs + q_pol[-1]
                 - i_lim * (x[0] + 273.15) * cell.entropy_change(soc) / cell.FARADAY_C_MOL)
            x = th.step(x, q, t_amb, h, DT)
            v = a * v + r1 * (1 - a) * i_lim
        t_core = th.outputs(x, 0.0, t_amb, h)[0]
        # upper: 5e-3 K covers the entropic term's T_mean held at T_k over the horizon (5.33)
        assert t_core <= 45.0 + 5e-3, (h, i_lim, t_core)
        # lower: "exact" is exact up to that entropic term; "seed" is conservative only through the
        # 5.31 bound max(V1^2)/R1 on the polarisation heat
        slack = 0.0 if mode == "exact" else gain * (max(max(q_pol), v * v / r1) - min(q_pol))
        assert t_core >= 45.0 - slack - 5e-3, (h, i_lim, t_core, slack)
        assert t_core > 44.0
    assert lim.i_t_dch_a > 0.0 > lim.i_t_chg_a
    assert lim.i_max_a == pytest.approx(lim.i_t_dch_a) and lim.i_min_a == pytest.approx(lim.i_t_chg_a)


@pytest.mark.parametrize("mode", ["exact", "seed"])
def test_thermal_limit_collapses_when_too_hot(mode):
    pc = PowerCapability(PowerCapabilityParams(polarisation_heat=mode))
    t_mean, gamma = _thermal_state(44.0, 3.0, 3.0)      # core already above 45 degC
    lim = pc.compute(0.5, 0.0, 0.01, 0.006, 2500.0, t_mean, gamma, 3.0, 44.0)
    # no current keeps T_core <= 45: both limits collapse to the least-heating current
    beta = (t_mean + 273.15) * cell.entropy_change(0.5) / cell.FARADAY_C_MOL
    assert lim.i_max_a == lim.i_min_a
    if mode == "seed":
        assert lim.i_max_a == pytest.approx(beta / 0.02)      # beta / (2 R_s)
    assert 0.0 < lim.i_max_a <= beta / 0.02                  # entropic cooling on discharge (Delta S > 0)
    assert lim.p_max_w >= 0.0 >= lim.p_min_w
    assert lim.p_max_w >= 0.0 >= lim.p_min_w


@pytest.mark.parametrize("soc", [0.35, 0.5, 0.65])
def test_voltage_limits_reached_after_n_steps(soc):
    p = PowerCapabilityParams(soc_min_frac=0.0, soc_max_frac=1.0, v_min_v=3.0, v_max_v=3.5, t_core_max_c=1e3)
    pc = PowerCapability(p)
    rs, r1, c1, v1 = 0.012, 0.008, 2000.0, 0.01
    lim = pc.compute(soc, v1, rs, r1, c1, 25.0, 0.0, 20.0, 25.0)
    q = 3600 * 2.3
    for i_lim, v_lim in ((lim.i_v_min_a, 3.0), (lim.i_v_max_a, 3.5)):
        s, v = soc, v1
        a = math.exp(-DT / (r1 * c1))
        for _ in range(100):
            s -= DT * i_lim / q
            v = a * v + r1 * (1 - a) * i_lim
        v_t = cell.ocv(s) - v - rs * i_lim
        # the only approximation in 5.28c-d is the OCV linearised at SOC_k
        lin_err = abs(cell.ocv(s) - (cell.ocv(soc) + cell.docv_dsoc(soc) * (s - soc)))
        assert abs(v_t - v_lim) <= lin_err + 1e-9
        assert v_t == pytest.approx(pc.voltage_after(i_lim, soc, v1, rs, r1, c1), abs=1e-12)


def test_soc_limits_and_power_signs():
    p = PowerCapabilityParams()
    pc = PowerCapability(p)
    lim = pc.compute(0.32, 0.0, 0.01, 0.006, 2500.0, 25.0, 0.0, 20.0, 25.0)
    # holding the SOC_min current for N steps lands exactly on SOC_min
    assert 0.32 - lim.i_soc_min_a * 100 * DT / (3600 * 2.3) == pytest.approx(0.3, abs=1e-12)
    assert lim.i_max_a == min(lim.i_soc_min_a, lim.i_v_min_a, lim.i_t_dch_a)
    assert lim.i_min_a == max(lim.i_soc_max_a, lim.i_v_max_a, lim.i_t_chg_a)
    assert lim.p_max_w == pytest.approx(lim.i_max_a * lim.v_dch_v * NS * NP)
    rng = np.random.default_rng(1)
    for _ in range(200):
        soc = rng.uniform(0.0, 1.0)
        tm = rng.uniform(0, 60)
        lim = pc.compute(soc, rng.uniform(-0.1, 0.1), 0.01, 0.006, 2500.0, tm, 0.0, rng.uniform(1, 50), 25.0)
        assert lim.p_max_w >= 0.0 >= lim.p_min_w
        if soc < 0.3:
            assert lim.p_max_w == 0.0
        if soc > 0.7:
            assert lim.p_min_w == 0.0


# -- BMS component ------------------------------------------------------------------------------
def _connect(b, m):
    for k in ("cell_current_meas_a", "cell_voltage_meas_v", "t_surface_meas_c", "t_ambient_meas_c"):
        m.u[k] = b.y[k]


def test_bms_closed_loop_keeps_core_below_45_through_cooling_fault():
    n = 12000
    prof = drive_profile(n, DT, scale=2.0)
    b = BatteryPack("battery", BatteryPackParams(soc_init_pct=55.0))
    m = BMS("bms", BMSParams.retuned())
    clamped = 0
    t_core = []
    for k in range(n):
        t = k * DT
        b.u["h_conv_w_m2k"] = 20.0 if t < 300.0 else 3.0
        p = min(max(prof[k], m.y["power_min_w"]), m.y["power_max_w"])
        clamped += p != prof[k]
        b.u["power_w"] = p
        b.do_step(t, DT)
        _connect(b, m)
        m.do_step(t, DT)
        t_core.append(b.y["t_core_c"])
        assert m.y["power_max_w"] >= 0.0 >= m.y["power_min_w"]
    assert clamped > 100                      # the limits were active
    assert max(t_core) > 44.0                 # ... and the cell was driven to the limit
    assert max(t_core) <= 45.2                # seed Table 3.3: core-estimate error ~0.25 degC
    assert abs(m.y["h_w_m2k"] - 3.0) < 1.5
    assert m.y["rs_ohm"] == pytest.approx(m.y["cell_rs_ohm"] * NS / NP)


def test_bms_uses_previous_mean_temperature_for_heat_and_restores_state():
    m = BMS("bms")
    rng = np.random.default_rng(0)
    snaps = None
    for k in range(50):
        t_prev = m.t_mean
        m.u.update(cell_current_meas_a=rng.normal(5, 5), cell_voltage_meas_v=3.28 + rng.normal(0, 0.01),
                   t_surface_meas_c=25.0 + 0.01 * k, t_ambient_meas_c=25.0)
        m.do_step(k * DT, DT)
        assert m.q_est == pytest.approx(m.dekf.heat(m.u["cell_current_meas_a"], t_prev))
        if k == 25:
            snaps = (m.get_state(), [])
        if k > 25:
            snaps[1].append((dict(m.u), dict(m.y)))
    m.set_state(snaps[0])
    for k, (u, y) in enumerate(snaps[1]):
        m.u.update(u)
        m.do_step((26 + k) * DT, DT)
        assert m.y == y


def test_bms_rejects_nan_measurement():
    m = BMS("bms")
    m.u["cell_voltage_meas_v"] = float("nan")
    with pytest.raises(SimulationError, match=r"bms.*t=0\.1.*voltage nan"):
        m.do_step(0.0, DT)


def test_parameter_files_match_code_defaults():
    from pathlib import Path

    from shevsim.core.params import load_params

    root = Path(__file__).resolve().parents[2] / "components"
    assert load_params(BMSParams, root / "bms" / "table_5_4.toml") == BMSParams()
    assert load_params(BMSParams, root / "bms" / "default.toml") == BMSParams.retuned()
    p = load_params(BatteryPackParams, root / "battery" / "default.toml")
    a, b = BatteryPack("a", p), BatteryPack("b")
    for k in range(20):
        for x in (a, b):
            x.u["power_w"] = 30e3
            x.do_step(k * DT, DT)
    assert a.y == b.y


def test_bms_horizon_in_seconds_follows_its_step():
    m = BMS("bms")
    assert m.pc.params.horizon_steps == 100 and m.pc.params.dt_s == 0.1
    m.do_step(0.0, 0.2)
    assert m.pc.params.horizon_steps == 50 and m.pc.params.dt_s == 0.2 and m.thermal.dt_s == 0.2


# -- the slow second branch (issue 14) -----------------------------------------------------------------
def test_dekf_with_the_slow_branch_meets_the_heat_targets_the_one_rc_filter_misses(plant_run):
    """The BMS default (factors on the nominal maps + V2 propagated from the nominal R2, C2 maps): the
    heat estimate's mean within 2 % and its RMSE below 2 % of the mean heat on the profile where the 1-RC
    filter (xfails above) misses both (measured: -0.1 % and 1.5 %; one-branch +2.3 % and 5.3 %); SOC still
    converges from the 10 % initial error."""
    est = run_dekf(plant_run, rs_model="table_scaled", rc_model="table_scaled", v2_model="nominal_maps", **RETUNED)
    half = len(est) // 2
    q_true, q_est = plant_run[half:, 4], est[half:, 2]
    assert abs(q_est.mean() / q_true.mean() - 1.0) < 0.02
    assert math.sqrt(np.mean((q_est - q_true) ** 2)) < 0.02 * q_true.mean()
    assert np.abs(est[half:, 0] - plant_run[half:, 2]).max() < 0.02


def test_dekf_v2_model_is_validated():
    with pytest.raises(ValueError, match="v2_model"):
        DEKFParams(v2_model="two_rc")
    from shevsim.components.bms import BMSParams
    with pytest.raises(Exception, match="v2_model"):
        BMSParams(v2_model="yes")
    assert BMSParams().v2_model == "nominal_maps" and DEKFParams().v2_model == "none"
