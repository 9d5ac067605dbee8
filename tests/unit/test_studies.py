"""Studies engine: GA, narrowing + exhaustive search, SQLite cache and resume, Dask vs serial, keys, CLI.

The machinery is tested on problems whose answer is known by brute force and on the analytic
surrogate (``shevsim.studies.problem.SyntheticProblem``); the real-scenario versions are at the
end and skip while ``scenarios/uac_proxy_mpc.toml`` does not exist.
"""
from __future__ import annotations

import itertools
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from shevsim.core.scenario import PROJECT_ROOT, parse_value
from shevsim.studies.cache import EvaluationCache
from shevsim.core.tomlio import toml_value
from shevsim.studies.evaluate import Evaluation
from shevsim.studies.ga import (GAConfig, exhaustive_genomes, narrow_bounds, rank_key, run_ga,
                                space_size)
from shevsim.studies.parallel import StudyInterrupted, StudyRunner
from shevsim.studies.powerrate_map import MapStudyConfig, run_powerrate_map
from shevsim.studies.problem import DEFAULT_EDGES_W, FE_KEY, SyntheticProblem, synthetic_metrics
from shevsim.studies.tradeoff import run_tradeoff

TWO_BODY = PROJECT_ROOT / "scenarios" / "verification" / "two_body.toml"
UAC_MPC = Path(os.environ.get("SHEVSIM_STUDY_SCENARIO", PROJECT_ROOT / "scenarios" / "uac_proxy_mpc.toml"))


# -- a known discrete problem: weighted distance to a target, with a sum constraint -----------------
T6 = np.array([1, 6, 3, 0, 5, 2])
W6 = np.array([1.0, 2.0, 0.5, 1.5, 1.0, 3.0])
C6 = 20           # sum(x) >= 20 makes the unconstrained optimum (sum 17) infeasible


def f6(g):
    g = np.asarray(g)
    return float(np.sum(W6 * (g - T6) ** 2)), float(max(0, C6 - g.sum()))


def brute_force_f6(bounds=None):
    ranges = [range(8)] * 6 if bounds is None else [range(lo, hi + 1) for lo, hi in bounds]
    grid = np.array(list(itertools.product(*ranges)))
    obj = ((grid - T6) ** 2 * W6).sum(1)
    feas = grid.sum(1) >= C6
    i = np.argmin(np.where(feas, obj, np.inf))
    assert np.sum(feas & (obj == obj[i])) == 1       # unique optimum, so the comparison is exact
    return tuple(int(x) for x in grid[i]), float(obj[i])


def test_rank_key_feasibility_rules():
    # feasible beats infeasible whatever the objective; feasible by objective; infeasible by violation
    assert rank_key(100.0, 0.0) < rank_key(1.0, 0.1)
    assert rank_key(1.0, 0.0) < rank_key(2.0, 0.0)
    assert rank_key(5.0, 0.1) < rank_key(1.0, 0.2)
    assert rank_key(1.0, 0.0) < rank_key(math.nan, 0.0)
    assert rank_key(1.0, 1e9) < rank_key(1.0, math.nan)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_ga_finds_known_constrained_optimum(seed):
    g_opt, f_opt = brute_force_f6()
    assert sum(g_opt) >= C6 and f_opt == 2.5      # the constraint is active at the optimum
    calls = []

    def batch(gs):
        calls.append(len(gs))
        assert len(set(gs)) == len(gs)            # duplicates within a generation evaluated once
        return [f6(g) for g in gs]

    res = run_ga([8] * 6, batch, GAConfig(seed=seed, unique_population=True))   # Table A.2: 30 x 50, 0.8, 0.01
    assert res.best == g_opt and res.best_objective == f_opt and res.best_violation == 0.0
    assert len(calls) == 50 and sum(calls) == len(res.evaluated) < 8 ** 6 / 100
    # the history is monotone (elitism) and feasible at the end
    best = [h["best_objective"] for h in res.history if h["best_violation"] == 0]
    assert all(b2 <= b1 for b1, b2 in zip(best, best[1:]))


