"""FMU faults (issue 13 items 5-7): a hanging doStep is bounded, the FMU's own exception text reaches the
error, unpack folders are removed even on failure; and a model-exchange FMU in a scenario file.

``py_faulty.fmu`` is built by the session from ``fmus/src/py_faulty`` (pythonfmu, FMI 2.0): dy/dt = u with
an injectable hang (``block_at_s``/``block_for_s``) and failure (``fail_at_s``).
"""
from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from shevsim.core.errors import SimulationError  # noqa: E402
from shevsim.fmu import FMUComponent, FMUStepError, FMUTimeoutError  # noqa: E402
from shevsim.fmu.adapter import sweep_stale_unpack_dirs  # noqa: E402
from shevsim.fmu.build import build_python_fmu, build_reference_fmu, fmu_sources_dir  # noqa: E402

pytestmark = pytest.mark.fmu


@pytest.fixture(scope="module")
def faulty(tmp_path_factory):
    d = tmp_path_factory.mktemp("faulty")
    return build_python_fmu(fmu_sources_dir() / "py_faulty" / "py_faulty.py", d / "py_faulty.fmu", 2)


def _unpack_dirs(name: str) -> set[str]:
    return {p.name for p in Path(tempfile.gettempdir()).glob(f"shevsim_fmu_{name}_*")}


def test_blocking_do_step_times_out_with_fmu_time_and_step(faulty):
    comp = FMUComponent("pump", faulty, parameters={"block_at_s": 0.2, "block_for_s": 3.0},
                        step_timeout_s=0.3)
    comp.initialize(0.0)
    comp.u["u"] = 2.0
    t0 = time.perf_counter()
    with pytest.raises(FMUTimeoutError) as ei:
        for k in range(10):
            comp.do_step(k * 0.1, 0.1)
    wall = time.perf_counter() - t0
    msg = str(ei.value)
    assert "'pump'" in msg and "py_faulty.fmu" in msg and "t = 0.2 s" in msg and "step to 0.3 s" in msg
    assert "0.3 s of wall time" in msg
    assert wall < 2.0, f"the timeout did not bound the step ({wall:.2f} s)"
    assert isinstance(ei.value, SimulationError)
    # the abandoned instance is not used again, and terminate still removes the unpack folder
    with pytest.raises(Exception, match="abandoned after a step that did not return"):
        comp.do_step(1.0, 0.1)
    before = _unpack_dirs("pump")
    comp.terminate()
    assert not (before and _unpack_dirs("pump") >= before)


def test_without_fault_the_bounded_step_is_the_same_as_the_direct_one(faulty):
    ys = []
    for bound in (None, 5.0):
        comp = FMUComponent("pump", faulty, step_timeout_s=bound)
        comp.initialize(0.0)
        for k in range(20):
            comp.u["u"] = math.sin(k)
            comp.do_step(k * 0.1, 0.1)
        ys.append(comp.y["y"])
        comp.terminate()
    assert ys[0] == ys[1]


def test_fmu_exception_text_is_carried_into_the_error(faulty):
    comp = FMUComponent("pump", faulty, parameters={"fail_at_s": 0.3}, step_timeout_s=None)
    comp.initialize(0.0)
    with pytest.raises(FMUStepError) as ei:
        for k in range(10):
            comp.do_step(k * 0.1, 0.1)
    msg = str(ei.value)
    assert "coolant pump model diverged at t = 0.3 s" in msg, msg
    assert "'pump'" in msg and "t = 0.3 s" in msg
    comp.terminate()


def test_unpack_folder_removed_when_initialisation_fails(faulty):
    before = _unpack_dirs("badinit")
    comp = FMUComponent("badinit", faulty)
    # a value the FMU refuses while it initialises (a wrong type is now refused when the component is built,
    # so it is put in after the build's check to reach the FMU's own initialisation)
    comp._parameters = {"block_at_s": "not a number"}
    with pytest.raises(Exception):
        comp.initialize(0.0)
    comp.terminate()
    assert _unpack_dirs("badinit") == before


def test_stale_unpack_folders_of_killed_runs_are_swept(tmp_path):
    # a folder with the owner marker of a process that is gone is removed; other folders are kept
    import subprocess
    import sys
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    stale = tmp_path / "shevsim_fmu_x_abc"
    stale.mkdir()
    (stale / ".shevsim_fmu_owner").write_text(f"{dead} some.fmu\n")
    os.utime(stale / ".shevsim_fmu_owner", (time.time() - 60, time.time() - 60))
    alive = tmp_path / "shevsim_fmu_y_def"
    alive.mkdir()
    (alive / ".shevsim_fmu_owner").write_text(f"{os.getpid()} other.fmu\n")
    foreign = tmp_path / "shevsim_fmu_user_notes"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    removed = sweep_stale_unpack_dirs(tmp_path, min_age_s=1.0)
    assert removed == [str(stale)]
    assert alive.is_dir() and (foreign / "notes.txt").is_file()


