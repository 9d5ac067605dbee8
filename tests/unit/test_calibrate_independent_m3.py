"""Calibration on a second FASTSim vehicle, one the calibration was not developed on (issue 24): the Tesla
Model 3 RWD.

The records ``tests/data/independent/vehicle_m3_*.csv`` were made once by FASTSim 3.1 from its own
``2022 Tesla Model 3 RWD thrml.yaml`` (cabin, HVAC and battery thermal models switched off: a constant
auxiliary load) on FASTSim's own UDDS and HWFET cycles - neither vehicle nor cycles are the Renault Zoe /
HD-UDDS records the vehicle calibration was developed against - and logged at 1 Hz instantaneously with the
Zoe records' sensor noise (``make_vehicle_fastsim.py --vehicle m3``; seeds and truth in
``vehicle_m3_truth.json``).  The nominal is the published vehicle in shevsim's terms
(``vehicle_m3_nominal.toml``, ``m3_motor_*.csv``).

Stated tolerances (the Zoe records'): mass within 5 %, auxiliary power within 15 %, the time shift within
0.25 s; no physical effect on a no-effect record.  The default run calibrates one record (``payload``) with
the whole library; the other four are ``slow``.
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from shevsim.calibrate.data import load_measured
from shevsim.calibrate.known import load_params_toml
from shevsim.calibrate.workflow import run_workflow

D = Path(__file__).resolve().parents[1] / "data" / "independent"
PHYSICAL = {"mass_error", "aux_load", "road_grade", "rolling_error", "aero_error", "regen_limit"}
CASES = ("none", "payload", "aux", "latency_2", "none_2")

#: FASTSim 3.1's ``2022 Tesla Model 3 RWD thrml.yaml`` as the package ships it (``fsim.Vehicle.from_resource``,
#: ``to_dict``): transcribed here so that the nominal is checked against the file, not against the script
#: that wrote both
FASTSIM_M3 = {
    "mass_kilograms": 1752.0, "drag_coef": 0.23, "frontal_area_square_meters": 2.22, "wheel_rr_coef": 0.007,
    "wheel_radius_meters": 0.33435, "wheel_inertia_kilogram_square_meters": 0.815, "num_wheels": 4,
    "pwr_aux_base_watts": 250.0,
    "em_pwr_out_max_watts": 239000.0, "transmission_eff": 0.98,
    "em_eff_grid": [0.0, 0.02, 0.04, 0.06, 0.08, 0.1, 0.2, 0.4, 0.6, 0.8, 1.0],
    "em_eff_values": [0.84, 0.86, 0.88, 0.9, 0.91, 0.92, 0.94, 0.95, 0.95, 0.94, 0.93],
}


@lru_cache(maxsize=None)
def _truth():
    return json.loads((D / "vehicle_m3_truth.json").read_text())


@lru_cache(maxsize=None)
def _m3(case: str):
    data = load_measured(str(D / f"vehicle_m3_{case}.csv"), "vehicle")
    return run_workflow("vehicle", data, load_params_toml(D / "vehicle_m3_nominal.toml"), plots=False)


def _record(case: str):
    a = np.loadtxt(D / f"vehicle_m3_{case}.csv", delimiter=",", skiprows=2, comments="#")
    return a[:, 0], a[:, 1], a[:, 2]


def test_m3_nominal_is_fastsims_published_vehicle():
    """The user's nominal holds FASTSim's chassis numbers (the wheels' inertia: per wheel x wheel count) and
    base auxiliary load, and its map is FASTSim's published machine curve (output-power fraction, read
    linearly) times the 0.98 transmission."""
    p = load_params_toml(D / "vehicle_m3_nominal.toml")
    f = FASTSIM_M3
    assert p["mass_kg"] == f["mass_kilograms"] and p["drag_coefficient"] == f["drag_coef"]
    assert p["frontal_area_m2"] == f["frontal_area_square_meters"] and p["rolling_coefficient"] == f["wheel_rr_coef"]
    assert p["wheel_radius_m"] == f["wheel_radius_meters"] and p["aux_power_w"] == f["pwr_aux_base_watts"]
    assert p["wheel_inertia_kg_m2"] == f["wheel_inertia_kilogram_square_meters"] * f["num_wheels"]
    assert p["gear_ratio"] == pytest.approx(9.036)
    assert _truth()["known"] == {k: v for k, v in p.items() if not k.startswith("__") and not k.endswith("_file")}
    eff = np.loadtxt(D / p["efficiency_map_file"], delimiter=",", skiprows=3)
    w, q, e = eff.T
    frac = np.minimum(np.abs(w * q) / f["em_pwr_out_max_watts"], 1.0)
    want = np.interp(frac, f["em_eff_grid"], f["em_eff_values"]) * f["transmission_eff"]
    assert np.max(np.abs(e - want)) < 1e-5
    assert e.min() == pytest.approx(0.84 * 0.98, abs=1e-5) and e.max() == pytest.approx(0.95 * 0.98, abs=1e-5)
    # the map covers the car's top speed (225 km/h) at the wheel radius and gear
    assert w.max() > 225.0 / 3.6 / p["wheel_radius_m"] * p["gear_ratio"]
    tc = np.loadtxt(D / p["torque_curves_file"], delimiter=",", skiprows=2)
    assert np.all(tc[:, 1] <= 420.0 + 1e-9)
    assert np.all(tc[:, 1] * tc[:, 0] <= f["em_pwr_out_max_watts"] * (1 + 1e-6))      # 239 kW above base speed
    assert np.array_equal(tc[:, 1], tc[:, 2])


def test_m3_records_are_the_car_on_its_cycles():
    """What the records say without any calibration: 700 s at 1 Hz; at standstill the logged power is the
    truth's auxiliary load (the thermal models are off: constant); the electrical traction energy over the
    published road load's wheel energy lies between the published drive efficiencies' extremes (0.95 and
    0.84, x 0.98); the latency record is the no-effect record's FASTSim history 2 samples later."""
    tr = _truth()
    assert "switched off" in tr["generator"]
    known = tr["known"]
    cda = known["drag_coefficient"] * known["frontal_area_m2"]
    for case in CASES:
        t, v, pw = _record(case)
        truth = tr["cases"][case]["truth"]
        assert tr["cases"][case]["cycle_met"]
        assert np.array_equal(t, np.arange(701.0))
        # UDDS peaks at 91.2 km/h, HWFET at 96.4 km/h (the noise 0.02 m/s)
        assert v.max() == pytest.approx(25.35 if case != "none_2" else 26.78, abs=0.1)
        still = v < 0.1                            # interior of standstills (3 s from their ends), not t = 0
        inner = np.convolve(still, np.ones(7), mode="same") == 7
        inner[0] = False
        if case == "none_2":                       # the highway cycle has no stop inside its 700 s
            assert inner.sum() == 0 and v[100:600].min() > 10.0
        else:
            n = int(inner.sum())
            assert n > 50
            assert abs(pw[inner].mean() - truth["aux_power_w"]) < 3.5 * 100.0 / np.sqrt(n)
        m = truth["mass_kg"]
        p_wheel = m * np.gradient(v, t) * v + 0.5 * 1.2 * cda * v ** 3 + m * 9.81 * known["rolling_coefficient"] * v
        ratio = np.sum(np.clip(pw - truth["aux_power_w"], 0.0, None)) / np.sum(p_wheel[p_wheel > 0])
        assert 1.0 / (0.95 * 0.98) < ratio < 1.0 / (0.84 * 0.98), (case, ratio)
    _, _, p0 = _record("none")
    _, _, p2 = _record("latency_2")
    err = {k: float(np.std(p2[4 + k:-4] - p0[4:-4 - k])) for k in range(-3, 4)}
    assert min(err, key=err.get) == 2 and err[2] < 200.0          # two noise draws of 100 W


