"""Compiled (numba) hot-path kernels against their Python reference implementations.

Each kernel runs the same arithmetic in the same order as the Python code it replaces on the hot
path, with the same libm calls (exp, expm1, sqrt, and pow where CPython's ``x ** 2`` uses it), so the
results are bit-identical; a failure here means a kernel and its reference diverged (or a numba/LLVM
upgrade started fusing ``a * b + c`` into FMAs - then compare to ~1e-12 instead).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from shevsim.bms.thermal_estimators import HAVE_NUMBA, ThermalDKF, ThermalKF

pytestmark = pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed")


def _inputs(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    y = 25.0 + 3.0 * np.sin(k / 500.0) + 0.02 * rng.standard_normal(n)
    ta = 25.0 + 0.02 * rng.standard_normal(n)
    q = 0.5 + 0.4 * np.sin(k / 37.0)
    # a cooling fault: h drops, surface warms
    y[n // 2:] += np.linspace(0.0, 2.0, n - n // 2)
    return y.tolist(), ta.tolist(), q.tolist()


@pytest.mark.parametrize("total", [True, False])
def test_dkf_compiled_step_matches_python_reference(total):
    kw = dict(dt_s=0.1, h0_w_m2k=20.0, total_derivative=total, x0_c=(25.0, 0.0), sigma_c=0.0158, beta2=0.03,
              s0=1e-2)
    fast, ref = ThermalDKF(**kw), ThermalDKF(**kw, compiled=False)
    assert fast.compiled and not ref.compiled
    y, ta, q = _inputs(6000)
    n_diff = 0
    for a, b, c in zip(y, ta, q):
        ef, er = fast.update(a, b, c), ref.update(a, b, c)
        n_diff += tuple(ef) != tuple(er)
    assert n_diff == 0
    # the state (through the same attributes) agrees too, and the estimate moved away from its start
    for name in ("x0", "x1", "p00", "p01", "p11", "h", "ph", "dx0", "dx1"):
        assert getattr(fast, name) == getattr(ref, name), name
    assert abs(fast.h - 20.0) > 0.1
    assert fast._u == ref._u == (q[-1], ta[-1])


def test_dkf_compiled_rejects_bad_input_like_the_reference():
    from shevsim.core.errors import SimulationError
    f = ThermalDKF(dt_s=0.1)
    with pytest.raises(SimulationError, match="non-finite"):
        f.update(math.nan, 25.0, 0.0)


def test_dkf_euler_discretisation_uses_the_python_path():
    f = ThermalDKF(dt_s=0.1, discretisation="euler")
    assert not f.compiled
    g = ThermalKF(dt_s=0.1)
    assert g.update(25.0, 25.0, 0.0).t_mean_c == pytest.approx(25.0, abs=1.0)


def test_engine_generator_compiled_advance_is_bit_identical():
    import random

    from shevsim.components.engine_generator import EngineGenerator
    fast, ref = EngineGenerator("eg"), EngineGenerator("eg", compiled=False)
    assert fast._advance is not None and ref._advance is None
    fast.initialize(0.0)
    ref.initialize(0.0)
    rng = random.Random(0)
    cmd, lim, n_diff = 0.0, 1e12, 0
    for k in range(4000):          # random commands incl. out-of-range ones, rate limits on and off
        if k % 2 == 0:
            cmd = max(-1e4, min(260e3, cmd + rng.gauss(0.0, 15e3)))
        rate = rng.choice([30e3, 12e3, 1e12])
        if k % 5 == 0:             # bus limit (load shedding): none, or anywhere from below 0 to above rating
            lim = rng.choice([1e12, 1e12, rng.uniform(-1e4, 230e3)])
        for c in (fast, ref):
            c.u["power_cmd_w"], c.u["power_rate_max_wps"], c.u["elec_power_max_w"] = cmd, rate, lim
            c.do_step(0.1 * k, 0.1)
        n_diff += fast.y != ref.y
    assert n_diff == 0
    assert ref.y["fuel_mass_g"] > 100.0 and ref.y["soot_transient_mg"] > 0.0   # the run did something
    assert ref.y["shed_count"] > 50 and ref.y["shed_time_s"] > 20.0            # and shed load often


def test_engine_generator_compiled_path_falls_back_for_non_clamp_maps():
    from shevsim.components.engine_generator import EngineGenerator
    from shevsim.powertrain.engine import CompiledAdvance
    eg = EngineGenerator("eg")
    eg.maps.ool_speed.mode = "linear"
    assert CompiledAdvance.make(eg.maps, eg.params) is None


@pytest.mark.parametrize("mode", ["exact", "seed"])
def test_power_capability_compiled_compute_is_bit_identical(mode):
    import random

    from shevsim.bms.power_capability import PowerCapability, PowerCapabilityParams
    prm = PowerCapabilityParams(polarisation_heat=mode, i_cell_max_a=60.0 if mode == "seed" else math.inf)
    fast, ref = PowerCapability(prm), PowerCapability(prm, compiled=False)
    assert fast.compiled and not ref.compiled
    rng = random.Random(2)
    n_diff, limited_by = 0, set()
    for _ in range(3000):       # states across the whole range: SOC, voltage, thermal and rating limits bind
        args = (rng.uniform(0.0, 1.0), rng.uniform(-0.1, 0.1), rng.uniform(0.005, 0.02), rng.uniform(0.005, 0.03),
                rng.uniform(100.0, 5000.0), rng.uniform(15.0, 50.0), rng.uniform(-100.0, 100.0),
                rng.uniform(1.0, 100.0), rng.uniform(15.0, 40.0))
        a, b = fast.compute(*args), ref.compute(*args)
        n_diff += tuple(a) != tuple(b)
        limited_by.add(min((b.i_soc_min_a, "soc"), (b.i_v_min_a, "v"), (b.i_t_dch_a, "t"))[1])
    assert n_diff == 0
    assert (fast.last_i_max_a, fast.last_i_min_a) == (ref.last_i_max_a, ref.last_i_min_a)
    assert limited_by == {"soc", "v", "t"}


@pytest.mark.parametrize("rs_model", ["free", "table_scaled"])
@pytest.mark.parametrize("retuned", [False, True])
def test_dekf_compiled_step_is_bit_identical(retuned, rs_model):
    import random

    from shevsim.bms.electrical import DEKF, DEKFParams
    from shevsim.core.errors import SimulationError
    prm = DEKFParams(q_soc=1e-5, q_v1=2e-3, q_rs=1e-8, q_c1=1e4, rs_model=rs_model) if retuned else \
        DEKFParams(rs_model=rs_model)
    fast, ref = DEKF(prm), DEKF(prm, compiled=False)
    assert fast.compiled and not ref.compiled
    rng = random.Random(3)
    n_diff = 0
    for k in range(5000):
        i = 20.0 * math.sin(k / 50.0) + rng.gauss(0.0, 5.0)
        v = 3.3 - 0.012 * i + rng.gauss(0.0, 0.01) - 0.1 * math.sin(k / 3000.0)
        tm = 25.0 + 5.0 * math.sin(k / 1000.0)     # table_scaled: R_s,nom looked up at tm, both directions
        qa, qb = fast.step_heat(i, v, 0.1, tm), ref.step_heat(i, v, 0.1, tm)
        n_diff += (qa, fast.soc, fast.v1, fast.rs, fast.r1, fast.c1, fast.px, fast.pth, fast.innovation) != \
            (qb, ref.soc, ref.v1, ref.rs, ref.r1, ref.c1, ref.px, ref.pth, ref.innovation)
    assert n_diff == 0
    assert fast.step(1.0, 3.3, 0.1) == ref.step(1.0, 3.3, 0.1)
    with pytest.raises(SimulationError, match="innovation"):
        fast.step(1.0, math.nan, 0.1)
