"""The one TOML value writer (shevsim.core.tomlio) against the standard library's TOML reader."""
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from shevsim.core.errors import ScenarioError
from shevsim.core.tomlio import toml_key, toml_value


@pytest.mark.parametrize("v", [True, False, 0, -7, 2**62, 0.1, -1e-300, 1.7976931348623157e308, 5e-324,
                               "", "a \"quoted\" \\ back\nslash", "température ü", [], [1, 2.5, "x"],
                               [[1, 2], [3]], {"mass_kg": 1.5, "a.b": "dotted key", "x y": [1, 2]}, {}])
def test_values_read_back_equal_through_tomllib(v):
    assert tomllib.loads(f"x = {toml_value(v)}")["x"] == v


def test_non_finite_floats_numpy_and_paths():
    doc = tomllib.loads(f"a = {toml_value(math.nan)}\nb = {toml_value(-math.inf)}\nc = {toml_value(np.float64(0.1))}\n"
                        f"d = {toml_value(np.int32(3))}\ne = {toml_value(np.array([1.0, 2.0]))}\n"
                        f"f = {toml_value(Path('/tmp/a b.csv'))}\ng = {toml_value(np.bool_(True))}")
    assert math.isnan(doc["a"]) and doc["b"] == -math.inf
    assert doc["c"] == 0.1 and type(doc["d"]) is int and doc["d"] == 3 and doc["e"] == [1.0, 2.0]
    assert doc["f"] == "/tmp/a b.csv" and doc["g"] is True


def test_keys_bare_or_quoted():
    assert toml_key("mass_kg") == "mass_kg"
    assert tomllib.loads(f"{toml_key('battery.soc')} = 1")["battery.soc"] == 1


def test_an_unwritable_value_is_a_scenario_error_and_a_type_error():
    with pytest.raises(ScenarioError, match="cannot write object value"):
        toml_value(object())
    with pytest.raises(TypeError):
        toml_value({1, 2})