def test_m3_payload_named_as_mass_within_5_percent():
    """The default-run test of the second vehicle, whole library: +22.7 % payload on UDDS is named as
    ``mass_error`` alone, the mass within 5 %, the held-out power error falls."""
    rep = _m3("payload")
    truth = _truth()["cases"]["payload"]["truth"]["mass_kg"]
    assert rep["selected_effects"] == ["mass_error"], rep["selected_effects"]
    assert rep["final_parameters"]["mass_kg"] == pytest.approx(truth, rel=0.05)
    assert not rep["baseline_failure"] and not rep["model_form_discrepancy"]
    before, after = (rep[k]["power_w"]["holdout"] for k in ("rmse_before", "rmse_after"))
    assert after < 0.6 * before


#: case -> (expected effects, parameter, tolerance, relative?)
EXPECT = {
    "none": ([], None, None, None),
    "aux": (["aux_load"], "aux_power_w", 0.15, True),
    "latency_2": (["timing"], "time_shift_s", 0.25, False),
    "none_2": ([], None, None, None),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(EXPECT))
def test_m3_whole_library(case):
    """No-effect records (UDDS; HWFET, a highway cycle) name nothing and raise no baseline failure; the
    auxiliary load is named with its power within 15 %; a 2 s power latency is named as timing within 0.25 s,
    never as mass."""
    rep = _m3(case)
    truth = _truth()["cases"][case]["truth"]
    expected, param, tol, rel = EXPECT[case]
    assert rep["selected_effects"] == expected, rep["selected_effects"]
    assert not (set(rep["selected_effects"]) - set(expected)) & PHYSICAL
    assert not rep["baseline_failure"] and not rep["model_form_discrepancy"]
    before, after = (rep[k]["power_w"]["holdout"] for k in ("rmse_before", "rmse_after"))
    if not expected:
        # the nominal is right: its held-out error is within its noise floor's reach
        assert before < 1.5 * rep["noise_floor"]["power_w"]["value"]
        return
    fitted = rep["timing"]["time_shift_s"] if param == "time_shift_s" else rep["final_parameters"][param]
    if rel:
        assert fitted == pytest.approx(truth[param], rel=tol)
    else:
        assert fitted == pytest.approx(truth[param], abs=tol)
    assert "mass_kg" not in rep["final_parameters"]
    assert after < 0.5 * before
