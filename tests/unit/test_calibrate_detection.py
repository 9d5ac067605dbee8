"""What a record can detect (``workflow.detection_limits``): the smallest change of each one-parameter effect that
the selection rule's held-out gain would see on this record, so that a miss is read as the record's limit or
the rule's.  Checked on FASTSim 3.1's Chevrolet Bolt EV records (``make_vehicle_fastsim_bolt.py``: not made by
shevsim's vehicle model) with an injected auxiliary load, and on a linear two-channel model against exact least
squares."""
from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shevsim.calibrate.data import load_measured
from shevsim.calibrate.known import load_params_toml
from shevsim.calibrate.workflow import MIN_GAIN, detection_limits, render_markdown, run_workflow

D = Path(__file__).resolve().parents[1] / "data" / "independent"


@functools.lru_cache(maxsize=None)      # one run per record for the module's tests (reports are only read)
def _run(case: str):
    tc = json.loads((D / "vehicle_bolt_truth.json").read_text())["cases"][case]
    data = load_measured(str(D / tc.get("file", f"vehicle_bolt_{case}.csv")), "vehicle")
    return run_workflow("vehicle", data, load_params_toml(D / tc.get("nominal", "vehicle_bolt_nominal.toml")),
                        plots=False), tc["truth"]


def _limit(rep, effect):
    (d,) = [d for d in rep["detection_limits"] if d["effect"] == effect]
    return d


def test_the_limit_is_in_the_report_per_direction_and_a_bound_of_the_nominal_shows_in_it():
    """FASTSim's Bolt on UDDS (no effect): a payload of 300 kg is above the mass limit in both directions (the
    payload record is named: test_calibrate_out_of_sample.py::test_vehicle_with_its_published_curve_names_the_payload).
    On HWFET with 300 kg of payload the nominal's regenerative efficiency sits on its upper bound and the record
    pushes past it (a model-form discrepancy): it moves both ways in the refit, so what of a heavier vehicle's extra
    regeneration it would take past the bound is not counted as the mass's own evidence.  Checked against what the
    record does: the mass candidate's fitted size and its measured held-out gain are the ones the limit implies
    within 3 points (measured: +272 kg, 7.7 % gained, 6.0 % implied; with the regeneration held on its bound the
    limit was 178 kg up and implied 33 %)."""
    ud, _ = _run("none")
    lim = _limit(ud, "mass_error")
    assert lim["unit"] == "kg" and lim["reachable"]
    assert max(lim["limit_up"], lim["limit_down"]) < 300.0, lim
    assert abs(lim["limit_up"] / lim["limit_down"] - 1.0) < 0.05
    assert {d["effect"] for d in ud["detection_limits"]} >= {"mass_error", "aux_load", "rolling_error", "aero_error",
                                                             "timing"}
    assert _limit(ud, "timing")["unit"] == "s"
    md = render_markdown(ud)
    assert "What this record can detect" in md and "`mass_error` mass_kg" in md
    hw, _ = _run("payload_hwfet")
    assert hw["selected_effects"] == []
    assert "regen_efficiency_scale_frac" in {b["parameter"] for b in hw["parameters_at_bounds"]}
    assert "regen_efficiency_scale_frac" in {b["parameter"] for d in hw["model_form_discrepancy"]
                                             for b in d.get("declared_on_bound") or []}
    m = _limit(hw, "mass_error")
    (cand,) = [c for c in hw["rounds"][0]["candidates"] if c["effects"] == ["mass_error"]]
    size = cand["parameters"]["mass_kg"] - m["neutral"]
    lim_dir = m["limit_up"] if size > 0 else m["limit_down"]
    need = (1.0 - MIN_GAIN) ** -2 - 1.0          # the record carries the effect: its residual includes it
    implied = 1.0 - math.sqrt(max(1.0 - need * (size / lim_dir) ** 2, 0.0))
    assert abs(cand["gain"] - implied) < 0.03, (cand["gain"], implied, size, lim_dir)


