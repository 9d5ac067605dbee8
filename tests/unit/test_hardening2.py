"""Second hardening pass (issue 22): no internal error from input or environment, no silent acceptance,
bounded work, errors that blame the right thing. Each case is one input a user could give."""
from __future__ import annotations

import errno
import math
import os
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from shevsim.cli import main
from shevsim.core.errors import DataError, OutputError, ScenarioError
from shevsim.core.scenario import load_scenario, parse_value

ROOT = Path(__file__).resolve().parents[2]
RULE = ROOT / "scenarios" / "hd_udds_rule.toml"


def _scenario(tmp_path, extra: str = "", edit=lambda s: s) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(edit(RULE.read_text()) + extra)
    return p


def _env(**kw):
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["MPLBACKEND"] = "Agg"
    env.update(kw)
    return env


# ----------------------------------------------------------------------------------- no silent acceptance
def test_metrics_table_is_checked_like_parameters(tmp_path):
    with pytest.raises(ScenarioError, match=r"\[metrics\]: unknown option 'fuel_densty_kg_per_l' \(did you mean "
                                            r"'fuel_density_kg_per_l'\?\)"):
        load_scenario(_scenario(tmp_path, "\n[metrics]\nfuel_densty_kg_per_l = 0.75\n"))
    with pytest.raises(ScenarioError, match=r"option 'fuel_density_kg_per_l' = 'abc': must be a number"):
        load_scenario(_scenario(tmp_path, '\n[metrics]\nfuel_density_kg_per_l = "abc"\n'))
    with pytest.raises(ScenarioError, match=r"unknown option 'k0'"):
        load_scenario(_scenario(tmp_path, "\n[metrics]\n" + "".join(f"k{i} = 1\n" for i in range(300_000))))
    with pytest.raises(ScenarioError, match=r"ah_weighting' = 'linear': must be one of 'constant', 'wang2011'"):
        load_scenario(_scenario(tmp_path, '\n[metrics]\nah_weighting = "linear"\n'))
    with pytest.raises(ScenarioError, match=r"soc_tolerance_pct.*valid range"):
        load_scenario(RULE, ["metrics.soc_tolerance_pct=150"])
    with pytest.raises(ScenarioError, match=r"--set 'metrics.trace_allow_mis=true'.*did you mean 'trace_allow_miss'"):
        load_scenario(RULE, ["metrics.trace_allow_mis=true"])
    sc = load_scenario(_scenario(tmp_path, "\n[metrics]\nfuel_density_kg_per_l = 0.75\ntrace_allow_miss = true\n"))
    assert sc.metrics == {"fuel_density_kg_per_l": 0.75, "trace_allow_miss": True}


def test_a_fault_before_the_run_is_refused(tmp_path):
    import shevsim
    p = _scenario(tmp_path, '\n[[faults]]\nat_s = -5.0\nport = "battery.h_conv_w_m2k"\nvalue = 3.0\n')
    with pytest.raises(ScenarioError, match=r"\[\[faults\]\] #1 at_s = -5.0 s .* before the start of the run"):
        shevsim.simulate(str(p), stop_s=10.0)


def test_set_takes_exactly_one_value(tmp_path):
    with pytest.raises(ScenarioError, match="exactly one value on one line"):
        load_scenario(RULE, ['vehicle.mass_kg=1\n[components.x]\ntype="os:system"'])
    with pytest.raises(ScenarioError, match="exactly one value"):
        parse_value("1\r\nx = 2")
    assert parse_value("18000") == 18000 and parse_value("[1, 2]") == [1, 2] and parse_value("heavy") == "heavy"
    assert parse_value('"a b"') == "a b" and parse_value("{ a = 1 }") == {"a": 1}
    sc = load_scenario(RULE, ["vehicle.mass_kg=18000"])
    assert next(c for c in sc.components if c.name == "vehicle").overrides["mass_kg"] == 18000


# --------------------------------------------------------------------------- no internal error from input
@pytest.mark.parametrize("deep", ["x = " + "[" * 100_000 + "]" * 100_000, "x = " + "{a = " * 3000 + "1" + "}" * 3000])
def test_deep_toml_nesting_is_a_plain_error(tmp_path, deep, capsys):
    with pytest.raises(ScenarioError, match=r"s.toml: TOML nested too deeply.*recursion limit"):
        load_scenario(_scenario(tmp_path, "\n[metrics]\n" + deep + "\n"))
    ov = tmp_path / "deep.toml"
    ov.write_text(deep + "\n")
    assert main(["run", "hd_udds_rule", "--params", f"vehicle={ov}", "-o", str(tmp_path / "o"), "-q"]) == 2
    assert "deep.toml: TOML nested too deeply" in capsys.readouterr().err
    with pytest.raises(ScenarioError, match="nested too deeply"):
        parse_value("[" * 5000 + "]" * 5000)


