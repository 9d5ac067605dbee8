"""Calibration on records made by a model that is not shevsim's (issue 24).

The vehicle records in ``tests/data/independent/`` were made once by FASTSim 3.1 (its own vehicle model,
a Renault Zoe, its own 0.1 s time stepping) and logged at 1 Hz instantaneously with sensor noise
(``make_vehicle_fastsim.py`` beside them; seeds and truth in ``vehicle_truth.json``).  The calibration is
given what a user has: the published vehicle data and motor efficiency curve (``vehicle_nominal.toml``).

Stated tolerances: mass within 5 %, auxiliary power within 15 %, the time shift within a quarter sample
(0.25 s), the grade profile's amplitude (fitted knots projected on the true sine) within 25 % (six
piecewise-linear knots overshoot a sine between them), FASTSim's regenerative-efficiency asymmetry within
0.03.  The engine-generator soot records come from an independent plant script (``make_engine_soot.py``):
analyser lag and offset within 25 %, the soot-map scale within 10 %.
"""
from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from shevsim.calibrate.known import load_params_toml
from shevsim.calibrate.data import load_measured
from shevsim.calibrate.timing import PropagatedInputNoise, input_noise_floor, sensor_noise_floor, smoother_noise
from shevsim.calibrate.workflow import BASELINE_FAILURE_RATIO, SENSOR_FAILURE_RATIO, run_workflow

D = Path(__file__).resolve().parents[1] / "data" / "independent"
PHYSICAL = {"mass_error", "aux_load", "road_grade", "rolling_error", "aero_error", "regen_limit"}


@lru_cache(maxsize=None)
def _truth():
    return json.loads((D / "vehicle_truth.json").read_text())


@lru_cache(maxsize=None)
def _vehicle(case: str):
    data = load_measured(str(D / f"vehicle_{case}.csv"), "vehicle")
    return run_workflow("vehicle", data, load_params_toml(D / "vehicle_nominal.toml"), plots=False)


#: FASTSim 3.1's drive regenerates at a constant 0.84 (its efficiency curve's zero-power point) where it
#: motors along the curve c(x): over the regenerative points of the HD-UDDS trace the curve gives 0.908
#: (energy-weighted), so the record's generating / motoring efficiency ratio is 0.84 / 0.908 = 0.925 in the
#: energy sense.  A least-squares fit of one constant ratio r to the power record estimates the ratio
#: weighted by the squared power instead, r = sum(c P_elec P_mech) / sum((c P_mech)^2) over the regenerative
#: steps of FASTSim's machine history (pwr_elec_prop_in_watts, pwr_mech_prop_out_watts): 0.9076 (none_2
#: 0.9087, none_3 0.9070) - the reference for the fitted parameter (make_vehicle_fastsim.py's FASTSim history;
#: docs/calibration_independent.md).  The energy-weighted 0.925 was the reference until the vehicle model had
#: the wheels' rotating inertia: without it the model's regenerated power lacked the wheels' share and the
#: fitted ratio came out higher (0.924 on this record; 0.893 with the inertia).
FASTSIM_REGEN_RATIO = 0.9076


def test_no_effect_fastsim_record_selects_nothing():
    rep = _vehicle("none")
    assert rep["timing"]["sample_convention"] == "instantaneous"      # the default, stated in the report
    assert not (set(rep["selected_effects"]) & PHYSICAL), rep["selected_effects"]
    assert rep["selected_effects"] == [] or rep["model_form_discrepancy"]
    # the honest noise floor: the power logger's 100 W (standstill segments), not the signal's dynamics, plus
    # the logged speed's 0.02 m/s carried through the model (differentiated: most of the correct model's
    # residual); the held-out residual is near that floor, not 8x it
    nf = rep["noise_floor"]["power_w"]
    assert nf["sensor"]["method"] == "quiet" and nf["sensor"]["value"] == pytest.approx(100.0, rel=0.2)
    assert nf["propagated_inputs"]["inputs"]["speed_mps"]["value"] == pytest.approx(0.02, rel=0.25)
    assert nf["propagated_inputs"]["value"] > 4.0 * nf["sensor"]["value"]
    assert rep["rmse_before"]["power_w"]["holdout"] < 1.5 * nf["value"] and not rep["baseline_failure"]
    # the drive's efficiency asymmetry is found as what it is (declared, always fitted), not as mass
    assert rep["final_parameters"]["regen_efficiency_scale_frac"] == pytest.approx(FASTSIM_REGEN_RATIO, abs=0.03)