def test_ga_is_deterministic_and_seed_dependent():
    r1 = run_ga([8] * 6, lambda gs: [f6(g) for g in gs], GAConfig(seed=5, generations=5))
    r2 = run_ga([8] * 6, lambda gs: [f6(g) for g in gs], GAConfig(seed=5, generations=5))
    r3 = run_ga([8] * 6, lambda gs: [f6(g) for g in gs], GAConfig(seed=6, generations=5))
    assert list(r1.evaluated) == list(r2.evaluated) and r1.history == r2.history
    assert list(r1.evaluated) != list(r3.evaluated)


def test_ga_rejects_bad_settings():
    with pytest.raises(ValueError, match="mutation_prob"):
        GAConfig(mutation_prob=1.5).check()
    with pytest.raises(ValueError, match="initial genome"):
        run_ga([3, 3], lambda gs: [(0.0, 0.0)] * len(gs), GAConfig(generations=1), initial=[(0, 5)])


def test_narrowed_exhaustive_search_finds_optimum_in_bounds():
    ranked = [(2, 6, 4, 0, 6, 2), (2, 6, 5, 0, 5, 2), (1, 7, 4, 0, 6, 2), (3, 6, 3, 1, 5, 3)]
    bounds, k = narrow_bounds(ranked, [8] * 6, top_k=10, max_cases=None)
    assert k == 4 and bounds == [(1, 3), (6, 7), (3, 5), (0, 1), (5, 6), (2, 3)]
    assert space_size(bounds) == 3 * 2 * 3 * 2 * 2 * 2
    cases = exhaustive_genomes(bounds)
    assert len(cases) == len(set(cases)) == space_size(bounds)
    assert all(all(lo <= x <= hi for x, (lo, hi) in zip(g, bounds)) for g in cases)
    es_best = min(cases, key=lambda g: rank_key(*f6(g), g))
    assert es_best == brute_force_f6(bounds)[0] == brute_force_f6()[0]
    # the cap shrinks k until the space fits; k = 1 is the best genome alone
    b2, k2 = narrow_bounds(ranked, [8] * 6, top_k=10, max_cases=20)
    assert space_size(b2) <= 20 and k2 < 4
    assert narrow_bounds(ranked, [8] * 6, top_k=1)[0] == [(x, x) for x in ranked[0]]


# -- cache -----------------------------------------------------------------------------------------
def test_cache_roundtrip_and_persistence(tmp_path):
    db = tmp_path / "c.sqlite"
    with EvaluationCache(db) as c:
        c.put("k1", {"a": 1}, {"fe": 3.2, "x": math.nan, "s": "completed"}, 1.5)
        c.put("k2", {"a": 2}, {"fe": 3.1}, 0.5)
        assert len(c) == 2 and "k1" in c and "k3" not in c
    with EvaluationCache(db) as c:                 # reopened: rows were committed
        got = c.get_many(["k1", "k2", "k3"])
        assert set(got) == {"k1", "k2"} and got["k2"] == {"fe": 3.1} and math.isnan(got["k1"]["x"])
        assert [r["key"] for r in c.rows()] == ["k1", "k2"] and c.rows()[0]["wall_s"] == 1.5


def _small_cfg(**kw):
    return MapStudyConfig(ga=GAConfig(population=10, generations=6, seed=3), top_k=4, max_cases=64, **kw)


def test_resume_after_stop_repeats_nothing_and_gives_same_answer(tmp_path):
    # uninterrupted reference
    ref = run_powerrate_map(SyntheticProblem(), StudyRunner(None, progress=False), _small_cfg(), log=lambda *_: None)
    # stopped after k new evaluations, then resumed on the same cache
    log = tmp_path / "runs.log"
    prob = SyntheticProblem(log_path=str(log))
    db = tmp_path / "cache.sqlite"
    k = 23
    with EvaluationCache(db) as cache:
        with pytest.raises(StudyInterrupted):
            run_powerrate_map(prob, StudyRunner(cache, progress=False, max_new_evaluations=k), _small_cfg(),
                              log=lambda *_: None)
        assert len(cache) == k
    assert len(log.read_text().split()) == k
    with EvaluationCache(db) as cache:
        runner = StudyRunner(cache, progress=False)
        res = run_powerrate_map(prob, runner, _small_cfg(), log=lambda *_: None)
        n_total = len(cache)
    keys = log.read_text().split()
    assert len(keys) == len(set(keys)) == n_total          # every evaluation ran exactly once overall
    assert runner.stats.new == n_total - k and runner.stats.cached >= k
    for field in ("best_map", "best_constant", "top_solutions", "narrowed", "baseline"):
        assert res[field] == ref[field]
    assert res["ga"]["history"] == ref["ga"]["history"]