def _gain_at(d: float, lim: dict) -> float:
    """The held-out gain the limit implies for a true effect of size ``d`` on top of the record."""
    need = len(lim["channels"]) * ((1.0 - MIN_GAIN) ** -2 - 1.0)
    return 1.0 - 1.0 / math.sqrt(1.0 + need * (d / lim["limit"]) ** 2)


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_an_aux_load_added_at_half_the_limit_is_not_named_and_at_twice_it_is(tmp_path, factor):
    """A constant auxiliary load adds to the battery power whatever the drive does: added to FASTSim's no-effect
    UDDS record (exact physics, not shevsim's), at half the record's limit for `aux_load` it is not named, at twice
    it is (within 15 %), and the candidate's measured held-out gain is the one the linear limit implies within 3
    points (measured: 2.1 % vs 2.8 % and 26.9 % vs 28.2 %)."""
    base, _ = _run("none")
    lim = _limit(base, "aux_load")
    add = factor * lim["limit"]
    src = D / "vehicle_bolt_none.csv"
    df = pd.read_csv(src, comment="#")
    df["power_w"] = df["power_w"] + add
    f = tmp_path / f"bolt_none_plus_{add:.0f}w.csv"
    df.to_csv(f, index=False)
    rep = run_workflow("vehicle", load_measured(str(f), "vehicle"), load_params_toml(D / "vehicle_bolt_nominal.toml"),
                       plots=False)
    (cand,) = [c for c in rep["candidates"] if c["effects"] == ["aux_load"]]
    assert abs(cand["gain"] - _gain_at(add, lim)) < 0.03, (cand["gain"], _gain_at(add, lim))
    if factor < 1.0:
        assert "aux_load" not in rep["selected_effects"], rep["selected_effects"]
    else:
        assert rep["selected_effects"] == ["aux_load"], rep["selected_effects"]
        fitted = rep["final_parameters"]["aux_power_w"] - base["final_parameters"].get(
            "aux_power_w", base["effect_neutral"]["aux_power_w"])
        assert fitted == pytest.approx(add, rel=0.15)


# ---- the limit against exact least squares on a linear two-channel model (an analytic reference, no simulator)

def _stub(effects, sim, n=3000, noise=0.3, seed=0):
    """A Fitter on a model ``sim(values) -> {ch1, ch2}`` with one declared parameter ``k``: every third sample held
    out; returns (fitter, record without any effect, final result of the nominal k = 1)."""
    import types

    from shevsim.calibrate.models import Param
    from shevsim.calibrate.workflow import Fitter
    rng = np.random.default_rng(seed)
    hold = np.zeros(n, bool)
    hold[::3] = True
    defaults = {"k": 1.0, **{p.name: e.neutral[p.name] for e in effects.values() for p in e.params}}
    f = Fitter.__new__(Fitter)
    f.model = types.SimpleNamespace(declared=(Param("k", "-", 0.0, 4.0, 1.0, "declared"),),
                                    full_values=lambda v: {**defaults, **v})
    f.channels, f.effects, f.measured, f.bounds_override = ["ch1", "ch2"], effects, {}, {}
    f.fit_idx, f.hold, f.nsim, f.progress = np.flatnonzero(~hold), hold, 0, None
    f.weights = {"ch1": 1.0 / noise, "ch2": 1.0 / noise}
    f.simulate = lambda v: sim({**defaults, **v})
    meas = {c: sim(defaults)[c] + noise * rng.standard_normal(n) for c in f.channels}
    rm = {c: {"holdout": float(np.sqrt(np.mean((sim(defaults)[c] - meas[c])[hold] ** 2)))} for c in f.channels}
    return f, meas, types.SimpleNamespace(params={"k": 1.0}, rmse=rm)


def _gains(f, meas, regs1, regs2, extra1):
    """Held-out gains (rule a: all channels over the record's own baseline; rule d: ch1) of the exact least-squares
    fit with the effect's regressors ``extra1`` (one array, or a list of them: its knots) on ch1 over the fit
    without them."""
    tr, ho = ~f.hold, f.hold
    extra = list(extra1) if isinstance(extra1, list) else [extra1]

    def fit(cols1, cols2):
        a = np.vstack([np.column_stack(cols1)[tr], np.column_stack(cols2)[tr]])
        beta = np.linalg.lstsq(a, np.concatenate([meas["ch1"][tr], meas["ch2"][tr]]), rcond=None)[0]
        return {c: float(np.sqrt(np.mean((np.column_stack(x) @ beta - meas[c])[ho] ** 2)))
                for c, x in (("ch1", cols1), ("ch2", cols2))}
    cur = fit(regs1, regs2)
    cand = fit(regs1 + extra, regs2 + [np.zeros_like(e) for e in extra])
    ga = 1.0 - math.sqrt((cand["ch1"] ** 2 + cand["ch2"] ** 2) / (cur["ch1"] ** 2 + cur["ch2"] ** 2))
    return ga, 1.0 - cand["ch1"] / cur["ch1"]


