"""bad_inputs.py - run a table of bad inputs and faults through the CLI / API and classify each outcome.

    python benchmarks/bad_inputs.py --tree /work/main --label after  --json /tmp/after.json
    python benchmarks/bad_inputs.py --tree /tmp/before --label before --json /tmp/before.json
    python benchmarks/bad_inputs.py --merge /tmp/before.json /tmp/after.json --markdown docs/bad_inputs.md

Every case runs in its own temporary folder, as a subprocess ``python -m shevsim.cli ...`` (or a short
``python -c`` for Python-API cases) with ``PYTHONPATH=<tree>``, so the same script measures any checkout
(the session-start commit in a separate worktree for the "before" column).  The data the cases need
(cycles, records, maps, scenario copies) are written by the script; scenario copies resolve their
component parameter files through the checkout's own search path.

Outcome classes (per case, from exit status, output and a post-check):

* ``clear error``: refused, non-zero exit, no traceback;
* ``handled``: accepted and the result is right (a quirk converted, a fault reported, partial results kept);
* ``silent``: accepted and the result is wrong or the problem is not said (exit 0 where an error or a
  report was expected);
* ``traceback``: a Python traceback or "internal error" reached the user;
* ``hang``: did not finish within the case's timeout (killed);
* ``data loss``: a file the user owned was removed or changed.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

PY = sys.executable


@dataclass
class Case:
    cid: str
    group: str
    what: str
    expect: str                         # "error" (should be refused) or "accept" (should work / be reported)
    setup: Callable                      # (ctx) -> argv list (after "python -m shevsim.cli") or ("-c", code)
    timeout: float = 60.0
    check: Callable | None = None        # (ctx, proc) -> (ok: bool, note: str) for accepted runs
    lost: Callable | None = None         # (ctx) -> True when a user's file was lost
    sigint_after: float | None = None    # send Ctrl-C after this many seconds
    signame: str = "SIGINT"              # ... or this signal
    want: str | None = None              # a refusal must say this (else: "misleading", the wrong thing blamed)
    want_rc: int | None = None           # ... and exit with this code (else: "misleading")
    env: dict | None = None              # extra environment (e.g. an ASCII-only locale)
    stdout_to: str | None = None         # stdout to this file (e.g. /dev/full) instead of a pipe
    fsize: int | None = None             # file-size limit (RLIMIT_FSIZE, bytes) of the process
    cleanup: Callable | None = None      # (ctx) -> None after the case (e.g. unmount)


@dataclass
class Ctx:
    tree: Path
    tmp: Path
    extra: dict = field(default_factory=dict)

    def scen(self, name: str) -> Path:
        return self.tree / "scenarios" / f"{name}.toml"

    def copy_scenario(self, name: str, edit=lambda s: s, new="s.toml") -> Path:
        txt = self.scen(name).read_text()
        p = self.tmp / new
        p.write_text(edit(txt))
        return p

    def write(self, name: str, text: str | bytes) -> Path:
        p = self.tmp / name
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_text(text)
        return p


# ------------------------------------------------------------------------------------------ helpers

def _cycle_rows(speed_scale=1.0, dt=1.0, n=120, vmax=20.0):
    rows = []
    for k in range(n):
        v = vmax * math.sin(math.pi * k / (n - 1))
        rows.append((k * dt, v * speed_scale))
    return rows


def cycle_csv(rows, header="time_s,speed_mps", sep=",", nl="\n", dec=".", trailing=""):
    out = [header.replace(",", sep) + trailing]
    for t, v in rows:
        out.append(sep.join((f"{t:g}", f"{v:.4f}".replace(".", dec))) + trailing)
    return nl.join(out) + nl


def cell_record(n=600, dt=1.0, i_amp=2.0, current_scale=1.0, time_scale=1.0, rest=False, heat=1.0):
    """A plausible cell record: current pulses, voltage from OCV - R i, temperatures near 25 degC."""
    import numpy as np
    rng = np.random.default_rng(0)
    t = np.arange(n) * dt
    i = np.zeros(n) if rest else i_amp * np.sign(np.sin(t / 25.0)) * (rng.random(n) > 0.15)
    v = 3.30 - 0.0003 * np.cumsum(i) * dt / 3.6 - 0.03 * i + rng.normal(0, 1e-3, n)
    ts = 25.0 + heat * 0.002 * np.cumsum(i * i) * dt / 10 + rng.normal(0, 0.03, n)
    lines = ["time_s,current_a,voltage_v,t_surface_c,t_ambient_c"]
    for k in range(n):
        lines.append(f"{t[k] * time_scale:.10g},{i[k] * current_scale:.5g},{v[k]:.5f},{ts[k]:.3f},25.0")
    return "\n".join(lines) + "\n"


def motor_map(ctx, transform) -> Path:
    src = (ctx.tree / "components" / "motor" / "motor_eff_map.csv").read_text().splitlines()
    head = [ln for ln in src if ln.startswith("#")]
    rows = [ln for ln in src if ln.strip() and not ln.startswith("#")]
    return ctx.write("motor_eff_map.csv", "\n".join(head + transform(rows)) + "\n")


def _scale_eff(rows):
    return [rows[0]] + [f"{a},{b},{float(c) * 1.5 / 0.92:.6g}" for a, b, c in (r.split(",") for r in rows[1:])]


def _nan_cell(rows):
    r = rows[:]
    a, b, _ = r[7].split(",")
    r[7] = f"{a},{b},nan"
    return r


def _results_ok(ctx, proc, needle=None):
    ok = proc.returncode == 0
    return ok, ""


def _cycle_loaded(expect_max_mps=None, expect_dur_s=119.0):
    """Check an accepted cycle: the run's summary names the cycle; the loaded cycle's max speed/duration
    are read back through the API of the same tree."""
    def chk(ctx, proc):
        code = ("import json,sys; from shevsim.cycles import load_cycle; c = load_cycle(sys.argv[1]); "
                "print(json.dumps([float(c.speed_mps.max()), float(c.duration_s)]))")
        r = subprocess.run([PY, "-c", code, str(ctx.extra["cycle"])], capture_output=True, text=True,
                           env=_env(ctx.tree), cwd=ctx.tmp, timeout=60)
        if r.returncode != 0:
            return False, "reload failed"
        vmax, dur = json.loads(r.stdout.strip().splitlines()[-1])
        want = max(v for _, v in _cycle_rows()) if expect_max_mps is None else expect_max_mps
        good = abs(vmax - want) < 1e-3 and abs(dur - expect_dur_s) < 1e-6
        return good, f"max {vmax:.4g} m/s, {dur:g} s"
    return chk


def _report_flags_identifiability(ctx, proc):
    rep = ctx.tmp / "cal" / "report.json"
    if not rep.is_file():
        return False, "no report"
    r = json.loads(rep.read_text())
    ni = r.get("not_identifiable")
    if ni:
        return True, f"not identifiable: {', '.join(ni[:4])}{'...' if len(ni) > 4 else ''}"
    return False, f"parameters reported as fitted (at bounds: {len(r.get('parameters_at_bounds', []))})"


def _sigint_check(ctx, proc):
    out = proc.stdout + proc.stderr
    saved = any(ctx.tmp.joinpath("o").glob("*"))
    return (proc.returncode != 0 and saved), f"exit {proc.returncode}, results saved: {saved}"


# ------------------------------------------------------------------------------------------ the cases

def _cases() -> list[Case]:
    C = []

    def add(*a, **k):
        C.append(Case(*a, **k))

    base = "hd_udds_rule"
    # --- scenario files -----------------------------------------------------------------------------
    add("S01", "scenario", "malformed TOML (unclosed table header)", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + "\n[components.x\n")), "--out", "o"])
    add("S02", "scenario", "unknown top-level key 'conections'", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + '\n[conections]\n"a.b" = "c.d"\n')), "--out", "o"])
    add("S03", "scenario", 'component type = "os:system"', "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace('type = "bus"', 'type = "os:system"'))),
                   "--out", "o"])
    add("S04", "scenario", 'component type = "this:x" (module path)', "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace('type = "bus"', 'type = "this:x"'))),
                   "--out", "o"])
    add("S05", "scenario", "unknown component type 'motr'", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace('type = "motor"', 'type = "motr"'))),
                   "--out", "o"])
    add("S06", "scenario", "shevsim info on a scenario with type = \"os:system\"", "error",
        lambda c: ["info", str(c.copy_scenario(base, lambda s: s.replace('type = "bus"', 'type = "os:system"')))])
    add("S07", "scenario", "dotted component name [components.\"a.b\"]", "error",
        lambda c: ["run", str(c.write("s.toml", '[scenario]\nstep_s = 0.1\nstop_s = 1.0\n[components."a.b"]\n'
                                              'type = "gain"\nstart = { in_1 = 1.0 }\n')), "--out", "o"])
    add("S08", "scenario", "scenario file does not exist", "error", lambda c: ["run", "nosuch.toml", "--out", "o"])
    add("S09", "scenario", "scenario path is a directory", "error",
        lambda c: (c.tmp.joinpath("d.toml").mkdir(), ["run", "d.toml", "--out", "o"])[1])
    add("S10", "scenario", "binary (non-UTF-8) scenario file", "error",
        lambda c: ["run", str(c.write("bin.toml", bytes(range(256)) * 4)), "--out", "o"])
    add("S11", "scenario", "step_s = 0 (zero step)", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace("step_s = 0.1", "step_s = 0.0"))), "--out", "o"])
    add("S12", "scenario", "step_s = 1e6 (huge step)", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace("step_s = 0.1", "step_s = 1e6"))), "--out", "o"])
    add("S13", "scenario", 'step_s = "abc" (wrong type)', "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace("step_s = 0.1", 'step_s = "abc"'))),
                   "--out", "o"])
    add("S14", "scenario", "stop_s = -5 (before t0)", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace("seed = 1", "seed = 1\nstop_s = -5.0"))),
                   "--out", "o"])
    add("S15", "scenario", "stop_s = 1e9 (160-hour run, memory grows)", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace("seed = 1", "seed = 1\nstop_s = 1e9"))),
                   "--out", "o"], timeout=25)
    add("S16", "scenario", "connection from an unknown port", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace(
            "[connections]", '[connections]\n"driver.nosuch_n" = "vehicle.nosuch_in"', 1))), "--out", "o"])
    add("S17", "scenario", "fault scheduled after the end of the run", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + '\n[[faults]]\nat_s = 99999.0\n'
                                              'port = "battery.h_conv_w_m2k"\nvalue = 3.0\n')), "--out", "o"])
    add("S18", "scenario", "fault on an unknown port", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + '\n[[faults]]\nat_s = 10.0\n'
                                              'port = "battery.nosuch"\nvalue = 3.0\n')), "--out", "o"])
    add("S19", "scenario", 'start value for a port the component does not have', "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace(
            'type = "bus"', 'type = "bus"\nstart = { nosuch = "x" }'))), "--out", "o"])
    add("S20", "scenario", "empty scenario file", "error", lambda c: ["run", str(c.write("e.toml", "")), "--out", "o"])
    add("S21", "scenario", "[metrics] fuel_density_kg_per_l = -0.85 (negative km/L)", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + "\n[metrics]\nfuel_density_kg_per_l = -0.85\n")),
                   "--out", "o"])
    # --- --set / parameters -----------------------------------------------------------------------------
    cool = "uac_proxy_mpc_cooling_fault"
    add("P01", "parameters", "--set bms.t_core_max_c=nan (protection off)", "error",
        lambda c: ["run", cool, "--set", "bms.t_core_max_c=nan", "--out", "o"], timeout=120)
    add("P02", "parameters", "--set bms.i_cell_max_a=nan", "error",
        lambda c: ["run", base, "--set", "bms.i_cell_max_a=nan", "--out", "o"])
    add("P03", "parameters", "--set bms.q_soc=nan (DEKF process noise)", "error",
        lambda c: ["run", base, "--set", "bms.q_soc=nan", "--out", "o"])
    add("P04", "parameters", "--set bms.p0_soc=nan (DEKF initial covariance)", "error",
        lambda c: ["run", base, "--set", "bms.p0_soc=nan", "--out", "o"])
    add("P05", "parameters", "--set battery.t_init_c=nan", "error",
        lambda c: ["run", base, "--set", "battery.t_init_c=nan", "--out", "o"])
    add("P06", "parameters", "--set battery.t_init_c=-300 (below absolute zero)", "error",
        lambda c: ["run", base, "--set", "battery.t_init_c=-300", "--out", "o"])
    add("P07", "parameters", "--set vehicle.mass_kg=-15554 (negative mass)", "error",
        lambda c: ["run", base, "--set", "vehicle.mass_kg=-15554", "--out", "o"])
    add("P08", "parameters", "--set battery.capacity_ah=0", "error",
        lambda c: ["run", base, "--set", "battery.capacity_ah=0", "--out", "o"])
    add("P09", "parameters", "--set battery.soc_init_pct=150", "error",
        lambda c: ["run", base, "--set", "battery.soc_init_pct=150", "--out", "o"])
    add("P10", "parameters", "--set motor.gear_ratio=0", "error",
        lambda c: ["run", base, "--set", "motor.gear_ratio=0", "--out", "o"])
    add("P11", "parameters", "--set engine_generator.fuel_lhv_j_per_g=-42600", "error",
        lambda c: ["run", base, "--set", "engine_generator.fuel_lhv_j_per_g=-42600", "--out", "o"])
    add("P12", "parameters", "--set cycle.repeat=0", "error", lambda c: ["run", base, "--set", "cycle.repeat=0", "--out", "o"])
    add("P13", "parameters", "--set bms.t_core_max_c=inf", "error",
        lambda c: ["run", base, "--set", "bms.t_core_max_c=inf", "--out", "o"])
    add("P14", "parameters", "--set without '='", "error", lambda c: ["run", base, "--set", "bms.t_core_max_c", "--out", "o"])
    add("P15", "parameters", "--set on an unknown component", "error",
        lambda c: ["run", base, "--set", "bmss.t_core_max_c=40", "--out", "o"])
    add("P16", "parameters", "--set an unknown parameter", "error",
        lambda c: ["run", base, "--set", "bms.t_core_max=40", "--out", "o"])
    add("P17", "parameters", "--set a string for a number", "error",
        lambda c: ["run", base, "--set", "vehicle.mass_kg=heavy", "--out", "o"])
    add("P18", "parameters", "--set vehicle.drag_coefficient=-0.7", "error",
        lambda c: ["run", base, "--set", "vehicle.drag_coefficient=-0.7", "--out", "o"])
    add("P25", "parameters", "--set supervisor.soc_min_pct=80 (above soc_max_pct = 70)", "error",
        lambda c: ["run", base, "--set", "supervisor.soc_min_pct=80", "--out", "o"])
    add("P19", "parameters", "parameter file with malformed TOML", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace(
            'params = "components/bus/default.toml"', f'params = "{c.write("bus.toml", "[params" + chr(10))}"'))), "--out", "o"])
    add("P20", "parameters", "parameter file with an unknown key", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace(
            'params = "components/bus/default.toml"',
            f'params = "{c.write("bus.toml", "[params]" + chr(10) + "aux_power = 5.0" + chr(10))}"'))), "--out", "o"])
    add("P21", "parameters", "parameter file path does not exist", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace(
            'params = "components/bus/default.toml"', 'params = "nosuch/bus.toml"'))), "--out", "o"])
    add("P22", "parameters", "--params overlay file does not exist", "error",
        lambda c: ["run", base, "--params", "nosuch.toml", "--out", "o"])
    add("P23", "parameters", "Python API: BMS built with BMSParams(i_cell_max_a=nan)", "error",
        lambda c: ("-c", "import math\nfrom shevsim.components.bms import BMS, BMSParams\n"
                         "from shevsim.core.errors import ShevsimError\ntry:\n"
                         "    BMS('bms', BMSParams(i_cell_max_a=math.nan))\nexcept ShevsimError as e:\n"
                         "    import sys; print('error:', e, file=sys.stderr); sys.exit(2)\n"))
    add("P24", "parameters", "Python API: make_params(BMSParams, {'t_core_max_c': nan})", "error",
        lambda c: ("-c", "import math, sys\nfrom shevsim.components.bms import BMSParams\n"
                         "from shevsim.core.params import make_params\nfrom shevsim.core.errors import ShevsimError\n"
                         "try:\n    make_params(BMSParams, {'t_core_max_c': math.nan}, 'api')\n"
                         "except ShevsimError as e:\n    print('error:', e, file=sys.stderr); sys.exit(2)\n"))
    # --- maps and tables -----------------------------------------------------------------------------------
    add("M01", "maps", "motor efficiency map of 1.5 (negative losses)", "error",
        lambda c: ["run", base, "--set", f"motor.efficiency_map_file='{motor_map(c, _scale_eff)}'", "--out", "o"])
    add("M02", "maps", "motor efficiency map with a NaN cell", "error",
        lambda c: ["run", base, "--set", f"motor.efficiency_map_file='{motor_map(c, _nan_cell)}'", "--out", "o"])
    add("M03", "maps", "map file does not exist", "error",
        lambda c: ["run", base, "--set", "motor.efficiency_map_file='/nonexistent/map.csv'", "--out", "o"])
    add("M04", "maps", "map file is binary garbage", "error",
        lambda c: ["run", base, "--set", f"motor.efficiency_map_file='{c.write('m.csv', bytes(range(256)) * 8)}'",
                   "--out", "o"])
    add("M05", "maps", "map with a column renamed (efficiency instead of efficiency_frac)", "error",
        lambda c: ["run", base, "--set", "motor.efficiency_map_file='" + str(motor_map(
            c, lambda r: [r[0].replace("efficiency_frac", "efficiency")] + r[1:])) + "'", "--out", "o"])
    add("M06", "maps", "battery OCV table with a UTF-8 BOM", "accept",
        lambda c: ["run", base, "--set", "battery.ocv_file='" + str(c.write(
            "ocv.csv", b"\xef\xbb\xbf" + (c.tree / "components/battery/a123_26650_ocv.csv").read_bytes())) + "'",
            "--set", "bms.ocv_file='" + str(c.tmp / "ocv.csv") + "'", "--out", "o"],
        check=_results_ok)
    # --- cycles ---------------------------------------------------------------------------------------------
    def cyc(cid, what, expect, text, check=None):
        def setup(c):
            p = c.write("cyc.csv", text) if isinstance(text, (str, bytes)) else c.write("cyc.csv", text(c))
            c.extra["cycle"] = p
            return ["run", base, "--set", f"cycle.cycle_file='{p}'", "--out", "o"]
        add(cid, "cycles", what, expect, setup, check=check)

    cyc("C01", "cycle in km/h (max 72 'm/s')", "error", cycle_csv(_cycle_rows(3.6)))
    cyc("C02", "cycle at 200 m/s", "error", cycle_csv(_cycle_rows(10.0)))
    cyc("C03", "cycle time in milliseconds", "error", cycle_csv(_cycle_rows(dt=1000.0)))
    cyc("C04", "cycle header with a UTF-8 BOM", "accept", "\ufeff" + cycle_csv(_cycle_rows()),
        check=_cycle_loaded())
    cyc("C05", "cycle with ';' separators and decimal commas", "accept", cycle_csv(_cycle_rows(), sep=";", dec=","),
        check=_cycle_loaded())
    cyc("C06", "cycle with CRLF and trailing empty columns", "accept",
        cycle_csv(_cycle_rows(), nl="\r\n", trailing=",,"), check=_cycle_loaded())
    cyc("C07", "cycle declared in km/h (speed_kmh header)", "accept",
        cycle_csv(_cycle_rows(3.6), header="time_s,speed_kmh"), check=_cycle_loaded())
    cyc("C08", "empty cycle CSV", "error", "")
    cyc("C09", "cycle with non-monotonic time", "error", "time_s,speed_mps\n0,0\n1,1\n3,2\n2,2\n4,1\n")
    cyc("C10", "cycle with a NaN speed", "error", "time_s,speed_mps\n0,0\n1,nan\n2,2\n")
    cyc("C11", "cycle with a negative speed", "error", "time_s,speed_mps\n0,0\n1,-3\n2,2\n")
    cyc("C12", "cycle with a gap in time", "error", "time_s,speed_mps\n0,0\n1,1\n2,2\n10,2\n11,1\n")
    cyc("C13", "cycle saved as UTF-16", "error", cycle_csv(_cycle_rows()).encode("utf-16"))
    cyc("C14", "cycle header only", "error", "time_s,speed_mps\n")
    cyc("C15", "cycle with a missing speed column", "error", "time_s,velocity\n0,0\n1,1\n2,2\n")
    # --- calibration -----------------------------------------------------------------------------------------
    def cal(cid, what, expect, text, extra=(), check=None, timeout=180):
        def setup(c):
            p = c.write("rec.csv", text() if callable(text) else text)
            return ["calibrate", "cell", str(p), "--out", str(c.tmp / "cal"), "--no-plots", "-q", *extra]
        add(cid, "calibration", what, expect, setup, check=check, timeout=timeout)

    cal("K01", "cell record with time in milliseconds", "error", lambda: cell_record(time_scale=1000.0))
    cal("K02", "cell record with current in mA (500 mA pulses)", "error",
        lambda: cell_record(i_amp=0.5, current_scale=1000.0))
    cal("K03", "cell record with no excitation (rest): parameters not identifiable", "accept",
        lambda: cell_record(n=300, rest=True), check=_report_flags_identifiability, timeout=300)
    cal("K04", "cell record with a UTF-8 BOM and ';' decimal commas", "accept",
        lambda: "\ufeff" + cell_record(n=200).replace(",", ";").replace(".", ","),
        check=lambda c, p: (p.returncode == 0, ""), timeout=300)
    cal("K05", "cell record with a missing column", "error", "time_s,current_a,voltage_v\n0,1,3.3\n1,1,3.3\n2,1,3.3\n")
    cal("K06", "calibration record does not exist", "error", None)
    C[-1].setup = lambda c: ["calibrate", "cell", "nosuch.csv", "--out", str(c.tmp / "cal"), "-q"]
    cal("K07", "empty calibration CSV", "error", "")
    cal("K08", "calibration record with time going backwards", "error",
        "time_s,current_a,voltage_v,t_surface_c,t_ambient_c\n0,1,3.3,25,25\n2,1,3.3,25,25\n1,1,3.3,25,25\n3,1,3.3,25,25\n")
    cal("K09", "temperatures in kelvin", "error",
        lambda: cell_record(n=100).replace(",25.0\n", ",298.15\n"))
    cal("K10", "--params file does not exist", "error", lambda: cell_record(n=100),
        extra=("--params", "/nonexistent_dir/p.toml"))
    # --- studies --------------------------------------------------------------------------------------------
    add("T01", "studies", "study tradeoff --supervisor nosuch", "error",
        lambda c: ["study", "tradeoff", str(c.scen("hd_udds_mpc")), "--supervisor", "nosuch", "--workers", "0",
                   "--rates", "30", "--no-plots", "--quiet", "--out", str(c.tmp / "st")], timeout=300)
    add("T02", "studies", "study on a scenario that does not exist", "error",
        lambda c: ["study", "tradeoff", "nosuch.toml", "--workers", "0", "--out", str(c.tmp / "st")])
    add("T03", "studies", "unknown study name", "error", lambda c: ["study", "tradof"])
    add("T04", "studies", "study tradeoff with a negative rate", "error",
        lambda c: ["study", "tradeoff", "--synthetic", "--rates", "-5", "--workers", "0", "--out", str(c.tmp / "st")])
    # --- runs, outputs, interruption (owned by other engineers: classified as observed) -------------------
    def notebook(c):
        # the case: a re-run into an earlier result folder the user has put a notebook in
        subprocess.run([PY, "-m", "shevsim.cli", "run", base, "--out", "o"], cwd=c.tmp, env=_env(c.tree),
                       capture_output=True, timeout=300)
        d = c.tmp / "o"
        d.mkdir(exist_ok=True)
        (d / "analysis.ipynb").write_text('{"cells": []}')
        return ["run", base, "--out", "o"]
    add("R01", "runs", "--out at an earlier result folder holding a user's notebook (re-run)", "accept", notebook,
        check=lambda c, p: ((c.tmp / "o" / "analysis.ipynb").is_file(), "notebook kept"),
        lost=lambda c: not (c.tmp / "o" / "analysis.ipynb").is_file(), timeout=120)
    add("R02", "runs", "--out is an existing file", "error",
        lambda c: (c.write("o", "user data"), ["run", base, "--out", "o"])[1],
        lost=lambda c: not (c.tmp / "o").is_file() or (c.tmp / "o").read_text() != "user data")
    add("R03", "runs", "engine forced off (fault: power command 0 W from 1 s): vehicle misses the trace", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + '\n[[faults]]\nat_s = 1.0\n'
                                              'port = "engine_generator.power_cmd_w"\nvalue = 0.0\n')),
                   "--out", "o"], timeout=120)
    add("R04", "runs", "Ctrl-C six seconds into a long run (HD-UDDS x50)", "accept",
        lambda c: ["run", base, "--set", "cycle.repeat=50", "--out", "o"], sigint_after=6.0, check=_sigint_check,
        timeout=90)
    add("R05", "runs", "unknown CLI sub-command", "error", lambda c: ["rnu", base])
    add("R06", "fmu", "type = \"fmu\" with a corrupt .fmu file", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s.replace(
            'type = "bus"\nparams = "components/bus/default.toml"',
            f'type = "fmu"\nfmu = "{c.write("bad.fmu", b"PK not a zip")}"'))), "--out", "o"])
    add("F01", "fmu", "FMU whose doStep blocks for an hour (default bound; case limit 75 s)",
        "error",
        lambda c: ["run", str(_faulty_scenario(c, "block_at_s = 0.2, block_for_s = 3600.0")), "--out", "o"],
        timeout=75)
    add("F02", "fmu", "FMU whose doStep blocks, scenario bound step_timeout_s = 2", "error",
        lambda c: ["run", str(_faulty_scenario(c, "block_at_s = 0.2, block_for_s = 3600.0, step_timeout_s = 2.0")),
                   "--out", "o"], timeout=60)
    add("F03", "fmu", "FMU whose doStep raises RuntimeError (its text must reach the user)", "error",
        lambda c: ["run", str(_faulty_scenario(c, "fail_at_s = 0.2")), "--out", "o"], timeout=60,
        check=None)
    _second_pass(add, base)
    return C


# ------------------------------------------------------------------------------ issue 22: second pass

def _earlier_result(c, out="o", scenario="hd_udds_rule", engine="fast") -> Path:
    """A complete earlier result in ``out`` (a short run of this tree), plus a user's notebook and data in it."""
    o = c.tmp / out
    subprocess.run([PY, "-m", "shevsim.cli", "run", scenario, "--set", "scenario.stop_s=30", "--engine", engine,
                    "--no-plots", "-q", "--out", str(o)], cwd=c.tmp, env=_env(c.tree), check=True,
                   capture_output=True, timeout=600)
    (o / "notebook.ipynb").write_text('{"cells": []}')
    (o / "data.csv").write_text("a,b\n1,2\n")
    c.extra["earlier"] = {p.name: p.read_bytes() for p in o.iterdir() if p.is_file()}
    return o