def test_synthetic_map_study_beats_constant_and_respects_constraint(tmp_path):
    res = run_powerrate_map(SyntheticProblem(), StudyRunner(None, progress=False),
                            MapStudyConfig(ga=GAConfig(seed=1)), out_dir=tmp_path, log=lambda *_: None)
    # plain GA (default) + narrowed ES; the surrogate's optimum over the full space is -7.65 % soot
    assert res["best_map"]["soot_change_pct"] < -7.2
    b = res["best_map"]
    assert b["fe_change_pct"] >= -0.4 - 1e-9 and b["soot_change_pct"] < res["best_constant"]["soot_change_pct"] < 0
    # the optimum over the narrowed space: no feasible ES case is better (checked independently)
    bounds = res["narrowed"]["bounds_wps"]
    lv = res["config"]["levels_wps"]
    rng = [[x for x in lv if lo <= x <= hi] for lo, hi in bounds]
    alpha = res["baseline"]["alpha_star_kmpl"]
    best_soot = min(m["soot_g_per_km"] for r in itertools.product(*rng)
                    for m in [synthetic_metrics(DEFAULT_EDGES_W, r)] if m[FE_KEY] >= alpha)
    assert b["soot_g_per_km"] == best_soot
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["best_map"]["rates_wps"] == b["rates_wps"]
    for f in ("top_solutions.csv", "exhaustive.csv", "ga_history.csv", "constant_limits.csv",
              "fig_a3_rate_maps.png", "fig_a4_comparison.png"):
        assert (tmp_path / f).stat().st_size > 0
    assert not list(tmp_path.glob(".*tmp"))


def test_synthetic_tradeoff_table(tmp_path):
    res = run_tradeoff(SyntheticProblem(), StudyRunner(None, progress=False), [30e3, 20e3, 10e3, 5e3], tmp_path,
                       log=lambda *_: None)
    rows = sorted(res["rows"], key=lambda r: -r["rate_wps"])
    assert [r["rate_wps"] for r in rows] == [30e3, 20e3, 10e3, 5e3]
    assert rows[0]["fe_change_pct"] == 0.0 and rows[0]["soot_change_pct"] == 0.0   # no effect at r_ref
    assert all(a["soot_g_per_km"] > b["soot_g_per_km"] and a["fuel_economy_kmpl"] > b["fuel_economy_kmpl"]
               for a, b in zip(rows, rows[1:]))
    assert res["best_within_loss"]["fe_change_pct"] >= -0.5
    assert (tmp_path / "tradeoff.csv").read_text().count("\n") == 5 and (tmp_path / "fig_a2_tradeoff.png").exists()


