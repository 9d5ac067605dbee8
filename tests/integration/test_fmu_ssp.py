"""SSP round trip on the HD-UDDS rule scenario: export -> fmpy's SSP runner, and export -> import -> our master.

* fmpy (``fmpy.ssp.simulation.simulate_ssp``) runs the exported package. Its master is a Jacobi
  iteration whose connectors start at 0.0 and it records the values after each step at the step's
  start time; our master reproduces those semantics here (method "jacobi", the connected outputs
  zeroed before the first exchange) and the trajectories agree to 1e-10 (relative to 1 + |value|);
  measured: 2.3e-12 over 30 s. Over 300 s (slow) they are identical when our components are stepped
  with fmpy's accumulated time (time += step); with the master's t0 + k h, ulp-level time
  differences are amplified by the rule supervisor's thresholds after ~48 s.
* The imported package (a scenario of FMU components, step/method/order from the shevsim
  annotation) run by our master equals the native scenario exactly (same code, float64 exchange).

Default run: 30 s of the cycle (the export of nine FMUs takes ~25 s); slow: 300 s.
"""
from __future__ import annotations

import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from shevsim.core.paths import bundled_scenario  # noqa: E402
from shevsim.core.scenario import build_master, load_scenario  # noqa: E402
from shevsim.fmu.ssp import NS, export_ssp, import_ssp  # noqa: E402
from shevsim.run import simulate  # noqa: E402

pytestmark = pytest.mark.fmu


def _scenario_path() -> Path:
    return bundled_scenario("hd_udds_rule")


def _ours_with_fmpy_semantics(n_steps: int, accumulate_time: bool = False) -> dict[str, np.ndarray]:
    """Our master's Jacobi run with fmpy's zero-started connectors.

    ``accumulate_time``: step the master's schedule with fmpy's time arithmetic (``time += step``,
    e.g. 47.800000000000004 s instead of the master's t0 + k h = 47.8 s) instead of ``Master.step``.
    """
    sc = load_scenario(_scenario_path())
    sc.settings.method = "jacobi"
    m = build_master(sc)
    m.initialize(sc.t0_s)
    for c in m.connections:               # fmpy's connectors start at 0.0
        m.components[c.src].y[c.src_port] = 0.0
    rows = []
    time, h = sc.t0_s, sc.settings.step_s
    for k in range(n_steps):
        if accumulate_time:               # the master's Jacobi step (copy all, then step all) at fmpy's time
            for comp, links, mult in m._sched:
                if k % mult == 0:
                    for du, dk, sy, sk in links:
                        du[dk] = sy[sk]
            for comp, links, mult in m._sched:
                if k % mult == 0:
                    comp.do_step(time, mult * h)
            time += h
        else:
            m.step()
        rows.append({f"{n}.{p}": v for n, comp in m.components.items() for p, v in comp.y.items()})
    m.terminate()
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def _compare(ours, res):
    names = [n for n in res.dtype.names[1:] if n in ours]
    worst = max(names, key=lambda k: float(np.max(np.abs(ours[k] - res[k]) / (1.0 + np.abs(ours[k])))))
    err = float(np.max(np.abs(ours[worst] - res[worst]) / (1.0 + np.abs(ours[worst]))))
    return names, worst, err


def _round_trip(tmp_path: Path, stop_s: float, accumulate_time: bool = False):
    from fmpy.ssp.simulation import simulate_ssp
    ssp = export_ssp(_scenario_path(), tmp_path / "rule.ssp", stop_s=stop_s)
    res = simulate_ssp(str(ssp), stop_time=stop_s, step_size=0.1)
    ours = _ours_with_fmpy_semantics(len(res), accumulate_time)
    return (ssp, res, ours) + _compare(ours, res)


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    return _round_trip(tmp_path_factory.mktemp("ssp"), 30.0)


