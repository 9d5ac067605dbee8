"""Runs never lose their results (issue 12 item 4, issue 13 items 4-6): stopped runs keep and save their
trajectory with the termination (reason, component, port, time) and exit non-zero; metrics that cannot be
computed are null with a note; --out is checked before running and never loses a user's file; runs far
beyond the machine are refused before they start; a trace miss is 'degraded'."""
import json
import os
import pickle
from pathlib import Path

import numpy as np
import pytest

import shevsim
from shevsim.cli import main
from shevsim.core.errors import ScenarioError, SimulationError
from shevsim.core.results import Termination, load_result

ROOT = Path(__file__).resolve().parents[2]
TWO_BODY = ROOT / "scenarios" / "verification" / "two_body.toml"


def _cycle(path, speeds, dt=1.0):
    path.write_text("time_s,speed_mps\n" + "".join(f"{i * dt:g},{v:g}\n" for i, v in enumerate(speeds)))
    return path


def test_termination_is_a_string_with_details_and_pickles():
    t = Termination("stopped", "boom", "battery", "soc_pct", 12.5)
    assert t == "stopped: boom" and t.status == "stopped" and not t.ok and t.time_s == 12.5
    u = pickle.loads(pickle.dumps(t))
    assert u == t and u.component == "battery" and u.port == "soc_pct"
    assert Termination.coerce("error: x").status == "stopped"
    assert Termination.coerce("completed").ok
    with pytest.raises(ValueError):
        Termination("finished")


def test_idle_cycle_metrics_are_null_with_a_note(tmp_path):
    # the vehicle never moves: per-distance metrics are undefined (was ZeroDivisionError in metrics.py)
    cyc = _cycle(tmp_path / "idle.csv", [0.0] * 61)
    res = shevsim.simulate("hd_udds_rule", {"cycle.cycle_file": str(cyc), "cycle.repeat": 1},
                           out=tmp_path / "o")
    assert res.termination == "completed"
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert m["distance_km"] == 0.0
    assert m["fuel_consumption_dsoc_corrected_l_per_100km"] is None
    assert any("did not move" in n for n in m["notes"])


def test_plant_limit_stop_keeps_the_trajectory_and_exits_1(tmp_path, capsys):
    # a tiny pack charged hard by the generator leaves SOC [0, 100] %: the run stops at the plant limit
    stops = {}
    for engine in ("python", "auto"):   # auto: the compiled fast path when eligible; same stop expected
        out = tmp_path / engine
        code = main(["run", "hd_udds_rule", "-o", str(out), "-q", "--no-plots", "-s", "cycle.repeat=1", "--engine",
                     engine, "-s", "battery.soc_init_pct=3", "-s", "battery.capacity_ah=0.05",
                     "-s", 'bms.own=["capacity_ah"]'])   # the BMS keeps its own (A123) capacity (issue 25)
        assert code == 1
        err = capsys.readouterr().err
        assert "stopped" in err and "component battery" in err and str(out) in err
        res = load_result(out)
        term = res.termination
        assert term.status == "stopped" and term.component == "battery" and "SOC left" in term.reason
        if engine == "python":              # the component's message names the port (soc_pct=...)
            assert term.port == "soc_pct"
        assert 0 < term.time_s < 1060 and res.time_s[-1] == pytest.approx(term.time_s)
        assert len(res) > 100 and np.all(np.isfinite(res["battery.soc_pct"]))
        assert json.loads((out / "metrics.json").read_text())["notes"][0].startswith("the run did not complete")
        stops[engine] = (len(res), term.time_s, res["battery.soc_pct"][-1])
    assert stops["python"] == pytest.approx(stops["auto"], rel=1e-9)


def _unstable_lag():
    # explicit first-order lag x += h g (u - x) with h g = 1000: |1 - h g| > 1, the iterate grows x999 a step
    sc = shevsim.new_scenario("unstable", step_s=0.1, stop_s=100.0)
    sc.add_component("lag", "trivial", set={"gain": 1e4}, start={"in0_1": 1.0})
    return sc


def test_non_finite_output_stops_with_component_port_and_time(tmp_path):
    res = shevsim.simulate(_unstable_lag(), out=tmp_path / "o")
    t = res.termination
    assert t.status == "stopped" and t.component == "lag" and t.port == "out0_1"
    # 999^k overflows a double (1.8e308) after ~103 steps: the stop is there, not at the end
    assert 9.0 < t.time_s < 12.0 and res.time_s[-1] == pytest.approx(t.time_s - 0.1)
    assert np.all(np.isfinite(res["lag.out0_1"])) and abs(res["lag.out0_1"][-1]) > 1e290
    assert load_result(tmp_path / "o").termination.port == "out0_1"
    # the low-level function raises (studies rely on it) with the partial result attached
    from shevsim.run import simulate as low
    with pytest.raises(SimulationError) as ei:
        low(_unstable_lag())
    assert ei.value.result.termination.status == "stopped" and len(ei.value.result) == len(res)


