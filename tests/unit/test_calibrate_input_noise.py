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


@pytest.mark.parametrize("n", [300, 3000])
def test_white_noise_alone_is_read_unbiased(n):
    """Pure white noise: every order reads it and they are pooled - the mean over 200 draws within 2 % of the
    truth at 300 samples as at 3000 (the smallest order alone: 0.95x at 300, a reviewer's measurement)."""
    got = [difference_noise(np.random.default_rng(s).normal(0.0, 1.0, n)) for s in range(200)]
    assert np.mean(got) == pytest.approx(1.0, abs=0.02)


def test_a_short_record_falls_back_on_the_smoother():
    """60 samples of a drive: too few stencils for three orders, so no differences' estimate (nan) - the low
    orders alone read the drive's shape as noise (15x) - and the input's floor is the smoother's."""
    rng = np.random.default_rng(5)
    v = 13.0 + 5.0 * np.sin(np.arange(60) / 9.0)
    y = v + rng.normal(0.0, 0.02, v.size)
    assert math.isnan(difference_noise(y))
    got = input_noise_floor(y)
    assert got["method"] == "smoother" and got["value"] < 2.0 * 0.02


def test_a_glitch_below_the_clip_and_a_dead_band():
    """The clip is the repeated value, not the record's extreme: one sample at -0.01 m/s below a standstill read as
    0 does not undo it; a current read exactly 0 A at rest inside its range (a dead band, 30 % of the record) is
    left out, not read as noise-free samples."""
    rng = np.random.default_rng(0)
    v = _drive(rng)
    y = np.maximum(v + rng.normal(0.0, 0.02, v.size), 0.0)
    y[int(np.flatnonzero(y == 0.0)[5])] = -0.01
    assert difference_noise(y) == pytest.approx(0.02, rel=0.15)
    lv = np.repeat(rng.uniform(-10.0, 20.0, 200), rng.integers(5, 41, 200))[:4000]
    i = lv + rng.normal(0.0, 0.005, lv.size)
    i[rng.random(lv.size) < 0.3] = 0.0
    assert difference_noise(i) == pytest.approx(0.005, rel=0.15)


def test_quantised_current():
    """A current logged at 10 mA resolution with 5 mA of noise: the logged error is the noise plus the
    quantiser's, sqrt(5^2 + 10^2 / 12) = 5.8 mA; read within 20 %."""
    rng = np.random.default_rng(2)
    lv = np.repeat(rng.uniform(-10.0, 20.0, 200), rng.integers(5, 41, 200))[:4000]
    y = np.round((lv + rng.normal(0.0, 0.005, lv.size)) / 0.01) * 0.01
    assert difference_noise(y) == pytest.approx(math.hypot(0.005, 0.01 / math.sqrt(12.0)), rel=0.2)


def test_noise_free_commands_have_no_noise():
    """A noise-free piecewise-constant command and a rate-limited set-point (its second differences mostly
    exactly 0; a reviewer's case, where the first differences alone read 210 W of 'noise' on a 200 W/s ramp):
    no noise to propagate."""
    y = np.repeat(np.arange(100.0), 20)
    assert input_noise_floor(y)["value"] == 0.0
    rng = np.random.default_rng(3)
    target = np.repeat(rng.uniform(0.0, 60e3, 40), 60)
    cmd = np.empty_like(target)
    cmd[0] = target[0]
    for k in range(1, cmd.size):
        cmd[k] = cmd[k - 1] + np.clip(target[k] - cmd[k - 1], -200.0, 200.0)
    assert difference_noise(cmd) == 0.0
    assert input_noise_floor(cmd)["value"] == 0.0


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


def test_pybamm_records_current_noise():
    """Every PyBaMM cell record shipped whose truth gives its current noise (another project's cell model, its own
    noise seeds, 1 Hz and 0.5 Hz, drives and swings): read within 30 %, the median within 10 %."""
    ratios = []
    for tf in sorted(D.glob("cell_*truth.json")):
        truth = json.loads(tf.read_text())
        true = (truth.get("noise") or {}).get("current_a")
        if not true:
            continue
        for case, c in truth["cases"].items():
            f = D / c.get("file", f"{tf.name.removesuffix('_truth.json')}_{case}.csv")
            if not f.is_file():
                continue
            df = pd.read_csv(f, comment="#")
            col = next(k for k in df.columns if "current" in k.lower() or k.startswith("I_"))
            ratios.append(difference_noise(df[col].to_numpy(float)) / true)
    assert len(ratios) >= 60
    assert 0.95 < min(ratios) and max(ratios) < 1.3
    assert float(np.median(ratios)) == pytest.approx(1.0, abs=0.1)