@pytest.mark.parametrize("case", ["none_2", "none_3", "none_4"])
def test_more_no_effect_fastsim_records_name_no_physical_effect(case):
    """Another HD-UDDS window, the Orange County bus cycle (half its traction energy comes back as regen:
    with one efficiency scale its regen asymmetry was read as mass -3 %) and the WVU interstate cycle."""
    rep = _vehicle(case)
    assert not (set(rep["selected_effects"]) & PHYSICAL), rep["selected_effects"]
    assert rep["selected_effects"] == [] or rep["model_form_discrepancy"]


def test_payload_named_as_mass_within_5_percent():
    rep = _vehicle("payload")
    truth = _truth()["cases"]["payload"]["truth"]["mass_kg"]
    assert rep["selected_effects"] == ["mass_error"]
    assert rep["final_parameters"]["mass_kg"] == pytest.approx(truth, rel=0.05)
    # the held-out residual of this trace has a floor that is not the payload's: the model differentiates
    # the logged speed (0.02 m/s noise), about 0.8 kW on the no-effect record of the same trace (other noise
    # seed).  The payload adds residual variance over that floor; the fitted mass removes most of it.
    floor = _vehicle("none")["rmse_before"]["power_w"]["holdout"]
    before, after = (rep[k]["power_w"]["holdout"] for k in ("rmse_before", "rmse_after"))
    assert before ** 2 - floor ** 2 > 0.3 * floor ** 2                      # the payload is visible
    assert after ** 2 - floor ** 2 < 0.25 * (before ** 2 - floor ** 2)


def test_aux_load_named_within_15_percent():
    rep = _vehicle("aux")
    truth = _truth()["cases"]["aux"]["truth"]["aux_power_w"]
    assert rep["selected_effects"] == ["aux_load"]
    assert rep["final_parameters"]["aux_power_w"] == pytest.approx(truth, rel=0.15)


def test_grade_profile_named_with_its_amplitude():
    rep = _vehicle("grade")
    tr = _truth()["cases"]["grade"]["truth"]
    assert rep["selected_effects"] == ["road_grade"]
    knots = np.array([rep["final_parameters"][f"grade_frac[{j}]"] for j in range(6)])
    s = np.sin(2 * math.pi * np.linspace(0.0, 1.0, 6))     # the knots are spread evenly over the distance
    amp = float(knots @ s / (s @ s))
    assert amp == pytest.approx(tr["grade_amplitude_frac"], rel=0.25)


@pytest.mark.parametrize("case", ["shift_half", "latency_2"])
def test_latency_named_as_timing_never_as_mass(case):
    rep = _vehicle(case)
    truth = _truth()["cases"][case]["truth"]["time_shift_s"]
    assert rep["selected_effects"] == ["timing"], rep["selected_effects"]
    assert rep["timing"]["time_shift_s"] == pytest.approx(truth, abs=0.25)
    assert "mass_kg" not in rep["final_parameters"]


