"""The A.1 gap study's fuel-map factor: scaling every fuel rate of the engine's maps by s scales the fuel
economy by 1/s (an identity of the quasi-static fuel model: the operating points do not move), checked by
two short whole-vehicle runs."""
import shutil
import tempfile
from pathlib import Path

import pytest

from shevsim.api import simulate
from shevsim.studies.a1_gap import SCENARIO, _fuel_overrides


def test_fuel_maps_scaled_by_s_scale_the_fuel_economy_by_one_over_s():
    tmp = Path(tempfile.mkdtemp())
    try:
        ov = _fuel_overrides(tmp, 0.9)
        base = simulate(SCENARIO, overrides={"cycle.repeat": 1}, stop_s=600.0).metrics
        scaled = simulate(SCENARIO, overrides={"cycle.repeat": 1, **ov}, stop_s=600.0).metrics
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    ratio = scaled["fuel_economy_dsoc_corrected_kmpl"] / base["fuel_economy_dsoc_corrected_kmpl"]
    assert ratio == pytest.approx(1.0 / 0.9, rel=0.01)
    assert scaled["distance_km"] == pytest.approx(base["distance_km"], rel=1e-3)