def test_ssp_package_structure(short):
    ssp = short[0]
    with zipfile.ZipFile(ssp) as zf:
        names = zf.namelist()
        root = ET.fromstring(zf.read("SystemStructure.ssd"))
    comps = root.findall("ssd:System/ssd:Elements/ssd:Component", NS)
    assert sorted(c.get("name") for c in comps) == sorted(
        ["cycle", "driver", "motor", "vehicle", "bus", "engine_generator", "battery", "bms", "supervisor",
         "motor_limits", "gen_limits"])             # limits held within the step (power_limits, issue 14)
    assert all(f"resources/{c.get('name')}.fmu" in names for c in comps)
    scen = load_scenario(_scenario_path())
    n_conn = len(root.findall("ssd:System/ssd:Connections/ssd:Connection", NS))
    m = build_master(scen)
    assert n_conn == len(m.connections)
    m.terminate()
    veh = next(c for c in comps if c.get("name") == "vehicle")
    params = {p.get("name"): float(p.find("ssv:Real", NS).get("value"))
              for p in veh.findall(".//ssv:Parameter", NS) if p.find("ssv:Real", NS) is not None}
    assert params["mass_kg"] > 1000.0


def test_fmpy_ssp_run_matches_ours(short):
    _, res, ours, names, worst, err = short
    assert len(names) > 60 and len(res) == 300
    print(f"fmpy simulate_ssp vs shevsim (Jacobi, zero start), {len(names)} outputs: {err:.3g} ({worst})")
    assert err < 1e-10, worst
    assert ours["vehicle.speed_mps"].max() > 1.0       # the vehicle moved


def test_imported_ssp_equals_native_scenario(short, tmp_path):
    from shevsim.core.errors import ScenarioError
    user = tmp_path / "mine"
    user.mkdir()
    (user / "battery.fmu").write_text("a user's file")
    with pytest.raises(ScenarioError, match="already holds battery.fmu"):
        import_ssp(short[0], user)
    assert (user / "battery.fmu").read_text() == "a user's file"
    scen = import_ssp(short[0], tmp_path / "imported")
    assert import_ssp(short[0], tmp_path / "imported") == scen       # re-import into its own folder
    si = load_scenario(scen)
    si.stop_s = 30.0
    sn = load_scenario(_scenario_path())
    sn.stop_s = 30.0
    ri, rn = simulate(si), simulate(sn)
    common = [k for k in rn.signals if k in ri.signals]
    assert len(common) == len(rn.signals)
    for k in common:
        np.testing.assert_allclose(ri[k], rn[k], rtol=1e-12, atol=1e-12, err_msg=k)


def test_import_rejects_non_ssp(tmp_path):
    from shevsim.core.errors import ScenarioError
    bad = tmp_path / "x.ssp"
    bad.write_text("not a zip")
    with pytest.raises(ScenarioError, match="not an SSP package"):
        import_ssp(bad, tmp_path / "out")
    with pytest.raises(ScenarioError, match="SSP file not found"):
        import_ssp(tmp_path / "nowhere.ssp", tmp_path / "out")


@pytest.mark.slow
def test_fmpy_ssp_run_matches_ours_300_s(tmp_path):
    """300 s: with fmpy's own time arithmetic the trajectories are identical; with the master's
    (t0 + k h) they part after ~48 s: fmpy's time += 0.1 drifts by ulps (47.800000000000004), the
    components' time-dependent logic sees it (1e-10 in the BMS's convection estimate at step 478),
    and the rule supervisor's thermostat amplifies it. Measured: 0.0 and 0.99 (bus.battery_power_w)."""
    _, res, ours, names, worst, err = _round_trip(tmp_path, 300.0, accumulate_time=True)
    print(f"300 s: fmpy simulate_ssp vs shevsim components at fmpy's time: {err:.3g} ({worst})")
    assert err < 1e-12, worst
    names, worst_m, err_m = _compare(_ours_with_fmpy_semantics(len(res)), res)
    print(f"300 s: fmpy simulate_ssp vs shevsim master (t0 + k h): {err_m:.3g} ({worst_m})")