def test_ctrl_c_saves_what_was_simulated_and_exits_130(tmp_path, monkeypatch, capsys):
    from shevsim.components.verification import SpringDamper
    orig = SpringDamper.do_step

    def do_step(self, t, h):
        if t >= 2.0:
            raise KeyboardInterrupt
        return orig(self, t, h)
    monkeypatch.setattr(SpringDamper, "do_step", do_step)
    out = tmp_path / "o"
    assert main(["run", str(TWO_BODY), "-o", str(out), "-q", "--no-plots"]) == 130
    assert "interrupted" in capsys.readouterr().err
    res = load_result(out)
    assert res.termination.status == "stopped" and "interrupted" in res.termination.reason
    assert res.time_s[-1] == pytest.approx(2.0) and len(res) == 201


def test_unwritable_or_foreign_out_is_refused_before_running(tmp_path, monkeypatch, capsys):
    import shevsim.run as run_mod
    called = []
    monkeypatch.setattr(run_mod, "build_master", lambda sc: called.append(1))
    f = tmp_path / "file.txt"
    f.write_text("mine")
    for out in (f / "sub", f):      # under a file (cannot be created), a file
        assert main(["run", str(TWO_BODY), "-o", str(out), "-q"]) == 2
    d = tmp_path / "thesis"
    d.mkdir()
    (d / "thesis.tex").write_text("x")
    assert main(["run", str(TWO_BODY), "-o", str(d), "-q"]) == 2
    err = capsys.readouterr().err
    assert "cannot be created" in err and "not a folder" in err and "not a shevsim result" in err
    assert not called and f.read_text() == "mine" and (d / "thesis.tex").read_text() == "x"


def test_rerun_replaces_only_its_own_files_and_cleans_stale_temp(tmp_path):
    out = tmp_path / "o"
    shevsim.simulate(TWO_BODY, stop_s=0.5, out=out, plots=True)
    assert (out / "overview.png").is_file()
    (out / "notes.ipynb").write_text("{}")                      # the user's notebook in the result folder
    stale = tmp_path / ".o.tmp-p999999999-abcd"                  # a killed run's temporary folder
    stale.mkdir()
    (stale / "timeseries.parquet").write_bytes(b"x" * 100)
    live = tmp_path / f".o.tmp-p{os.getpid()}-live"              # a running process's: kept
    live.mkdir()
    shevsim.simulate(TWO_BODY, stop_s=0.3, out=out)              # no plots this time
    assert (out / "notes.ipynb").read_text() == "{}"
    assert not (out / "overview.png").exists()                   # ours, not written again: removed
    assert load_result(out).time_s[-1] == pytest.approx(0.3)
    assert not stale.exists() and live.exists()
    assert sorted(json.loads((out / "run.json").read_text())["files"]) == \
        ["metrics.json", "run.json", "scenario.toml", "timeseries.parquet"]


def test_plot_failure_saves_the_run_then_reports(tmp_path):
    from shevsim.core.results import save_result
    res = shevsim.simulate(TWO_BODY, stop_s=0.2)

    def boom(result, folder):
        (folder / "partial.png").write_text("half")
        raise RuntimeError("disk full")
    with pytest.raises(RuntimeError, match="disk full") as ei:
        save_result(res, tmp_path / "o", plots=boom)
    assert any("without figures" in n for n in ei.value.__notes__)
    back = load_result(tmp_path / "o")
    np.testing.assert_array_equal(back["body1.position_m"], res["body1.position_m"])
    assert not (tmp_path / "o" / "partial.png").exists()
    assert "disk full" in json.loads((tmp_path / "o" / "run.json").read_text())["plot_error"]


def test_run_far_beyond_the_machine_is_refused_with_the_estimate(tmp_path):
    from shevsim.run import check_run_size
    with pytest.raises(ScenarioError, match=r"refused before starting.*GB.*--allow-large"):
        shevsim.simulate(TWO_BODY, stop_s=1e9)
    # memory bound from the estimate against the memory available (given here, not this machine's)
    with pytest.raises(ScenarioError, match=r"needs ~0\.0024 GB .* 0\.001 GB are available"):
        check_run_size(10_000, 9, memory_bytes=1_000_000)
    assert check_run_size(10_000, 9, memory_bytes=1_000_000, allow_large=True)["rows"] == 10_002
    assert check_run_size(10_000, 9, record_every=100, memory_bytes=1_000_000)["rows"] == 102