def test_model_exchange_fmu_in_a_scenario_file(tmp_path):
    """Same scenario syntax as a co-simulation FMU; solver and tolerance given in ``set``."""
    from shevsim.core.scenario import build_master, load_scenario
    fmu = build_reference_fmu("BouncingBall", tmp_path / "ball.fmu", 2, interfaces=("me",))
    sc = tmp_path / "ball.toml"
    sc.write_text('[scenario]\nname = "ball"\nstep_s = 0.01\nstop_s = 0.8\n\n'
                  '[components.ball]\ntype = "fmu"\nfmu = "ball.fmu"\n'
                  'set = { solver = "RK45", tolerance = 1e-10, e = 0.5 }\n')
    s = load_scenario(sc)
    m = build_master(s)
    assert m.components["ball"].kind == "me" and m.components["ball"].solver == "RK45"
    res = m.run(0.8)
    m.terminate()
    g, e = 9.81, 0.5
    t1 = math.sqrt(2 / g)
    v = e * g * t1                      # after the first bounce (e = 0.5 set in the scenario)
    t = 0.8
    h_exact = v * (t - t1) - 0.5 * g * (t - t1) ** 2
    assert t1 < t < t1 + 2 * v / g
    assert abs(res.signals["ball.h"][-1] - h_exact) < 1e-8


def test_stepped_component_dropped_without_terminate_is_freed(faulty):
    # the helper thread that runs bounded steps must not keep the component alive
    import gc
    comp = FMUComponent("dropped", faulty, step_timeout_s=30.0)
    comp.initialize(0.0)
    comp.do_step(0.0, 0.1)
    assert _unpack_dirs("dropped")
    del comp
    gc.collect()
    deadline = time.time() + 5.0
    while _unpack_dirs("dropped") and time.time() < deadline:
        time.sleep(0.05)
    assert not _unpack_dirs("dropped")


@pytest.mark.parametrize("fault", ["fail", "timeout"])
def test_a_run_stopped_by_an_fmu_keeps_its_trajectory(faulty, tmp_path, fault):
    """Issue 12 item 4 / issue 13 item 6 at run level: an FMU that fails (its own message) or hangs
    (doStep timeout) stops the run; the CLI saves the trajectory up to the stop, names the FMU component
    and the time, and exits 1."""
    import json

    import pandas as pd

    from shevsim.cli import main
    (tmp_path / "py_faulty.fmu").write_bytes(Path(faulty).read_bytes())
    opts = 'fail_at_s = 0.5' if fault == "fail" else 'block_at_s = 0.5, block_for_s = 3.0, step_timeout_s = 0.3'
    sc = tmp_path / "pump.toml"
    sc.write_text('[scenario]\nname = "pump"\nstep_s = 0.1\nstop_s = 2.0\n\n'
                  '[components.pump]\ntype = "fmu"\nfmu = "py_faulty.fmu"\n'
                  f'set = {{ {opts} }}\n')
    out = tmp_path / "out"
    assert main(["run", str(sc), "-o", str(out), "--no-plots"]) == 1
    run = json.loads((out / "run.json").read_text())
    term = run["termination_detail"]
    assert term["status"] == "stopped" and term["component"] == "pump"
    assert term["time_s"] == pytest.approx(0.5)
    if fault == "fail":
        assert "coolant pump model diverged" in term["reason"]
    else:
        assert "0.3 s of wall time" in term["reason"]
    df = pd.read_parquet(out / "timeseries.parquet")
    assert len(df) == 6 and df["time_s"].iloc[-1] == pytest.approx(0.5)     # t = 0 ... 0.5 s kept


def test_a_set_value_of_the_wrong_type_is_bad_input_before_instantiating(faulty, tmp_path):
    # issue 22: a string for a Real parameter used to fail at initialisation (a stopped run, exit 1)
    from shevsim.cli import main
    from shevsim.fmu import FMUMappingError
    with pytest.raises(FMUMappingError, match=r"'block_at_s' = 'abc'.*type Real and takes a number"):
        FMUComponent("pump", faulty, parameters={"block_at_s": "abc"})
    scen = tmp_path / "f.toml"
    scen.write_text(f'[scenario]\nstep_s = 0.1\nstop_s = 1.0\n[components.pump]\ntype = "fmu"\nfmu = "{faulty}"\n'
                    f'set = {{ block_at_s = "abc" }}\nstart = {{ u = 2.0 }}\n')
    assert main(["run", str(scen), "-o", str(tmp_path / "o"), "--no-plots", "-q"]) == 2
    assert not (tmp_path / "o").exists()


def test_the_default_step_bound_is_one_a_user_can_wait_for():
    from shevsim.fmu.adapter import DEFAULT_STEP_TIMEOUT_S
    assert 10.0 <= DEFAULT_STEP_TIMEOUT_S <= 60.0


def test_a_binary_without_the_interfaces_functions_is_named(faulty, monkeypatch):
    # issue 22: an FMU whose model description declares co-simulation while its binary implements only model
    # exchange fails in fmpy's library binding with "undefined symbol: fmi2DoStep"; the error says what it means
    import fmpy.fmi2
    from shevsim.fmu.errors import FMULoadError

    class NoDoStep(fmpy.fmi2.FMU2Slave):
        def __init__(self, *a, **k):
            raise AttributeError(f"{k.get('unzipDirectory')}/binaries/linux64/x.so: undefined symbol: fmi2DoStep")
    monkeypatch.setattr(fmpy.fmi2, "FMU2Slave", NoDoStep)
    with pytest.raises(FMULoadError, match=r"undefined symbol: fmi2DoStep - its binary does not implement "
                                           r"fmi2DoStep, a function of the co-simulation interface"):
        FMUComponent("cs", faulty)
