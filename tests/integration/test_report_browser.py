"""The HTML reports open in a real headless Chromium (the system's, driven by Playwright): no console error,
the expected number of Plotly figures render with their traces, hover text carries display units, and the
time figures of a page zoom together. Screenshots go to ``results/report_screenshots/`` for review by eye.

Chromium comes from the system packages (``.ci/run`` installs Debian's ``chromium``); Playwright is told to
use it (``executable_path``) and never downloads a browser of its own. Without a local Chromium the test
skips and says so.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

import shevsim
from shevsim.report import write_report

ROOT = Path(__file__).resolve().parents[2]
SHOTS = ROOT / "results" / "report_screenshots"


def _chromium() -> str | None:
    for name in (os.environ.get("SHEVSIM_CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


CHROMIUM = _chromium()
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium installed locally (apt-get install chromium; "
                                                           ".ci/run installs it)")


@pytest.fixture(scope="module")
def browser():
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright not installed (pip install shevsim[dev])")
    import subprocess
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox", "--disable-gpu"])
        system = subprocess.run([CHROMIUM, "--version"], capture_output=True, text=True, timeout=60).stdout
        assert b.version in system, (b.version, system)          # the system's browser, not a downloaded one
        yield b
        b.close()


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """One folder of each kind, written by the same code paths as the command line."""
    from shevsim.calibrate.cli import main_calibrate
    from shevsim.calibrate.synthetic import synth_vehicle
    from shevsim.studies.cli import main_study
    tmp = tmp_path_factory.mktemp("reports")
    out = {}
    rule = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1}, stop_s=150.0, engine="python",
                            out=tmp / "run_rule", plots=True)
    heavy = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1, "vehicle.mass_kg": 20000.0}, stop_s=150.0,
                             engine="python", out=tmp / "run_heavy", plots=True)
    out["run"] = tmp / "run_rule" / "report.html"
    out["compare"] = write_report([tmp / "run_rule", tmp / "run_heavy"], out=tmp / "comparison.html")
    assert main_study(["tradeoff", "--synthetic", "--workers", "0", "--quiet", "--rates-kwps", "30", "20", "10", "5",
                       "-o", str(tmp / "tradeoff")]) == 0
    out["tradeoff"] = tmp / "tradeoff" / "report.html"
    assert main_study(["powerrate-map", "--synthetic", "--workers", "0", "--quiet", "--generations", "3",
                       "--population", "8", "-o", str(tmp / "map")]) == 0
    out["powerrate_map"] = tmp / "map" / "report.html"
    df, _ = synth_vehicle({"regen_limit": {}}, seed=7, duration_s=600.0)
    df.to_csv(tmp / "veh.csv", index=False)
    assert main_calibrate(["vehicle", str(tmp / "veh.csv"), "--out", str(tmp / "cal"), "-q"]) == 0
    out["calibration"] = tmp / "cal" / "report.html"
    out["_results"] = (rule, heavy)
    return out


#: kind -> (figures the page must render, text that must be on it)
EXPECTED = {
    "run": (4, ["Speed (km/h)", "Power (kW)", "State of charge (%)", "Cell temperature (°C)", "Time (s)"]),
    "compare": (4, ["Speed (km/h)", "vehicle.mass_kg", "Parameters that differ"]),
    "tradeoff": (2, ["Maximum engine-generator power rate (kW/s)", "Soot (g/km)"]),
    "powerrate_map": (3, ["Generation", "Maximum power rate (kW/s)", "Fuel economy (km/l)"]),
    "calibration": (3, ["Power (kW)", "Power residual (kW)", "Evidence table", "regen_limit"]),
}


def _open(browser, path: Path):
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    errors: list[str] = []
    page.on("console", lambda m: errors.append(f"console {m.type}: {m.text}") if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
    page.on("requestfailed", lambda r: errors.append(f"request failed: {r.url}"))
    # self-contained: the page itself is the only thing loaded (no CDN, no font, no image from elsewhere)
    page.on("request", lambda r: errors.append(f"fetched: {r.url[:80]}")
            if not r.url.startswith(("file://", "data:", "blob:")) else None)
    page.goto(path.resolve().as_uri())
    page.wait_for_function("document.querySelectorAll('.js-plotly-plot').length > 0 && "
                           "Array.from(document.querySelectorAll('.js-plotly-plot')).every(d => d._fullLayout)",
                           timeout=60000)
    return page, errors


@pytest.mark.parametrize("kind", list(EXPECTED))
def test_report_renders_in_headless_chromium(browser, reports, kind):
    path = reports[kind]
    n_expected, texts = EXPECTED[kind]
    assert path.is_file()
    assert path.read_text().count("<script") >= 2 + n_expected      # Plotly inline, one per figure, the zoom link
    page, errors = _open(browser, path)
    try:
        n = page.evaluate("document.querySelectorAll('.js-plotly-plot').length")
        declared = page.evaluate("document.querySelector('meta[name=shevsim-figures]').content")
        traces = page.evaluate("Array.from(document.querySelectorAll('.js-plotly-plot'))"
                               ".map(d => d.querySelectorAll('g.trace').length)")
        body = page.inner_text("body")
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / f"{kind}.png"), full_page=True)
    finally:
        page.close()
    assert errors == []
    assert n == n_expected == int(declared), (n, n_expected, declared)
    assert all(t > 0 for t in traces), traces            # every figure drew its traces
    for text in texts:
        assert text in body, text
    if kind in ("run", "compare"):
        assert "P_b" not in body and "dP_g" not in body     # thesis symbols only in the hover text


def test_run_report_hover_shows_display_units_and_time_figures_zoom_together(browser, reports):
    page, errors = _open(browser, reports["run"])
    try:
        figs = page.query_selector_all(".shevsim-time .js-plotly-plot")
        assert len(figs) == 4
        # zoom the first time figure to 40-60 s: the others follow (the page's linked time axes)
        page.evaluate("Plotly.relayout(document.querySelectorAll('.shevsim-time .js-plotly-plot')[0], "
                      "{'xaxis.range[0]': 40, 'xaxis.range[1]': 60})")
        page.wait_for_timeout(500)
        ranges = page.evaluate("Array.from(document.querySelectorAll('.shevsim-time .js-plotly-plot'))"
                               ".map(d => d._fullLayout.xaxis.range)")
        # hover over the middle of the speed plot: the unified hover label names km/h
        figs[0].scroll_into_view_if_needed()
        box = figs[0].query_selector(".nsewdrag").bounding_box()
        page.mouse.move(box["x"] + box["width"] * 0.5, box["y"] + box["height"] * 0.5)
        page.wait_for_timeout(400)
        hover = page.evaluate("Array.from(document.querySelectorAll('.hoverlayer')).map(h => h.textContent).join(' ')")
    finally:
        page.close()
    assert errors == []
    for r in ranges:
        assert r == pytest.approx([40, 60], abs=1e-6), ranges
    assert "km/h" in hover, hover


def test_run_report_values_are_the_result_in_display_units(browser, reports):
    """The speed trace on the page is the simulated speed in km/h (read back from the rendered figure)."""
    rule = reports["_results"][0]
    page, errors = _open(browser, reports["run"])
    try:
        data = page.evaluate("""(() => { const d = document.querySelectorAll('.shevsim-time .js-plotly-plot')[0];
            const t = d._fullData.find(t => t.name === 'Vehicle speed');
            return {x: Array.from(t.x), y: Array.from(t.y)}; })()""")
    finally:
        page.close()
    assert errors == []
    np.testing.assert_allclose(data["x"], rule.time_s, rtol=1e-6)
    np.testing.assert_allclose(data["y"], 3.6 * rule["vehicle.speed_mps"], rtol=1e-6, atol=1e-5)


def test_reports_carry_metrics_termination_and_parameters(reports):
    html = reports["run"].read_text()
    m = json.loads((reports["run"].parent / "metrics.json").read_text())
    assert "Termination" in html and "completed" in html
    assert f"{m['distance_km']:.4g}" in html and "Distance" in html
    assert "Parameters" in html and "mass_kg" in html
    size = reports["run"].stat().st_size
    assert 4e6 < size < 20e6, size           # Plotly's JavaScript inside (~4.8 MB) plus the data