def _forge_files(files):
    def setup(c):
        o = _earlier_result(c)
        meta = json.loads((o / "run.json").read_text())
        meta["files"] = files
        (o / "run.json").write_text(json.dumps(meta))
        c.extra["earlier"]["run.json"] = (o / "run.json").read_bytes()
        return ["run", "hd_udds_rule", "--set", "scenario.stop_s=30", "--no-plots", "--out", "o"]
    return setup


def _users_files_lost(c) -> bool:
    o = c.tmp / "o"
    return any(not (o / n).is_file() or (o / n).read_bytes() != b for n, b in c.extra.get("earlier", {}).items()
               if n in ("notebook.ipynb", "data.csv"))


def _earlier_lost(c) -> bool:
    """The earlier complete result (or a user's file in its folder) was removed or changed."""
    o = c.tmp / "o"
    return any(not (o / n).is_file() or (o / n).read_bytes() != b for n, b in c.extra.get("earlier", {}).items())


def _partial_kept(c, proc):
    """A stopped run: its partial result saved (in o or beside it) with rows, and the time to stop."""
    import glob
    cands = [Path(p) for p in glob.glob(str(c.tmp / "o-interrupted-*"))] + [c.tmp / "o"]
    code = ("import sys, json; from shevsim.core.results import load_result; r = load_result(sys.argv[1]); "
            "print(json.dumps([len(r), str(r.termination)]))")
    for d in cands:
        if (d / "run.json").is_file() and json.loads((d / "run.json").read_text()).get("termination", "") != "completed":
            r = subprocess.run([PY, "-c", code, str(d)], capture_output=True, text=True, env=_env(c.tree), timeout=120)
            if r.returncode == 0:
                rows, term = json.loads(r.stdout.strip().splitlines()[-1])
                where = "beside the earlier result" if d.name != "o" else "in o"
                return rows > 1, (f"exit {proc.returncode}, stopped {c.extra.get('stop_s', float('nan')):.1f} s after "
                                  f"the signal; partial result {where}: {rows} rows; earlier result kept")
    return False, f"exit {proc.returncode}, stopped {c.extra.get('stop_s', float('nan')):.1f} s after the signal; no partial result"


