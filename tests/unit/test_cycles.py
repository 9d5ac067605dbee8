"""Drive cycles: loader validation, statistics, the UAC proxy and the cycle source component."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from shevsim.components.cycle import CycleParams, CycleSource
from shevsim.core.errors import DataError, ScenarioError
from shevsim.core.params import load_params
from shevsim.cycles import cycle_from_arrays, cycles_command, list_cycles, load_cycle

ROOT = Path(__file__).resolve().parents[2]
CYCLES = ROOT / "cycles"


def write(tmp_path, text, name="c.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


# ------------------------------------------------------------------ shipped data
def test_hd_udds_matches_epa_totals():
    c = load_cycle(CYCLES / "hd_udds.csv")
    s = c.stats()
    # EPA UDDSHDV: 1060 s, 5.55 mi (8.93 km), 18.86 mph mean
    assert s["duration_s"] == 1060.0
    assert s["distance_m"] / 1609.344 == pytest.approx(5.55, abs=0.005)
    assert s["mean_speed_mps"] / 0.44704 == pytest.approx(18.86, abs=0.05)
    assert s["max_speed_mps"] * 3.6 == pytest.approx(93.3, abs=0.1)


def test_list_cycles_and_command_table():
    names = [c.name for c in list_cycles(CYCLES)]
    assert {"hd_udds", "orange_county_bus", "wvu_interstate", "uac_proxy"} <= set(names)
    table = cycles_command(CYCLES)
    assert "hd_udds" in table and "uac_proxy" in table and "8.935" in table and "8.800" in table


def test_command_lists_invalid_file(tmp_path):
    write(tmp_path, "time_s,speed_mps\n0,0\n1,1\n2,2\n", "good.csv")
    write(tmp_path, "time_s,speed_mps\n0,0\n1,nan\n2,2\n", "bad.csv")
    table = cycles_command(tmp_path)
    assert "good" in table
    assert "bad" in table and "INVALID" in table and "line 3" in table


# ---------------------------------------------------------------- validation
@pytest.mark.parametrize("text, line, column, words", [
    ("time,speed_mps\n0,0\n1,1\n", 1, "time_s", "missing column"),
    ("time_s,speed\n0,0\n1,1\n", 1, "speed_mps", "missing column"),
    ("time_s,speed_mps\n0,0\n1,nan\n2,1\n", 3, "speed_mps", "non-finite"),
    ("time_s,speed_mps\n0,0\n1,abc\n2,1\n", 3, "speed_mps", "not a number"),
    ("time_s,speed_mps\n0,0\n1,\n2,1\n", 3, "speed_mps", "missing value"),
    ("time_s,speed_mps\n0,0\n1,-0.5\n2,1\n", 3, "speed_mps", "negative speed"),
    ("time_s,speed_mps\n0,0\n1,1\n1,1\n2,1\n", 4, "time_s", "duplicate time"),
    ("time_s,speed_mps\n0,0\n2,1\n1,1\n3,1\n", 4, "time_s", "non-monotonic"),
    ("time_s,speed_mps\n0,0\n1,1\n2,1\n5,1\n6,1\n", 5, "time_s", "gap"),
    ("# c\ntime_s,speed_mps\n0,0\n1,inf\n", 4, "speed_mps", "non-finite"),
])
def test_bad_cycles_rejected_with_file_line_column(tmp_path, text, line, column, words):
    p = write(tmp_path, text)
    with pytest.raises(DataError) as ei:
        load_cycle(p)
    msg = str(ei.value)
    assert str(p) in msg and f"line {line}" in msg and f"'{column}'" in msg and words in msg


def test_empty_and_short_and_missing(tmp_path):
    with pytest.raises(DataError, match="empty"):
        load_cycle(write(tmp_path, "# only a comment\n"))
    with pytest.raises(DataError, match="at least 2"):
        load_cycle(write(tmp_path, "time_s,speed_mps\n0,0\n"))
    with pytest.raises(DataError, match="not found"):
        load_cycle(tmp_path / "nope.csv")


def test_comments_extra_columns_and_offset(tmp_path):
    p = write(tmp_path, "# provenance\n\nspeed_mps,grade,time_s\n# mid comment\n1.0,0,10.5\n2.0,0,11.0\n3.0,0,11.5\n")
    c = load_cycle(p)
    np.testing.assert_allclose(c.time_s, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(c.speed_mps, [1.0, 2.0, 3.0])
    assert c.time_offset_s == 10.5 and c.dt_s == 0.5


def test_from_arrays_checks():
    with pytest.raises(DataError, match="negative"):
        cycle_from_arrays("x", [0, 1, 2], [0, -1, 0])
    with pytest.raises(DataError, match="non-finite"):
        cycle_from_arrays("x", [0, 1, 2], [0, np.nan, 0])
    with pytest.raises(DataError, match="uniform"):
        cycle_from_arrays("x", [0, 1, 3], [0, 1, 0])


# ---------------------------------------------------------------- statistics
def test_statistics_of_a_trapezoid_trip():
    # idle 5 s, +1 m/s2 for 10 s, cruise 10 m/s for 20 s, -2 m/s2 for 5 s, idle 5 s
    v = np.concatenate([np.zeros(5), np.arange(0, 10, 1.0), np.full(21, 10.0), 10 - 2.0 * np.arange(1, 6),
                        np.zeros(5)])
    c = cycle_from_arrays("trip", np.arange(v.size), v)
    s = c.stats()
    dist = 50.0 + 200.0 + 25.0  # accel + cruise + decel, exact for a piecewise-linear trace
    assert s["distance_m"] == pytest.approx(dist)
    assert s["duration_s"] == v.size - 1
    assert s["max_speed_mps"] == 10.0
    assert s["accel_p95_mps2"] == pytest.approx(1.0) and s["accel_p50_mps2"] == pytest.approx(1.0)
    assert s["decel_p95_mps2"] == pytest.approx(2.0) and s["decel_max_mps2"] == pytest.approx(2.0)
    assert s["pke_mps2"] == pytest.approx(100.0 / (2 * dist))
    # RMS over all intervals: 10 intervals of 1, 5 of 2 (squared 4), rest 0
    assert s["rms_accel_mps2"] == pytest.approx(math.sqrt((10 * 1 + 5 * 4) / (v.size - 1)))
    # idle intervals: both ends below 0.1 m/s (v[0..5] and the 6 trailing zeros)
    assert s["idle_frac"] == pytest.approx((5 + 5) / (v.size - 1))
    assert s["n_stops"] == 1


# ---------------------------------------------------------------- UAC proxy
def test_uac_proxy_regenerates_identically(tmp_path):
    from shevsim.uac_proxy import write_uac_proxy
    out = write_uac_proxy(CYCLES, tmp_path / "uac_proxy.csv")
    assert out.read_text() == (CYCLES / "uac_proxy.csv").read_text()


def test_uac_proxy_distance_named_and_harsher_than_hd_udds():
    text = (CYCLES / "uac_proxy.csv").read_text()
    assert "proxy" in text.splitlines()[0].lower() and "NOT the Urban Assault Cycle" in text
    p = load_cycle(CYCLES / "uac_proxy.csv").stats()
    h = load_cycle(CYCLES / "hd_udds.csv").stats()
    assert p["distance_m"] == pytest.approx(8800.0, abs=10.0)
    # the stated harshness statistic: 95th percentiles of acceleration and deceleration, and PKE
    assert p["accel_p95_mps2"] > 1.2 * h["accel_p95_mps2"]
    assert p["decel_p95_mps2"] > 1.2 * h["decel_p95_mps2"]
    assert p["pke_mps2"] > 1.2 * h["pke_mps2"]


def test_uac_proxy_is_drivable_by_the_matv():
    """Independent check (own road-load assumptions, harsher than the generator's)."""
    c = load_cycle(CYCLES / "uac_proxy.csv")
    v = c.speed_mps
    a = np.diff(v)
    assert a.max() <= 2.0 + 1e-6        # peak acceleration ~0.2 g
    assert -a.min() <= 2.5 + 1e-6       # peak deceleration ~0.25 g (friction brakes available)
    m, g = 15554.0, 9.81
    vm = 0.5 * (v[1:] + v[:-1])
    road = 0.012 * m * g + 0.5 * 1.2 * 0.8 * 5.72 * vm ** 2
    p_wheel = 0.5 * m * 1.05 * (v[1:] ** 2 - v[:-1] ** 2) + road * vm
    assert p_wheel.max() <= 0.92 * 380e3, f"needs {p_wheel.max() / 1e3:.0f} kW at the wheels"


# ---------------------------------------------------------------- component
def test_cycle_source_interpolation_feedforward_and_repeat(tmp_path):
    p = write(tmp_path, "time_s,speed_mps\n0,0\n1,2\n2,3\n3,0\n")
    c = CycleSource("cycle", CycleParams(cycle_file=str(p), repeat=2))
    c.initialize(0.0)
    assert c.natural_stop_time() == 6.0
    y = c.y
    assert (y["speed_ref_mps"], y["accel_ref_mps2"]) == (0.0, 2.0)
    c.do_step(0.0, 0.5)
    assert y["speed_ref_mps"] == pytest.approx(1.0) and y["accel_ref_mps2"] == 2.0
    c.do_step(0.5, 0.9)  # t = 1.4: segment [1, 2)
    assert y["speed_ref_mps"] == pytest.approx(2.4) and y["accel_ref_mps2"] == pytest.approx(1.0)
    c.do_step(1.4, 1.6)  # t = 3.0 exactly: start of the 2nd repetition
    assert y["time_in_cycle_s"] == pytest.approx(0.0) and y["speed_ref_mps"] == 0.0 and y["accel_ref_mps2"] == 2.0
    c.do_step(3.0, 2.5)  # t = 5.5 in repetition 2 -> tc = 2.5, segment [2, 3)
    assert y["time_in_cycle_s"] == pytest.approx(2.5) and y["speed_ref_mps"] == pytest.approx(1.5)
    assert y["accel_ref_mps2"] == pytest.approx(-3.0)
    c.do_step(5.5, 1.0)  # past the end: hold
    assert (y["speed_ref_mps"], y["accel_ref_mps2"], y["time_in_cycle_s"]) == (0.0, 0.0, 3.0)


def test_cycle_source_state_restore_and_start_time(tmp_path):
    p = write(tmp_path, "time_s,speed_mps\n0,0\n1,2\n2,3\n3,0\n")
    c = CycleSource("cycle", CycleParams(cycle_file=str(p)))
    c.initialize(10.0)
    assert c.natural_stop_time() == 13.0
    c.do_step(10.0, 1.5)
    s = c.get_state()
    y1 = dict(c.y)
    c.do_step(11.5, 1.0)
    c.set_state(s)
    assert c.y == y1
    c.do_step(11.5, 1.0)
    assert c.y["speed_ref_mps"] == pytest.approx(1.5)


def test_cycle_parameter_files_and_bad_repeat(tmp_path):
    for name, dur in (("hd_udds", 1060.0), ("uac_proxy", None)):
        p = load_params(CycleParams, ROOT / "components" / "cycle" / f"{name}.toml")
        c = CycleSource("cycle", p)
        c.initialize(0.0)
        if dur:
            assert c.natural_stop_time() == dur * p.repeat
    assert CycleSource("c").cycle.name == "hd_udds"  # defaults work
    t = write(tmp_path, '[params]\ncycle_file = "x.csv"\nrepeat = 0\n', "c.toml")
    with pytest.raises(ScenarioError, match="repeat"):
        load_params(CycleParams, t)
