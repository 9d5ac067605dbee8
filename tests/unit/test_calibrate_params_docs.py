"""The ``--params`` nominal as documented (trial 40: the baseline-failure text told a user to give their own
``discharge_file``, but no page said what that file is): the example of ``docs/getting_started.md`` ("Calibrating
your own record") is parsed as written, its R/C table is the battery's, and the help points to the page."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from shevsim.calibrate.cli import build_parser, load_params_toml

DOC = Path(__file__).resolve().parents[2] / "docs" / "getting_started.md"
SECTION = "### Calibrating your own record"


def _examples() -> dict[str, str]:
    """The section's fenced examples by the file name of their first (comment) line."""
    text = DOC.read_text(encoding="utf-8")
    assert SECTION in text
    sec = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    out = {}
    for lang, body in re.findall(r"```(\w+)\n(.*?)```", sec, flags=re.S):
        name = body.splitlines()[0].lstrip("# ").strip()
        out[name] = body
    return out


def test_documented_params_example_loads_and_its_ecm_table_is_the_cells(tmp_path):
    from shevsim.battery.cell import CellTables
    from shevsim.calibrate.cell import CellModel
    ex = _examples()
    assert set(ex) == {"my_cell.toml", "my_cell_ecm.csv"}, set(ex)
    for name, body in ex.items():
        (tmp_path / name).write_text(body, encoding="utf-8")
    known = load_params_toml(tmp_path / "my_cell.toml")
    m = CellModel(known, str(tmp_path / "my_cell.toml"))
    assert Path(m.base.discharge_file) == tmp_path / "my_cell_ecm.csv" == Path(m.base.charge_file)
    given = {d["parameter"] for d in m.defaults_used()}
    assert not given & {"capacity_ah", "ocv_file", "discharge_file", "radius_m", "length_m", "h_conv_w_m2k"}, given
    # the table as the battery reads it: bilinear in SOC and temperature, clamped at the edges
    t = CellTables(discharge_file=tmp_path / "my_cell_ecm.csv", charge_file=tmp_path / "my_cell_ecm.csv")
    assert t.params(0.5, 25.0, 1.0) == pytest.approx((0.025, 0.0125, 1750.0, 0.016, 25000.0))
    assert t.params(0.0, 17.5, -1.0) == pytest.approx((0.0375, 0.0225, 1250.0, 0.030, 17500.0))
    assert t.params(1.0, 60.0, 1.0) == pytest.approx((0.020, 0.010, 2000.0, 0.012, 30000.0))
    # the calibration's nominal reads the same table (in the short form, at 25 degC)
    assert m._tables().params(0.5, 25.0, 1.0) == pytest.approx((0.025, 0.0125, 1750.0, 0.016, 25000.0))
    assert m.known["ocv_soc_frac"] == (0.0, 0.5, 1.0)


def test_params_help_points_to_the_format():
    h = next(a.help for a in build_parser()._actions if "--params" in a.option_strings)
    assert "discharge_file" in h and "soc_frac,t_c,rs_ohm,r1_ohm,c1_f,r2_ohm,c2_f" in h
    assert "docs/getting_started.md" in h and "'Calibrating your own record'" in h
    assert SECTION[4:] in DOC.read_text(encoding="utf-8")