def _export_target(name):
    def setup(c):
        p = c.write(name, b"the user's own file")
        c.extra["target"] = p
        if name.endswith(".fmu"):
            return ["fmu", "export", "vehicle", "--params", str(c.tree / "components/vehicle/matv.toml"), "-o", name]
        return ["fmu", "export-ssp", "hd_udds_rule", "-o", name]
    return setup


def _target_lost(c) -> bool:
    return c.extra["target"].read_bytes() != b"the user's own file"


def _big_md_fmu() -> Path:
    """An FMU whose modelDescription.xml unpacks to 2 GiB (2 MiB compressed), built once."""
    import zipfile
    out = _FMU_CACHE / "big_md.fmu"
    if not out.is_file():
        _FMU_CACHE.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(".part")
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
            with zf.open("modelDescription.xml", "w", force_zip64=True) as f:
                f.write(b'<?xml version="1.0"?><fmiModelDescription fmiVersion="2.0" modelName="big" guid="x">'
                        b'<!--')
                block = b" " * (1 << 20)
                for _ in range(2048):
                    f.write(block)
                f.write(b"--></fmiModelDescription>")
        tmp.replace(out)
    return out


def _me_only_fmu() -> Path:
    """A model-exchange-only FMU: BouncingBall (Modelica Reference-FMUs, vendored) built for ME only."""
    out = _FMU_CACHE / "BouncingBall_me.fmu"
    if not out.is_file():
        _FMU_CACHE.mkdir(parents=True, exist_ok=True)
        own = Path(__file__).resolve().parents[1]
        code = ("import sys, shutil; from pathlib import Path; from shevsim.fmu.build import build_reference_fmu; "
                "build_reference_fmu('BouncingBall', Path(sys.argv[1]), 2, interfaces=('me',))")
        subprocess.run([PY, "-c", code, str(out)], env=_env(own), check=True, capture_output=True, timeout=600)
    return out


