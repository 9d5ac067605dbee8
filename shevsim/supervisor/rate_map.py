"""rate_map.py - the engine-generator power-rate constraint map (seed Fig. 5.3, App. A.3).

The maximum allowed rate of rise of the engine-generator power, ``Delta P_g,max``, is a
piecewise-constant function of the present engine-generator power ``P_g``: the power axis is cut
into partitions ``d_i = [edge_i, edge_{i+1})`` (seed A.2, e.g. 25 kW bins) and each partition has
one rate ``beta_i``.  A constant limit is the one-partition map.  Powers below the first edge use
the first partition, powers at or above the last edge use the last one.
"""
from __future__ import annotations

import math
from bisect import bisect_right
from typing import Sequence

from shevsim.core.errors import ScenarioError


class PowerRateMap:
    """Piecewise-constant maximum engine-generator power rate ``Delta P_g,max(P_g)``.

    Parameters
    ----------
    power_edges_w : sequence of float
        Partition edges [W], strictly increasing, ``len = len(max_rate_wps) + 1``.
    max_rate_wps : sequence of float
        Maximum power rate in each partition [W/s], each > 0 and finite.
    where : str
        Name used in error messages (file/field or component).

    Examples
    --------
    >>> m = PowerRateMap([0.0, 75e3, 236e3], [30e3, 15e3])
    >>> m(50e3), m(100e3), m(300e3)
    (30000.0, 15000.0, 15000.0)
    """

    __slots__ = ("edges_w", "rates_wps", "_inner", "where")

    def __init__(self, power_edges_w: Sequence[float], max_rate_wps: Sequence[float],
                 where: str = "power-rate map"):
        try:
            edges = [float(e) for e in power_edges_w]
            rates = [float(r) for r in max_rate_wps]
        except (TypeError, ValueError) as exc:
            raise ScenarioError(f"{where}: rate_map_power_edges_w / rate_map_max_rate_wps must be lists "
                                f"of numbers ({exc})") from exc
        if len(rates) < 1:
            raise ScenarioError(f"{where}: rate_map_max_rate_wps needs at least one partition rate")
        if len(edges) != len(rates) + 1:
            raise ScenarioError(f"{where}: rate_map_power_edges_w has {len(edges)} edges but "
                                f"rate_map_max_rate_wps has {len(rates)} rates (need edges = rates + 1)")
        if not all(math.isfinite(e) for e in edges):
            raise ScenarioError(f"{where}: rate_map_power_edges_w must be finite, got {edges}")
        bad = [i for i in range(len(edges) - 1) if not edges[i + 1] > edges[i]]
        if bad:
            raise ScenarioError(f"{where}: rate_map_power_edges_w must be strictly increasing "
                                f"(edge {bad[0]} = {edges[bad[0]]} >= edge {bad[0] + 1} = {edges[bad[0] + 1]})")
        badr = [i for i, r in enumerate(rates) if not (math.isfinite(r) and r > 0.0)]
        if badr:
            raise ScenarioError(f"{where}: rate_map_max_rate_wps[{badr[0]}] = {rates[badr[0]]} must be a "
                                f"positive finite rate [W/s]")
        self.edges_w = tuple(edges)
        self.rates_wps = tuple(rates)
        self._inner = list(edges[1:-1])
        self.where = where

    @classmethod
    def constant(cls, max_rate_wps: float, p_min_w: float = 0.0, p_max_w: float = 1e6) -> "PowerRateMap":
        """One-partition map: the same ``max_rate_wps`` at every power."""
        return cls([p_min_w, p_max_w], [max_rate_wps])

    @property
    def n_partitions(self) -> int:
        return len(self.rates_wps)

    def __call__(self, power_w: float) -> float:
        """Maximum power rate [W/s] at engine-generator power ``power_w`` [W]."""
        return self.rates_wps[bisect_right(self._inner, power_w)]

    def __repr__(self) -> str:
        return f"PowerRateMap(edges_w={list(self.edges_w)}, max_rate_wps={list(self.rates_wps)})"