def test_a_full_disk_while_saving_leaves_the_earlier_result_and_no_half_file(tmp_path, monkeypatch):
    import shevsim.core.results as results
    from shevsim.run import run
    out = tmp_path / "o"
    run("hd_udds_rule", stop_s=20.0, out=out, engine="python")
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(results, "write_json_atomic", full)
    with pytest.raises(OutputError, match=r"could not save the result in .*\(run.json\): No space left on device "
                                          r"\(ENOSPC\); the disk is full.*Nothing was changed"):
        run("hd_udds_rule", stop_s=30.0, out=out, engine="python")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".o.")]


def test_a_file_size_limit_while_saving_is_a_plain_error(tmp_path):
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (300_000, 300_000))
    r = subprocess.run([sys.executable, "-m", "shevsim.cli", "run", "hd_udds_rule", "--engine", "python",
                        "--set", "scenario.stop_s=600", "--no-plots", "-q", "-o", "o"], cwd=tmp_path, env=_env(),
                       capture_output=True, text=True, preexec_fn=limit, timeout=600)
    assert r.returncode == 2, r.stderr
    assert "File too large (EFBIG)" in r.stderr and "ulimit -f" in r.stderr and "internal" not in r.stderr
    assert not (tmp_path / "o").exists() and not list(tmp_path.glob(".o.*"))


def test_an_oversized_fmu_member_is_refused_before_reading(tmp_path):
    from shevsim.fmu.adapter import MAX_MODEL_DESCRIPTION_BYTES, read_fmi_version
    from shevsim.fmu.errors import FMULoadError
    p = tmp_path / "big.fmu"
    with zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        with zf.open("modelDescription.xml", "w", force_zip64=True) as f:
            f.write(b'<?xml version="1.0"?><fmiModelDescription fmiVersion="2.0"><!--')
            for _ in range(MAX_MODEL_DESCRIPTION_BYTES // 2**20 + 8):
                f.write(b" " * 2**20)
            f.write(b"--></fmiModelDescription>")
    assert p.stat().st_size < 2 * 2**20                    # a small file that unpacks to 72 MiB
    t0 = time.perf_counter()
    with pytest.raises(FMULoadError, match=r"modelDescription.xml unpacks to 72 MiB \(limit 64 MiB"):
        read_fmi_version(p)
    assert time.perf_counter() - t0 < 5.0


def test_non_ascii_names_and_paths_under_an_ascii_locale(tmp_path):
    env = _env(LC_ALL="C", LANG="C", PYTHONUTF8="0", PYTHONCOERCECLOCALE="0")
    r = subprocess.run([sys.executable, "-m", "shevsim.cli", "run", "hd_udds_rule", "--engine", "python", "--set",
                        "scenario.stop_s=20", "--no-plots", "-o", "r\u00e9sultat"], cwd=tmp_path, env=env,
                       capture_output=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "r\u00e9sultat" / "run.json").is_file()
    s = RULE.read_text().replace("[components.bus]", '[components."b\u00fas"]').replace('"bus.', '"b\u00fas.')
    (tmp_path / "u.toml").write_text(s.replace('"bus", "battery"', '"b\u00fas", "battery"'), encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "shevsim.cli", "info", "u.toml"], cwd=tmp_path, env=env,
                       capture_output=True, timeout=600)
    assert r.returncode == 0 and b"b\\xfas" in r.stdout, r.stderr
    r = subprocess.run([sys.executable, "-m", "shevsim.cli", "run", "u.toml", "--set", "b\u00fas.nosuch=1", "-o", "x"],
                       cwd=tmp_path, env=env, capture_output=True, timeout=600)
    assert r.returncode == 2 and b"unknown parameter 'nosuch'" in r.stderr, r.stderr


def test_stdout_on_a_full_device_is_a_plain_error(tmp_path):
    with open("/dev/full", "w") as full:
        r = subprocess.run([sys.executable, "-m", "shevsim.cli", "scenarios"], stdout=full, stderr=subprocess.PIPE,
                           text=True, env=_env(), timeout=120)
    assert r.returncode == 2, r.stderr
    assert "cannot write to standard output: No space left on device (ENOSPC)" in r.stderr
    assert "internal" not in r.stderr and "Exception ignored" not in r.stderr


