"""BMS studies of issue 3 on the full SHEV (UAC proxy, MPC supervisor, BMS in the loop).

Default tests use shortened runs (each ~10 s); the full-length versions are ``slow``.
The plant is the OCV-R-RC-RC battery with noisy measurements, richer than the BMS's OCV-R-RC
model; truths come from the plant, never from the estimator's own equations.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from shevsim.studies import bms_study as bs

SEED = 1
T_MAX_C = 45.0


# -- power capability under the cooling fault (seed Fig. 5.15) ------------------------------------
@pytest.fixture(scope="module")
def fault_runs():
    """Cooling-fault scenario shortened to 1500 s: the limited run
    passes 44.5 degC at ~1230 s and 45 degC at ~1380 s (h 20 -> 3 W/m2K at 300 s); the counterfactual
    crosses 45 degC at ~910 s."""
    runs = {}
    # the one-step-late wiring (the bus's limits of the previous step): the mechanism checked below
    for label, sets in (("limited", ()), ("unlimited", ("bus.enforce_battery_limits=false",))):
        runs[label] = bs.simulate_partial(bs._scenario(bs.FAULT_SCENARIO_ONE_STEP_LATE, SEED, 1500.0, sets))
    return runs


def test_cooling_fault_study_within_the_step_holds_the_same_step_limits(tmp_path):
    """The study's default scenario (limits held within the step), 1500 s: no same-step excursion beyond
    1 kW, core at the limit; its counterfactual (every limit component off) exceeds 45 degC."""
    met = bs.power_capability_study(tmp_path, seed=SEED, stop_s=1500.0, counterfactuals=("unlimited",))
    lim, unl = met["runs"]["limited"], met["runs"]["unlimited"]
    assert lim["t_core_max_c"] > T_MAX_C - 0.5 and lim["t_core_max_c"] <= T_MAX_C
    assert lim["time_battery_power_beyond_same_step_limits_s"] < 1.0
    assert unl["t_core_max_c"] > T_MAX_C + 1.0


def test_cooling_fault_limits_keep_core_at_45c_and_states_in_bounds(fault_runs):
    r = fault_runs["limited"]
    assert r.termination == "completed"
    m = bs._run_metrics(r)
    # the constraint is active in this window (otherwise the check below would prove nothing)
    assert m["t_core_max_c"] > T_MAX_C - 0.5, m["t_core_max_c"]
    assert m["t_core_max_c"] <= T_MAX_C + 0.5, m["t_core_max_c"]
    assert m["voltage_in_bounds"], (m["cell_voltage_min_v"], m["cell_voltage_max_v"])
    assert m["soc_in_bounds"], (m["soc_min_pct"], m["soc_max_pct"])
    # the BMS's core estimate is what the limit acts on: it must follow the plant's core
    assert m["bms_t_core_rmse_c"] < 0.5


def test_cooling_fault_without_limits_exceeds_45c(fault_runs):
    a, b = fault_runs["limited"], fault_runs["unlimited"]
    mb = bs._run_metrics(b)
    assert mb["t_core_max_c"] > T_MAX_C + 1.0, mb["t_core_max_c"]
    # same seed: the runs are identical until the limited run's motor first sits at a bus limit
    # (published one step earlier: the motor uses the bus's previous limits), which the other exceeds
    diff = np.flatnonzero(a["motor.elec_power_w"] != b["motor.elec_power_w"])
    assert diff.size
    k = int(diff[0])
    assert np.array_equal(a["battery.t_core_c"][:k], b["battery.t_core_c"][:k])
    pm = a["motor.elec_power_w"][k]
    lim = a["bus.motor_power_max_w"][k - 1] if pm > 0 else a["bus.motor_power_min_w"][k - 1]
    assert abs(pm - lim) < 0.01 * abs(lim), (a.time_s[k], pm, lim)
    assert abs(b["motor.elec_power_w"][k]) > abs(lim)
    # the price of the limits: the unconstrained vehicle follows the trace, the limited one falls behind
    assert mb["speed_rmse_mps"] < 0.05
    assert bs._run_metrics(a)["distance_m"] < mb["distance_m"]


# -- DEKF (seed Fig. 5.11-5.12) ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def dekf_quick():
    """1800 s of the UAC proxy run replayed into the plant + a BMS started 10 % low in SOC."""
    return bs.dekf_replay(bs.BASE_SCENARIO, SEED, stop_s=1800.0, soc_offset_pct=-10.0)


def test_dekf_replay_reproduces_the_closed_loop_plant(dekf_quick):
    # the replayed pack power drives the same plant to the same SOC trajectory (alignment check)
    assert np.max(np.abs(dekf_quick["soc_pct"] - dekf_quick["run_soc_pct"])) < 1e-9


def test_dekf_soc_converges_below_2pct_and_stays(dekf_quick):
    m = bs.dekf_metrics(dekf_quick)
    assert m["soc_err_initial_pct"] == pytest.approx(-10.0, abs=1e-6)
    t_conv = m["soc_time_below_2pct_s"]
    assert t_conv is not None and t_conv <= 1500.0, t_conv      # below 2 % for at least the last 300 s
    err = np.abs(dekf_quick["soc_est_pct"] - dekf_quick["soc_pct"])
    assert err[dekf_quick["t_s"] >= t_conv].max() < 2.0


def test_dekf_rs_tracks_plant(dekf_quick):
    t_conv = bs.dekf_metrics(dekf_quick)["soc_time_below_2pct_s"]
    m = bs.dekf_metrics(dekf_quick, settle_s=t_conv)
    # RMS within 5 % of the plant's R_s of each step; the max is larger because the plant's charge
    # table is 5 % below its discharge table and one R_s estimate cannot follow that switch
    assert m["rs_rel_err_rms_after_settle"] < 0.05, m
    assert m["rs_rel_err_max_after_settle"] < 0.10, m


def test_dekf_heat_estimate_energy_within_2pct(dekf_quick):
    # the thermal filter integrates the heat: its mean (energy) after convergence is what matters
    m = bs.dekf_metrics(dekf_quick)
    assert abs(m["heat_mean_rel_err"]) < 0.02, m["heat_mean_rel_err"]


# -- CLI -------------------------------------------------------------------------------------------
def test_cli_study_bms_thermal_quick(tmp_path):
    from shevsim.studies.cli import main_study
    out = tmp_path / "bms"
    assert main_study(["bms", str(out), "--quick", "--only", "thermal"]) == 0
    for name in ("table_3_3.csv", "table_3_3.png", "table_3_3_summary.json", "summary.json",
                 "table_3_3_uac_proxy.csv", "table_3_3_uac_proxy.png", "table_3_3_uac_proxy_x2.csv"):
        assert (out / name).is_file(), name
    s = json.loads((out / "summary.json").read_text())
    r = s["thermal"]["rmse_core_c"]
    # stage III: the KF with 2x the true h is worse than the filters that estimate h
    assert r["III"]["KF"] > r["III"]["DKF"] and r["III"]["KF"] > r["III"]["JEKF"]
    u = s["thermal"]["uac_proxy"]
    # current x2 -> heat x4 (same trace)
    assert u["table_3_3_uac_proxy_x2"]["heat_mean_w"] == pytest.approx(4 * u["table_3_3_uac_proxy"]["heat_mean_w"])
    for v in u.values():
        rr = v["rmse_core_c"]
        assert rr["III"]["KF"] > rr["III"]["DKF"]
        assert "III_h0_star" not in rr          # the row that started at the true h (= stage I) is gone
    # Table 3.3 at both sample times, core and surface (issue 14)
    assert (out / "table_3_3_rates.csv").is_file()
    assert set(s["thermal"]["rates"]) == {"1.0", "0.1"}
    assert not list(out.glob(".*tmp*")), "temporary files left behind"


def test_table_3_3_at_0p1s_adaptive_filters_beat_the_mistuned_kf_from_a_wrong_h():
    """Issue 14: stage III at the 0.1 s BMS rate, DKF/JEKF started at a wrong h (2 h* and h*/2, never the
    true h*): both beat the KF that is given 2 h*, in core and surface RMSE."""
    from shevsim.studies.thermal_estimators import H_STAR_W_M2K
    from shevsim.studies.bms_study import table_3_3_rates
    r = table_3_3_rates(None, seed=0, duration_s=1200.0, dt_values=(0.1,), wrong_h0_factors=(2.0, 0.5))
    rows = r["dt_s"][0.1]
    for label in ("III", "III_h0_x0.5"):
        row = rows[label]
        assert abs(row["h0_adaptive_w_m2k"] / H_STAR_W_M2K - 1.0) >= 0.5      # started at a wrong h
        assert row["h_kf_w_m2k"] == pytest.approx(2.0 * H_STAR_W_M2K)
        for f in ("DKF", "JEKF"):
            assert row[f]["core_c"] < 0.5 * row["KF"]["core_c"], (label, f, row)
            assert row[f]["surface_c"] < row["KF"]["surface_c"], (label, f, row)
    with pytest.raises(ValueError, match="wrong_h0_factors"):
        table_3_3_rates(None, duration_s=10.0, dt_values=(1.0,), wrong_h0_factors=(1.0,))


def test_cli_study_bms_rejects_unknown_part(tmp_path):
    from shevsim.studies.cli import main_study
    assert main_study(["bms", str(tmp_path), "--only", "dekff"]) == 2


# -- full length (slow) ------------------------------------------------------------------------------
@pytest.mark.slow
def test_full_cooling_fault_study(tmp_path):
    m = bs.power_capability_study(tmp_path, seed=SEED)
    lim = m["runs"]["limited"]
    assert lim["termination"] == "completed"
    assert lim["t_core_max_c"] <= T_MAX_C + 0.5
    assert lim["voltage_in_bounds"] and lim["soc_in_bounds"]
    # issue 14: the whole 2926 s run beyond the same-step limits (1 kW tolerance) for < 1 s in total
    assert lim["time_battery_power_beyond_same_step_limits_s"] < 1.0
    assert lim["t_core_max_c"] <= T_MAX_C
    for k in m["counterfactuals"]:
        assert m["runs"][k]["t_core_max_c"] > T_MAX_C + 1.0
    assert (tmp_path / "power_capability.png").is_file() and (tmp_path / "power_capability.csv").is_file()


@pytest.fixture(scope="module")
def dekf_full():
    return bs.dekf_replay(bs.BASE_SCENARIO, SEED, soc_offset_pct=-10.0)


@pytest.mark.slow
def test_full_dekf_soc_within_2pct_over_second_cycle(dekf_full):
    m = bs.dekf_metrics(dekf_full)            # window: the second UAC proxy repetition
    assert m["soc_time_below_2pct_s"] is not None
    assert m["soc_err_max_after_settle_pct"] < 2.0
    assert m["rs_rel_err_rms_after_settle"] < 0.05


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="table-scaled R_s (default): max error 5.5 % over the second repetition, "
                                       "all of it at |i| < 1 A where the measured current's noise picks the "
                                       "other (5 % lower) table while the plant's zero current counts as "
                                       "discharge; with |i| > 1 A the max is 0.3 % (test below). Seed's free "
                                       "R_s: 7.7 %")
def test_full_dekf_rs_max_within_5pct(dekf_full):
    assert bs.dekf_metrics(dekf_full)["rs_rel_err_max_after_settle"] < 0.05


@pytest.mark.slow
def test_full_dekf_rs_max_within_5pct_under_load(dekf_full):
    # steps with |i| > 1 A, where R_s acts (seed's free R_s: 7.7 %, its charge/discharge average)
    assert bs.dekf_metrics(dekf_full)["rs_rel_err_max_loaded"] < 0.05


@pytest.mark.slow
def test_full_dekf_heat_rmse_below_2pct(dekf_full):
    # default (table-scaled R_s, R1, C1 + slow branch V2, issue 14): 0.5 %; one-branch table-scaled 1.8 %
    # (seed's free R_s, R1, C1: 6.0 %; one-branch OCV-R-RC floor 1.6 %)
    assert bs.dekf_metrics(dekf_full)["heat_rmse_rel_mean"] < 0.02


@pytest.fixture(scope="module")
def dekf_full_seed_filter():
    # the seed's one-branch filter with free R_s, R1, C1 and the SOC walk it was re-tuned with (issue 14
    # made the slow branch and q_soc = 1e-3 the default)
    return bs.dekf_replay(bs.BASE_SCENARIO, SEED, soc_offset_pct=-10.0,
                          bms_sets=("bms.rs_model=free", "bms.rc_model=free", "bms.v2_model=none", "bms.q_soc=1e-5"))


@pytest.mark.slow
def test_full_dekf_seed_filter_still_meets_soc_and_misses_rs_and_heat(dekf_full_seed_filter):
    # the seed's free R_s, R1, C1 (rs_model = rc_model = "free") stays available and behaves as recorded
    m = bs.dekf_metrics(dekf_full_seed_filter)
    assert m["soc_err_max_after_settle_pct"] < 2.0
    assert m["rs_rel_err_max_loaded"] > 0.05 and m["heat_rmse_rel_mean"] > 0.04


def test_table_3_3_tuning_is_one_continuous_intensity_at_every_sample_time():
    """Issue 27: Table 3.2 read at 1 s and converted: per-step random-walk variance beta^2 dt / 1 s."""
    import math
    from shevsim.studies.thermal_estimators import run_stage
    for dt in (1.0, 0.1):
        tun = run_stage("I", seed=0, duration_s=20.0, dt_s=dt, tuning_ref_dt_s=1.0)["tuning"]
        assert tun["KF"]["beta1"] ** 2 == pytest.approx(5e-4 ** 2 * dt)
        assert tun["DKF"]["beta2"] ** 2 == pytest.approx(7e-3 ** 2 * dt)
        assert tun["JEKF"]["beta2"] ** 2 == pytest.approx(6e-3 ** 2 * dt)
        assert tun["KF"]["sigma_c"] == 0.05                       # sensor noise is per sample: not scaled
    raw = run_stage("I", seed=0, duration_s=2.0, dt_s=0.1, tuning_ref_dt_s=None)["tuning"]
    assert raw["KF"] == {"sigma_c": 0.05}                          # the constructors' per-step defaults
    assert math.isclose(5e-4 * math.sqrt(0.1), run_stage("I", duration_s=2.0, dt_s=0.1,
                                                         tuning_ref_dt_s=1.0)["tuning"]["DKF"]["beta1"])


def test_table_3_3_stage_iii_pattern_is_the_thesis_s_at_0p1s_and_reversed_at_1s():
    """With the converted tuning the mistuned KF's error lands in the core at 0.1 s (the thesis's pattern:
    core 1.58, surface 0.15 degC) and in the surface at 1 s; the thesis's literal theta(0) = h* start makes
    DKF/JEKF repeat stage I, so the thesis's stage-III DKF/JEKF degradation is not from the literal start."""
    from shevsim.studies.bms_study import table_3_3_rates
    r = table_3_3_rates(None, seeds=(0,), duration_s=1200.0, dt_values=(1.0, 0.1), wrong_h0_factors=(2.0,))
    fast, slow = r["dt_s"][0.1], r["dt_s"][1.0]
    assert fast["III"]["KF"]["core_c"] > 2.0 * fast["III"]["KF"]["surface_c"]
    assert slow["III"]["KF"]["surface_c"] > 2.0 * slow["III"]["KF"]["core_c"]
    for f in ("DKF", "JEKF"):
        assert fast["III"][f]["core_c"] < 0.5 * fast["III"]["KF"]["core_c"]
        # the literal start behaves like stage I (same h; other noise draws), far better than from 2 h*
        assert fast["III_h0_star"][f]["core_c"] < min(1.5 * fast["I"][f]["core_c"], 0.5 * fast["III"][f]["core_c"])
    assert r["fit"][0.1] < r["fit"][1.0]