def test_fault_after_the_end_is_an_error(tmp_path):
    p = tmp_path / "tb.toml"
    p.write_text(TWO_BODY.read_text() + '\n[[faults]]\nat_s = 12.0\nport = "body1.force_n"\nvalue = 0.0\n')
    with pytest.raises(ScenarioError, match=r"\[\[faults\]\] #1 at_s = 12.0 s .*never act"):
        shevsim.simulate(p)
    shevsim.simulate(p, stop_s=12.5)                    # acts within a longer run


def test_dotted_or_reserved_component_name_is_refused_at_load(tmp_path):
    for name in ('"a.b"', "scenario"):
        p = tmp_path / "s.toml"
        p.write_text(f'[scenario]\nstop_s = 1.0\n[components.{name}]\ntype = "gain"\n')
        with pytest.raises(ScenarioError, match=r"s.toml: \[components\.(a\.b|scenario)\]: component name"):
            shevsim.load_scenario(p)


def test_trace_miss_is_degraded_unless_allowed(tmp_path, capsys):
    # a cycle the vehicle cannot follow (162 km/h for a minute, reached at 1.5 m/s^2): it reaches its
    # stop time but misses the trace
    speeds = [min(1.5 * i, 45.0) for i in range(31)] + [45.0] * 60 + [max(45.0 - 1.5 * i, 0.0) for i in range(1, 31)]
    cyc = _cycle(tmp_path / "fast.csv", speeds)
    sets = ["-s", f"cycle.cycle_file={cyc}", "-s", "cycle.repeat=1", "-q", "--no-plots"]
    assert main(["run", "hd_udds_rule", "-o", str(tmp_path / "a"), *sets]) == 1
    assert "degraded" in capsys.readouterr().err
    t = load_result(tmp_path / "a").termination
    assert t.status == "degraded" and "trace miss" in t.reason and t.component == "vehicle"
    assert main(["run", "hd_udds_rule", "-o", str(tmp_path / "b"), *sets,
                 "-s", "metrics.trace_allow_miss=true"]) == 0
    # a partial record does not hide the miss: the trace signals are recorded too
    assert main(["run", "hd_udds_rule", "-o", str(tmp_path / "c"), *sets,
                 "--record", "battery.soc_pct", "vehicle.distance_m"]) == 1
    r = load_result(tmp_path / "c")
    assert r.termination.status == "degraded"
    assert {"battery.soc_pct", "vehicle.speed_mps", "cycle.speed_ref_mps"} <= set(r.signals)
    # a followed cycle is completed
    res = shevsim.simulate("hd_udds_rule", {"cycle.repeat": 1}, stop_s=120.0)
    assert res.termination == "completed"


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_real_interrupt_of_the_command_saves_the_run(tmp_path, sig):
    # the shevsim process itself, stopped with Ctrl-C (SIGINT) or kill (SIGTERM) while simulating
    import signal
    import subprocess
    import sys
    import time
    out = tmp_path / "o"

    def default_sigint():
        # a test run started in the background by a non-interactive shell inherits SIGINT ignored, and Python
        # then keeps it ignored; a user's Ctrl-C reaches a foreground process, whose SIGINT is the default
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    p = subprocess.Popen([sys.executable, "-m", "shevsim.cli", "run", str(TWO_BODY), "-s", "scenario.stop_s=1e5",
                          "--record-every", "100", "--engine", "python", "-o", str(out), "--no-plots"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                         preexec_fn=default_sigint)
    try:
        seen = ""
        t0 = time.time()
        while "simulating" not in seen and time.time() - t0 < 120:     # the progress bar: it runs
            seen += p.stderr.read(1)
        time.sleep(1.0)
        p.send_signal(getattr(signal, sig))
        _, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, err
    res = load_result(out)
    assert res.termination.status == "stopped" and "interrupted" in res.termination.reason
    assert 0 < res.time_s[-1] < 1e5 and len(res) > 2


def test_bad_input_leaves_no_output_folder_behind(tmp_path):
    out = tmp_path / "a" / "b" / "o"
    with pytest.raises(ScenarioError):
        shevsim.simulate(TWO_BODY, {"body1.mass_kg": -1.0}, out=out)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("key, value", [("trace_distance_tolerance", -0.1), ("trace_distance_tolerance", 1.5),
                                        ("trace_speed_window_s", -1.0), ("trace_allow_miss", 1)])
def test_trace_options_out_of_range_are_refused(key, value):
    with pytest.raises(ScenarioError, match=rf"{key}'? = {value!r}"):
        shevsim.simulate(TWO_BODY, {f"metrics.{key}": value}, stop_s=0.1)
