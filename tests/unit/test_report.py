"""HTML reports without a browser: what gets written where, plain labels and display units, the
``shevsim report`` command and its refusals (the rendering itself: tests/integration/test_report_browser.py)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import shevsim
from shevsim.cli import main
from shevsim.report import folder_kind, run_report, write_report
from shevsim.report.labels import display_unit, metric_label, signal_label, to_display

ROOT = Path(__file__).resolve().parents[2]
TWO_BODY = ROOT / "scenarios" / "verification" / "two_body.toml"


def test_display_units_and_plain_labels():
    y, u = to_display([200000.0, -50000.0], "W")
    assert u == "kW" and np.allclose(y, [200.0, -50.0])
    y, u = to_display([10.0], "m/s")
    assert u == "km/h" and np.allclose(y, [36.0])
    y, u = to_display([0.0], "K")
    assert u == "°C" and np.allclose(y, [-273.15])
    assert display_unit("rad/s")[0] == "rpm" and np.isclose(display_unit("rad/s")[1] * 2 * np.pi, 60.0)
    assert signal_label("bms.power_max_w") == ("Battery discharge limit (BMS)", "P_b,max")
    assert signal_label("motor.torque_max_nm")[0] == "Motor: torque max"          # any other signal: prettified
    assert metric_label("fuel_economy_raw_kmpl") == ("Fuel economy (raw)", "km/l")
    assert metric_label("soot_dsoc_corrected_g_per_km")[1] == "g/km"
    assert metric_label("soc_sustained_windows_count")[0] == "SOC sustained windows"


def test_cli_run_writes_report_beside_overview_and_report_command_rewrites_it(tmp_path, capsys):
    out = tmp_path / "tb"
    assert main(["run", str(TWO_BODY), "-o", str(out), "-q", "--set", "scenario.stop_s=1.0"]) == 0
    html = (out / "report.html").read_text()
    assert (out / "overview.png").stat().st_size > 1000
    assert '<meta name="generator" content="shevsim' in html and "two_body" in html
    assert "report.html" in json.loads((out / "run.json").read_text())["files"]   # replaced by a re-run only
    assert '<meta name="shevsim-figures" content="1">' in html   # one figure (signals grouped by unit) for this scenario
    (out / "report.html").unlink()
    assert main(["report", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out and folder_kind(out) == "run"
    assert (out / "report.html").read_text().count("Plotly.newPlot") == 1
    assert main(["run", str(TWO_BODY), "-o", str(tmp_path / "np"), "-q", "--no-plots",
                 "--set", "scenario.stop_s=0.5"]) == 0
    assert not (tmp_path / "np" / "report.html").exists()


def test_report_command_refusals(tmp_path, capsys):
    assert main(["report", str(tmp_path / "missing")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["report", str(tmp_path / "empty")]) == 2
    assert "holds no shevsim outputs (expected run.json" in capsys.readouterr().err
    res = shevsim.simulate(TWO_BODY, stop_s=0.5)
    res.save(tmp_path / "r")
    mine = tmp_path / "r" / "report.html"
    mine.write_text("<html>my own notes</html>")
    assert main(["report", str(tmp_path / "r")]) == 2
    assert "was not written by shevsim: not replaced" in capsys.readouterr().err
    assert mine.read_text() == "<html>my own notes</html>"                  # nothing a user wrote is touched
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "summary.json").write_text(json.dumps({"study": "tradeoff", "rows": []}))
    assert main(["report", str(tmp_path / "r"), str(tmp_path / "s"), "-o", str(tmp_path / "c.html")]) == 2
    assert "a comparison takes run folders only" in capsys.readouterr().err


def test_comparison_of_saved_runs_labels_them_apart(tmp_path):
    a = shevsim.simulate(TWO_BODY, stop_s=0.5, out=tmp_path / "a")
    b = shevsim.simulate(TWO_BODY, {"coupling.damping_ns_per_m": 3.0}, stop_s=0.5, out=tmp_path / "b")
    path = write_report([tmp_path / "a", tmp_path / "b"], out=tmp_path / "cmp.html")
    html = path.read_text()
    assert "two_body (coupling.damping_ns_per_m=0.5)" in html and "two_body (coupling.damping_ns_per_m=3)" in html
    assert "Parameters that differ" in html
    assert a.termination.ok and b.termination.ok


def test_run_report_of_a_stopped_run_shows_why(tmp_path):
    res = shevsim.simulate(TWO_BODY, stop_s=0.5)
    from shevsim.core.results import Termination
    res.termination = Termination("stopped", "non-finite value", "body1", "position_m", 0.25)
    html = run_report(res)
    assert 'class="badge stopped"' in html and "non-finite value" in html and "at t = 0.25 s" in html


def test_write_html_from_results_in_memory(tmp_path):
    from shevsim.report import write_html
    a = shevsim.simulate(TWO_BODY, stop_s=0.5)
    b = shevsim.simulate(TWO_BODY, {"coupling.damping_ns_per_m": 3.0}, stop_s=0.5)
    one = write_html(a, tmp_path / "a.html").read_text()
    assert "Run report: two_body" in one
    two = write_html([a, b], tmp_path / "ab.html", labels=["soft", "stiff"]).read_text()
    assert "Comparison of runs: soft, stiff" in two
    with pytest.raises(shevsim.ShevsimError, match="give a Result"):
        write_html([], tmp_path / "x.html")
