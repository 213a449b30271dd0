"""Comparison report: run several methods on one exemplar, measure, and write HTML + JSON.

The report is data first: :func:`run_comparison` (:mod:`~texsyn.report.comparison`) returns
a :class:`Report` of records (:mod:`~texsyn.report.records`: method, parameters, seed,
timings, metrics, images, versions); :meth:`Report.to_html` renders one self-contained HTML
file (:mod:`~texsyn.report.html`, images embedded as PNG data URIs), :meth:`Report.to_dict`
the JSON sidecar, and :func:`write_report` (:mod:`~texsyn.report.files`) writes both, all or
nothing.
"""

from __future__ import annotations

from .comparison import library_versions, run_comparison
from .files import claim_report, report_paths, write_report
from .html import TABLE_STYLE
from .records import MethodRecord, MethodRun, Report

__all__ = [
    "TABLE_STYLE",
    "library_versions",
    "MethodRun",
    "MethodRecord",
    "Report",
    "claim_report",
    "report_paths",
    "run_comparison",
    "write_report",
]