def _thread_env():
    import os
    return tuple(os.environ.get(k) for k in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"))


def test_dask_two_workers_identical_to_serial():
    pytest.importorskip("distributed")
    cfg = MapStudyConfig(ga=GAConfig(population=8, generations=4, seed=2), top_k=3, max_cases=40)
    ser = run_powerrate_map(SyntheticProblem(), StudyRunner(None, progress=False), cfg, log=lambda *_: None)
    with StudyRunner(None, workers=2, progress=False) as runner:
        assert runner.stats.slots == 2
        par = run_powerrate_map(SyntheticProblem(), runner, cfg, log=lambda *_: None)
        items = [SyntheticProblem().item(DEFAULT_EDGES_W, [r] * 8) for r in (5e3, 9e3, 5e3, 30e3)]
        assert runner.evaluate(items) == StudyRunner(None, progress=False).evaluate(items)
        # workers run single-threaded BLAS/OpenMP
        env = runner.client.run(_thread_env)
        assert len(env) == 2 and all(v == ("1", "1", "1") for v in env.values())
        # --scheduler path: a second runner on the same (existing) cluster
        with StudyRunner(None, scheduler=runner.client.scheduler.address, progress=False) as ext:
            assert ext.stats.slots == 2 and ext.evaluate(items[::-1]) == runner.evaluate(items)[::-1]
    ser.pop("performance"), par.pop("performance")
    assert par == ser


# -- real evaluation items ---------------------------------------------------------------------------
@pytest.mark.parametrize("v", [1, 2.5, -1e-3, 1e300, True, "abc", [1.0, 2e4], [[1, 2], [3]], math.inf])
def test_toml_value_roundtrip(v):
    assert parse_value(toml_value(v)) == v


def test_evaluation_key_deterministic_and_sensitive(tmp_path):
    a = Evaluation.make(TWO_BODY, {"body1.x0_m": 2.0, "coupling.mass_kg": 1.0})
    b = Evaluation.make(TWO_BODY, {"coupling.mass_kg": 1.0, "body1.x0_m": 2.0})
    assert a == b and a.key() == b.key() and len(a.key()) == 64
    assert Evaluation.make(TWO_BODY, {"body1.x0_m": 2.5, "coupling.mass_kg": 1.0}).key() != a.key()
    assert Evaluation.make(TWO_BODY, {"body1.x0_m": 2.0, "coupling.mass_kg": 1.0}, stop_s=1.0).key() != a.key()
    copy = tmp_path / "two_body.toml"
    shutil.copy(TWO_BODY, copy)
    same = Evaluation.make(copy, {"body1.x0_m": 2.0, "coupling.mass_kg": 1.0})
    assert same.key() == a.key()                  # content, not location, decides
    copy.write_text(copy.read_text().replace("step_s = 0.01", "step_s = 0.005"))
    assert Evaluation.make(copy, {"body1.x0_m": 2.0, "coupling.mass_kg": 1.0}).key() != a.key()


def test_evaluation_runs_scenario_with_overrides():
    # linear system: doubling the initial displacement doubles the whole trajectory
    sig = ("body1.position_m", "coupling.position2_m")
    o1 = Evaluation.make(TWO_BODY, {"body1.x0_m": 1.0}, stop_s=2.0, final_signals=sig).run()
    o2 = Evaluation.make(TWO_BODY, {"body1.x0_m": 2.0}, stop_s=2.0, final_signals=sig).run()
    assert o1["termination"] == "completed"
    for s in sig:
        assert abs(o1[f"final:{s}"]) > 1e-3
        assert o2[f"final:{s}"] == pytest.approx(2 * o1[f"final:{s}"], rel=1e-9)
    bad = Evaluation.make(TWO_BODY, {"nobody.x0_m": 1.0}, stop_s=1.0).run()
    assert "nobody" in bad["error"]


def test_cli_dispatch_and_synthetic_runs(tmp_path, capsys):
    from shevsim.studies.cli import STUDIES, main_study
    assert {"tradeoff", "powerrate-map", "thermal", "bms"} <= set(STUDIES)
    assert main_study(["nosuch"]) == 2 and "unknown study" in capsys.readouterr().err
    out = tmp_path / "m"
    assert main_study(["powerrate-map", "--synthetic", "--workers", "0", "--generations", "3", "--population", "6",
                       "--out", str(out), "--quiet", "--no-plots"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["config"]["ga"]["generations"] == 3 and (out / "cache.sqlite").exists()
    # rerun: everything from the cache
    assert main_study(["powerrate-map", "--synthetic", "--workers", "0", "--generations", "3", "--population", "6",
                       "--out", str(out), "--quiet", "--no-plots"]) == 0
    assert json.loads((out / "summary.json").read_text())["performance"]["new_evaluations"] == 0
    assert main_study(["tradeoff", "--synthetic", "--workers", "0", "--rates-kwps", "30", "10", "--out",
                       str(tmp_path / "t"), "--quiet", "--no-plots"]) == 0
    assert main_study(["tradeoff", str(tmp_path / "missing.toml"), "--workers", "0"]) == 2
    assert "not found" in capsys.readouterr().err


# -- the real scenario (UAC proxy with the MPC supervisor) ------------------------------------------
needs_uac = pytest.mark.skipif(not UAC_MPC.exists(), reason="scenarios/uac_proxy_mpc.toml not written yet "
                                                            "(lead: remove this skip when it lands)")


def _supervisor_default_map(path):
    """(edges, rates) of the scenario's supervisor rate map as configured (file + set overrides)."""
    import tomllib
    from shevsim.core.scenario import load_scenario
    spec = next(c for c in load_scenario(path).components if c.name == "supervisor")
    params = tomllib.loads(spec.params_file.read_text()).get("params", {}) if spec.params_file else {}
    params.update(spec.overrides)
    return params.get("rate_map_power_edges_w"), params.get("rate_map_max_rate_wps")


@needs_uac
def test_real_tradeoff_small(tmp_path):
    from shevsim.studies.problem import ScenarioProblem
    prob = ScenarioProblem(str(UAC_MPC), "supervisor", stop_s=200.0)
    res = run_tradeoff(prob, StudyRunner(None, progress=False), [30e3, 5e3], tmp_path, log=lambda *_: None,
                       fe_key="fuel_economy_dsoc_corrected_kmpl")     # 200 s: shorter than two cycles
    rows = {r["rate_wps"]: r for r in res["rows"]}
    assert all(not r["error"] for r in rows.values()), rows
    # the map reaches the supervisor: a 5 kW/s limit changes the run ...
    assert rows[5e3]["soot_g_per_km"] != res["baseline"]["soot_g_per_km"]
    # ... and 30 kW/s in all 8 partitions is the same limit as a one-partition 30 kW/s map: identical run
    edges, rates = _supervisor_default_map(UAC_MPC)
    if rates is not None and len(set(rates)) == 1 and rates[0] == 30e3 and edges[0] <= 0 and edges[-1] >= 236e3:
        assert rows[30e3]["fuel_economy_kmpl"] == res["baseline"]["fuel_economy_kmpl"]
        assert rows[30e3]["soot_g_per_km"] == res["baseline"]["soot_g_per_km"]


@needs_uac
def test_real_powerrate_map_small(tmp_path):
    from shevsim.studies.problem import ScenarioProblem
    prob = ScenarioProblem(str(UAC_MPC), "supervisor", stop_s=200.0)
    cfg = MapStudyConfig(edges_w=(0.0, 100e3, 236e3), levels_wps=(10e3, 30e3), fe_loss_max_frac=0.05,
                         ga=GAConfig(population=2, generations=1, seed=0, elitism=0), top_k=1, max_cases=1,
                         fe_key="fuel_economy_dsoc_corrected_kmpl")
    res = run_powerrate_map(prob, StudyRunner(None, progress=False), cfg, tmp_path, plots=False, log=lambda *_: None)
    b = res["best_map"]
    assert b["fe_change_pct"] >= -5.0 and (tmp_path / "summary.json").exists()
    # the answer is the lowest-soot feasible map among the 2 x 2 evaluated ones (all cached)
    cands = [c for c in res["constant_limits"] if c["feasible"]] + res["top_solutions"]
    assert b["soot_g_per_km"] <= min(c["soot_g_per_km"] for c in cands)


def test_results_from_workers_with_other_sources_are_not_cached(tmp_path):
    from shevsim.studies.evaluate import code_version
    item = SyntheticProblem().item(DEFAULT_EDGES_W, [10e3] * 8)
    with EvaluationCache(tmp_path / "c.sqlite") as cache:
        runner = StudyRunner(cache, progress=False)
        res = {}
        runner._finish(item.key(), item, {"x": 1.0}, 0.1, res, None, worker_code="0" * 64)
        assert len(cache) == 0 and runner.stats.not_cached == 1 and res[item.key()] == {"x": 1.0}
        runner._finish(item.key(), item, {"x": 1.0}, 0.1, res, None, worker_code=code_version())
        assert cache.get(item.key()) == {"x": 1.0}


def test_a_small_ga_never_reports_a_map_worse_than_the_best_constant():
    """Issue 27: a GA too small to beat the constants (2 x 1, no seeding) reports the best constant, labelled."""
    kinds = []
    for seed in range(6):
        cfg = MapStudyConfig(ga=GAConfig(population=2, generations=1, seed=seed, elitism=0), top_k=1, max_cases=1,
                             seed_constants=False, fill_cases=False)
        res = run_powerrate_map(SyntheticProblem(), StudyRunner(None, progress=False), cfg, log=lambda *_: None)
        best, const = res["best_map"], res["best_constant"]
        assert best["soot_g_per_km"] <= const["soot_g_per_km"]
        assert (best["kind"] == "constant") == (len(set(best["rates_wps"])) == 1)
        kinds.append(best["kind"])
    assert "constant" in kinds and "map" in kinds          # both outcomes exercised over the seeds


def test_partitions_cover_the_power_the_generator_can_reach():
    from shevsim.core.paths import bundled_scenario
    from shevsim.studies.problem import ScenarioProblem, reachable_edges
    e = reachable_edges(200.6e3)
    assert len(e) == 9 and e[-1] == pytest.approx(200.6e3)
    assert e[1] == pytest.approx(25.075e3) and e[2] == pytest.approx(50.15e3)   # the seed's 25 kW bins, to 200.6 kW
    edges = ScenarioProblem(str(bundled_scenario("uac_proxy_mpc_seed")), "supervisor").default_edges()
    assert edges[-1] == pytest.approx(200.6e3)             # the supervisor's power_gen_max_w, not the 236 kW rating
    assert all(b > a for a, b in zip(edges, edges[1:]))


def test_narrowed_space_grows_to_the_case_cap_and_never_past_it():
    from shevsim.studies.ga import narrow_bounds, space_size
    rng = np.random.default_rng(0)
    ranked = [tuple(int(x) for x in rng.integers(0, 8, size=6)) for _ in range(200)]
    ranked = [(3, 3, 3, 3, 3, 3)] * 10 + ranked            # a converged GA: the top 10 are one map
    b0, k0 = narrow_bounds(ranked, [8] * 6, top_k=10, max_cases=648)
    assert space_size(b0) == 1 and k0 == 10
    b1, k1 = narrow_bounds(ranked, [8] * 6, top_k=10, max_cases=648, grow=True)
    assert k1 > 10 and 1 < space_size(b1) <= 648
    assert space_size(narrow_bounds(ranked, [8] * 6, top_k=10, max_cases=648, grow=True)[0]) == space_size(b1)
    # one more map would pass the cap (or there is none left)
    if k1 < len(ranked):
        nxt = np.array(ranked[:k1 + 1])
        assert space_size([(int(nxt[:, j].min()), int(nxt[:, j].max())) for j in range(6)]) > 648


def test_key_covers_the_bundled_data_files_components_take_by_default(tmp_path, monkeypatch):
    """Files a component takes from its code defaults (e.g. the supervisor's fuel curve when its
    ``fuel_curve_file`` is empty) are not named by a scenario, so a study does not capture them: the key covers
    them through the code version.  One byte changed in a copy of the data root changes the key."""
    from shevsim.core import paths
    from shevsim.studies.evaluate import code_version
    root = tmp_path / "data_root"
    for f in ("components", "cycles", "scenarios", "fmus", "vehicles", "data/measured"):
        if (paths.DATA_ROOT / f).is_dir():
            shutil.copytree(paths.DATA_ROOT / f, root / f)
    ev = Evaluation.make(PROJECT_ROOT / "scenarios" / "hd_udds_rule.toml", stop_s=10.0)
    monkeypatch.setattr(paths, "DATA_ROOT", root)
    code_version.cache_clear()
    try:
        before = (code_version(), Evaluation.make(ev.scenario, stop_s=10.0, bundle=ev.bundle).key())
        curve = root / "components" / "engine_generator" / "fuel_vs_power.csv"
        data = bytearray(curve.read_bytes())
        i = data.rindex(b"5")
        data[i:i + 1] = b"6"
        curve.write_bytes(bytes(data))
        code_version.cache_clear()
        after = (code_version(), Evaluation.make(ev.scenario, stop_s=10.0, bundle=ev.bundle).key())
        assert before[0] != after[0] and before[1] != after[1]
    finally:
        monkeypatch.undo()
        code_version.cache_clear()
