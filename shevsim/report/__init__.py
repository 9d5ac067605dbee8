"""shevsim.report - self-contained HTML reports of runs, comparisons, studies and calibrations.

::

    import shevsim
    from shevsim.report import write_report, run_report, compare_report
    res = shevsim.simulate("hd_udds_rule", out="results/rule", plots=True)   # writes results/rule/report.html
    write_report("results/rule")                 # (re)write a folder's report from its saved outputs
    write_report(["results/rule", "results/mpc"], out="compare.html")      # a comparison of saved runs
    write_html([rule, mpc], "rule_vs_mpc.html", labels=["rule", "MPC"])   # results in memory (a notebook)
    html = compare_report([rule, mpc], labels=["rule", "MPC"])             # the page as text

The command line: ``shevsim report DIR [DIR ...] [-o FILE]``. Each file embeds Plotly's JavaScript (about
4.8 MB), so it opens offline and can be mailed as one file.
"""
from __future__ import annotations

from .html import (calibration_report, calibration_summary_html, compare_report, result_summary_html,
                   run_report, scenario_html, study_report, study_summary_html)
from .write import (folder_kind, load_study_tables, write_calibration_html, write_html, write_report,
                    write_run_html)

__all__ = ["run_report", "compare_report", "study_report", "calibration_report", "write_report", "write_html",
           "folder_kind", "write_run_html", "write_calibration_html", "load_study_tables",
           "result_summary_html", "scenario_html", "study_summary_html", "calibration_summary_html"]