def test_payload_with_half_sample_shift_names_both_mass_and_timing():
    """The payload vehicle with its power channel 0.5 s late: both the effect and the timing are named, the
    shift within the same 0.25 s as ``shift_half`` and the mass within the payload case's 5 %.  (Before: a
    shift read by linear interpolation bought smoothing, and the generator's PCHIP trace was sampled
    half-way between its knots: 0.69 s and 2107 kg, +8.1 %; docs/calibration_independent.md.)"""
    rep = _vehicle("payload_shift")
    tr = _truth()["cases"]["payload_shift"]["truth"]
    assert sorted(rep["selected_effects"]) == ["mass_error", "timing"], rep["selected_effects"]
    assert rep["timing"]["time_shift_s"] == pytest.approx(tr["time_shift_s"], abs=0.25)
    assert rep["final_parameters"]["mass_kg"] == pytest.approx(tr["mass_kg"], rel=0.05)


def test_regen_limit_named_with_its_power():
    """FASTSim's drive with its electrical regenerative power saturating at 6 kW (its machine efficiency curve
    over the signed power fraction, make_vehicle_fastsim.py): named as ``regen_limit``, the limit within
    10 %, and the generating-efficiency scale does not take it (it stays near the no-effect record's)."""
    rep = _vehicle("regen_limit")
    truth = _truth()["cases"]["regen_limit"]["truth"]["regen_power_max_w"]
    assert rep["selected_effects"] == ["regen_limit"], rep["selected_effects"]
    assert rep["final_parameters"]["regen_power_max_w"] == pytest.approx(truth, rel=0.10)
    assert rep["final_parameters"]["regen_efficiency_scale_frac"] > 0.85


def test_fractional_read_is_a_delay_not_a_filter():
    """A prediction read between samples (sample convention, fitted time shift) keeps every frequency's
    amplitude whatever the fraction: a linear read at half a sample keeps 71 % of white noise's rms, at a
    whole sample all of it, so a fitted shift could buy smoothing (payload_shift: 0.69 s, mass +8 %)."""
    from shevsim.calibrate.timing import band_limited_read, shift_prediction
    rng = np.random.default_rng(5)
    t = np.arange(4000.0)
    w = rng.normal(size=t.size)
    for frac in (0.1, 0.25, 0.5, 0.75, 1.0, -2.5):
        assert np.std(band_limited_read(w, t, frac)) == pytest.approx(1.0, abs=0.03)
    assert np.std(np.interp(t + 0.5, t, w)) == pytest.approx(math.sqrt(0.5), abs=0.03)     # the former read
    # a band-limited signal is delayed exactly (away from the mirrored ends)
    y = np.sin(2 * math.pi * t / 17.0) + 0.5 * np.cos(2 * math.pi * t / 5.3)
    for off in (0.5, -0.37, 2.2):
        ref = np.sin(2 * math.pi * (t + off) / 17.0) + 0.5 * np.cos(2 * math.pi * (t + off) / 5.3)
        assert np.max(np.abs(band_limited_read(y, t, off) - ref)[50:-50]) < 2e-3
    # an irregular record (logger jitter) is delayed on its median-step grid (to it and back linearly:
    # twice the linear-interpolation error of a 17-sample period, (2 pi / 17)^2 / 8 = 0.017)
    tj = t[:500] + rng.uniform(-0.05, 0.05, 500)
    yj = np.sin(2 * math.pi * tj / 17.0)
    got = shift_prediction({"y": yj, "k": 3.0}, tj, 0.5)
    assert got["k"] == 3.0
    assert np.max(np.abs(got["y"] - np.sin(2 * math.pi * (tj + 0.5) / 17.0))[20:-20]) < 0.05


