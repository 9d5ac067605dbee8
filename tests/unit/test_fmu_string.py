"""An FMU with a String input (pythonfmu3, FMI 3.0; fmus/src/py_labelled3): accepted, its String variable
listed and settable as a start value, and only a connection to it refused (issue 26).  The reference is
fmpy's own simulate_fmu on the same FMU with the same start values."""
from __future__ import annotations

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu3")

import shevsim  # noqa: E402
from shevsim.core.errors import ShevsimError  # noqa: E402
from shevsim.fmu import FMUComponent  # noqa: E402
from shevsim.fmu.build import build_python_fmu, fmu_sources_dir  # noqa: E402
from shevsim.fmu.info import fmu_info  # noqa: E402

pytestmark = pytest.mark.fmu


@pytest.fixture(scope="module")
def labelled_fmu(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmu_string") / "py_labelled3.fmu"
    return build_python_fmu(fmu_sources_dir() / "py_labelled3" / "py_labelled3.py", out, 3)


def _scenario(fmu, tmp_path, mode: str | None, connect_mode: bool = False) -> str:
    st = "" if mode is None else f'set = {{ mode = "{mode}" }}'
    extra = '"lab.mode" = "src.out_1"\n' if connect_mode else ""
    text = f"""
[scenario]
name = "labelled"
step_s = 0.5
stop_s = 2.0

[components.src]
type = "gain"
set = {{ gain = 0.0, offset = 3.0 }}

[components.lab]
type = "fmu"
fmu = "{fmu}"
{st}

[connections]
"lab.u" = "src.out_1"
{extra}"""
    p = tmp_path / f"labelled_{mode}_{connect_mode}.toml"
    p.write_text(text)
    return str(p)


def test_string_input_listed_and_not_a_port(labelled_fmu):
    c = FMUComponent("lab", labelled_fmu)
    try:
        assert c.value_variables["mode"]["type"] == "String"
        assert c.value_variables["mode"]["causality"] == "input"
        ports = {v.name for v in c.variables()}
        assert "mode" not in ports and {"u", "y"} <= ports
    finally:
        c.terminate()
    text = fmu_info(labelled_fmu)
    assert "input 'mode' (String, start 'single')" in text and "NOT usable" not in text


@pytest.mark.parametrize("mode, gain", [(None, 1.0), ("double", 2.0), ("negate", -1.0)])
def test_string_start_value_matches_fmpy(labelled_fmu, tmp_path, mode, gain):
    res = shevsim.simulate(_scenario(labelled_fmu, tmp_path, mode), engine="python")
    assert res.termination.ok
    starts = {"u": 3.0} if mode is None else {"u": 3.0, "mode": mode}
    ref = fmpy.simulate_fmu(str(labelled_fmu), stop_time=2.0, output_interval=0.5, start_values=starts)
    np.testing.assert_allclose(res["lab.y"][1:], ref["y"][1:], rtol=0, atol=0)
    np.testing.assert_allclose(res["lab.y"][1:], gain * 3.0)


def test_connecting_a_string_input_is_refused_by_name(labelled_fmu, tmp_path):
    with pytest.raises(ShevsimError, match=r"'mode' of component 'lab' is a String input.*cannot be connected"):
        shevsim.simulate(_scenario(labelled_fmu, tmp_path, "double", connect_mode=True), engine="python")