def _deep(kind: str, n: int) -> str:
    return ("x = " + "[" * n + "]" * n) if kind == "array" else ("x = " + "{a = " * n + "1" + "}" * n)


def _kmh_city_cycle(c) -> str:
    """HD-UDDS's first 200 s scaled to a 46.5 km/h top speed, written in km/h under a speed_mps header."""
    rows = [ln.split(",") for ln in (c.tree / "cycles" / "hd_udds.csv").read_text().splitlines()
            if ln and not ln.startswith("#")][1:]
    out = ["time_s,speed_mps"]
    for t, v in rows:
        if float(t) > 200:
            break
        out.append(f"{float(t):g},{float(v) * 3.6 * 0.85:.4f}")
    return "\n".join(out) + "\n"


def _tmpfs(c, size="400k") -> Path:
    d = c.tmp / "small_disk"
    d.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"needs root to mount a small tmpfs: {r.stderr.strip()}")
    return d


def _second_pass(add, base):
    # --- data loss ---------------------------------------------------------------------------------------
    add("L01", "data loss", 'run.json in --out forged with "files": [""] (a user notebook and data in the folder)',
        "accept", _forge_files([""]), lost=_users_files_lost, timeout=600,
        check=lambda c, p: (True, "notebook and data kept"))
    add("L02", "data loss", 'run.json in --out lists "notebook.ipynb" among its files', "accept",
        _forge_files(["run.json", "notebook.ipynb"]), lost=_users_files_lost, timeout=600,
        check=lambda c, p: (True, "notebook and data kept"))
    add("L03", "data loss", "SIGTERM 6 s into hd_udds_mpc x200 (compiled path) into a folder with an earlier result",
        "accept", lambda c: (_earlier_result(c), ["run", "hd_udds_mpc", "--set", "cycle.repeat=200", "--engine",
                                                 "fast", "--no-plots", "--out", "o"])[1],
        sigint_after=6.0, signame="SIGTERM", lost=_earlier_lost, check=_partial_kept, timeout=240)
    add("L04", "data loss", "Ctrl-C 6 s into hd_udds_rule x200 (Python master) into a folder with an earlier result",
        "accept", lambda c: (_earlier_result(c), ["run", "hd_udds_rule", "--set", "cycle.repeat=200", "--engine",
                                                 "python", "--no-plots", "--out", "o"])[1],
        sigint_after=6.0, signame="SIGINT", lost=_earlier_lost, check=_partial_kept, timeout=240)
    add("L05", "data loss", "fmu export -o model.fmu over a user's existing model.fmu", "error",
        _export_target("model.fmu"), lost=_target_lost, timeout=600)
    add("L06", "data loss", "fmu export-ssp -o system.ssp over a user's existing system.ssp", "error",
        _export_target("system.ssp"), lost=_target_lost, timeout=900)
    # --- environment and input that made internal errors -------------------------------------------------
    add("E01", "environment", "TOML value nested 100 000 arrays deep (scenario)", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + "\n[metrics]\n" + _deep("array", 100_000) + "\n")),
                   "--out", "o"], want="nested too deeply")
    add("E02", "environment", "TOML value nested 3000 inline tables deep (--params overlay)", "error",
        lambda c: ["run", base, "--params", f"vehicle={c.write('deep.toml', _deep('table', 3000) + chr(10))}",
                   "--out", "o"], want="nested too deeply")
    add("E03", "environment", "full disk (ENOSPC) while saving: --out on a 400 kB tmpfs", "error",
        lambda c: ["run", base, "--no-plots", "--out", str(_tmpfs(c) / "o")], want="No space left",
        cleanup=lambda c: subprocess.run(["umount", str(c.tmp / "small_disk")], capture_output=True))
    add("E04", "environment", "file-size limit (EFBIG, ulimit -f 300 kB) while saving", "error",
        lambda c: ["run", base, "--no-plots", "--out", "o"], fsize=300_000, want="File too large")
    add("E05", "environment", "FMU whose modelDescription.xml unpacks to 2 GiB", "error",
        lambda c: ["info", str(_big_md_fmu())], want="limit", timeout=120)
    add("E06", "environment", "non-ASCII --out under an ASCII-only locale (LC_ALL=C, PYTHONUTF8=0)", "accept",
        lambda c: ["run", base, "--set", "scenario.stop_s=30", "--out", "r\u00e9sultat"],
        env={"LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"},
        check=lambda c, p: (any(c.tmp.glob("r*sultat/run.json")), "saved"))
    add("E07", "environment", "non-ASCII component name under an ASCII-only locale (shevsim info)", "accept",
        lambda c: ["info", str(c.copy_scenario(base, lambda s: s.replace("[components.bus]", '[components."b\u00fas"]')
                                               .replace('"bus.', '"b\u00fas.').replace('"bus", "battery"', '"b\u00fas", "battery"')))],
        env={"LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"})
    add("E08", "environment", "stdout on a full device (shevsim scenarios > /dev/full)", "error",
        lambda c: ["scenarios"], stdout_to="/dev/full", want="standard output")
    # --- silent acceptance ------------------------------------------------------------------------------
    add("Q01", "silent", "[metrics] misspelt key fuel_densty_kg_per_l", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + "\n[metrics]\nfuel_densty_kg_per_l = 0.75\n")),
                   "--out", "o"], want="fuel_density_kg_per_l")
    add("Q02", "silent", '[metrics] fuel_density_kg_per_l = "abc"', "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + '\n[metrics]\nfuel_density_kg_per_l = "abc"\n')),
                   "--out", "o"])
    add("Q03", "silent", "300 000 unknown [metrics] keys", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + "\n[metrics]\n" + "".join(
            f"k{i} = 1\n" for i in range(300_000)))), "--out", "o"], timeout=120)
    add("Q04", "silent", "fault at_s = -5.0 (before the run starts)", "error",
        lambda c: ["run", str(c.copy_scenario(base, lambda s: s + '\n[[faults]]\nat_s = -5.0\n'
                                              'port = "battery.h_conv_w_m2k"\nvalue = 3.0\n')), "--out", "o"])
    add("Q05", "silent", "--set 'vehicle.mass_kg=1<newline>[components.x]<newline>type=\"os:system\"'", "error",
        lambda c: ["run", base, "--set", 'vehicle.mass_kg=1\n[components.x]\ntype="os:system"', "--out", "o"],
        want="one value")
    # --- bounded work -----------------------------------------------------------------------------------
    add("B01", "bounded", "calibrate on a 2 000 000-row cell record (no --allow-large)", "error",
        lambda c: ["calibrate", "cell", str(c.write("rec.csv", cell_record(n=2_000_000, dt=0.1, heat=0.05))), "-o", "cal",
                   "--no-plots"], want="rows", timeout=120)
    # --- errors that blame the right thing ----------------------------------------------------------------
    add("W01", "blame", "--params overlay with an unknown key (vehicle.mass_kgg)", "error",
        lambda c: ["run", base, "--params", str(c.write("ov.toml", "[vehicle]\nmass_kgg = 5.0\n")), "--out", "o"],
        want="ov.toml")
    add("W02", "blame", "--params overlay with mass_kg = nan", "error",
        lambda c: ["run", base, "--params", str(c.write("ov.toml", "[vehicle]\nmass_kg = nan\n")), "--out", "o"],
        want="ov.toml")
    add("W03", "blame", "cycle_file that is a folder", "error",
        lambda c: (c.tmp.joinpath("cyc").mkdir(), ["run", base, "--set", "cycle.cycle_file='cyc'", "--out", "o"])[1],
        want="folder")
    add("W04", "blame", "cycle_file = /dev/zero", "error",
        lambda c: ["run", base, "--set", "cycle.cycle_file='/dev/zero'", "--out", "o"], want="device", timeout=60)
    add("W05", "blame", "cycle_file = /dev/urandom", "error",
        lambda c: ["run", base, "--set", "cycle.cycle_file='/dev/urandom'", "--out", "o"], want="device", timeout=60)
    add("W06", "blame", "model-exchange-only FMU with interface = \"cs\" (a co-simulation slot)", "error",
        lambda c: ["run", str(c.write("me.toml", f'[scenario]\nstep_s = 0.01\nstop_s = 1.0\n[components.ball]\n'
                                                 f'type = "fmu"\nfmu = "{_me_only_fmu()}"\nset = {{ interface = "cs" }}\n')),
                   "--out", "o"], want="model", timeout=600)
    add("W07", "blame", "study tradeoff --max-evaluations 0", "error",
        lambda c: ["study", "tradeoff", base, "--max-evaluations", "0", "--out", "st"], want_rc=2)
    add("W08", "blame", "FMU set parameter of the wrong type (block_at_s = \"abc\")", "error",
        lambda c: ["run", str(_faulty_scenario(c, 'block_at_s = "abc"')), "--out", "o"], want_rc=2, timeout=60)
    add("W09", "blame", "cycle in km/h whose top speed is 46.5 km/h (under 50 km/h)", "error",
        lambda c: ["run", base, "--set", f"cycle.cycle_file='{c.write('cyc.csv', _kmh_city_cycle(c))}'",
                   "--out", "o"], want="km/h")