def test_fractional_read_of_a_record_with_a_gap_is_read_per_segment(monkeypatch):
    """A logger stopped for a day: the read is split at the gap and each segment delayed on its own - the
    FFT's size is bounded by the samples (at most GAP_STEPS x), not by the time span (the whole span's grid
    was 2 x 88 200 points for 1 800 samples: 0.5 s a read), and equals the per-segment read."""
    import scipy.fft
    from shevsim.calibrate.timing import GAP_STEPS, band_limited_read
    rng = np.random.default_rng(11)
    ta, tb = np.arange(1000.0), 1000.0 + 86400.0 + np.arange(800.0)
    t = np.concatenate([ta, tb])
    y = np.sin(2 * math.pi * t / 17.0) + 0.1 * rng.normal(size=t.size)
    sizes = []
    rfft = scipy.fft.rfft
    monkeypatch.setattr(scipy.fft, "rfft", lambda x, *a, **k: (sizes.append(len(x)), rfft(x, *a, **k))[1])
    for off in (0.5, -1.25, 2.0):
        sizes.clear()
        got = band_limited_read(y, t, off)
        assert sizes and max(sizes) <= 2 * GAP_STEPS * t.size and sum(sizes) == 2 * t.size
        want = np.concatenate([band_limited_read(y[:1000], ta, off), band_limited_read(y[1000:], tb, off)])
        assert np.array_equal(got, want)
        # and each segment is the delayed sine away from its mirrored ends (the noise moved with it)
        ref = np.sin(2 * math.pi * (t + off) / 17.0)
        inner = np.r_[50:950, 1050:1750]
        assert np.std((got - ref)[inner]) == pytest.approx(0.1, rel=0.1)


@pytest.mark.parametrize("case,rounded", [("none", False), ("none_2", False), ("none_4", False),
                                          ("none_2", True)])
def test_dynamic_record_with_100x_residual_is_a_baseline_failure(case, rounded, tmp_path):
    """The FASTSim car's records against the shevsim default vehicle (a 15.5 t truck): the nominal's residual
    is far above the 100 W logger noise, whatever the 1 Hz power's swings.  The propagated part of the floor
    is the truck's own amplification of the speed noise (its mass): on ``none_2`` and ``none_4`` the residual
    (69 / 49 kW) is 790x / 537x the sensor floor but only 8.7x / 8.9x the truck's combined floor, and with
    the speed logged to 1 km/h (quantisation noise 0.08 m/s) less still - a wrong nominal must not hide its
    own failure: >= 100x the sensor floor fails whatever the model."""
    path = D / f"vehicle_{case}.csv"
    if rounded:
        lines = path.read_text().splitlines()
        body = [ln.split(",") for ln in lines[2:]]
        path = tmp_path / "rounded.csv"
        path.write_text("\n".join(lines[:2] + [f"{a},{round(float(v) * 3.6) / 3.6!r},{p}" for a, v, p in body]) + "\n")
    data = load_measured(str(path), "vehicle")
    rep = run_workflow("vehicle", data, None, plots=False, effects=[])     # the nominal's verdict only
    bf = {b["channel"]: b for b in rep["baseline_failure"]}
    assert "power_w" in bf, rep["noise_floor"]["power_w"]
    b = bf["power_w"]
    assert b["ratio_to_sensor_floor"] >= SENSOR_FAILURE_RATIO
    assert b["sensor_noise_floor"] == pytest.approx(100.0, rel=0.2)
    assert b["ratio_to_sensor_floor"] == pytest.approx(b["holdout_rmse"] / b["sensor_noise_floor"])
    assert b["ratio_to_noise_floor"] == pytest.approx(b["holdout_rmse"] / b["noise_floor"])
    assert any("sensor noise floor" in r for r in b["rules"])
    assert (any("combined" in r for r in b["rules"])) == (b["ratio_to_noise_floor"] > BASELINE_FAILURE_RATIO)
    if case == "none":      # against the truck's combined floor (its mass amplifies the speed noise) still > 10x
        assert b["ratio_to_noise_floor"] > BASELINE_FAILURE_RATIO


