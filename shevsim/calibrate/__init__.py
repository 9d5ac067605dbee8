"""shevsim.calibrate - close the loop with measured data.

Fit a model's declared parameters to measured time series, diagnose the residual, test a library of
named physical effects the model lacks, select the ones that truly help (held-out error AND an
information criterion), refit and report error before/after (``report.json``, ``report.md``).

Modules
-------
data       load and check measured CSV files into canonical columns (:func:`load_measured`).
models     fast calibration models (``cell``, ``vehicle``, ``engine`` soot) with declared parameters and
           effect libraries.
workflow   the fit / diagnose / test / select / refit / report loop (:func:`run_workflow`).
synthetic  a richer "truth" generator with undeclared effects, for tests.
cli        ``shevsim calibrate MODEL DATA.csv --out DIR ...`` (:func:`main_calibrate`).
"""
from .data import MeasuredData, load_measured  # noqa: F401
from .models import MODELS, get_model  # noqa: F401
