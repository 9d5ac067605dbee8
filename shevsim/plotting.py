"""plotting.py - the standard figures of a SHEV run (cf. seed Figs. 5.15, A.6).

Every panel is drawn only when its signals are in the result, so any scenario
(also the verification ones) gets the figures that apply to it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

def headless_pyplot():
    """``matplotlib.pyplot`` for writing figure files, without taking over the caller's backend.

    When nothing has imported pyplot yet (command-line runs, workers), select the non-interactive
    Agg backend so no display is needed; when pyplot is already in use (a notebook, a GUI session),
    keep the backend the user chose.
    """
    import sys

    import matplotlib
    if "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


#: key metrics printed in the header of ``overview.png`` (when the run has them)
HEADLINE_METRICS = ("distance_km", "fuel_economy_dsoc_corrected_kmpl", "fuel_economy_raw_kmpl", "delta_soc_pct",
                    "soot_dsoc_corrected_g_per_km", "speed_miss_rms_kmh")


def _panels(result) -> list[tuple[str, list[tuple[str, np.ndarray, str, str | None]]]]:
    """(y-axis title with unit, [(legend, values in display unit, signal, thesis symbol)]) of each panel."""
    from .report.html import run_figure_spec, signal_series
    from .report.labels import signal_label, to_display
    panels = []
    for _ftitle, rows in run_figure_spec([result]):
        for rtitle, sigs in rows:
            series, du_row = [], None
            for sgn in sigs:
                ser = signal_series(result, sgn)
                if ser is None:
                    continue
                _, y, unit = ser
                y, du = to_display(y, unit)
                du_row = du_row or du
                label, sym = signal_label(sgn)
                series.append((label, y, sgn, sym))
            if series:
                panels.append((f"{rtitle} ({du_row})" if du_row and du_row != "-" else rtitle, series))
    return panels


def scenario_plots(result, folder: Path) -> list[Path]:
    """Write ``overview.png`` (the run at a glance: title, termination and key metrics above the panels, plain
    names with units on the axes, thesis symbols in a note under them) and ``report.html`` (the interactive
    report, :mod:`shevsim.report`) into ``folder``."""
    # a bare Figure (no pyplot): the caller's backend and open figures are left alone
    from matplotlib.figure import Figure

    from .report.labels import fmt, metric_label
    from .report.write import write_run_html
    folder = Path(folder)
    t = np.asarray(result.time_s, dtype=float)
    panels = _panels(result)
    ncol = 2 if len(panels) > 3 else 1
    nrow = -(-len(panels) // ncol)
    head_in, foot_in = 1.45, 0.65
    height = head_in + foot_in + 2.1 * nrow
    fig = Figure(figsize=(13 if ncol == 2 else 9, height))
    axes = fig.subplots(nrow, ncol, sharex=True, squeeze=False)
    fig.subplots_adjust(left=0.07 if ncol == 2 else 0.1, right=0.98, hspace=0.28, wspace=0.18,
                        top=1 - head_in / height, bottom=foot_in / height + 0.35 / height)
    symbols = []
    for k, ax in enumerate(axes.ravel()):                 # row by row, read left to right
        if k >= len(panels):
            ax.set_visible(False)
            continue
        ytitle, series = panels[k]
        for label, y, _sig, sym in series:
            ax.plot(t, y, lw=0.8, label=label)
            if sym and f"{sym}: {label}" not in symbols:
                symbols.append(f"{sym}: {label}")
        ax.set_ylabel(ytitle, fontsize=8)
        ax.tick_params(labelsize=7)
        if len(series) > 1:
            ax.legend(fontsize=6.5, loc="best", framealpha=0.8)
        ax.grid(True, alpha=0.3)
    for col in range(ncol):                               # the lowest panel of each column shows the time axis
        shown = [axes[r, col] for r in range(nrow) if axes[r, col].get_visible()]
        if shown:
            shown[-1].set_xlabel("Time (s)", fontsize=8)
            shown[-1].xaxis.set_tick_params(labelbottom=True)
    name = result.meta.get("scenario", "")
    term = result.termination
    fig.text(0.01, 1 - 0.3 / height, f"{name}", fontsize=13, weight="bold", va="top")
    dur = f"{t[-1] - t[0]:g} s simulated" if len(t) > 1 else ""
    fig.text(0.01, 1 - 0.62 / height, f"termination: {term}   ·   {dur}   ·   engine {result.meta.get('engine', '?')}",
             fontsize=9, va="top", color="#1b4332" if getattr(term, "ok", True) else "#7a0010")
    heads = []
    for key in HEADLINE_METRICS:
        v = result.metrics.get(key)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            lab, unit = metric_label(key)
            heads.append(f"{lab}: {fmt(v)} {unit}".strip())
    for i in range(0, min(len(heads), 6), 3):             # three per line
        fig.text(0.01, 1 - (0.88 + 0.2 * i / 3) / height, "   ·   ".join(heads[i:i + 3]), fontsize=8.5, va="top")
    if symbols:
        fig.text(0.01, 0.12 / height, "Thesis symbols (Kim 2014): " + "; ".join(symbols), fontsize=6.5,
                 color="#555", va="bottom", wrap=True)
    path = folder / "overview.png"
    fig.savefig(path, dpi=110)
    return [path, write_run_html(result, folder)]


def plot_signals(results, signals, ax=None, labels=None):
    """Plot ``signals`` of one or more results against time, one axis per display unit.

    Values are shown in engineering units (W as kW, m/s as km/h, J as kWh, rad/s as rpm); axes are
    titled in plain language with the unit ("Power (kW)").

    Parameters
    ----------
    results : sequence of Result
        Runs to overlay (same signal names).
    signals : sequence of str
        ``component.port`` names.
    ax : Axes or sequence of Axes, optional
        One per display unit (in order of first appearance); a new figure (pyplot, the caller's
        backend) when omitted.
    labels : sequence of str, optional
        One per result (default: :func:`shevsim.core.results.run_labels`).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn on (its axes, one per unit: ``fig.axes``).
    """
    from .report.html import QUANTITY
    from .report.labels import display_unit, signal_label, signal_unit, to_display
    results = list(results)
    signals = list(signals)
    for r in results:
        for s in signals:
            r[s]                                   # KeyError naming close matches
    units: list[str] = []
    by_unit: dict[str, list[str]] = {}
    for s in signals:
        du = display_unit(signal_unit(s, results[0].units))[0] if results else ""
        if du not in units:
            units.append(du)
        by_unit.setdefault(du, []).append(s)
    if ax is None:
        import matplotlib.pyplot as plt          # the caller's backend
        fig, axes = plt.subplots(len(units), 1, sharex=True, squeeze=False, figsize=(8, 2.4 * len(units) + 0.4))
        axes = list(axes[:, 0])
    else:
        axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
        if len(axes) < len(units):
            raise ValueError(f"plot: {len(units)} units ({units}) need {len(units)} axes, got {len(axes)}")
        fig = axes[0].figure
    if labels is None:
        from .core.results import run_labels
        labels = run_labels(results)
    for a, du in zip(axes, units):
        sigs = by_unit[du]
        for r, lab in zip(results, labels):
            for s in sigs:
                y, _ = to_display(r[s], signal_unit(s, r.units))
                name = signal_label(s)[0]
                a.plot(r.time_s, y, lw=0.9, label=name if len(results) == 1 else f"{name} ({lab})")
        title = signal_label(sigs[0])[0] if len(sigs) == 1 else QUANTITY.get(du, "Value")
        a.set_ylabel(f"{title} ({du})" if du and du != "-" else title, fontsize=9)
        a.grid(True, alpha=0.3)
        a.legend(fontsize=7)
    axes[len(units) - 1].set_xlabel("Time (s)")
    return fig
