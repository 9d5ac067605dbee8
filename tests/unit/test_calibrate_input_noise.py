"""The noise of a measured input (timing.difference_noise, input_noise_floor), against signals of known noise.

The input's noise is carried through the model into the output's noise floor, so an input noise read 2x too high
makes a floor that a correct model never reaches and hides the part of the residual an effect could explain (a new
user's FASTSim Leaf records: speed noise 0.1 km/h read as 0.142 km/h by the 7-sample quadratic smoother, the
power's floor above the nominal's own held-out error).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from shevsim.calibrate.timing import difference_noise, input_noise_floor

D = Path(__file__).resolve().parents[1] / "data" / "independent"


def _drive(rng, n: int = 1400) -> np.ndarray:
    """A drive-like speed [m/s] at 1 Hz, no noise: accelerations drawn every 8 s within -2..1.5 m/s^2 and
    smoothed over a few seconds (a driver's, not a step's), integrated, stopped at 0 (held there 10-40 s) and
    capped at 30 m/s."""
    from scipy.ndimage import gaussian_filter1d
    a = gaussian_filter1d(np.repeat(rng.uniform(-2.0, 1.5, n // 8 + 1), 8)[:n], 2.0)
    v, out, hold = 0.0, [], 0
    for ak in a:
        if hold > 0:
            hold -= 1
            v = 0.0
        else:
            v = min(v + ak, 30.0)
            if v <= 0.0:
                v, hold = 0.0, int(rng.integers(10, 41))
        out.append(v)
    return np.array(out)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_speed_noise_on_a_drive_clipped_at_standstill(seed):
    """White noise on a drive's speed, clipped at zero as a speed logger is: read within 15 % of the truth (the
    smoother, over the clipped standstill too, reads 0.76-0.98x on these drives)."""
    rng = np.random.default_rng(seed)
    v = _drive(rng)
    y = np.maximum(v + rng.normal(0.0, 0.02, v.size), 0.0)
    assert (y == 0.0).mean() > 0.02                           # the record does stop (the clip is exercised)
    assert difference_noise(y) == pytest.approx(0.02, rel=0.15)
    got = input_noise_floor(y)
    assert got["method"] == "differences" and got["value"] == pytest.approx(0.02, rel=0.15)


def test_current_noise_on_steps():
    """A step-like current (levels held 5-40 s, a drive's current profile) with 5 mA of noise: within 15 %."""
    rng = np.random.default_rng(7)
    lv = np.repeat(rng.uniform(-10.0, 20.0, 200), rng.integers(5, 41, 200))[:4000]
    y = lv + rng.normal(0.0, 0.005, lv.size)
    assert difference_noise(y) == pytest.approx(0.005, rel=0.15)


def test_white_noise_alone_is_read_unbiased():
    """Pure white noise: every order reads it; the smallest of six is low by a few per cent, not more."""
    y = np.random.default_rng(11).normal(0.0, 1.0, 20000)
    assert 0.93 < difference_noise(y) <= 1.02


def test_held_values_are_no_noise():
    """A noise-free piecewise-constant command (most differences exactly 0) has no differences' estimate; the
    input then has no noise to propagate."""
    y = np.repeat(np.arange(100.0), 20)
    assert math.isnan(difference_noise(y))
    assert input_noise_floor(y)["value"] == 0.0


@pytest.mark.parametrize("pre,column,scale,truth_key,cases", [
    ("vehicle_trial40_leaf", "VehSpd_kph", 1.0, "speed_kmh", ("none", "payload", "grade_hill")),
    ("vehicle_trial41_emv", "speed_kmh", 1.0, "speed_kmh", ("none", "payload", "none_2hz")),
    ("vehicle_bolt", "speed_mps", 1.0, "speed_mps", ("none", "payload_hwfet")),
])
def test_fastsim_records_speed_noise(pre, column, scale, truth_key, cases):
    """FASTSim 3.1 records (another project's vehicle model, its own noise seeds): the speed noise read within
    the stated 15 % of the noise the generator added."""
    truth = json.loads((D / f"{pre}_truth.json").read_text())
    true = truth["noise"][truth_key]
    for case in cases:
        c = truth["cases"][case]
        y = pd.read_csv(D / c.get("file", f"{pre}_{case}.csv"), comment="#")[column].to_numpy(float) * scale
        assert difference_noise(y) == pytest.approx(true, rel=0.15), case