def _road_load_record(folder: Path, speed_noise: float, power_noise: float, seed: int = 7):
    """A 1 Hz record made here from the road-load equation (not shevsim's vehicle): a 1600 kg car on a smooth
    speed trace (13 +- 5 m/s over 60 s, +- 2 m/s over 21 s; analytic acceleration), electrical power at each
    sample instant = (m a v + drag + rolling) / 0.9 in traction, x 0.9 in regeneration, + 250 W; logged
    instantaneously with white noise.  The nominal is the same car with a flat 0.9 drive map: a correct
    model.  Returns (csv, nominal toml, the hand-computed propagated floor of the power for ``speed_noise``
    as a function of a sample mask)."""
    m, eta, aux, rho, cda, fr, g = 1600.0, 0.9, 250.0, 1.2, 0.33 * 2.5121646, 0.009, 9.81
    lines = (D / "zoe_motor_eff_map.csv").read_text().splitlines()
    rows = [ln for ln in lines if ln and not ln.startswith("#")]
    (folder / "flat_eff.csv").write_text("\n".join(["# flat 0.9 on the Zoe map's grid (test)", rows[0]] + [
        ",".join(r.split(",")[:2] + [str(eta)]) for r in rows[1:]]) + "\n")
    (folder / "torque.csv").write_text((D / "zoe_motor_torque_curves.csv").read_text())
    (folder / "nominal.toml").write_text((D / "vehicle_nominal.toml").read_text().replace(
        "zoe_motor_eff_map.csv", "flat_eff.csv").replace("zoe_motor_torque_curves.csv", "torque.csv"))
    t = np.arange(600.0)
    w1, w2 = 2 * math.pi / 60.0, 2 * math.pi / 21.0
    v = 13.0 + 5.0 * np.sin(w1 * t) + 2.0 * np.sin(w2 * t + 1.0)
    a = 5.0 * w1 * np.cos(w1 * t) + 2.0 * w2 * np.cos(w2 * t + 1.0)
    pm = m * a * v + 0.5 * rho * cda * v ** 3 + m * g * fr * v
    gain = np.where(pm > 0, 1.0 / eta, eta)
    pe = pm * gain + aux
    rng = np.random.default_rng(seed)
    vs, ps = v + rng.normal(0.0, speed_noise, t.size), pe + rng.normal(0.0, power_noise, t.size)
    (folder / "rec.csv").write_text("time_s,speed_mps,power_w\n" + "".join(
        f"{a:g},{float(b)!r},{float(c)!r}\n" for a, b, c in zip(t, vs, ps)))
    # by hand: the model's power over a sample period is m v (v_k - v_k-1) / dt x gain (the rest of the road
    # load moves by rho cd A v^2 dv, ~1e-3 of it here), so white speed noise s gives m v gain sqrt(2) s / dt
    def hand(mask):
        return math.sqrt(2.0) * speed_noise * math.sqrt(float(np.mean((m * v * gain)[mask] ** 2)))
    return folder / "rec.csv", folder / "nominal.toml", hand


