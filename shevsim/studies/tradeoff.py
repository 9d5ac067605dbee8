"""tradeoff.py - fuel economy and soot against a constant maximum engine power rate (seed Fig. A.2).

For each rate r in ``rates_wps`` the scenario runs with the power-rate constraint map set to r in
every partition (a constant limit); the baseline is the scenario as written. Fuel economy and soot are
reported absolute and relative to the baseline, both Delta-SOC-corrected by default
(``fuel_economy_dsoc_corrected_kmpl``, ``soot_dsoc_corrected_g_per_km``: the same equivalent fuel, issue 14;
``fe_key``/``soot_key`` select others, e.g. the SOC-sustainable A.1 figure or raw g/km).
The seed's reading of the curve: pick the tightest rate whose fuel-economy loss stays within
``fe_loss_max_frac`` (0.5 %: 19.3 kW/s gave -1.9 % soot) - reported as ``best_within_loss``.

Outputs in ``out_dir``: ``tradeoff.csv``, ``fig_a2_tradeoff.png``, ``summary.json`` (atomic), ``report.html``.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

from ..core.errors import ShevsimError
from .evaluate import code_version, failure_reason, is_failed, shevsim_version
from .problem import DEFAULT_EDGES_W, FE_KEY, SOOT_DSOC_KEY


def run_tradeoff(problem, runner, rates_wps, out_dir: str | Path | None = None, edges_w=DEFAULT_EDGES_W,
                 fe_loss_max_frac: float = 0.005, fe_key: str = FE_KEY,
                 soot_key: str = SOOT_DSOC_KEY, plots: bool = True, log=print) -> dict:
    """Sweep constant maximum power rates; returns (and writes) the summary with the table rows."""
    rates = sorted({float(r) for r in rates_wps}, reverse=True)
    if not rates or any(not (r > 0) or math.isinf(r) for r in rates):
        raise ValueError(f"rates must be positive and finite (W/s), got {list(rates_wps)}")
    t0 = time.perf_counter()
    n_part = len(edges_w) - 1
    items = [problem.item(edges_w, None)] + [problem.item(edges_w, [r] * n_part) for r in rates]
    outs = runner.evaluate(items, desc="trade-off")
    base = outs[0]
    if is_failed(base, fe_key, soot_key):
        raise ShevsimError(f"{problem.describe()}: baseline run failed or lacks {fe_key}/{soot_key}: {base}")
    fe0, s0 = base[fe_key], base[soot_key]
    rows = []
    for r, out in zip(rates, outs[1:]):
        reason = failure_reason(out, fe_key, soot_key)
        failed = bool(reason)
        fe = math.nan if failed else out[fe_key]
        soot = math.nan if failed else out[soot_key]
        rows.append({"rate_wps": r, "fuel_economy_kmpl": fe, "soot_g_per_km": soot,
                     "fe_change_pct": 100 * (fe / fe0 - 1), "soot_change_pct": 100 * (soot / s0 - 1),
                     "error": reason})
    ok = [row for row in rows if not row["error"] and row["fe_change_pct"] >= -100 * fe_loss_max_frac - 1e-9]
    best = min(ok, key=lambda row: (row["soot_g_per_km"], -row["rate_wps"])) if ok else None
    wall = time.perf_counter() - t0
    summary = {"study": "tradeoff", "problem": problem.describe(), "edges_w": list(edges_w),
               "shevsim_version": shevsim_version(), "code_sha256": code_version(),
               "baseline": {"fuel_economy_kmpl": fe0, "soot_g_per_km": s0},
               "fe_loss_max_frac": fe_loss_max_frac, "best_within_loss": best, "rows": rows,
               "performance": {"wall_s": wall, **runner.stats.as_dict()}}
    log(f"baseline: fuel economy {fe0:.5g} km/l, soot {s0:.5g} g/km")
    log(f"{'rate (kW/s)':>12} {'FE (km/l)':>10} {'FE chg %':>9} {'soot g/km':>10} {'soot chg %':>10}")
    for row in rows:
        log(f"{row['rate_wps'] / 1e3:12.4g} {row['fuel_economy_kmpl']:10.5g} {row['fe_change_pct']:9.3f} "
            f"{row['soot_g_per_km']:10.5g} {row['soot_change_pct']:10.3f}{'  ' + row['error'] if row['error'] else ''}")
    if best:
        log(f"best constant rate within -{100 * fe_loss_max_frac:.2f} % fuel economy: {best['rate_wps'] / 1e3:g} kW/s "
            f"-> soot {best['soot_change_pct']:+.2f} %, fuel economy {best['fe_change_pct']:+.3f} %")
    if out_dir is not None:
        import pandas as pd
        from ..core.results import write_json_atomic
        from ..core.atomic import write_csv_atomic
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_csv_atomic(out / "tradeoff.csv", pd.DataFrame(rows))
        if plots:
            plot_tradeoff(summary, out / "fig_a2_tradeoff.png")
        write_json_atomic(out / "summary.json", summary)
        if plots:
            from ..report.write import write_study_html
            write_study_html(out, summary)
    return summary


def plot_tradeoff(summary: dict, path: Path) -> None:
    """Write `tradeoff_figure` to ``path`` (PNG)."""
    tradeoff_figure(summary).savefig(path, dpi=120)


def tradeoff_figure(summary: dict):
    """Fig. A.2 analogue: fuel-economy and soot change vs the constant maximum power rate (a matplotlib
    ``Figure``, not registered with pyplot)."""
    from matplotlib.figure import Figure
    rows = sorted(summary["rows"], key=lambda r: r["rate_wps"])
    x = [r["rate_wps"] / 1e3 for r in rows]
    fig = Figure(figsize=(6.5, 4))
    a1 = fig.subplots()
    a1.plot(x, [r["fe_change_pct"] for r in rows], "o-", color="tab:blue", label="fuel economy")
    a1.set_xlabel("maximum engine-generator power rate (kW/s)")
    a1.set_ylabel("fuel economy change (%)", color="tab:blue")
    a1.axhline(-100 * summary["fe_loss_max_frac"], color="tab:blue", ls=":", lw=1)
    a2 = a1.twinx()
    a2.plot(x, [r["soot_change_pct"] for r in rows], "s-", color="tab:red", label="soot")
    a2.set_ylabel("soot change (%)", color="tab:red")
    if summary["best_within_loss"]:
        a1.axvline(summary["best_within_loss"]["rate_wps"] / 1e3, color="0.4", ls="--", lw=1)
    a1.set_title("Constant max power rate vs baseline (cf. seed Fig. A.2)")
    a1.grid(alpha=0.3)
    fig.tight_layout()
    return fig
