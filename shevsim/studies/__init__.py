"""Studies: fuel/soot trade-off, power-rate map optimisation (GA + exhaustive search), on Dask with a SQLite cache.

Modules: ``evaluate`` (evaluation items and keys), ``cache`` (SQLite store), ``parallel``
(Dask/serial runner), ``ga`` (genetic algorithm, narrowing, exhaustive search), ``problem``
(scenario vs synthetic evaluation of a rate map), ``tradeoff``, ``powerrate_map``, ``cli``.
"""