def test_noise_floor_includes_the_inputs_noise_propagated_through_the_model(tmp_path):
    """The floor of a residual is the output's sensor noise plus the measured inputs' noise carried through
    the model.  On a road-load record with a quiet power sensor (30 W) and a 0.02 m/s speed logger, the
    correct model's residual is the differentiated speed noise, ~0.6 kW = 20x the power sensor: against the
    sensor floor alone that was a false baseline failure.  Checked against the hand value m v sqrt(2) s / dt,
    and a wrong nominal (the 15.5 t truck) is still a baseline failure."""
    rec, nominal, hand = _road_load_record(tmp_path, 0.02, 30.0)
    data = load_measured(str(rec), "vehicle")
    rep = run_workflow("vehicle", data, load_params_toml(nominal), plots=False, effects=[],
                       sensor_noise={"power_w": 30.0})
    nf = rep["noise_floor"]["power_w"]
    assert nf["sensor"] == {"value": 30.0, "method": "declared", "estimates": {"declared": 30.0}}
    speed = nf["propagated_inputs"]["inputs"]["speed_mps"]
    assert speed["method"] == "differences" and speed["value"] == pytest.approx(0.02, rel=0.2)
    # the Monte Carlo propagation (over the held-out samples) against the hand formula at the input floor it used
    t = data.df["time_s"].to_numpy()
    held_mask = np.zeros(t.size, bool)
    for a, b in rep["split"]["holdout_intervals_s"]:
        held_mask |= (t >= a) & (t <= b)
    assert nf["propagated_inputs"]["value"] == pytest.approx(hand(held_mask) * speed["value"] / 0.02, rel=0.2)
    assert nf["value"] == pytest.approx(math.hypot(30.0, nf["propagated_inputs"]["value"]))
    # a declared speed noise (--sensor-noise speed_mps=0.02) is propagated as given
    rep_d = run_workflow("vehicle", data, load_params_toml(nominal), plots=False, effects=[],
                         sensor_noise={"power_w": 30.0, "speed_mps": 0.02})
    pd_ = rep_d["noise_floor"]["power_w"]["propagated_inputs"]
    assert pd_["inputs"]["speed_mps"]["method"] == "declared"
    assert pd_["value"] == pytest.approx(hand(held_mask), rel=0.2)
    held = rep["rmse_before"]["power_w"]["holdout"]
    assert held > 10 * 30.0                     # the sensor floor alone would call this correct model a failure
    assert rep["baseline_failure"] == [] and held < 2.0 * nf["value"]
    # the same record against a wrong nominal (the default 15.5 t truck): its own floor is larger (the mass
    # amplifies the speed noise), and the residual still far above it
    rep = run_workflow("vehicle", data, None, plots=False, effects=[], sensor_noise={"power_w": 30.0})
    bf = {b["channel"]: b for b in rep["baseline_failure"]}
    assert "power_w" in bf and bf["power_w"]["ratio_to_noise_floor"] > 10.0
    assert bf["power_w"]["ratio_to_sensor_floor"] > 100.0
    assert bf["power_w"]["noise_floor"] == pytest.approx(math.hypot(bf["power_w"]["sensor_noise_floor"],
                                                                    bf["power_w"]["propagated_input_floor"]))


def test_noise_floor_holds_on_a_dynamic_signal_without_rest():
    """On a fast-swinging signal with no quiet segment the local-quadratic smoother still finds the noise,
    where the first-difference estimate is dominated by the swings."""
    rng = np.random.default_rng(3)
    t = np.arange(2000.0)
    sig = 4e4 * np.sin(2 * math.pi * t / 23.0) * np.sin(2 * math.pi * t / 157.0)
    y = sig + rng.normal(0.0, 300.0, t.size)
    fd = 1.4826 * np.median(np.abs(np.diff(y))) / math.sqrt(2.0)
    assert fd > 10 * 300.0                                     # the former estimate: blind
    assert smoother_noise(y) == pytest.approx(300.0, rel=0.25)
    nf = sensor_noise_floor(y, y - sig + rng.normal(0, 1e4, t.size), None)
    assert nf["method"] == "smoother" and nf["value"] == pytest.approx(300.0, rel=0.25)
    assert sensor_noise_floor(y, y, None, declared=250.0) == {"value": 250.0, "method": "declared",
                                                              "estimates": {"declared": 250.0}}


def test_numerically_zero_input_noise_is_no_noise_to_propagate():
    """An input whose smoother estimate is floating-point rounding (a constant ambient jittering by a few ulp:
    6e-15 degC; the engine script's noise-free power command: 1.6e-10 W on 128 kW rms) has no noise to
    propagate: floor 0, method ``none`` saying why - never a 'Monte Carlo' floor of rounding.  A real noise
    on a small channel is kept (the threshold is relative to the channel's own scale)."""
    rng = np.random.default_rng(1)
    amb = 25.0 + rng.integers(-3, 4, 3600) * np.spacing(25.0)
    assert 0.0 < smoother_noise(amb) < 1e-13                                    # what it was taken for
    got = input_noise_floor(amb)
    assert got["value"] == 0.0 and got["method"].startswith("none") and "numerically zero" in got["method"]
    power = load_measured(str(D / "engine_none.csv"), "engine").df["power_w"].to_numpy(float)
    assert 0.0 < smoother_noise(power) < 1e-6
    assert input_noise_floor(power)["value"] == 0.0
    small = 1e-3 * np.sin(np.arange(3600) / 300.0) + rng.normal(0.0, 1e-6, 3600)   # 1 uA noise on a mA signal
    assert input_noise_floor(small)["value"] == pytest.approx(1e-6, rel=0.15)
    assert input_noise_floor(amb, declared=0.01)["value"] == 0.01               # declared: as given
    assert PropagatedInputNoise(None, None, {"t_ambient_c": input_noise_floor(amb)["value"]}).method.startswith(
        "none (no measured input")


