"""Property-based tests (hypothesis) of the loaders a user hands files to: scenario, parameter, cycle and
measured-data.  Whatever the input, the result is a valid object or the project's own error
(:class:`shevsim.core.errors.ShevsimError`) with a message - never another exception."""
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from shevsim.calibrate.data import load_measured
from shevsim.core.errors import ShevsimError
from shevsim.core.params import load_params, make_params
from shevsim.core.scenario import build_master, load_scenario
from shevsim.cycles import load_cycle

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                    derandomize=True)
TMP = Path(tempfile.mkdtemp(prefix="shevsim_hypothesis_"))


def _file(name: str, data: bytes | str) -> Path:
    p = TMP / name
    if isinstance(data, str):
        p.write_text(data, encoding="utf-8", errors="surrogatepass")
    else:
        p.write_bytes(data)
    return p


def _own_error_or_value(fn, *args, **kw):
    try:
        return fn(*args, **kw)
    except ShevsimError as exc:
        assert str(exc).strip(), "an error without a message"
        return None


numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**20, 10**20), st.just(10**400))
scalars = st.one_of(numbers, st.booleans(), st.text(max_size=12), st.none())
values = st.one_of(scalars, st.lists(scalars, max_size=4), st.dictionaries(st.text(max_size=5), scalars, max_size=2))


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if v != v else ("inf" if v == math.inf else "-inf" if v == -math.inf else repr(v))
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v if x is not None) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f'"{k}" = {_toml_value(x)}' for k, x in v.items() if x is not None) + "}"
    return '""'


# ------------------------------------------------------------------------------------------- parameters

def _param_classes():
    from shevsim.components import REGISTRY, get_component_class
    return sorted({get_component_class(t).Params for t in REGISTRY if get_component_class(t).Params},
                  key=lambda c: c.__name__)


PARAM_CLASSES = _param_classes()


@SETTINGS
@given(cls=st.sampled_from(PARAM_CLASSES), data=st.data())
def test_make_params_arbitrary_values(cls, data):
    import dataclasses
    names = [f.name for f in dataclasses.fields(cls)]
    keys = data.draw(st.lists(st.one_of(st.sampled_from(names), st.text(max_size=8)), max_size=4))
    vals = {k: data.draw(values) for k in keys}
    obj = _own_error_or_value(make_params, cls, vals, "<hypothesis>")
    if obj is not None:           # a valid object: every number in it is finite or a declared 'no limit'
        for f in dataclasses.fields(cls):
            v = getattr(obj, f.name)
            if isinstance(v, float):
                assert not math.isnan(v)