# ------------------------------------------------------------------------------------------ bounded work
def test_a_long_calibration_record_is_refused_with_an_estimate(tmp_path, capsys):
    from shevsim.calibrate.cli import MAX_RECORD_ROWS, main_calibrate
    n = MAX_RECORD_ROWS + 50_000
    t = np.arange(n) * 0.1
    i = 2.0 * np.sign(np.sin(t / 25.0))
    v = 3.3 - 0.03 * i
    rec = tmp_path / "rec.csv"
    np.savetxt(rec, np.c_[t, i, v, np.full(n, 25.0), np.full(n, 25.0)], delimiter=",", fmt="%.6g",
               header="time_s,current_a,voltage_v,t_surface_c,t_ambient_c", comments="")
    assert main_calibrate(["cell", str(rec), "-o", str(tmp_path / "cal"), "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert f"the record has {n:,} rows, more than the {MAX_RECORD_ROWS:,}" in err
    assert "one simulation of the model over it takes" in err and "--decimate 2" in err and "--allow-large" in err
    assert not (tmp_path / "cal").exists()


# ------------------------------------------------------------------------------- the right thing blamed
def test_an_overlay_error_names_the_overlay(tmp_path):
    ov = tmp_path / "ov.toml"
    ov.write_text("[vehicle]\nmass_kgg = 5.0\n")
    import shevsim
    for text, needle in (("[vehicle]\nmass_kgg = 5.0\n", "unknown parameter 'mass_kgg'"),
                         ("[vehicle]\nmass_kg = nan\n", "'mass_kg' = nan")):
        ov.write_text(text)
        with pytest.raises(ScenarioError) as e:
            shevsim.simulate(load_scenario(RULE, overlays=[str(ov)]), stop_s=1.0)
        assert f"--params '{ov}'" in str(e.value) and needle in str(e.value)
        assert "matv.toml" not in str(e.value)


@pytest.mark.parametrize("target, needle", [("folder", "is a folder, not a cycle file"),
                                            ("/dev/zero", "is a character device"),
                                            ("/dev/urandom", "is a character device")])
def test_a_cycle_path_that_is_no_file_is_named_as_such(tmp_path, target, needle):
    from shevsim.cycles import load_cycle
    if target == "folder":
        target = tmp_path / "cyc"
        target.mkdir()
    with pytest.raises(DataError, match=needle):
        load_cycle(target)


def test_a_km_per_h_city_cycle_under_50_km_per_h_is_recognised(tmp_path):
    from shevsim.cycles import load_cycle
    src = load_cycle(ROOT / "cycles" / "hd_udds.csv")
    keep = src.time_s <= 200.0
    kmh = src.speed_mps[keep] * 3.6 * 0.85          # a 46.5 km/h city cycle, written in km/h
    assert kmh.max() < 50.0
    p = tmp_path / "c.csv"
    p.write_text("time_s,speed_mps\n" + "".join(f"{t:g},{v:.4f}\n" for t, v in zip(src.time_s[keep], kmh)))
    with pytest.raises(DataError, match=r"W per kg.*looks like km/h.*speed_kmh"):
        load_cycle(p)
    p.write_text(p.read_text().replace("speed_mps", "speed_kmh", 1))
    assert load_cycle(p).speed_mps.max() == pytest.approx(kmh.max() / 3.6, rel=1e-4)


def test_max_evaluations_zero_is_a_usage_error(tmp_path, capsys):
    # (it used to reach the study and exit 3, an internal error); argparse's usage error: exit 2
    with pytest.raises(SystemExit) as e:
        main(["study", "tradeoff", "hd_udds_rule", "--max-evaluations", "0", "--out", str(tmp_path / "st")])
    assert e.value.code == 2
    assert "expected an integer >= 1, got 0" in capsys.readouterr().err


def test_closed_stdout_is_said_unless_quiet(tmp_path):
    r = subprocess.run(f"{sys.executable} -m shevsim.cli scenarios >&-", shell=True, capture_output=True,
                       text=True, env=_env(), timeout=120)
    assert r.returncode == 2 and "standard output is closed" in r.stderr, r.stderr
    r = subprocess.run(f"{sys.executable} -m shevsim.cli -q scenarios >&-", shell=True, capture_output=True,
                       text=True, env=_env(), timeout=120)
    assert r.returncode == 0, r.stderr


def test_record_table_is_checked(tmp_path):
    with pytest.raises(ScenarioError, match=r"\[record\] field 'signals' is an empty list"):
        load_scenario(_scenario(tmp_path, edit=lambda s: s.replace('signals = "all"', "signals = []")))
    with pytest.raises(ScenarioError, match=r"\[record\]: unknown key 'signal' \(did you mean 'signals'\?\)"):
        load_scenario(_scenario(tmp_path, edit=lambda s: s.replace('signals = "all"', 'signal = ["vehicle.speed_mps"]')))
    with pytest.raises(ScenarioError, match=r"'speed' is not 'component.port'"):
        load_scenario(_scenario(tmp_path, edit=lambda s: s.replace('signals = "all"', 'signals = ["speed"]')))