# ------------------------------------------------------------------ engine-generator soot (independent script)

@lru_cache(maxsize=None)
def _engine(case: str):
    data = load_measured(str(D / f"engine_{case}.csv"), "engine")
    return run_workflow("engine", data, None, plots=False)


@lru_cache(maxsize=None)
def _engine_truth():
    return json.loads((D / "engine_truth.json").read_text())


def test_engine_no_effect_record_names_nothing_and_states_the_model_form():
    """The independent plant's power response (first-order 0.8 s, operating point on the optimal line at every
    instant) is not the component's form (turbo lag, PI rack, speed loop): nothing is named - not even a
    time shift, which removes only 17 % of the residual variance above the noise (a logger latency would remove
    nearly all of it) - and what the library cannot explain is stated as a model-form discrepancy.  The
    baseline failure is raised against a noise floor that holds on the dynamic soot signal (the script's
    noise: 2 % + 0.05 mg/s)."""
    rep = _engine("none")
    assert rep["selected_effects"] == [], rep["selected_effects"]
    stated = {d.get("effect") or d.get("channel") for d in rep["model_form_discrepancy"]}
    assert {"timing", "soot_rate_mgps"} <= stated
    truth = _engine_truth()["cases"]["none"]["truth"]["soot_scale_frac"]
    assert rep["final_parameters"]["soot_scale_frac"] == pytest.approx(truth, rel=0.10)
    # the script's noise at the median soot rate (the floor is a robust, median-based estimate): 0.15 mg/s
    soot = load_measured(str(D / "engine_none.csv"), "engine").df["soot_rate_mgps"].to_numpy()
    noise = math.hypot(0.02 * float(np.median(soot)), 0.05)
    assert rep["noise_floor"]["soot_rate_mgps"]["sensor"]["value"] == pytest.approx(noise, rel=0.35)
    bf = {b["channel"]: b for b in rep["baseline_failure"]}
    assert bf["soot_rate_mgps"]["ratio_to_noise_floor"] > 10.0


@pytest.mark.parametrize("case,effect,param,rel", [("analyzer_lag", "analyzer_lag", "soot_analyzer_tau_s", 0.25),
                                                   ("analyzer_offset", "analyzer_offset", "soot_analyzer_offset_mgps", 0.25)])
def test_engine_analyser_effects_named_with_their_parameter(case, effect, param, rel):
    """The analyser effect is named, alone among the physical effects.  (On ``analyzer_lag`` a -0.53 s time
    shift removes 49.7 % of the residual variance above the noise that the lag leaves - at the timing rule's
    one-half boundary - so it is stated as a model-form discrepancy; timing is not a physical effect either way.)"""
    rep = _engine(case)
    assert set(rep["selected_effects"]) - {"timing"} == {effect}, rep["selected_effects"]
    assert rep["final_parameters"][param] == pytest.approx(_engine_truth()["cases"][case]["truth"][param], rel=rel)


def test_engine_transient_puff_named_as_transient_soot():
    rep = _engine("transient")
    assert rep["selected_effects"] == ["transient_soot"]
    assert rep["rmse_after"]["soot_rate_mgps"]["holdout"] < 0.8 * rep["rmse_before"]["soot_rate_mgps"]["holdout"]