_FMU_CACHE = Path(tempfile.gettempdir()) / "shevsim_bad_inputs_fmu"


def _faulty_fmu() -> Path:
    """py_faulty.fmu (fmus/src/py_faulty, pythonfmu) built once with this script's own checkout, so both
    columns step the same FMU file."""
    out = _FMU_CACHE / "py_faulty.fmu"
    if not out.is_file():
        _FMU_CACHE.mkdir(parents=True, exist_ok=True)
        own = Path(__file__).resolve().parents[1]
        code = ("import sys; from pathlib import Path; from shevsim.fmu.build import build_python_fmu; "
                "build_python_fmu(Path(sys.argv[1]), Path(sys.argv[2]), 2)")
        subprocess.run([PY, "-c", code, str(own / "fmus" / "src" / "py_faulty" / "py_faulty.py"), str(out)],
                       env=_env(own), check=True, capture_output=True, timeout=300)
    return out


def _faulty_scenario(c, sets: str) -> Path:
    fmu = _faulty_fmu()
    return c.write("f.toml", f'[scenario]\nstep_s = 0.1\nstop_s = 1.0\n[components.pump]\ntype = "fmu"\n'
                             f'fmu = "{fmu}"\nset = {{ {sets} }}\nstart = {{ u = 2.0 }}\n')