@SETTINGS
@given(cls=st.sampled_from(PARAM_CLASSES), text=st.one_of(
    st.text(max_size=200),
    st.lists(st.tuples(st.text(alphabet="abcdefghijklmnopqrstuvwxyz_0123456789", min_size=1, max_size=20),
                       values), max_size=5).map(
        lambda kv: "[params]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in kv if v is not None))))
def test_load_params_arbitrary_file(cls, text):
    p = _file("p.toml", text)
    _own_error_or_value(load_params, cls, p)


# -------------------------------------------------------------------------------------------- scenarios

COMPONENT_TYPES = ["gain", "gain", "gain", "mass_spring", "spring_damper", "trivial", "cycle", "nosuch", "os:system",
                   "a.b"]


@st.composite
def scenario_texts(draw):
    lines = ["[scenario]"]
    if draw(st.booleans()):
        lines += ["step_s = 0.1", "stop_s = 1.0"]
    for k in draw(st.lists(st.sampled_from(["t0_s", "seed", "name", "solver", "bogus", "description"]),
                           max_size=3, unique=True)):
        lines.append(f"{k} = {_toml_value(draw(scalars))}")
    names = draw(st.lists(st.sampled_from(["a", "b", "a", "b", "c", "x.y", ""]), min_size=0, max_size=3, unique=True))
    for n in names:
        lines.append(f'[components."{n}"]')
        lines.append(f'type = {_toml_value(draw(st.sampled_from(COMPONENT_TYPES)))}')
        if draw(st.booleans()):
            lines.append(f"set = {{ gain = {_toml_value(draw(st.one_of(numbers, st.floats(-10, 10))))} }}")
        if draw(st.booleans()):
            lines.append(f"start = {{ in_1 = {_toml_value(draw(st.one_of(scalars, st.floats(-1, 1))))} }}")
    if draw(st.booleans()) and names:
        lines.append("[connections]")
        lines.append(f'"{draw(st.sampled_from(names))}.out_1" = "{draw(st.sampled_from(names))}.in_1"')
    text = "\n".join(lines) + "\n"
    if draw(st.integers(0, 3)) == 0:   # damage it
        i = draw(st.integers(0, len(text)))
        text = text[:i] + draw(st.text(max_size=5)) + text[i:]
    return text


@SETTINGS
@given(text=scenario_texts(), sets=st.lists(st.one_of(st.text(max_size=20), st.sampled_from(
    ["a.gain=nan", "a.gain=2", "scenario.stop_s=0.5", "metrics.fuel_density_kg_per_l=-1", "b.x=1"])), max_size=2))
def test_scenario_loader_arbitrary_text(text, sets):
    p = _file("s.toml", text)
    sc = _own_error_or_value(load_scenario, p, sets)
    if sc is not None:
        _own_error_or_value(build_master, sc)


# ------------------------------------------------------------------------------------------------ cycles

def _damage(draw, text: str) -> str:
    """Sometimes insert, delete or replace a few characters."""
    if not text or draw(st.integers(0, 2)) != 0:
        return text
    i = draw(st.integers(0, len(text) - 1))
    j = min(len(text), i + draw(st.integers(0, 4)))
    return text[:i] + draw(st.text(alphabet=",;\t\n.-e0123456789nanif \ufeff\r", max_size=4)) + text[j:]


@st.composite
def cycle_texts(draw):
    header = draw(st.sampled_from(["time_s,speed_mps", "time_s,speed_mps", "time_ms,speed_kmh", "speed_mps,time_s",
                                   "time_s;speed_mps", "\ufefftime_s,speed_mps", "t,v", "time_s,speed_mps,", ""]))
    sep = ";" if ";" in header else ","
    n = draw(st.integers(0, 30))
    dt = draw(st.sampled_from([1.0, 0.1, 0.5, 1000.0, 20.0]))
    t0 = draw(st.sampled_from([0.0, 5.0, -3.0]))
    vmax = draw(st.sampled_from([25.0, 25.0, 90.0, 200.0]))
    v = 0.0
    rows = []
    for k in range(n):
        v = min(vmax, max(0.0, v + draw(st.floats(-1.5, 1.5))))
        tt, vv = t0 + k * dt, v
        if "speed_mps,time_s" in header:
            tt, vv = vv, tt
        cell = f"{tt:g}{sep}{vv:.4f}" + (sep if header.endswith(",") else "")
        rows.append(cell.replace(".", ",") if sep == ";" and draw(st.booleans()) else cell)
    nl = draw(st.sampled_from(["\n", "\r\n"]))
    return _damage(draw, nl.join([header] + rows) + nl)


@SETTINGS
@given(text=st.one_of(cycle_texts(), cycle_texts(), st.text(max_size=120)), raw=st.binary(max_size=40),
       use_raw=st.sampled_from([False, False, False, True]))
def test_cycle_loader_arbitrary_input(text, raw, use_raw):
    p = _file("c.csv", raw if use_raw else text)
    c = _own_error_or_value(load_cycle, p)
    if c is not None:
        assert c.time_s.size >= 2 and np.all(np.isfinite(c.speed_mps)) and np.all(c.speed_mps >= 0)
        assert np.all(np.diff(c.time_s) > 0)


# --------------------------------------------------------------------------------------- measured data

@st.composite
def measured_texts(draw):
    model = draw(st.sampled_from(["cell", "vehicle", "engine"]))
    n = draw(st.integers(0, 60))
    t = np.arange(n) * draw(st.sampled_from([1.0, 0.1, 1000.0]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    if model == "cell":
        i = draw(st.sampled_from([2.0, 0.5, 500.0])) * np.sign(np.sin(t / 7.0 + 0.1))
        cols = {"time_s": t, "current_a": i, "voltage_v": 3.3 - 0.03 * i + rng.normal(0, 1e-3, n),
                "t_surface_c": 25 + rng.normal(0, .1, n), "t_ambient_c": np.full(n, draw(st.sampled_from([25.0, 298.0])))}
    elif model == "vehicle":
        s_ = np.clip(15 * np.sin(t / 30.0), 0, None) * draw(st.sampled_from([1.0, 3.6]))
        cols = {"time_s": t, "speed_mps": s_, "power_w": 2e4 * s_ + 1e3}
    else:
        p = 1e5 * (1 + np.sin(t / 10.0)) * draw(st.sampled_from([1.0, 1e-3]))
        cols = {"time_s": t, "power_w": p, "soot_rate_mgps": 1 + p / 1e4}
    names = list(cols)
    if draw(st.booleans()):
        k = draw(st.integers(0, len(names) - 1))
        names[k] = draw(st.sampled_from(["time_ms", "current_ma", "speed_kmh", "power_kw", "x", "", names[k]]))
    sep = draw(st.sampled_from([",", ",", ";", "\t"]))
    rows = [sep.join(names)]
    for k in range(n):
        cells = [f"{cols[c][k]:.6g}" for c in cols]
        rows.append(sep.join(c.replace(".", ",") if sep == ";" else c for c in cells))
    return model, _damage(draw, "\n".join(rows) + "\n")


@SETTINGS
@given(mt=st.one_of(measured_texts(), st.tuples(st.sampled_from(["cell", "vehicle", "engine"]), st.text(max_size=120))),
       units=st.sampled_from([None, None, None, {"time_s": "ms"}, {"current_a": "mA"}, {"bogus": "x"},
                              {"time_s": "furlong"}]))
def test_measured_loader_arbitrary_input(mt, units):
    model, text = mt
    p = _file("m.csv", text)
    d = _own_error_or_value(load_measured, p, model, units=units)
    if d is not None:
        assert np.all(np.diff(d.df["time_s"].to_numpy()) > 0)
