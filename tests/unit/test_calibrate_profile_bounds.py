"""The profile of a declared parameter past its plausibility guard (``workflow._widened``)."""
from __future__ import annotations

import pytest


def test_a_plausibility_guard_is_widened_in_the_parameters_own_scale():
    """The profile past a declared guard (workflow._widened; a reviewer's finding): a parameter fitted in logs is
    widened by a ratio - a linear move of half its range below a lower bound of 0.1 in 0.1..10 would reach -4.9,
    whose log is not defined - and a linear one by a difference; either stops at the parameter's limits."""
    from shevsim.calibrate.models import Param
    from shevsim.calibrate.workflow import _widened
    lin = Param("efficiency_scale_frac", "-", 0.8, 1.08, 1.0, limits=(0.0, 2.0))
    assert _widened(lin, True, 0.8, 1.08, 0.5) == pytest.approx((0.8, 1.22))
    assert _widened(lin, False, 0.8, 1.08, 0.5) == pytest.approx((0.66, 1.08))
    lg = Param("r_scale", "-", 0.1, 10.0, 1.0, log=True, limits=(0.0, 1e3))
    assert _widened(lg, False, 0.1, 10.0, 0.5) == pytest.approx((0.01, 10.0))
    assert _widened(lg, True, 0.1, 10.0, 0.5) == pytest.approx((0.1, 100.0))
    tight = Param("r_scale", "-", 0.1, 10.0, 1.0, log=True, limits=(0.05, 50.0))
    assert _widened(tight, False, 0.1, 10.0, 0.5) == pytest.approx((0.05, 10.0))
    assert _widened(tight, True, 0.1, 10.0, 0.5) == pytest.approx((0.1, 50.0))