# ------------------------------------------------------------------------------------------ running

def _env(tree: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("SHEVSIM_TRACEBACK", "PYTHONPATH")}
    env["PYTHONPATH"] = str(tree)
    env["MPLBACKEND"] = "Agg"
    env["OPENBLAS_NUM_THREADS"] = "1"
    return env


def classify(case: Case, ctx: Ctx, proc, hung: bool) -> tuple[str, str]:
    out = (proc.stdout or "") + (proc.stderr or "") if proc is not None else ""
    if case.lost is not None and case.lost(ctx):
        return "data loss", "a file the user owned was removed or changed"
    if hung:
        return "hang", f"killed after {case.timeout:g} s"
    msg = next((ln.strip() for ln in reversed((proc.stderr or "").splitlines())
                if ln.strip() and not ln.startswith(" ")), "")
    if "Traceback (most recent call last)" in out or "internal error" in out:
        last = [ln for ln in (proc.stderr or "").splitlines() if ln.strip()]
        return "traceback", (last[-1].strip() if last else "")[:400]
    if proc.returncode != 0 and case.sigint_after is None:
        if case.want_rc is not None and proc.returncode != case.want_rc:
            return "misleading", f"exit {proc.returncode} (expected {case.want_rc}): {msg[:380]}"
        if case.want is not None and case.want.lower() not in out.lower():
            return "misleading", f"does not say '{case.want}': {msg[:380]}"
        return "clear error", msg[:400]
    if case.check is not None:
        ok, note = case.check(ctx, proc)
        if ok:
            return "handled", note
        return ("silent" if proc.returncode == 0 else "clear error"), note or msg[:400]
    if case.expect == "error":
        return "silent", "exit 0: the bad input was accepted"
    return "handled", ""


