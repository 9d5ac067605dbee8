"""powerrate_map.py - the engine power-rate constraint map optimisation of seed App. A.3 (A.2).

Problem (A.2): choose the maximum engine-generator power rate beta in each engine-power partition
d_i (``edges_w``, default 8 partitions of 0-236 kW: [0,50), [50,75), ..., [175,200), [200,236] kW -
25 kW bins, the lowest two and the top ones grouped so the space has the seed's 8 variables x
8 levels) from discrete levels beta_j (``levels_wps``, default 5...30 kW/s), to

    minimise soot (g/km)   subject to   fuel economy >= alpha* = (1 - 0.004) x baseline

(baseline = the scenario as written, i.e. without the map).  Fuel economy is the Delta-SOC-corrected
figure (``FE_KEY`` = ``fuel_economy_dsoc_corrected_kmpl``; the SOC-sustainable definition A.1 is selectable
with ``fe_key`` / ``--fe-metric`` but needs one-cycle windows a short run may lack), and soot is on the
same basis by default (``SOOT_DSOC_KEY`` = ``soot_dsoc_corrected_g_per_km``, `shevsim.metrics.soot_dsoc_corrected`:
the battery's net energy booked as fuel at the run's soot per fuel), so a map whose run ends at a lower
SOC does not show soot borrowed from the battery as a cut (issue 14; ``soot_key = "soot_g_per_km"`` for
the raw figure). Three steps:

1. GA (``ga.run_ga``; population 30, 50 generations, crossover 0.8, mutation 0.01 - Table A.2;
   Deb's feasibility rules for the constraint; the first population also holds the feasible
   constant maps, which are evaluated anyway for the comparison);
2. narrowed bounds: per variable, min/max level over the k best feasible GA solutions
   (k = ``top_k``, reduced until the space has <= ``max_cases`` combinations, then, with ``fill_cases``, grown
   while it stays within them: seed 648 cases);
3. exhaustive search of the narrowed space.

Every evaluation goes through a `StudyRunner` (Dask + SQLite cache): duplicates
within a generation run once, anything already cached (earlier generations, a stopped run, the
trade-off study on the same cache) is not rerun. Outputs in ``out_dir``: ``summary.json`` (written
atomically), ``top_solutions.csv``, ``exhaustive.csv``, ``ga_history.csv``, ``constant_limits.csv``,
``fig_a3_rate_maps.png`` (Fig. A.3 analogue), ``fig_a4_comparison.png`` (Fig. A.4 analogue) and
``report.html`` (interactive: trade-off, GA history, chosen map).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..core.errors import ShevsimError
from .evaluate import code_version, failure_reason, is_failed, shevsim_version
from .ga import GAConfig, exhaustive_genomes, narrow_bounds, rank_key, run_ga, space_size
from .problem import DEFAULT_EDGES_W, DEFAULT_LEVELS_WPS, FE_KEY, SOOT_DSOC_KEY, check_map


@dataclass
class MapStudyConfig:
    """Settings of the power-rate map optimisation (units in the names)."""

    edges_w: tuple = DEFAULT_EDGES_W
    levels_wps: tuple = DEFAULT_LEVELS_WPS
    fe_loss_max_frac: float = 0.004          # alpha* = (1 - this) x baseline fuel economy (seed: 0.4 %)
    ga: GAConfig = field(default_factory=GAConfig)
    top_k: int = 10                          # step 2: best feasible GA solutions that set the bounds
    max_cases: int = 648                     # step 2: cap on the exhaustive space (seed: 648 cases)
    fill_cases: bool = True                  # step 2: more than top_k best maps while the space stays <= max_cases
    n_top: int = 8                           # solutions in the top table (seed Fig. A.3: best + 7)
    seed_constants: bool = True              # put feasible constant maps in the first GA population
    fe_key: str = FE_KEY
    soot_key: str = SOOT_DSOC_KEY            # same basis as fe_key (raw g/km: SOOT_KEY)

    def check(self) -> None:
        check_map(self.edges_w, None)
        lv = [float(x) for x in self.levels_wps]
        if not lv or any(not (x > 0) or math.isinf(x) for x in lv) or sorted(set(lv)) != lv:
            raise ValueError(f"levels_wps must be positive, finite and strictly increasing, got {lv}")
        if not 0.0 <= self.fe_loss_max_frac < 1.0:
            raise ValueError(f"fe_loss_max_frac must be in [0, 1), got {self.fe_loss_max_frac}")
        self.ga.check()


class Objective:
    """Map outputs -> (soot objective, relative fuel-economy violation) for the GA / ES."""

    def __init__(self, fe0: float, soot0: float, cfg: MapStudyConfig):
        self.fe0, self.soot0, self.cfg = fe0, soot0, cfg
        self.alpha_star = (1.0 - cfg.fe_loss_max_frac) * fe0

    def __call__(self, out: dict) -> tuple[float, float]:
        if is_failed(out, self.cfg.fe_key, self.cfg.soot_key):
            return math.inf, math.inf
        fe, soot = out[self.cfg.fe_key], out[self.cfg.soot_key]
        # small tolerance so a map equal to the baseline is never infeasible by round-off
        viol = max(0.0, (self.alpha_star - fe) / self.fe0 - 1e-12)
        return float(soot), float(viol)

    def changes(self, out: dict) -> dict:
        fe, soot = out.get(self.cfg.fe_key, math.nan), out.get(self.cfg.soot_key, math.nan)
        return {"fuel_economy_kmpl": fe, "soot_g_per_km": soot,
                "fe_change_pct": 100.0 * (fe / self.fe0 - 1.0), "soot_change_pct": 100.0 * (soot / self.soot0 - 1.0),
                # seed A.3 / Fig. A.7c: the battery's effective Ah-processed per cell (the cost of the map)
                "ah_effective_cell_ah": out.get("ah_effective_cell_ah", math.nan)}


def _rates(levels, genome) -> list[float]:
    return [float(levels[i]) for i in genome]


def run_powerrate_map(problem, runner, cfg: MapStudyConfig | None = None, out_dir: str | Path | None = None,
                      plots: bool = True, log=print) -> dict:
    """Run the three-step optimisation; returns (and writes) the summary dict.

    Parameters
    ----------
    problem : ScenarioProblem or SyntheticProblem
        ``problem.item(edges_w, rates_wps)`` builds one evaluation.
    runner : StudyRunner
        Evaluates batches (serial or Dask) through the cache.
    cfg : MapStudyConfig
    out_dir : path or None
        Where outputs go (None: nothing written).
    """
    cfg = cfg or MapStudyConfig()
    cfg.check()
    edges, levels = tuple(float(x) for x in cfg.edges_w), tuple(float(x) for x in cfg.levels_wps)
    n_var, n_lev = len(edges) - 1, len(levels)
    t_start = time.perf_counter()
    stats0 = runner.stats.as_dict()

    def items(genomes):
        return [problem.item(edges, _rates(levels, g)) for g in genomes]

    base_out, obj = _baseline(problem, runner, cfg, edges, log)
    constants, feas_const, best_const = _constant_limits(runner, items, obj, cfg, levels, n_var)
    ga, ranked = _ga_step(problem, runner, items, obj, cfg, levels, n_var, feas_const, best_const, log)

    # step 2: narrowed bounds
    bounds, k_used = narrow_bounds(ranked, [n_lev] * n_var, cfg.top_k, cfg.max_cases, grow=cfg.fill_cases)
    n_cases = space_size(bounds)
    log(f"step 2: bounds from the {k_used} best feasible GA maps -> {n_cases} cases "
        f"(of {n_lev ** n_var} in the full space, {100 * n_cases / n_lev ** n_var:.4f} %)")

    # step 3: exhaustive search
    es_genomes = exhaustive_genomes(bounds)
    es_outs = runner.evaluate(items(es_genomes), desc="exhaustive search")
    es_scored = [(g, *obj(o), o) for g, o in zip(es_genomes, es_outs)]
    es_ranked = sorted(es_scored, key=lambda r: rank_key(r[1], r[2], r[0]))
    best = _best_of_search(problem, es_ranked, best_const, obj, levels, n_var, log)
    top = [{"rank": i + 1, "rates_wps": _rates(levels, g), **obj.changes(out)}
           for i, (g, o, v, out) in enumerate([r for r in es_ranked if r[2] <= 0][:cfg.n_top])]
    log(f"step 3 exhaustive: best map {best['rates_wps']} W/s: soot {best['soot_change_pct']:+.2f} %, "
        f"fuel economy {best['fe_change_pct']:+.3f} %")
    if best_const is not None:
        log(f"best constant limit at the same constraint: {best_const['rate_wps'] / 1e3:g} kW/s: soot "
            f"{best_const['soot_change_pct']:+.2f} %, fuel economy {best_const['fe_change_pct']:+.3f} %")
    wall = time.perf_counter() - t_start
    perf = _performance(runner.stats.as_dict(), stats0, wall, log)
    summary = {
        "study": "powerrate_map", "problem": problem.describe(), "config": _cfg_dict(cfg),
        "shevsim_version": shevsim_version(), "code_sha256": code_version(),
        "baseline": {"fuel_economy_kmpl": obj.fe0, "soot_g_per_km": obj.soot0, "alpha_star_kmpl": obj.alpha_star,
                     "ah_effective_cell_ah": base_out.get("ah_effective_cell_ah", math.nan)},
        "best_map": {"edges_w": list(edges), **best},
        "best_constant": best_const,
        "soot_reduction_ratio_map_vs_constant": (best["soot_change_pct"] / best_const["soot_change_pct"]
                                                 if best_const and best_const["soot_change_pct"] < 0 else None),
        "ga": {"best_rates_wps": _rates(levels, ga.best), "best_soot_g_per_km": ga.best_objective,
               "distinct_evaluations": len(ga.evaluated), "history": ga.history},
        "narrowed": {"bounds_level_index": bounds,
                     "bounds_wps": [[levels[lo], levels[hi]] for lo, hi in bounds],
                     "k_used": k_used, "cases": n_cases, "full_space": n_lev ** n_var},
        "top_solutions": top, "constant_limits": constants, "performance": perf,
    }
    if out_dir is not None:
        _write_outputs(Path(out_dir), summary, es_scored, obj, levels, plots)
    return summary


def _baseline(problem, runner, cfg: MapStudyConfig, edges, log) -> tuple[dict, Objective]:
    """Run the baseline map; its fuel economy and soot fix the objective and the constraint."""
    base_out = runner.evaluate([problem.item(edges, None)], desc="baseline")[0]
    if is_failed(base_out, cfg.fe_key, cfg.soot_key):
        raise ShevsimError(f"{problem.describe()}: baseline run failed or lacks "
                           f"{cfg.fe_key}/{cfg.soot_key}: {base_out}")
    obj = Objective(base_out[cfg.fe_key], base_out[cfg.soot_key], cfg)
    log(f"baseline: fuel economy {obj.fe0:.5g} km/l, soot {obj.soot0:.5g} g/km; "
        f"constraint fuel economy >= {obj.alpha_star:.5g} km/l (-{100 * cfg.fe_loss_max_frac:.2f} %)")
    return base_out, obj


def _constant_limits(runner, items, obj: Objective, cfg: MapStudyConfig, levels, n_var: int):
    """Every constant limit (the seed's comparison): ``(rows, feasible (row, genome) pairs, best feasible row)``."""
    const_genomes = [tuple([j] * n_var) for j in range(len(levels))]
    const_outs = runner.evaluate(items(const_genomes), desc="constant limits")
    constants = []
    for j, out in enumerate(const_outs):
        o, v = obj(out)
        constants.append({"rate_wps": levels[j], "feasible": v <= 0.0, **obj.changes(out),
                          "error": failure_reason(out, cfg.fe_key, cfg.soot_key)})
    feas_const = [(c, g) for c, g in zip(constants, const_genomes) if c["feasible"]]
    best_const = min(feas_const, key=lambda cg: (cg[0]["soot_g_per_km"], cg[1]))[0] if feas_const else None
    return constants, feas_const, best_const


def _ga_step(problem, runner, items, obj: Objective, cfg: MapStudyConfig, levels, n_var: int, feas_const,
             best_const, log):
    """Step 1: the GA over level indices; returns it and its feasible maps ranked (best first)."""
    def evaluate_batch(genomes, _gen=[0]):
        outs = runner.evaluate(items(genomes), desc=f"GA generation {_gen[0] + 1}/{cfg.ga.generations}")
        _gen[0] += 1
        return [obj(o) for o in outs]

    # the first population holds the best feasible constant maps (lowest soot first), so the GA starts
    # from the comparison it must beat; a quarter of the population at most
    by_soot = sorted(feas_const, key=lambda cg: (cg[0]["soot_g_per_km"], cg[1]))
    initial = [g for _, g in by_soot][:max(1, cfg.ga.population // 4)] if cfg.seed_constants else []
    ga = run_ga([len(levels)] * n_var, evaluate_batch, cfg.ga, initial=initial)
    ranked = [g for g, _, _ in ga.ranked(feasible_only=True)]
    if not ranked and best_const is not None:   # the GA found nothing feasible: the best constant is the answer
        ranked = [tuple([levels.index(best_const["rate_wps"])] * n_var)]
    if not ranked:
        raise ShevsimError(f"{problem.describe()}: the GA found no map with fuel economy >= {obj.alpha_star:.5g} km/l;"
                           " widen the levels or relax the fuel-economy constraint")
    log(f"step 1 GA: {len(ga.evaluated)} distinct maps evaluated, best soot {ga.best_objective:.5g} g/km "
        f"({100 * (ga.best_objective / obj.soot0 - 1):+.2f} %), map {_rates(levels, ga.best)} W/s")
    return ga, ranked


def _best_of_search(problem, es_ranked, best_const, obj: Objective, levels, n_var: int, log) -> dict:
    """The best map of the exhaustive search, or the best constant limit where that is better."""
    best_g, best_o, best_v, best_out = es_ranked[0]
    if best_v > 0:
        raise ShevsimError(f"{problem.describe()}: no feasible map in the narrowed space (unexpected: it holds the GA's best)")
    best = {"rates_wps": _rates(levels, best_g), "genome": list(best_g),
            "kind": "constant" if len(set(best_g)) == 1 else "map", **obj.changes(best_out)}
    if best_const is not None and best_const["soot_g_per_km"] < best["soot_g_per_km"]:
        # never report a map worse than the best constant limit it was compared with: the constant is the
        # answer then, labelled as such
        j = levels.index(best_const["rate_wps"])
        best = {"rates_wps": [levels[j]] * n_var, "genome": [j] * n_var, "kind": "constant",
                **{k: best_const[k] for k in ("fuel_economy_kmpl", "soot_g_per_km", "fe_change_pct",
                                               "soot_change_pct", "ah_effective_cell_ah")}}
        log(f"the best constant limit ({best_const['rate_wps'] / 1e3:g} kW/s) beats every map searched: reported as"
            " the best (kind = constant)")
    return best


def _performance(st: dict, stats0: dict, wall: float, log) -> dict:
    """Evaluations, cache hits and parallel efficiency of this study (runner statistics since ``stats0``)."""
    new = st["new"] - stats0["new"]
    run_wall = st["wall_s"] - stats0["wall_s"]
    busy = st["busy_s"] - stats0["busy_s"]
    perf = {"wall_s": wall, "new_evaluations": new, "cached_evaluations": st["cached"] - stats0["cached"],
            "evals_per_s": new / run_wall if run_wall > 0 else math.nan, "slots": st["slots"],
            "parallel_efficiency": busy / (st["slots"] * run_wall) if run_wall > 0 else math.nan,
            "code_changed_mid_study": st["code_changed_mid_study"],
            "not_cached_code_mismatch": st["not_cached_code_mismatch"]}
    log(f"{new} new evaluations in {wall:.1f} s: {perf['evals_per_s']:.3g} evaluations/s, "
        f"parallel efficiency {perf['parallel_efficiency']:.2f} on {st['slots']} slot(s)")
    return perf


def _cfg_dict(cfg: MapStudyConfig) -> dict:
    d = asdict(cfg)
    d["edges_w"], d["levels_wps"] = list(cfg.edges_w), list(cfg.levels_wps)
    return d


def _write_outputs(out: Path, summary: dict, es_scored, obj: Objective, levels, plots: bool) -> None:
    import pandas as pd
    from ..core.atomic import write_csv_atomic
    from ..core.results import write_json_atomic
    out.mkdir(parents=True, exist_ok=True)
    n_var = len(summary["best_map"]["edges_w"]) - 1
    rcols = [f"rate_d{i + 1}_wps" for i in range(n_var)]

    def frame(rows):
        return pd.DataFrame([{**{c: r for c, r in zip(rcols, row["rates_wps"])},
                              **{k: v for k, v in row.items() if k not in ("rates_wps", "genome")}} for row in rows])

    write_csv_atomic(out / "top_solutions.csv", frame(summary["top_solutions"]))
    es_rows = [{"rates_wps": [levels[i] for i in g], "feasible": v <= 0, **obj.changes(o),
                "error": failure_reason(o, obj.cfg.fe_key, obj.cfg.soot_key)} for g, _, v, o in es_scored]
    write_csv_atomic(out / "exhaustive.csv", frame(es_rows))
    write_csv_atomic(out / "ga_history.csv", pd.DataFrame(summary["ga"]["history"]))
    write_csv_atomic(out / "constant_limits.csv", pd.DataFrame(summary["constant_limits"]))
    if plots:
        plot_rate_maps(summary, out / "fig_a3_rate_maps.png")
        plot_comparison(summary, out / "fig_a4_comparison.png")
    write_json_atomic(out / "summary.json", summary)
    if plots:                                   # the interactive report of all of the above
        from ..report.write import write_study_html
        write_study_html(out, summary)


def _step(edges_w, rates_wps):
    xs, ys = [], []
    for lo, hi, r in zip(edges_w, edges_w[1:], rates_wps):
        xs += [lo / 1e3, hi / 1e3]
        ys += [r / 1e3, r / 1e3]
    return xs, ys


def plot_rate_maps(summary: dict, path: Path) -> None:
    """Write `rate_maps_figure` to ``path`` (PNG)."""
    rate_maps_figure(summary).savefig(path, dpi=120)


def rate_maps_figure(summary: dict):
    """Fig. A.3 analogue: design space (grey), narrowed space (blue band), top maps, best map (a
    matplotlib ``Figure``, not registered with pyplot)."""
    from matplotlib.figure import Figure
    edges = summary["best_map"]["edges_w"]
    lv = summary["config"]["levels_wps"]
    fig = Figure(figsize=(7, 4.2))
    ax = fig.subplots()
    for i, (lo, hi) in enumerate(zip(edges, edges[1:])):
        ax.fill_between([lo / 1e3, hi / 1e3], min(lv) / 1e3, max(lv) / 1e3, color="0.88", lw=0,
                        label="design space" if i == 0 else None)
        blo, bhi = summary["narrowed"]["bounds_wps"][i]
        ax.fill_between([lo / 1e3, hi / 1e3], blo / 1e3, bhi / 1e3, color="tab:blue", alpha=0.25, lw=0,
                        label="narrowed by GA" if i == 0 else None)
    for row in summary["top_solutions"][1:]:
        ax.plot(*_step(edges, row["rates_wps"]), color="0.45", lw=0.9, alpha=0.8)
    kind = summary["best_map"].get("kind", "map")
    ax.plot(*_step(edges, summary["best_map"]["rates_wps"]), color="tab:blue", lw=2.2,
            label="best: a constant limit (no map beat it)" if kind == "constant" else "best map (ES)")
    if summary["best_constant"]:
        r = summary["best_constant"]["rate_wps"] / 1e3
        ax.axhline(r, color="tab:red", ls="--", lw=1.2, label=f"best constant limit ({r:g} kW/s)")
    ax.set_xlabel("engine-generator power (kW)")
    ax.set_ylabel("max power rate (kW/s)")
    ax.set_title("Power-rate constraint maps: best ES solutions")
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_comparison(summary: dict, path: Path) -> None:
    """Write `comparison_figure` to ``path`` (PNG)."""
    comparison_figure(summary).savefig(path, dpi=120)


def comparison_figure(summary: dict):
    """Fig. A.4 analogue: fuel-economy and soot change of the top maps and the best constant limit (a
    matplotlib ``Figure``, not registered with pyplot)."""
    from matplotlib.figure import Figure
    best = summary["best_map"]
    kind = best.get("kind", "map")
    rows = [("best" if kind == "map" else "best (constant)", best)]
    rows += [(f"#{r['rank']}", r) for r in summary["top_solutions"] if r["rates_wps"] != best["rates_wps"]][:7]
    if summary["best_constant"]:
        rows.append((f"const {summary['best_constant']['rate_wps'] / 1e3:g}", summary["best_constant"]))
    labels = [l for l, _ in rows]
    colors = ["tab:blue"] + ["0.55"] * (len(rows) - 1 - bool(summary["best_constant"])) \
        + (["tab:red"] if summary["best_constant"] else [])
    fig = Figure(figsize=(7, 5))
    a1, a2 = fig.subplots(2, 1, sharex=True)
    a1.bar(labels, [r["fe_change_pct"] for _, r in rows], color=colors)
    a1.axhline(-100 * summary["config"]["fe_loss_max_frac"], color="k", ls=":", lw=1, label="constraint")
    a1.set_ylabel("fuel economy change (%)")
    a1.legend(fontsize=8)
    a2.bar(labels, [r["soot_change_pct"] for _, r in rows], color=colors)
    a2.set_ylabel("soot change (%)")
    a1.set_title("Top maps vs baseline (blue: the reported best" + (", a constant limit" if kind == "constant" else "")
                 + "; red: best constant limit)")
    for a in (a1, a2):
        a.grid(alpha=0.3, axis="y")
        a.axhline(0, color="k", lw=0.6)
    fig.tight_layout()
    return fig
