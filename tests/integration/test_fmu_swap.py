"""Whole-vehicle run with the battery pack swapped for its exported FMU (issue 5 round trip)."""
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from shevsim.core.errors import ScenarioError
from shevsim.core.scenario import load_scenario
from shevsim.fmu.export import export_component
from shevsim.run import simulate

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.fmu


@pytest.fixture(scope="module")
def battery_fmu(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmu") / "battery.fmu"
    export_component("battery", ROOT / "components" / "battery" / "default.toml", out)
    return out


def _fmu_scenario(fmu_path, stop_s):
    text = (ROOT / "scenarios" / "hd_udds_fmu_battery.toml").read_text().replace('"fmus/battery.fmu"', f'"{fmu_path}"')
    return load_scenario(ROOT / "scenarios" / "hd_udds_fmu_battery.toml", [], text=text)


@pytest.mark.parametrize("stop_s", [150.0])
def test_fmu_battery_matches_native_whole_vehicle(battery_fmu, stop_s):
    native = load_scenario(ROOT / "scenarios" / "hd_udds_mpc.toml")
    native.stop_s = stop_s
    fmu = _fmu_scenario(battery_fmu, stop_s)
    fmu.stop_s = stop_s
    a = simulate(native)
    b = simulate(fmu)
    assert a.time_s.shape == b.time_s.shape
    common = [k for k in a.signals if k in b.signals and "solve_time" not in k]
    assert len(common) > 60
    worst = max(common, key=lambda k: float(np.max(np.abs(a[k] - b[k]) / (1.0 + np.abs(a[k])))))
    err = float(np.max(np.abs(a[worst] - b[worst]) / (1.0 + np.abs(a[worst]))))
    print(f"largest relative difference native vs FMU over {len(common)} signals: {err:.3g} ({worst})")
    # same model code on both sides, values exchanged as float64: agreement to round-off
    assert err < 1e-9, worst
    assert a["vehicle.speed_mps"].max() > 10.0


def test_missing_fmu_file_names_the_build_command(tmp_path):
    sc = _fmu_scenario(tmp_path / "nowhere.fmu", 10.0)
    from shevsim.core.scenario import build_master
    with pytest.raises(ScenarioError, match=r"field 'fmu': file .*nowhere.fmu' not found .*shevsim fmu export"):
        build_master(sc)


def test_fmu_travels_with_the_study_bundle(battery_fmu, tmp_path):
    """A study captures the user's FMU by content (issue 28): its evaluation runs, with the direct run's
    metrics, after the user's scenario folder and FMU are gone."""
    import shutil

    from shevsim.run import compute_run_metrics
    from shevsim.studies.evaluate import Evaluation
    user = tmp_path / "user"
    user.mkdir()
    shutil.copy(battery_fmu, user / "mybattery.fmu")
    text = (ROOT / "scenarios" / "hd_udds_fmu_battery.toml").read_text().replace('"fmus/battery.fmu"',
                                                                                 '"mybattery.fmu"')
    (user / "s.toml").write_text(text)
    sc = load_scenario(user / "s.toml")
    sc.stop_s = 30.0
    ref = compute_run_metrics(simulate(sc), sc)
    ev = Evaluation.make(user / "s.toml", stop_s=30.0)
    run, blobs = ev.payload()
    tok = [t for t in run.tokens() if t.endswith("/mybattery.fmu")]
    assert len(tok) == 1 and blobs[tok[0].split(":", 1)[1].split("/")[0]] == battery_fmu.read_bytes()
    shutil.rmtree(user)
    out = ev.run()
    assert "error" not in out, out
    nums = {k: float(v) for k, v in ref.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    assert len(nums) > 20 and all(out[k] == v for k, v in nums.items())


def test_bundled_fmu_scenario_is_built_then_captured_by_a_study(tmp_path, monkeypatch):
    """The bundled ``hd_udds_fmu_battery`` names ``fmus/battery.fmu``, which the package does not ship: a study
    builds it first through the same export as ``shevsim run`` (into the user cache), then captures its bytes;
    its evaluation gives the direct run's metrics."""
    from shevsim.core.paths import bundled_scenario, user_cache_dir
    from shevsim.run import compute_run_metrics
    from shevsim.studies.evaluate import Evaluation
    monkeypatch.setenv("SHEVSIM_CACHE_DIR", str(tmp_path / "cache"))     # built afresh, in a folder of the test's
    scen = bundled_scenario("hd_udds_fmu_battery")
    assert not (scen.parent.parent / "fmus" / "battery.fmu").exists()
    ev = Evaluation.make(scen, stop_s=5.0)
    run, blobs = ev.payload()
    built = list((user_cache_dir() / "fmus").glob("battery-*.fmu"))
    assert len(built) == 1
    tok = [t for t in run.tokens() if t.endswith(".fmu")]
    assert len(tok) == 1 and blobs[tok[0].split(":", 1)[1].split("/")[0]] == built[0].read_bytes()
    assert len(ev.key()) == 64
    out = ev.run()
    assert "error" not in out, out
    sc = load_scenario(scen)
    sc.stop_s = 5.0
    ref = compute_run_metrics(simulate(sc), sc)
    nums = {k: float(v) for k, v in ref.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    assert len(nums) > 20 and all(out[k] == v for k, v in nums.items())