def run_case(case: Case, tree: Path) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix=f"bad_{case.cid}_"))
    ctx = Ctx(tree, tmp)
    t0 = time.perf_counter()
    try:
        argv = case.setup(ctx)
        cmd = [PY, *argv] if isinstance(argv, tuple) else [PY, "-m", "shevsim.cli", *argv]
        env = _env(tree)
        env.update(case.env or {})
        stdout = open(case.stdout_to, "w") if case.stdout_to else subprocess.PIPE

        def pre():
            signal.signal(signal.SIGINT, signal.SIG_DFL)     # as a foreground process started by a user
            if case.fsize is not None:
                import resource
                resource.setrlimit(resource.RLIMIT_FSIZE, (case.fsize, case.fsize))
        p = subprocess.Popen(cmd, cwd=tmp, env=env, stdout=stdout, stderr=subprocess.PIPE,
                             text=True, start_new_session=True, preexec_fn=pre)
        hung = False
        try:
            if case.sigint_after is not None:
                try:
                    p.wait(timeout=case.sigint_after)
                except subprocess.TimeoutExpired:
                    os.kill(p.pid, getattr(signal, case.signame))
                    ctx.extra["signal_sent"] = time.perf_counter()
            out, err = p.communicate(timeout=case.timeout)
            if "signal_sent" in ctx.extra:
                ctx.extra["stop_s"] = time.perf_counter() - ctx.extra["signal_sent"]
        except subprocess.TimeoutExpired:
            hung = True
            os.killpg(p.pid, signal.SIGKILL)
            out, err = p.communicate()
        if case.stdout_to:
            stdout.close()
        proc = subprocess.CompletedProcess(cmd, p.returncode, out or "", err)
        outcome, note = classify(case, ctx, proc, hung)
    except Exception as exc:  # the harness's own failure is reported, not hidden
        outcome, note = "harness error", f"{type(exc).__name__}: {exc}"
    finally:
        if case.cleanup is not None:
            try:
                case.cleanup(ctx)
            except Exception:  # noqa: BLE001
                pass
    wall = time.perf_counter() - t0
    shutil.rmtree(tmp, ignore_errors=True)
    return {"id": case.cid, "group": case.group, "what": case.what, "expect": case.expect, "outcome": outcome,
            "note": note, "wall_s": round(wall, 2)}


def merge_markdown(before: dict, after: dict) -> str:
    b = {r["id"]: r for r in before["results"]}
    rows = after["results"]
    L = ["# Bad inputs and faults: before and after (issues 13 and 22)", "",
         f"Generated by `python benchmarks/bad_inputs.py` (see its docstring). **Before**: the session-start "
         f"commit `{before.get('commit', '?')}` in a separate worktree; **after**: `{after.get('commit', '?')}`"
         f"{' plus uncommitted work in the tree' if after.get('dirty') else ''}, run {after.get('date', '')}. "
         "Each case runs as a subprocess (`python -m shevsim.cli ...`, or `python -c` for the Python-API rows) "
         "in its own temporary folder; the outcome is classified from the exit status, the output and a "
         "post-check:", "",
         "- **clear error**: refused, non-zero exit, no traceback (the message is quoted);",
         "- **handled**: accepted and right (a quirk converted, a fault reported, the user's file kept);",
         "- **misleading**: refused, but the message blames the wrong thing (or the exit code is not the "
         "documented one);",
         "- **silent**: accepted although wrong, or the problem not said;",
         "- **traceback**: a Python traceback / internal error reached the user;",
         "- **hang**: killed at the case's time limit; **data loss**: a user's file removed or changed.", ""]
    cnt_b, cnt_a = {}, {}
    for r in rows:
        cnt_a[r["outcome"]] = cnt_a.get(r["outcome"], 0) + 1
        ob = b.get(r["id"], {}).get("outcome", "-")
        cnt_b[ob] = cnt_b.get(ob, 0) + 1
    keys = ["clear error", "handled", "misleading", "silent", "traceback", "hang", "data loss", "harness error"]
    L += ["| outcome | before | after |", "|---|---|---|"]
    for k in keys:
        if cnt_b.get(k) or cnt_a.get(k):
            L.append(f"| {k} | {cnt_b.get(k, 0)} | {cnt_a.get(k, 0)} |")
    L += ["", f"{len(rows)} cases. Messages are quoted with the case's temporary folder removed.", "",
          "| # | group | input or fault | expected | before | after | message / note (after) | before: message / note |",
          "|---|---|---|---|---|---|---|---|"]

    def short(text, n):
        import re
        text = re.sub(r"/tmp/bad_[A-Z][0-9]+_[^/ ]+/", "", text or "").replace("|", "\\|").replace("\n", " ")
        return text if len(text) <= n else text[:n - 3] + "..."
    for r in rows:
        rb = b.get(r["id"], {})
        ob = rb.get("outcome", "-")
        L.append(f"| {r['id']} | {r['group']} | {r['what']} | {'refuse' if r['expect'] == 'error' else 'accept/report'} "
                 f"| {ob} | **{r['outcome']}** | {short(r['note'], 300)} | {short(rb.get('note', ''), 110)} |")
    L += ["", NOTES, "", HOW_CHECKED]
    return "\n".join(L)


NOTES = """## Reading the table

- **Before** is the session start of each pass: the S/P/M/C/K/R/F rows of issue 13 were measured against the
  start of issue 22 too (`42827a5`), so their before column already holds issue 13's fixes; the L/E/Q/B/W rows
  are issue 22's cases.
- **L03/L04 (a stopped run)**: the note gives the time from the signal to the process's exit (the loop
  stops within one chunk of ~0.2 s on the compiled path, at once on the master; the rest is writing the
  partial record, proportional to its length) and where the partial result went: beside the earlier result,
  in `o-interrupted-<UTC time>`, while the earlier complete result in `o` is kept byte for byte.
- **L01/L02**: a forged `run.json` no longer decides what is removed. Each file shevsim may replace is a
  plain name it writes, listed in run.json with the SHA-256 recorded when it was written and checked before
  it is replaced; here the earlier files are no longer vouched for, so the run is refused before it starts
  (clear error) and nothing in the folder is touched.
- **F01**: a blocking `doStep` is now bounded by `step_timeout_s`, default 30 s (was 600 s): the run stops
  with the FMU, the time and the bound named, within this case's 75 s limit; F02 shows a scenario's own bound.
- **W06** was already clear before (`interface = "cs"` on a model-exchange-only FMU names the interfaces the
  FMU has); the "undefined symbol" the issue reports comes from a binary that lacks the declared interface's
  functions, now said as such (tested with the symbol lookup failing, `tests/unit/test_fmu_faults.py`).
- **misleading** marks a refusal that blames the wrong thing (the base parameter file for an overlay's
  value, "not found" for a folder or a device) or exits with another code than the documented one (3 for a
  usage error, 1 for a bad FMU parameter)."""