def test_on_two_channels_the_combined_score_binds_and_exact_least_squares_agree():
    """The effect acts on ch1 only, the rule's combined score counts ch2 too: the limit is the combined score's
    (about sqrt 2 the one-channel value), and an effect of that size added to the record gains the rule's 10 %
    on the combined score in an exact least-squares fit (within 3 points: the noise's cross term)."""
    from shevsim.calibrate.models import Effect, Param
    n = 3000
    t = np.arange(n, dtype=float)
    u1, u2, s = np.sin(t / 37.0), np.cos(t / 91.0), np.sign(np.sin(t / 13.0))
    eff = {"e": Effect("e", "a step signal on ch1", (Param("p", "u", -10.0, 10.0, 0.0, "size"),), {"p": 0.0},
                       ("ch1",))}
    f, meas, final = _stub(eff, lambda v: {"ch1": v["k"] * u1 + v["p"] * s, "ch2": v["k"] * u2}, n)
    (d,) = detection_limits(f, [], final, {c: final.rmse[c]["holdout"] for c in f.channels})
    assert d["binding"] == "combined score" and not d["nonlinear"]
    for factor, lo, hi in ((1.0, MIN_GAIN - 0.03, MIN_GAIN + 0.03), (0.5, -1.0, MIN_GAIN - 0.03),
                           (2.0, MIN_GAIN + 0.03, 1.0)):
        m = dict(meas, ch1=meas["ch1"] + factor * d["limit"] * s)
        ga, gd = _gains(f, m, [u1], [u2], s)
        assert lo <= ga <= hi, (factor, ga)
        assert gd > ga                       # its own channel alone would have passed sooner


def test_a_saturating_effect_is_read_on_its_secant_and_a_claim_effect_gets_no_limit():
    """``p`` acts through tanh(p) (a time constant's saturation): the tangent at 0 overstates the signal; the secant
    over the limit gives the size at which the exact fit gains the rule's 10 %.  An effect whose claim is tested on
    its own channel (any held-out gain passes once verified) is listed without a limit."""
    from shevsim.calibrate.models import Effect, Param
    n = 3000
    t = np.arange(n, dtype=float)
    u1, u2, s = np.sin(t / 37.0), np.cos(t / 91.0), np.sign(np.sin(t / 13.0))
    eff = {"sat": Effect("sat", "saturating", (Param("p", "u", 0.0, 10.0, 0.0, "size"),), {"p": 0.0}, ("ch1", "ch2")),
           "law": Effect("law", "claimed", (Param("q", "u", 0.0, 10.0, 0.0, "size"),), {"q": 0.0}, ("ch1",),
                         channel_claim=(("ch1",), ()))}
    f, meas, final = _stub(eff, lambda v: {"ch1": v["k"] * u1 + 0.25 * np.tanh(v["p"]) * s + v["q"] * u2,
                                           "ch2": v["k"] * u2}, n)
    by = {d["effect"]: d for d in detection_limits(f, [], final, {c: final.rmse[c]["holdout"] for c in f.channels})}
    assert by["law"]["limit"] is None and "claim" in by["law"]["why_none"]
    d = by["sat"]
    assert d["nonlinear"] and d["limit"] > 1.2 * d["tangent_limit"]
    ga, _ = _gains(f, dict(meas, ch1=meas["ch1"] + 0.25 * np.tanh(d["limit"]) * s), [u1], [u2], s)
    assert abs(ga - MIN_GAIN) <= 0.03, ga


def _two_knots(along_u1: float):
    """Two knots ``c[0]``, ``c[1]`` on ch1 (signals ``s1``, ``s2``; ``s2`` partly along ``s1`` and, by
    ``along_u1``, along the declared parameter's ``u1``): ``(t, u1, u2, s1, s2, {"knots": Effect})``."""
    from shevsim.calibrate.models import Effect, Param
    t = np.arange(3000, dtype=float)
    u1, u2 = np.sin(t / 37.0), np.cos(t / 91.0)
    s1 = np.sign(np.sin(t / 13.0))
    share = 0.6 if along_u1 < 1.0 else 0.3
    s2 = share * s1 + (0.5 if along_u1 < 1.0 else 0.3) * np.sin(t / 5.0) + along_u1 * u1
    eff = {"knots": Effect("knots", "two knots on ch1", (Param("c[0]", "V", -10.0, 10.0, 0.0, "knot at 0.2"),
                                                         Param("c[1]", "V", -10.0, 10.0, 0.0, "knot at 0.8")),
                           {"c[0]": 0.0, "c[1]": 0.0}, ("ch1",))}
    return t, u1, u2, s1, s2, eff


