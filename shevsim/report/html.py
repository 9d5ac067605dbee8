"""html.py - self-contained HTML reports (Plotly, its JavaScript embedded: the file works offline).

One page per run, comparison of runs, study or calibration: a header, the termination, the metrics, the
interactive figures (zoom, pan, hover; the time axes of a page zoom together) and the parameters. Axes
read in plain language with units ("Battery power (kW)", "Speed (km/h)"); thesis symbols appear only in
the hover text.

Builders return the page as a string; [`shevsim.report.write_report()`][shevsim.report.write_report] writes one beside a folder's
outputs. Each builder also records how many figures it drew (``page.n_figures``), which the browser test
checks against the plots that render.
"""
from __future__ import annotations

import datetime as _dt
import html as _html
import json
import math
from typing import Any, Iterable, Sequence

import numpy as np

from .labels import display_unit, fmt, metric_label, signal_label, signal_unit, slug, to_display

#: figures of a run: (figure title, [(row title, [signals])]); a row is drawn when any of its signals is there
RUN_FIGURES: list[tuple[str, list[tuple[str, list[str]]]]] = [
    ("Driving", [("Speed", ["cycle.speed_ref_mps", "vehicle.speed_mps"])]),
    ("Power flow", [("Power", ["bus.demand_power_w", "engine_generator.elec_power_w", "bus.battery_power_w"]),
                    ("Battery power and limits", ["bus.battery_power_w", "bms.power_max_w", "bms.power_min_w"])]),
    ("Engine-generator", [("Power", ["engine_generator.engine_power_w", "supervisor.power_cmd_w"]),
                          ("Power rate", ["__rate__engine_generator.elec_power_w"]),
                          ("Soot emission", ["engine_generator.soot_rate_mgps"]),
                          ("Fuel rate", ["engine_generator.fuel_rate_gps"])]),
    ("Battery", [("State of charge", ["battery.soc_pct", "bms.soc_pct"]),
                 ("Current", ["battery.current_a"]),
                 ("Voltage", ["battery.voltage_v"]),
                 ("Cell temperature", ["battery.t_core_c", "battery.t_surface_c", "bms.t_core_c"])]),
]

#: what a display unit measures (row titles of the generic figure)
QUANTITY = {"kW": "Power", "km/h": "Speed", "m": "Position", "N": "Force", "%": "Percent", "°C": "Temperature",
            "V": "Voltage", "A": "Current", "kWh": "Energy", "rpm": "Rotational speed", "N·m": "Torque",
            "kW/s": "Power rate", "g/s": "Mass flow", "mg/s": "Mass flow", "m/s²": "Acceleration", "s": "Time",
            "g": "Mass", "mg": "Mass", "rad": "Angle", "Ohm": "Resistance", "F": "Capacitance", "-": "Value"}

