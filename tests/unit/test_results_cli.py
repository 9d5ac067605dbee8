"""Results saving (atomic), loading, and the CLI on the verification scenario."""
import json
from pathlib import Path

import numpy as np
import pytest

from shevsim.cli import main
from shevsim.core.results import load_result, save_result
from shevsim.run import run_scenario

ROOT = Path(__file__).resolve().parents[2]
TWO_BODY = ROOT / "scenarios" / "verification" / "two_body.toml"


def test_run_saves_everything(tmp_path):
    res, metrics, out = run_scenario(TWO_BODY, tmp_path / "tb", plots=True)
    for f in ("timeseries.parquet", "run.json", "metrics.json", "scenario.toml", "overview.png"):
        assert (out / f).exists(), f
    meta = json.loads((out / "run.json").read_text())
    assert meta["scenario"] == "two_body" and meta["seed"] == 0 and meta["version"]
    assert meta["units"]["body1.position_m"] == "m"
    back = load_result(out)
    np.testing.assert_array_equal(back["body1.position_m"], res["body1.position_m"])


def test_crash_while_plotting_leaves_no_half_figure_nor_temp_folder(tmp_path):
    # (the run itself is saved, then the error raised: tests/unit/test_termination.py)
    res, _, out = run_scenario(TWO_BODY, tmp_path / "tb", plots=False)
    before = (out / "timeseries.parquet").read_bytes()

    def boom(result, folder):
        (folder / "partial.png").write_text("half")
        raise RuntimeError("disk full")
    with pytest.raises(RuntimeError, match="disk full"):
        save_result(res, out, plots=boom)
    assert (out / "timeseries.parquet").read_bytes() == before
    assert not (out / "partial.png").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".tb")]


def test_cli_run_and_info(tmp_path, capsys):
    assert main(["run", str(TWO_BODY), "--out", str(tmp_path / "o"), "--no-plots", "--quiet",
                 "--set", "coupling.damping_ns_per_m=1.0"]) == 0
    assert (tmp_path / "o" / "metrics.json").exists()
    assert main(["info", str(TWO_BODY)]) == 0
    out = capsys.readouterr().out
    assert "body1" in out and "force_n" in out and "[N]" in out and "feedthrough" in out


def test_cli_reports_errors_cleanly(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[scenario]\nstep_s = -1\n[components.a]\ntype='gain'\n")
    assert main(["run", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "step_s must be a positive number" in err


# --------------------------------------------------------------- bug hunt (core), 2026-11-22
def test_out_that_is_a_file_or_a_foreign_folder_is_not_replaced(tmp_path):
    from shevsim.core.errors import ShevsimError
    f = tmp_path / "notes.txt"
    f.write_text("precious")
    with pytest.raises(ShevsimError, match=r"notes.txt.*not a folder"):
        run_scenario(TWO_BODY, f, plots=False)
    assert f.read_text() == "precious"
    d = tmp_path / "thesis"
    d.mkdir()
    (d / "thesis.tex").write_text("x")
    with pytest.raises(ShevsimError, match=r"thesis.*not a shevsim result"):
        run_scenario(TWO_BODY, d, plots=False)
    assert (d / "thesis.tex").read_text() == "x"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "thesis"]
    # an empty folder and a previous result are fine
    e = tmp_path / "empty"
    e.mkdir()
    run_scenario(TWO_BODY, e, plots=False)
    run_scenario(TWO_BODY, e, plots=False)
    assert (e / "run.json").exists()


def test_saved_scenario_records_t0_and_order(tmp_path):
    text = TWO_BODY.read_text().replace("stop_s = 10.0", "stop_s = 1.0\nt0_s = 0.5\norder = [\"body1\", \"coupling\"]")
    p = tmp_path / "tb.toml"
    p.write_text(text)
    res, _, out = run_scenario(p, tmp_path / "o", plots=False)
    rs = load_result(out).meta["resolved_scenario"]
    assert rs["t0_s"] == 0.5 and rs["order"] == ["body1", "coupling"]
    assert res.time_s[0] == 0.5


def test_plots_leave_the_callers_matplotlib_backend_and_figures_alone(tmp_path):
    # a notebook user's backend (and open figures) must survive run_scenario(..., plots=True) and Result.plot
    import matplotlib
    import matplotlib.pyplot as plt
    before = matplotlib.get_backend()
    try:
        plt.switch_backend("svg")
        fig = plt.figure()
        res, _, out = run_scenario(TWO_BODY, tmp_path / "tb", plots=True)
        assert (out / "overview.png").stat().st_size > 1000
        res.plot(["body1.position_m"])
        assert matplotlib.get_backend() == "svg"
        assert plt.fignum_exists(fig.number)
    finally:
        plt.close("all")
        plt.switch_backend(before)


def test_saved_result_folder_has_the_usual_permissions(tmp_path):
    # mkdtemp makes the temporary folder 0700; once renamed into place it must be readable like any folder
    import os
    umask = os.umask(0)
    os.umask(umask)
    _, _, out = run_scenario(TWO_BODY, tmp_path / "tb", plots=False)
    assert (out.stat().st_mode & 0o777) == (0o777 & ~umask)


def test_info_shows_start_time_and_when_an_off_grid_fault_acts(tmp_path, capsys):
    text = TWO_BODY.read_text().replace("stop_s = 10.0", "stop_s = 1.0\nt0_s = 0.5") + \
        '\n[[faults]]\nat_s = 0.655\nport = "body1.force_n"\nvalue = 0.0\n'
    p = tmp_path / "tb.toml"
    p.write_text(text)
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    assert "start 0.5 s" in out
    assert "at 0.655 s: body1.force_n = 0.0 (acts from the communication point 0.66 s)" in out


def test_cli_output_into_a_closed_pipe_is_quiet(tmp_path):
    # `shevsim info X | head -1`: no BrokenPipeError traceback
    import subprocess
    import sys
    p = subprocess.Popen([sys.executable, "-c", "import sys; from shevsim.cli import main; sys.exit(main())",
                          "info", str(TWO_BODY)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()                    # the reader is gone before anything is written
    err = p.stderr.read().decode()
    p.wait(timeout=60)
    assert "Traceback" not in err and "BrokenPipe" not in err, err


def test_saved_scenario_records_the_command_line_overrides(tmp_path):
    # the folder's scenario.toml is "the scenario as run": --set overrides must not be lost
    _, _, out = run_scenario(TWO_BODY, tmp_path / "o", sets=["coupling.damping_ns_per_m=1.0"], plots=False)
    text = (out / "scenario.toml").read_text()
    assert "--set coupling.damping_ns_per_m=1.0" in text
    assert json.loads((out / "run.json").read_text())["sets"] == ["coupling.damping_ns_per_m=1.0"]
    import tomllib
    assert tomllib.loads(text) == tomllib.loads(TWO_BODY.read_text())     # still the same TOML document