HOW_CHECKED = """## How inputs are checked (what the "after" column relies on)

- **One validation layer for every number** (`shevsim/core/params.py`). Each numeric field of a component's
  parameter dataclass has one physical range, declared once: `dataclasses.field(metadata=rng(...))` on the
  field, or else the unit-suffix convention of its name (`NAME_RULES`: `_pct` in [0, 100], `_frac` in [0, 1],
  `_c` above absolute zero, `_kg`/`_ah`/`_ohm`/`_f`/densities/heat capacities > 0, durations `_s` and
  lengths `_m` >= 0, noise and covariance tunings `sigma_`/`q_`/`r_`/`p0_`/`s0_` >= 0, efficiencies in
  (0, 1], counts `n_*` >= 1, ...). NaN is always refused, +-inf only where a field declares `allow_inf`
  ("no limit": `bms.i_cell_max_a`, `motor.regen_power_max_w`). Fields named alike except for min/max are a
  pair (min <= max). The check runs in `make_params` (parameter files, scenario `set` tables, `--set`,
  overlays; defaults included) and in `Component.__init__` (objects built through the Python API). The
  message names the file or the `--set` option, the field and the valid range.
- **Maps and tables** (`shevsim/powertrain/maps.py`, `shevsim/battery/cell.py`): the same name rules apply to
  the columns a loader reads (`efficiency_frac` in (0, 1], `fuel_gps` >= 0, `rs_ohm` > 0); a NaN cell is
  named by its file line and column; duplicate grid nodes are refused.
- **Scenario options**: the `[metrics]` table and `--set metrics.*` are checked by the same name rules
  (`fuel_density_kg_per_l` > 0).
- **Units on data** (`shevsim/cycles.py`, `shevsim/calibrate/data.py`): a unit declared in the header
  (`speed_kmh`, `speed_mph`, `time_ms`, `current_ma`, `power_kw`, `t_surface_k`, `voltage_mv`) or by
  `shevsim calibrate --unit time_s=ms` is converted; an undeclared unit that looks wrong is refused saying
  what was detected and how to declare it: cycle speed > 50 m/s (km/h), cycle or record step >= 10 s (ms),
  cycle acceleration > 10 m/s^2, vehicle-record speed changing slower than 0.02 m/s^2 (ms), a cell's
  dV/dI below 0.1 mOhm with currents above 50 (mA), temperatures > 150 degC median (K), voltage median > 100
  (mV), engine power below 2 kW (kW).
- **Spreadsheet quirks** are read as they come: UTF-8 byte-order mark, CRLF, `;` separators with decimal
  commas, tabs, trailing empty columns. A record row longer than its header is an error (never truncated).
- **Identifiability** (`shevsim/calibrate/workflow.py: identifiability`): after the fit, the Jacobian of the
  training residual with respect to each parameter (normalised to its bound range) is taken by central
  differences; each channel is scaled by max(RMSE, noise floor), inflated for lag-1 autocorrelation. The
  covariance (J^T J)^-1 gives each parameter's 1-sigma uncertainty as a fraction of its range; above 0.1 the
  parameter is reported as **not identifiable** (report.json `not_identifiable`, report.md, the log), with its
  most correlated partner. Parameters on a bound are flagged as before, now with `identifiable`.
- **Result folders** (`shevsim/core/results.py`): run.json lists the files of a result with the SHA-256 of
  each as written; only plain names shevsim writes (`timeseries.*`, `run.json`, `metrics.json`,
  `scenario.toml`, `report.html`, `*.png`) whose content still has that hash are replaced or removed by a
  later run; a file changed or added since stops the run before it starts. A run stopped by Ctrl-C or
  SIGTERM saves its partial result at once (no figures); into a folder holding an earlier result it goes to
  `NAME-interrupted-<UTC time>` beside it. Exports (`fmu export`, `fmu export-ssp`) refuse an existing file
  unless `--force`.
- **Limits before reading**: FMU and SSP archives are checked from their directory (modelDescription.xml or
  SystemStructure.ssd at most 64 MiB, 2 GiB and 100 000 members unpacked); input paths that are folders or
  devices are named as such; a cycle CSV is at most 1 GiB; TOML nested beyond Python's recursion limit is a
  plain error; a `--set` value is exactly one TOML value on one line; a calibration record above 200 000 rows
  needs `--decimate K` or `--allow-large` (the refusal times one model simulation for an estimate; long
  calibrations log progress every 10 s).
- **The environment**: a write refused by the machine (ENOSPC, EFBIG, EDQUOT, read-only, full stdout) is a
  plain error naming the file and the limit, exit 2, with the temporary files removed; output streams never
  fail on a character the locale cannot encode (surrogate-escaped bytes are written back, others escaped).
- **`[metrics]`** is checked like component parameters: unknown options with a suggestion, types, ranges;
  `[[faults]]` must act within the run (`t0_s <= at_s < stop`); km/h read as m/s is caught also below
  50 km/h (`v dv/dt` above 100 W/kg).
- **Studies** (`shevsim/studies/`): `--supervisor` must name a component whose parameters hold the power-rate
  map, and a probe map must build, before any evaluation; a trade-off whose evaluations all failed exits 1.
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", type=Path, help="checkout to measure (PYTHONPATH root)")
    ap.add_argument("--label", default="after")
    ap.add_argument("--json", type=Path, help="write the results here")
    ap.add_argument("--only", nargs="+", help="case ids to run")
    ap.add_argument("--merge", nargs=2, type=Path, metavar=("BEFORE.json", "AFTER.json"))
    ap.add_argument("--markdown", type=Path, help="with --merge: write the table here")
    a = ap.parse_args(argv)
    if a.merge:
        before, after = (json.loads(p.read_text()) for p in a.merge)
        text = merge_markdown(before, after)
        if a.markdown:
            a.markdown.write_text(text)
        else:
            print(text)
        return 0
    tree = (a.tree or Path(__file__).resolve().parents[1]).resolve()
    cases = [c for c in _cases() if not a.only or c.cid in a.only]
    commit = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True).stdout.strip())
    results = []
    for c in cases:
        r = run_case(c, tree)
        results.append(r)
        print(f"{r['id']:4s} {r['outcome']:13s} {r['wall_s']:6.1f}s  {r['what'][:60]:60s} {r['note'][:90]}",
              flush=True)
    doc = {"label": a.label, "tree": str(tree), "commit": commit, "dirty": dirty,
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "results": results}
    if a.json:
        a.json.write_text(json.dumps(doc, indent=1))
    counts = {}
    for r in results:
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
    print(f"{len(results)} cases: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