#: the most points a trace keeps (min/max-preserving decimation beyond)
MAX_POINTS = 20000

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,Arial,sans-serif;margin:0;color:#1d2733;background:#f6f7f9}
header{background:#1d3557;color:#fff;padding:14px 24px}
header h1{margin:0;font-size:22px;font-weight:600}
header p{margin:4px 0 0;opacity:.85;font-size:13px}
main{padding:8px 24px 40px;max-width:1400px}
section{background:#fff;border:1px solid #dde2e8;border-radius:6px;margin:14px 0;padding:10px 16px}
h2{font-size:17px;margin:6px 0 10px}
table{border-collapse:collapse;font-size:13px;margin:4px 0}
th,td{border-bottom:1px solid #e5e8ec;padding:3px 10px;text-align:left;vertical-align:top}
th{background:#f0f2f5;font-weight:600}
td.num{text-align:right;font-variant-numeric:tabular-nums}
.badge{display:inline-block;padding:2px 10px;border-radius:10px;font-weight:600;font-size:13px}
.completed{background:#d8f3dc;color:#1b4332}.stopped{background:#ffd6d6;color:#7a0010}
.degraded{background:#fff1c1;color:#6b4e00}
.note{color:#55606e;font-size:12px}
details summary{cursor:pointer;font-weight:600;margin:4px 0}
.grid{display:flex;flex-wrap:wrap;gap:18px}
code{background:#f0f2f5;padding:0 3px;border-radius:3px}
"""

# the time axes of a page zoom together: a relayout of one time figure is applied to the others
_LINK_JS = """
(function(){
  var figs = Array.prototype.slice.call(document.querySelectorAll('.shevsim-time .js-plotly-plot'));
  var busy = false;
  figs.forEach(function(src){
    src.on('plotly_relayout', function(ev){
      if (busy || !ev) return;
      var upd = null;
      for (var k in ev){
        var m = k.match(/^xaxis\\d*\\.range\\[([01])\\]$/);
        if (m){ upd = upd || {}; upd['xaxis.range[' + m[1] + ']'] = ev[k]; }
        else if (/^xaxis\\d*\\.range$/.test(k)){ upd = {'xaxis.range': ev[k]}; }
        else if (/^xaxis\\d*\\.autorange$/.test(k)){ upd = {'xaxis.autorange': true}; }
      }
      if (!upd) return;
      busy = true;
      var todo = figs.filter(function(f){ return f !== src; }).map(function(f){ return Plotly.relayout(f, upd); });
      Promise.all(todo).then(function(){ busy = false; }, function(){ busy = false; });
    });
  });
})();
"""


def esc(x: Any) -> str:
    """HTML-escaped text."""
    return _html.escape(str(x), quote=True)


class Page:
    """An HTML page being built: sections of HTML and Plotly figures, rendered by `render()`."""

    def __init__(self, title: str, subtitle: str = ""):
        self.title, self.subtitle = title, subtitle
        self.parts: list[str] = []
        self.n_figures = 0

    def section(self, heading: str, body: str, sid: str | None = None) -> None:
        self.parts.append(f'<section id="{esc(sid or slug(heading))}"><h2>{esc(heading)}</h2>{body}</section>')

    def figure(self, fig, heading: str, note: str = "", time_axis: bool = False) -> None:
        """Add a Plotly figure in its own section (``time_axis``: zooms together with the page's other time
        figures)."""
        self.n_figures += 1
        div = fig.to_html(full_html=False, include_plotlyjs=False, div_id=f"fig-{self.n_figures}",
                          config={"displaylogo": False, "responsive": True, "scrollZoom": False,
                                  "toImageButtonOptions": {"filename": slug(heading)}})
        cls = "shevsim-fig shevsim-time" if time_axis else "shevsim-fig"
        self.parts.append(f'<section id="{esc(slug(heading))}"><h2>{esc(heading)}</h2>'
                          f'<div class="{cls}">{div}</div>'
                          + (f'<p class="note">{esc(note)}</p>' if note else "") + "</section>")

    def render(self) -> str:
        from plotly.offline import get_plotlyjs
        from ..version import __version__
        stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        sub = esc(self.subtitle) + (" · " if self.subtitle else "") + f"shevsim {esc(__version__)} · {stamp}"
        return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
                f"<meta name=\"generator\" content=\"shevsim {esc(__version__)}\">"
                f"<meta name=\"shevsim-figures\" content=\"{self.n_figures}\">"
                f"<title>{esc(self.title)}</title><style>{_CSS}</style>"
                f"<script type=\"text/javascript\">{get_plotlyjs()}</script></head><body>"
                f"<header><h1>{esc(self.title)}</h1><p>{sub}</p></header><main>"
                + "\n".join(self.parts)
                + f"</main><script type=\"text/javascript\">{_LINK_JS}</script></body></html>\n")


# ------------------------------------------------------------------------------------------ pieces

def table(header: Sequence[str], rows: Iterable[Sequence[Any]], num_cols: Iterable[int] = (),
          titles: Sequence[Sequence[str]] | None = None) -> str:
    """An HTML table; cells are escaped; ``num_cols`` are right-aligned; ``titles`` are hover texts per cell."""
    nums = set(num_cols)
    out = ["<table>" + ("<thead><tr>" + "".join(f"<th>{esc(h)}</th>" for h in header) + "</tr></thead>"
                        if any(header) else "") + "<tbody>"]
    for i, row in enumerate(rows):
        cells = []
        for j, c in enumerate(row):
            t = titles[i][j] if titles and i < len(titles) and j < len(titles[i]) and titles[i][j] else ""
            attr = (' class="num"' if j in nums else "") + (f' title="{esc(t)}"' if t else "")
            cells.append(f"<td{attr}>{esc(c)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def termination_html(term) -> str:
    """The termination as a coloured badge and its details."""
    from ..core.results import Termination
    t = Termination.coerce(term)
    parts = [f'<span class="badge {esc(t.status)}">{esc(t.status)}</span>']
    if t.reason:
        parts.append(f" {esc(t.reason)}")
    where = [f"component {t.component}" if t.component else "", f"port {t.port}" if t.port else "",
             f"at t = {t.time_s:g} s" if t.time_s is not None else ""]
    where = [w for w in where if w]
    if where:
        parts.append(f'<p class="note">{esc(", ".join(where))}</p>')
    return "".join(parts)


def metric_rows(metrics: dict) -> list[tuple[str, str, str, str]]:
    """(label, value, unit, key) of every scalar metric."""
    rows = []
    for k, v in metrics.items():
        if isinstance(v, bool) or not (isinstance(v, (int, float)) or v is None):
            continue
        label, unit = metric_label(k)
        rows.append((label, fmt(v), unit, k))
    return rows


def metrics_html(metrics: dict) -> str:
    """The headline metrics, then all of them in a collapsed table."""
    from .labels import HEADLINE
    rows = metric_rows(metrics)
    if not rows:
        return '<p class="note">No metrics.</p>'
    head = [r for k in HEADLINE for r in rows if r[3] == k]
    body = ""
    if head:
        body += table(["Metric", "Value", "Unit"], [r[:3] for r in head], num_cols=[1],
                      titles=[[f"key: {r[3]}", "", ""] for r in head])
    body += (f"<details{'' if head else ' open'}><summary>All metrics ({len(rows)})</summary>"
             + table(["Metric", "Value", "Unit"], [r[:3] for r in rows], num_cols=[1],
                     titles=[[f"key: {r[3]}", "", ""] for r in rows]) + "</details>")
    notes = metrics.get("notes") or []
    if notes:
        body += "<ul class=\"note\">" + "".join(f"<li>{esc(n)}</li>" for n in notes) + "</ul>"
    return body + '<p class="note">Hover a metric for its key in metrics.json.</p>'


def _short(v: Any, n: int = 6) -> str:
    if isinstance(v, (list, tuple)):
        if len(v) > n:
            return "[" + ", ".join(fmt(x) for x in v[:n]) + f", …] ({len(v)} values)"
        return "[" + ", ".join(fmt(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {_short(x, 3)}" for k, x in list(v.items())[:n]) + (
            ", …}" if len(v) > n else "}")
    return fmt(v)


def parameters_html(parameters: dict) -> str:
    """One collapsible table per component: parameter, value, unit."""
    if not parameters:
        return '<p class="note">No parameters recorded.</p>'
    out = []
    for comp, params in parameters.items():
        if not isinstance(params, dict):
            out.append(f"<p>{esc(comp)}: {esc(_short(params))}</p>")
            continue
        rows = []
        for k, v in params.items():
            rows.append((k, _short(v), split_unit_text(k) if isinstance(k, str) else ""))
        out.append(f"<details><summary>{esc(comp)} ({len(rows)})</summary>"
                   + table(["Parameter", "Value", "Unit (SI)"], rows) + "</details>")
    return "".join(out)


def _decimate(t: np.ndarray, y: np.ndarray, limit: int = MAX_POINTS):
    """At most ~``limit`` points, keeping each bucket's minimum and maximum (peaks stay visible): per bucket the
    first minimum and first maximum ignoring NaN (``np.nanargmin``/``nanargmax``), in time order, or the
    bucket's first point when it is all NaN.  Vectorised over the buckets (a loop of two numpy calls per bucket
    took seconds of every run's report)."""
    n = len(t)
    if n <= limit:
        return t, y
    nb = limit // 2
    edges = np.linspace(0, n, nb + 1).astype(int)
    a, lens = edges[:-1], np.diff(edges)
    keep = lens > 0
    a, lens = a[keep], lens[keep]
    cols = np.arange(int(lens.max()))
    inside = cols[None, :] < lens[:, None]
    seg = np.where(inside, np.asarray(y, dtype=float)[np.minimum(a[:, None] + cols[None, :], n - 1)], np.nan)
    nan = np.isnan(seg)
    lo = np.where(nan, np.inf, seg).argmin(axis=1)
    hi = np.where(nan, -np.inf, seg).argmax(axis=1)
    allnan = nan.all(axis=1)
    first = np.where(allnan, a, a + np.minimum(lo, hi))
    second = a + np.maximum(lo, hi)
    pairs = np.stack([first, second], axis=1)
    take = np.stack([np.ones_like(allnan), ~allnan & (lo != hi)], axis=1)
    idx = pairs[take]
    return t[idx], y[idx]


def signal_series(result, name: str):
    """(time, SI values, SI unit) of a signal, or None; ``__rate__X`` is the time derivative of X."""
    t = np.asarray(result.time_s, dtype=float)
    if name.startswith("__rate__"):
        base = name[len("__rate__"):]
        if base not in result.signals or len(t) < 2:
            return None
        unit = result.units.get(base, "")
        return t, np.gradient(np.asarray(result.signals[base], dtype=float), t), (unit + "/s" if unit else "1/s")
    if name not in result.signals:
        return None
    return t, np.asarray(result.signals[name], dtype=float), signal_unit(name, result.units)


def run_figure_spec(results: Sequence) -> list[tuple[str, list[tuple[str, list[str]]]]]:
    """The figures (title, rows) that apply to these results: the standard ones whose signals are there,
    else one figure of the first signals grouped by unit."""
    have = set()
    for r in results:
        have |= set(r.signals)
        have |= {"__rate__" + s for s in r.signals}
    figs = []
    for title, rows in RUN_FIGURES:
        rr = [(rt, [s for s in sigs if s in have]) for rt, sigs in rows]
        rr = [(rt, sigs) for rt, sigs in rr if sigs]
        if rr:
            figs.append((title, rr))
    if figs:
        return figs
    first = results[0]
    names = list(first.signals)[:12]
    groups: dict[str, list[str]] = {}
    for n in names:
        du = display_unit(signal_unit(n, first.units))[0]
        groups.setdefault(du, []).append(n)
    return [("Signals", [(QUANTITY.get(du, "Value"), sigs) for du, sigs in groups.items()])]


def time_figure(results: Sequence, labels: Sequence[str], rows: list[tuple[str, list[str]]]):
    """A Plotly figure: one row per (title, signals), shared time axis; several results overlaid."""
    from plotly.subplots import make_subplots
    import plotly.graph_objects as go
    palette = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"]
    dashes = ["solid", "dash", "dot", "dashdot"]
    fig = make_subplots(rows=len(rows), cols=1, shared_xaxes=True, vertical_spacing=0.06 if len(rows) > 1 else 0.1)
    multi = len(results) > 1
    colors: dict[str, str] = {}               # one colour per signal across the rows of a figure
    for _, sigs in rows:
        for s in sigs:
            colors.setdefault(s, palette[len(colors) % len(palette)])
    shown: set = set()
    for i, (rtitle, sigs) in enumerate(rows, start=1):
        du_row = None
        for j, s in enumerate(sigs):
            for k, (res, lab) in enumerate(zip(results, labels)):
                ser = signal_series(res, s)
                if ser is None:
                    continue
                t, y, unit = ser
                y, du = to_display(y, unit)
                du_row = du_row or du
                t, y = _decimate(t, y)
                t, y = t.astype(np.float32), y.astype(np.float32)   # half the size; 7 digits suffice on screen
                name, sym = signal_label(s)
                legend = f"{name} — {lab}" if multi else name
                extra = f"<br>thesis symbol: {sym}" if sym else ""
                color = palette[k % len(palette)] if multi else colors[s]
                dash = dashes[j % len(dashes)] if multi else ("dash" if s.startswith("bms.") or
                                                              s.startswith("cycle.") or "cmd" in s else "solid")
                fig.add_trace(go.Scatter(
                    x=t, y=y, mode="lines", name=legend, legendgroup=f"{s}|{k}", showlegend=(s, k) not in shown,
                    line={"width": 1.3, "color": color, "dash": dash},
                    hovertemplate=f"%{{y:.4g}} {du}<br>t = %{{x:.1f}} s<extra>{esc(legend)}<br>"
                                  f"<span style='font-size:10px'>{esc(s)}{esc(extra)}</span></extra>"),
                    row=i, col=1)
                shown.add((s, k))
        fig.update_yaxes(title_text=f"{rtitle} ({du_row})" if du_row and du_row != "-" else rtitle,
                         row=i, col=1, title_font={"size": 12})
    fig.update_xaxes(title_text="Time (s)", row=len(rows), col=1)
    fig.update_layout(height=170 + 190 * len(rows), margin={"l": 70, "r": 20, "t": 30, "b": 50},
                      hovermode="x unified" if not multi else "closest", template="plotly_white",
                      legend={"orientation": "h", "yanchor": "bottom", "y": 1.01, "x": 0, "font": {"size": 11}},
                      legend_tracegroupgap=4)
    return fig


def _meta_rows(meta: dict) -> list[tuple[str, str]]:
    keys = [("scenario", "Scenario"), ("engine", "Engine"), ("wall_s", "Wall time (s)"), ("seed", "Seed"),
            ("version", "shevsim version"), ("git_commit", "Source commit"), ("out", "Saved in")]
    rows = [(lab, fmt(meta[k])) for k, lab in keys if meta.get(k) not in (None, "")]
    rs = meta.get("resolved_scenario") or {}
    for k, lab in (("step_s", "Communication step (s)"), ("stop_s", "Stop time (s)"), ("method", "Master method")):
        if rs.get(k) is not None:
            rows.append((lab, fmt(rs[k])))
    return rows


# ------------------------------------------------------------------------------------------ run

def run_page(result, title: str | None = None) -> Page:
    """The report of one run."""
    name = str(result.meta.get("scenario", "run"))
    t = np.asarray(result.time_s)
    span = f"{t[0]:g}–{t[-1]:g} s, {len(t)} points" if len(t) else "no points"
    page = Page(title or f"Run report: {name}", f"{span}, {len(result.signals)} signals")
    page.section("Termination", termination_html(result.termination))
    page.section("Metrics", metrics_html(result.metrics))
    for ftitle, rows in run_figure_spec([result]):
        page.figure(time_figure([result], [name], rows), ftitle, time_axis=True,
                    note="Drag to zoom (all time figures follow), double-click to reset; hover for values. "
                         "Thesis symbols (Kim 2014) are given in the hover text.")
    page.section("Run", table(["", ""], _meta_rows(result.meta)))
    page.section("Parameters", parameters_html(result.parameters))
    return page


def run_report(result, title: str | None = None) -> str:
    """HTML text of the report of one run."""
    return run_page(result, title).render()


# ------------------------------------------------------------------------------------------ comparison

def compare_page(results: Sequence, labels: Sequence[str] | None = None, title: str | None = None) -> Page:
    """The report comparing runs: the metrics side by side, the figures overlaid, the parameters that differ."""
    from .labels import metric_label as _ml
    results = list(results)
    if labels is None:
        from ..core.results import run_labels
        labels = run_labels(results)
    labels = [str(x) for x in labels]
    page = Page(title or "Comparison of runs: " + ", ".join(labels), f"{len(results)} runs")
    page.section("Termination", table(["Run", "Termination"], [(lab, str(r.termination))
                                                                  for lab, r in zip(labels, results)]))
    keys: list[str] = []
    for r in results:
        for k, v in r.metrics.items():
            if k not in keys and (v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))):
                keys.append(k)
    rows, titles = [], []
    for k in keys:
        lab, unit = _ml(k)
        rows.append([lab, unit] + [fmt(r.metrics.get(k)) for r in results])
        titles.append([f"key: {k}"])
    from .labels import HEADLINE
    head = [i for k in HEADLINE for i, kk in enumerate(keys) if kk == k]
    body = table(["Metric", "Unit"] + labels, [rows[i] for i in head], num_cols=range(2, 2 + len(results)),
                 titles=[titles[i] for i in head]) if head else ""
    body += (f"<details{'' if head else ' open'}><summary>All metrics ({len(rows)})</summary>"
             + table(["Metric", "Unit"] + labels, rows, num_cols=range(2, 2 + len(results)), titles=titles)
             + "</details>")
    page.section("Metrics", body)
    for ftitle, frows in run_figure_spec(results):
        page.figure(time_figure(results, labels, frows), ftitle, time_axis=True,
                    note="One colour per run. Drag to zoom (all time figures follow), double-click to reset.")
    diff = []
    comps = []
    for r in results:
        comps += [c for c in r.parameters if c not in comps]
    for c in comps:
        names: list[str] = []
        for r in results:
            names += [k for k in (r.parameters.get(c) or {}) if k not in names]
        for k in names:
            vals = [(r.parameters.get(c) or {}).get(k) for r in results]
            if any(json.dumps(v, default=str) != json.dumps(vals[0], default=str) for v in vals[1:]):
                diff.append([f"{c}.{k}"] + [_short(v) for v in vals])
    page.section("Parameters that differ",
                 table(["Parameter"] + labels, diff) if diff else '<p class="note">None: the runs have the same '
                                                                  'parameters.</p>')
    return page


def compare_report(results: Sequence, labels: Sequence[str] | None = None, title: str | None = None) -> str:
    """HTML text of a comparison of runs."""
    return compare_page(results, labels, title).render()


# ------------------------------------------------------------------------------------------ studies

def _xy_figure(traces, xtitle: str, ytitle: str, height: int = 420):
    import plotly.graph_objects as go
    fig = go.Figure()
    for tr in traces:
        fig.add_trace(tr)
    fig.update_layout(template="plotly_white", height=height, margin={"l": 70, "r": 20, "t": 30, "b": 50},
                      xaxis_title=xtitle, yaxis_title=ytitle, legend={"orientation": "h", "y": 1.02, "yanchor": "bottom"})
    return fig


def _config_rows(d: dict, prefix: str = "") -> list[tuple[str, str]]:
    rows = []
    for k, v in d.items():
        if isinstance(v, dict):
            rows += _config_rows(v, f"{prefix}{k}.")
        else:
            rows.append((f"{prefix}{k}", _short(v, 10)))
    return rows


def _kw(x):
    return None if x is None else float(x) / 1e3


def study_page(summary: dict, tables: dict | None = None, title: str | None = None) -> Page:
    """The report of a study from its ``summary.json`` (and, for a power-rate map, its CSV tables:
    ``constant_limits``, ``exhaustive``, ``top_solutions``, ``ga_history`` as DataFrames)."""
    tables = tables or {}
    kind = summary.get("study", "study")
    page = Page(title or f"Study report: {kind.replace('_', ' ')}", str(summary.get("problem", "")))
    base = summary.get("baseline") or {}
    if kind == "tradeoff":
        _tradeoff_sections(page, summary, base)
    elif kind == "powerrate_map":
        _powerrate_map_sections(page, summary, tables, base)
    else:
        page.section("Summary", table(["Key", "Value"], _config_rows({k: v for k, v in summary.items()
                                                                          if k not in ("rows",)})))
    cfg = {k: summary[k] for k in ("config", "edges_w", "fe_loss_max_frac", "shevsim_version", "code_sha256",
                                   "performance") if k in summary}
    if cfg:
        page.section("Parameters", table(["Parameter", "Value"], _config_rows(cfg)))
    return page


def _tradeoff_sections(page: Page, summary: dict, base: dict) -> None:
    """Result, trade-off figures and run table of a constant-limit trade-off study."""
    import plotly.graph_objects as go
    rows = sorted(summary.get("rows", []), key=lambda r: r["rate_wps"])
    ok = [r for r in rows if not r.get("error")]
    x = [r["rate_wps"] / 1e3 for r in ok]
    best = summary.get("best_within_loss")
    lim = -100 * float(summary.get("fe_loss_max_frac", 0.0))
    fig = _xy_figure([
        go.Scatter(x=x, y=[r["fe_change_pct"] for r in ok], mode="lines+markers", name="Fuel economy change",
                   hovertemplate="%{y:.3f} % at %{x:g} kW/s<extra>fuel economy</extra>"),
        go.Scatter(x=x, y=[r["soot_change_pct"] for r in ok], mode="lines+markers", name="Soot change",
                   hovertemplate="%{y:.3f} % at %{x:g} kW/s<extra>soot</extra>"),
        go.Scatter(x=[min(x or [0]), max(x or [1])], y=[lim, lim], mode="lines", name="Accepted fuel-economy loss",
                   line={"dash": "dot", "color": "#555"}, hoverinfo="skip")],
        "Maximum engine-generator power rate (kW/s)", "Change from the baseline (%)")
    if best:
        fig.add_vline(x=best["rate_wps"] / 1e3, line_dash="dash", line_color="#888",
                      annotation_text=f"chosen: {best['rate_wps'] / 1e3:g} kW/s")
    page.section("Result", table(["", ""], [
        ("Baseline fuel economy (km/l)", fmt(base.get("fuel_economy_kmpl"))),
        ("Baseline soot (g/km)", fmt(base.get("soot_g_per_km"))),
        ("Accepted fuel-economy loss (%)", fmt(-lim)),
        ("Tightest rate within that loss (kW/s)", fmt(_kw(best["rate_wps"])) if best else "none"),
        ("Its soot change (%)", fmt(best["soot_change_pct"]) if best else "—"),
        ("Its fuel-economy change (%)", fmt(best["fe_change_pct"]) if best else "—")]))
    page.figure(fig, "Trade-off: fuel economy and soot against the power-rate limit",
                note="Each point is one run with a constant maximum engine-generator power rate "
                     "(dP_g/dt max in the thesis, Fig. A.2).")
    page.figure(_xy_figure([
        go.Scatter(x=[r["fuel_economy_kmpl"] for r in ok], y=[r["soot_g_per_km"] for r in ok],
                   mode="markers+text", text=[f"{v:g}" for v in x], textposition="top center",
                   name="Constant limit (kW/s)",
                   hovertemplate="%{x:.4g} km/l, %{y:.4g} g/km<extra>%{text} kW/s</extra>"),
        go.Scatter(x=[base.get("fuel_economy_kmpl")], y=[base.get("soot_g_per_km")], mode="markers",
                   marker={"symbol": "star", "size": 14, "color": "#222"}, name="Baseline")],
        "Fuel economy (km/l)", "Soot (g/km)"), "Soot against fuel economy")
    page.section("Runs", table(["Rate limit (kW/s)", "Fuel economy (km/l)", "Change (%)", "Soot (g/km)",
                                "Change (%)", "Error"],
                               [(fmt(r["rate_wps"] / 1e3), fmt(r["fuel_economy_kmpl"]), fmt(r["fe_change_pct"]),
                                 fmt(r["soot_g_per_km"]), fmt(r["soot_change_pct"]), r.get("error") or "")
                                for r in rows], num_cols=range(5)))


def _powerrate_map_sections(page: Page, summary: dict, tables: dict, base: dict) -> None:
    """GA history, trade-off cloud, chosen map and result table of a power-rate map study."""
    import plotly.graph_objects as go
    hist = (summary.get("ga") or {}).get("history") or []
    if hist:
        page.figure(_ga_history_figure(hist), "Genetic algorithm history",
                    note="Best objective: soot of the best map that keeps the fuel-economy loss within the limit.")
    traces = []
    for key, name, sym in (("exhaustive", "Exhaustive search", "circle"), ("top_solutions", "Best GA maps", "diamond"),
                           ("constant_limits", "Constant limits", "square")):
        df = tables.get(key)
        if df is not None and len(df):
            d = df[df["error"].fillna("") == ""] if "error" in df else df
            traces.append(go.Scatter(x=d["fuel_economy_kmpl"], y=d["soot_g_per_km"], mode="markers", name=name,
                                     marker={"symbol": sym, "size": 7, "opacity": 0.75},
                                     hovertemplate="%{x:.4g} km/l, %{y:.4g} g/km<extra>" + name + "</extra>"))
    bm = summary.get("best_map")
    if bm:
        traces.append(go.Scatter(x=[bm["fuel_economy_kmpl"]], y=[bm["soot_g_per_km"]], mode="markers",
                                 name="Chosen map", marker={"symbol": "star", "size": 16, "color": "#d62728"}))
    if base:
        traces.append(go.Scatter(x=[base.get("fuel_economy_kmpl")], y=[base.get("soot_g_per_km")], mode="markers",
                                 name="Baseline", marker={"symbol": "x", "size": 12, "color": "#222"}))
    if traces:
        page.figure(_xy_figure(traces, "Fuel economy (km/l)", "Soot (g/km)"), "Trade-off: soot against fuel economy")
    if bm and bm.get("edges_w"):
        e = bm["edges_w"]
        parts = [f"{e[i] / 1e3:g}–{e[i + 1] / 1e3:g} kW" for i in range(len(e) - 1)]
        bars = [go.Bar(x=parts, y=[r / 1e3 for r in bm["rates_wps"]], name="Chosen map",
                       hovertemplate="%{y:g} kW/s<extra>%{x}</extra>")]
        bc = summary.get("best_constant")
        if bc:
            bars.append(go.Scatter(x=parts, y=[bc["rate_wps"] / 1e3] * len(parts), mode="lines",
                                   name="Best constant limit", line={"dash": "dash"}))
        page.figure(_xy_figure(bars, "Engine-generator power (partition)", "Maximum power rate (kW/s)", 380),
                    "Chosen power-rate map",
                    note="The limit on the engine-generator power rate in each power partition "
                         "(the thesis' constraint map dP_g/dt max(P_g)).")
    res_rows = [("Baseline fuel economy (km/l)", fmt(base.get("fuel_economy_kmpl"))),
                ("Baseline soot (g/km)", fmt(base.get("soot_g_per_km")))]
    if bm:
        res_rows += [("Chosen map: fuel-economy change (%)", fmt(bm.get("fe_change_pct"))),
                     ("Chosen map: soot change (%)", fmt(bm.get("soot_change_pct")))]
    bc = summary.get("best_constant")
    if bc:
        res_rows += [("Best constant limit (kW/s)", fmt(bc["rate_wps"] / 1e3)),
                     ("Best constant limit: soot change (%)", fmt(bc.get("soot_change_pct")))]
    if summary.get("soot_reduction_ratio_map_vs_constant") is not None:
        res_rows.append(("Soot reduction, map / constant", fmt(summary["soot_reduction_ratio_map_vs_constant"])))
    page.parts.insert(0, f'<section id="result"><h2>Result</h2>{table(["", ""], res_rows)}</section>')


def _ga_history_figure(hist: list):
    """Best soot, feasible maps and evaluations per GA generation (two stacked panels)."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots
    fig = make_subplots(rows=2, cols=1, shared_xaxes=True, vertical_spacing=0.08)
    g = [h["generation"] for h in hist]
    fig.add_trace(go.Scatter(x=g, y=[h["best_objective"] for h in hist], mode="lines+markers",
                             name="Best soot (g/km)", hovertemplate="%{y:.5g} g/km<extra>generation %{x}</extra>"),
                  row=1, col=1)
    fig.add_trace(go.Scatter(x=g, y=[h["n_feasible"] for h in hist], mode="lines+markers",
                             name="Feasible maps in the population"), row=2, col=1)
    fig.add_trace(go.Scatter(x=g, y=[h["total_evaluations"] for h in hist], mode="lines+markers",
                             name="Evaluations so far"), row=2, col=1)
    ys = [h["best_objective"] for h in hist if finite(h["best_objective"])]
    if ys and max(ys) - min(ys) <= 1e-9 * max(abs(max(ys)), 1e-30):   # flat: Plotly would show +-1
        pad = 0.02 * abs(ys[0]) or 1.0
        fig.update_yaxes(range=[ys[0] - pad, ys[0] + pad], row=1, col=1)
    fig.update_yaxes(title_text="Best soot (g/km)", row=1, col=1)
    fig.update_yaxes(title_text="Count", row=2, col=1)
    fig.update_xaxes(title_text="Generation", row=2, col=1)
    fig.update_layout(template="plotly_white", height=520, margin={"l": 70, "r": 20, "t": 30, "b": 50})
    return fig


# ------------------------------------------------------------------------------------------ calibration

def _channel_axis(c: str) -> tuple[str, str, float, float]:
    """(label, display unit, factor, offset) of a calibration channel (``power_w``, ``voltage_v``...)."""
    from .labels import split_unit
    stem, unit = split_unit(c)
    du, f, o = display_unit(unit)
    label = {"power": "Power", "voltage": "Voltage", "t_surface": "Surface temperature", "speed": "Speed",
             "current": "Current", "fuel_rate": "Fuel rate", "soot_rate": "Soot rate"}.get(
        stem, stem.replace("_", " ").capitalize())
    return label, du, f, o


def calibration_page(rep: dict, traces=None, title: str | None = None) -> Page:
    """The report of a calibration from its ``report.json`` (and ``fit_traces.csv`` as a DataFrame with
    ``time_s``, ``holdout`` and per channel ``C_measured``, ``C_before``, ``C_after``)."""
    model = rep.get("model", "?")
    d = rep.get("data", {})
    page = Page(title or f"Calibration report: {model}",
                f"{d.get('path', '')} · {d.get('n_samples', '?')} samples, {fmt(d.get('duration_s'))} s")
    sel = rep.get("selected_effects") or []
    rows = []
    for c, b in (rep.get("rmse_before") or {}).items():
        a = rep["rmse_after"][c]
        lab, du, f, _ = _channel_axis(c)
        ch = a["holdout"] / b["holdout"] - 1 if b["holdout"] else float("nan")
        rows.append((f"{lab} ({du})", fmt(b["train"] * f), fmt(b["holdout"] * f), fmt(a["train"] * f),
                     fmt(a["holdout"] * f), f"{ch:+.1%}"))
    body = (f"<p><b>Selected effects: {esc(', '.join(sel))}</b></p>" if sel else
            "<p><b>Nothing found</b>: no candidate effect passed the selection rule.</p>")
    body += table(["Channel (unit)", "RMSE before, training", "before, held-out", "after, training",
                   "after, held-out", "Held-out change"], rows, num_cols=range(1, 6))
    if rep.get("not_identifiable"):
        body += f"<p>Not identifiable from this record: {esc(', '.join(rep['not_identifiable']))}</p>"
    dl = [x for x in rep.get("detection_limits") or [] if x.get("limit") is not None]
    if dl:
        g = (rep.get("detection_rule") or {}).get("min_holdout_gain", 0.1)
        body += (f"<p>What this record can detect, to first order (the smallest change of an effect not selected "
                 f"whose own signal would gain the rule's {g:.0%} held-out, the fitted parameters refitted beside "
                 f"it): " + esc("; ".join(f"{x['effect']} {x['parameter']} "
                                         + ("±" if x.get("limit_up") and x.get("limit_down")
                                            else "+" if x.get("limit_up") else "−")
                                         + f"{fmt(x['limit'])} {x['unit']}"
                                         + ("" if x.get("reachable", True) else " (beyond its plausible range)")
                                         for x in dl)) + "</p>")
    shp = rep.get("detection_shapes") or []
    if shp:
        body += ("<p>Effects with several knots: the rms change of the knots that would gain it, from the most to the "
                 "least visible shape: " + esc("; ".join(
                     f"{x['effect']} ({len(x['parameters'])} knots) {fmt(x['limit_rms_min'])} to "
                     + (fmt(x["limit_rms_max"]) if x["limit_rms_max"] != float("inf") else "never")
                     + f" {x['unit']}" for x in shp)) + "</p>")
    for n in d.get("notes") or []:
        body += f'<p class="note">note: {esc(n)}</p>'
    from .calibration_text import decimate_advice
    adv = decimate_advice(rep)
    if adv:
        body += f"<p><b>{esc(adv.replace('`', ''))}</b></p>"
    page.section("Result", body)
    chans = list((rep.get("rmse_before") or {}).keys())
    hold = (rep.get("split") or {}).get("holdout_intervals_s") or []
    if traces is not None and len(traces) and chans:
        t = traces["time_s"].to_numpy()
        for kind in ("fit", "residual"):
            fig = _fit_figure(traces, t, chans, hold, kind)
            page.figure(fig, "Fit before and after" if kind == "fit" else "Residuals before and after", time_axis=True,
                        note="Grey bands: held-out data (not used in the fit). Drag to zoom, double-click to reset.")
    else:
        page.section("Fit before and after", '<p class="note">This calibration folder has no fit_traces.csv '
                                              '(written by newer versions): see the PNG figures beside it.</p>')
    rounds = rep.get("rounds") or []
    if rounds:
        _evidence_sections(page, rep, rounds)
    from .calibration_text import BASELINE_COLUMN, baseline_values
    bv = baseline_values(rep)
    prm = [(k, "-" if bv[k][0] is None else fmt(bv[k][0]) + (" (nominal)" if bv[k][1] == "nominal" else ""),
            fmt(v), split_unit_text(k)) for k, v in (rep.get("final_parameters") or {}).items()]
    page.section("Parameters", table(["Parameter", "Baseline", "Final", "Unit (SI)"], prm, num_cols=[1, 2])
                 + f'<p class="note">Baseline column: {esc(BASELINE_COLUMN)}.</p>'
                 + (f'<p class="note">Use them with: <code>shevsim run SCENARIO --params '
                    f'{esc(rep["overlay"]["file"])}</code></p>' if rep.get("overlay") else ""))
    return page


def _fit_figure(traces, t, chans: list, hold: list, kind: str):
    """Measured and model channels before/after (``kind`` "fit") or their residuals ("residual"), one
    panel a channel, held-out intervals shaded."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots
    fig = make_subplots(rows=len(chans), cols=1, shared_xaxes=True, vertical_spacing=0.07)
    for i, c in enumerate(chans, start=1):
        lab, du, f, o = _channel_axis(c)
        if f"{c}_measured" not in traces:
            continue
        m = traces[f"{c}_measured"].to_numpy()
        b = traces[f"{c}_before"].to_numpy()
        a = traces[f"{c}_after"].to_numpy()
        if kind == "fit":
            series = [("Measured", m * f + o, "#222", "solid"), ("Model before", b * f + o, "#1f77b4", "solid"),
                      ("Model after", a * f + o, "#d62728", "dash")]
            ytitle = f"{lab} ({du})"
        else:
            series = [("Residual before (measured - model)", (m - b) * f, "#1f77b4", "solid"),
                      ("Residual after (measured - model)", (m - a) * f, "#d62728", "solid")]
            ytitle = f"{lab} residual ({du})"
        for name, y, col, dash in series:
            fig.add_trace(go.Scatter(x=t, y=y, mode="lines", name=name, legendgroup=name, showlegend=(i == 1),
                                     line={"width": 1.1, "color": col, "dash": dash},
                                     hovertemplate=f"%{{y:.4g}} {du}<br>t = %{{x:.1f}} s<extra>{esc(name)}</extra>"),
                          row=i, col=1)
        fig.update_yaxes(title_text=ytitle, row=i, col=1)
    for a0, b0 in hold:
        fig.add_vrect(x0=a0, x1=b0, fillcolor="#999", opacity=0.15, line_width=0, layer="below")
    fig.update_xaxes(title_text="Time (s)", row=len(chans), col=1)
    fig.update_layout(template="plotly_white", height=160 + 260 * len(chans),
                      margin={"l": 70, "r": 20, "t": 30, "b": 50},
                      legend={"orientation": "h", "y": 1.02, "yanchor": "bottom"}, hovermode="x unified")
    return fig


def _evidence_sections(page: Page, rep: dict, rounds: list) -> None:
    """The candidate effects of each selection round: score bars and the evidence table."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots
    fig = make_subplots(rows=len(rounds), cols=1, vertical_spacing=0.12,
                        subplot_titles=[f"Round {rd['round']}: on top of {', '.join(rd['on_top_of']) or 'the baseline'}"
                                        f" — selected {rd.get('selected') or 'none'}" for rd in rounds])
    n = 0
    for i, rd in enumerate(rounds, start=1):
        cs = sorted(rd["candidates"], key=lambda c: c["score"]) + rd.get("pairs", [])
        n += len(cs)
        fig.add_trace(go.Bar(y=[c["name"] for c in cs], x=[c["score"] for c in cs], orientation="h",
                             marker={"color": ["#2ca02c" if c["passed"] else "#b0b0b0" for c in cs]},
                             name=f"round {rd['round']}", showlegend=False,
                             customdata=[c["reason"] or "passes" for c in cs],
                             hovertemplate="score %{x:.3f}<br>%{customdata}<extra>%{y}</extra>"), row=i, col=1)
        fig.add_vline(x=rd["current_score"], line_color="#222", row=i, col=1)
        fig.update_xaxes(title_text="Held-out score (current model = its line; lower is better)", row=i, col=1)
    fig.update_layout(template="plotly_white", height=120 + 28 * n + 90 * len(rounds),
                      margin={"l": 150, "r": 20, "t": 40, "b": 50})
    page.figure(fig, "Evidence: candidate effects", note="Green: passes the selection rule. Hover a bar for "
                                                           "the reason.")
    ev = []
    for rd in rounds:
        for c in sorted(rd["candidates"], key=lambda c: c["score"]) + rd.get("pairs", []):
            own = {k: v for k, v in c["parameters"].items() if k not in rep.get("baseline_parameters", {})}
            ev.append((rd["round"], c["name"], fmt(c["score"], 3), f"{c['gain']:+.1%}", f"{c['delta_bic']:+.1f}",
                       ", ".join(f"{k} = {fmt(v)}" for k, v in own.items()),
                       "selected" if rd.get("selected") == c["name"] else (c.get("reason") or "passes")))
    r = rep.get("selection_rule") or {}
    rule = (f"Rule: held-out score gain ≥ {r.get('min_holdout_gain', 0):.0%}, no channel worse by more than "
            f"{r.get('max_channel_worsening', 0):.0%}, BIC drop ≥ {fmt(r.get('min_bic_drop'))}.") if r else ""
    page.section("Evidence table", f'<p class="note">{esc(rule)}</p>' + table(
        ["Round", "Effect", "Held-out score", "Gain", "ΔBIC", "Parameters", "Verdict"], ev, num_cols=[2, 3, 4]))


def split_unit_text(key: str) -> str:
    from .labels import split_unit
    u = split_unit(key)[1]
    return "" if u == "-" else u


def calibration_report(rep: dict, traces=None, title: str | None = None) -> str:
    return calibration_page(rep, traces, title).render()


def study_report(summary: dict, tables: dict | None = None, title: str | None = None) -> str:
    return study_page(summary, tables, title).render()


# ------------------------------------------------------------------------------------------ notebook snippets
# (no JavaScript: a notebook shows these inline; the full report is one call away)

def result_summary_html(result) -> str:
    """A short HTML summary of a result for a notebook: termination, key metrics, signals."""
    name = esc(result.meta.get("scenario", "run"))
    t = np.asarray(result.time_s)
    span = f"{t[0]:g}–{t[-1]:g} s, {len(t)} points" if len(t) else "no points"
    rows = metric_rows(result.metrics)
    sig = ", ".join(f"{esc(s)} [{esc(result.units.get(s, ''))}]" for s in result.signals)
    return (f"<div><b>Result</b> {name} · {esc(span)} · engine {esc(result.meta.get('engine', '?'))}<br>"
            f"{termination_html(result.termination)}"
            + (table(["Metric", "Value", "Unit"], [r[:3] for r in rows], num_cols=[1]) if rows else "")
            + f"<details><summary>{len(result.signals)} signals</summary><p style='font-size:12px'>{sig}</p></details>"
            "<p style='font-size:11px;color:#666'>res.plot() for a figure; shevsim.report.write_report(...) or "
            "res.save(out, plots=True) for the interactive HTML report</p></div>")


def scenario_html(sc) -> str:
    """A short HTML view of a scenario: settings, components, connections."""
    comps = [(c.name, c.type, str(c.fmu or c.params_file or ""), ", ".join(f"{k}={_short(v, 3)}"
                                                                              for k, v in c.overrides.items()))
             for c in sc.components]
    conns = [(f"{c.src}.{c.src_port}", "→", f"{c.dst}.{c.dst_port}") for c in sc.connections]
    head = (f"<b>Scenario</b> {esc(sc.name)} · step {fmt(sc.settings.step_s)} s · stop "
            f"{fmt(sc.stop_s) if sc.stop_s is not None else 'from the cycle'} · seed {esc(sc.seed)}")
    if sc.description:
        head += f"<br><span style='color:#555'>{esc(sc.description)}</span>"
    return (f"<div>{head}" + table(["Component", "Type", "Parameters / FMU", "Overrides"], comps)
            + f"<details><summary>{len(conns)} connections (source → input)</summary>"
            + table(["Source (output)", "", "Destination (input)"], conns) + "</details></div>")


def study_summary_html(summary: dict) -> str:
    """A short HTML view of a study summary (for a study result object's ``_repr_html_``)."""
    kind = summary.get("study", "study")
    base = summary.get("baseline") or {}
    rows = [("Study", kind), ("Problem", summary.get("problem", "")),
            ("Baseline fuel economy (km/l)", fmt(base.get("fuel_economy_kmpl"))),
            ("Baseline soot (g/km)", fmt(base.get("soot_g_per_km")))]
    best = summary.get("best_within_loss") or summary.get("best_map")
    if best:
        if "rate_wps" in best:
            rows.append(("Chosen rate limit (kW/s)", fmt(best["rate_wps"] / 1e3)))
        if "rates_wps" in best:
            rows.append(("Chosen map (kW/s)", _short([r / 1e3 for r in best["rates_wps"]], 12)))
        rows += [("Soot change (%)", fmt(best.get("soot_change_pct"))),
                 ("Fuel-economy change (%)", fmt(best.get("fe_change_pct")))]
    return f"<div>{table(['', ''], rows)}</div>"


def calibration_summary_html(rep: dict) -> str:
    """A short HTML view of a calibration report (for a calibration report object's ``_repr_html_``)."""
    sel = rep.get("selected_effects") or []
    rows = []
    for c, b in (rep.get("rmse_before") or {}).items():
        a = rep["rmse_after"][c]
        lab, du, f, _ = _channel_axis(c)
        rows.append((f"{lab} ({du})", fmt(b["holdout"] * f), fmt(a["holdout"] * f)))
    path = (rep.get("data") or {}).get("path")
    return (f"<div><b>Calibration</b> {esc(rep.get('model', '?'))}" + (f" on {esc(path)}" if path else "")
            + f": selected <b>{esc(', '.join(sel) or 'nothing')}</b>"
            + table(["Channel", "Held-out RMSE before", "after"], rows, num_cols=[1, 2]) + "</div>")


def finite(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)