def test_an_effect_with_knots_gets_the_limit_of_each_shape_and_exact_least_squares_agree():
    """Two knots ``c[0]``, ``c[1]`` on ch1 whose signals overlap each other and the declared parameter's: the
    shape row's Gram matrix gives, for any change of the knots, the size at which its own signal gains the rule's
    10 %; an exact least-squares fit of both knots on a record carrying that change gains it within 3 points, at
    half of it less, at twice of it more - along the most visible shape, the least visible and another.  An effect
    whose parameters are not knots of one unit gets no shape row."""
    from shevsim.calibrate.models import Effect, Param
    from shevsim.calibrate.workflow import shape_limit
    t, u1, u2, s1, s2, eff = _two_knots(0.4)
    n = t.size
    eff = {**eff,
           "two": Effect("two", "two parameters, not knots", (Param("g", "1", -1.0, 1.0, 0.0, "gain"),
                                                             Param("h", "1", -1.0, 1.0, 0.0, "scale")),
                         {"g": 0.0, "h": 0.0}, ("ch1",))}
    f, meas, final = _stub(eff, lambda v: {"ch1": v["k"] * u1 + v["c[0]"] * s1 + v["c[1]"] * s2
                                           + v["g"] * v["h"] * u2, "ch2": v["k"] * u2}, n)
    shapes: list = []
    detection_limits(f, [], final, {c: final.rmse[c]["holdout"] for c in f.channels}, shapes=shapes)
    (row,) = shapes
    assert row["effect"] == "knots" and row["linear"] and row["limit_rms_min"] < row["limit_rms_max"]
    assert shape_limit(row, row["shape_min"])["limit_rms"] == pytest.approx(row["limit_rms_min"])
    for u in (row["shape_min"], row["shape_max"], [1.0, -0.3]):
        u = np.asarray(u) / np.linalg.norm(u)
        lim = shape_limit(row, u)["limit_rms"] * math.sqrt(2)          # |delta| at the limit
        for factor, lo, hi in ((1.0, MIN_GAIN - 0.03, MIN_GAIN + 0.03), (0.5, -1.0, MIN_GAIN - 0.03),
                               (2.0, MIN_GAIN + 0.03, 1.0)):
            d = factor * lim * u
            ga, _ = _gains(f, dict(meas, ch1=meas["ch1"] + d[0] * s1 + d[1] * s2), [u1], [u2], [s1, s2])
            assert lo <= ga <= hi, (list(u), factor, ga)
            if factor != 1.0:
                assert (shape_limit(row, d)["ratio"] > 1.0) == (factor > 1.0)


def test_with_a_refit_parameter_on_its_bound_the_extreme_shapes_come_from_their_own_signals():
    """The declared ``k`` on its lower bound 0 (the record made with k = 0): the refit moves it one way only, so the
    projection is not linear; the row says so, and the two extreme shapes' limits agree with an exact bounded
    least-squares fit (scipy's lsq_linear, k >= 0) within 3 points of the rule's 10 % (the second knot's signal
    lies mostly along the declared one's: read from the unbounded Gram matrix, the most visible shape's limit
    gained 13.1 %)."""
    import types

    from scipy import optimize

    t, u1, u2, s1, s2, eff = _two_knots(1.5)
    n = t.size

    def sim(v):
        return {"ch1": v["k"] * u1 + v["c[0]"] * s1 + v["c[1]"] * s2, "ch2": v["k"] * u2}
    f, meas, final = _stub(eff, lambda v: sim({**v, "k": v.get("k", 1.0)}), n)
    rng = np.random.default_rng(1)
    meas = {c: sim({"k": 0.0, "c[0]": 0.0, "c[1]": 0.0})[c] + 0.3 * rng.standard_normal(n) for c in ("ch1", "ch2")}
    hold = f.hold
    rm = {c: {"holdout": float(np.sqrt(np.mean(meas[c][hold] ** 2)))} for c in meas}
    final = types.SimpleNamespace(params={"k": 0.0}, rmse=rm)
    shapes: list = []
    detection_limits(f, [], final, {c: rm[c]["holdout"] for c in meas}, shapes=shapes, only_shapes=True)
    (row,) = shapes
    assert row["linear"] is False
    tr, ho = ~hold, hold

    def held_rmse(m, cols1, cols2, lb):
        a = np.vstack([np.column_stack(cols1)[tr], np.column_stack(cols2)[tr]])
        beta = optimize.lsq_linear(a, np.concatenate([m["ch1"][tr], m["ch2"][tr]]),
                                   bounds=(lb, [np.inf] * len(lb))).x
        return [float(np.sqrt(np.mean((np.column_stack(x) @ beta - m[c])[ho] ** 2)))
                for c, x in (("ch1", cols1), ("ch2", cols2))]

    gains = []
    for u, lim_rms in ((row["shape_min"], row["limit_rms_min"]), (row["shape_max"], row["limit_rms_max"])):
        best = None
        for sgn in (1.0, -1.0):
            d = sgn * lim_rms * math.sqrt(2) * np.asarray(u)
            m = dict(meas, ch1=meas["ch1"] + d[0] * s1 + d[1] * s2)
            cur = held_rmse(m, [u1], [u2], [0.0])
            cand = held_rmse(m, [u1, s1, s2], [u2, 0 * s1, 0 * s2], [0.0, -np.inf, -np.inf])
            g = 1.0 - math.sqrt((cand[0] ** 2 + cand[1] ** 2) / (cur[0] ** 2 + cur[1] ** 2))
            best = g if best is None else (max(best, g) if u is row["shape_min"] else min(best, g))
        gains.append(best)
    assert all(abs(g - MIN_GAIN) <= 0.03 for g in gains), gains
