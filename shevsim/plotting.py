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


PANELS = [
    ("speed tracking [km/h]", [("cycle.speed_ref_mps", 3.6, "reference"), ("vehicle.speed_mps", 3.6, "vehicle")]),
    ("power split [kW]", [("bus.demand_power_w", 1e-3, "demand"), ("engine_generator.elec_power_w", 1e-3, "engine-generator"),
                          ("bus.battery_power_w", 1e-3, "battery (+ discharge)")]),
    ("battery limits [kW]", [("bms.power_max_w", 1e-3, "P_b,max (BMS)"), ("bms.power_min_w", 1e-3, "P_b,min (BMS)"),
                             ("bus.battery_power_w", 1e-3, "battery power")]),
    ("SOC [%]", [("battery.soc_pct", 1.0, "plant"), ("bms.soc_pct", 1.0, "BMS estimate")]),
    ("engine power [kW]", [("engine_generator.engine_power_w", 1e-3, "engine"), ("supervisor.power_cmd_w", 1e-3, "command")]),
    ("engine power rate [kW/s]", [("__rate__engine_generator.elec_power_w", 1e-3, "dP_g/dt")]),
    ("soot rate [mg/s]", [("engine_generator.soot_rate_mgps", 1.0, "soot")]),
    ("battery current [A] (+ discharge)", [("battery.current_a", 1.0, "pack current")]),
    ("battery voltage [V]", [("battery.voltage_v", 1.0, "pack voltage")]),
    ("cell temperatures [°C]", [("battery.t_core_c", 1.0, "core"), ("battery.t_surface_c", 1.0, "surface"),
                                ("bms.t_core_c", 1.0, "core (BMS)")]),
]


def scenario_plots(result, folder: Path) -> list[Path]:
    """Write ``overview.png`` (all applicable panels) and one PNG per panel into ``folder``."""
    # a bare Figure (no pyplot): the caller's backend and open figures are left alone
    from matplotlib.figure import Figure
    folder = Path(folder)
    t = result.time_s
    drawn = []
    for title, sigs in PANELS:
        series = []
        for name, scale, label in sigs:
            if name.startswith("__rate__"):
                base = name[len("__rate__"):]
                if base in result.signals and len(t) > 1:
                    series.append((np.gradient(result.signals[base], t) * scale, label))
            elif name in result.signals:
                series.append((result.signals[name] * scale, label))
        if series:
            drawn.append((title, series))
    if not drawn:
        names = list(result.signals)[:8]
        drawn = [("signals", [(result.signals[n], n) for n in names])]
    fig = Figure(figsize=(10, 2.1 * len(drawn)))
    axes = fig.subplots(len(drawn), 1, sharex=True, squeeze=False)
    for ax, (title, series) in zip(axes[:, 0], drawn):
        for y, label in series:
            ax.plot(t, y, lw=0.8, label=label)
        ax.set_ylabel(title, fontsize=7)
        ax.legend(fontsize=6, loc="upper right")
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    name = result.meta.get("scenario", "")
    fig.suptitle(f"{name}", fontsize=9)
    fig.tight_layout()
    path = folder / "overview.png"
    fig.savefig(path, dpi=110)
    return [path]


def plot_signals(results, signals, ax=None, labels=None):
    """Plot ``signals`` of one or more results against time, one axis per unit.

    Parameters
    ----------
    results : sequence of Result
        Runs to overlay (same signal names).
    signals : sequence of str
        ``component.port`` names.
    ax : Axes or sequence of Axes, optional
        One per unit (in order of first appearance); a new figure (pyplot, the caller's
        backend) when omitted.
    labels : sequence of str, optional
        One per result (default: the scenario name, numbered when repeated).

    Returns
    -------
    list of Axes
    """
    results = list(results)
    signals = list(signals)
    for r in results:
        for s in signals:
            r[s]                                   # KeyError naming close matches
    units: list[str] = []
    for s in signals:
        u = results[0].units.get(s, "") if results else ""
        if u not in units:
            units.append(u)
    if ax is None:
        import matplotlib.pyplot as plt          # the caller's backend
        _, axes = plt.subplots(len(units), 1, sharex=True, squeeze=False, figsize=(8, 2.4 * len(units)))
        axes = list(axes[:, 0])
    else:
        axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
        if len(axes) < len(units):
            raise ValueError(f"plot: {len(units)} units ({units}) need {len(units)} axes, got {len(axes)}")
    if labels is None:
        names = [str(r.meta.get("scenario", f"run {i + 1}")) for i, r in enumerate(results)]
        labels = [f"{n} #{i + 1}" if names.count(n) > 1 else n for i, n in enumerate(names)]
    for a, u in zip(axes, units):
        for r, lab in zip(results, labels):
            for s in signals:
                if r.units.get(s, "") == u:
                    name = s if len(results) == 1 else f"{s} ({lab})"
                    a.plot(r.time_s, r[s], lw=0.9, label=name)
        a.set_ylabel(f"[{u}]" if u else "[-]")
        a.grid(True, alpha=0.3)
        a.legend(fontsize=7)
    axes[len(units) - 1].set_xlabel("time [s]")
    return axes[:len(units)]
