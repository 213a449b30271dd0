"""The comparison as data: one record per method, one run per seed (``docs/cli.md``, ``compare``).

The report is data first: :func:`texsyn.report.run_comparison` returns a :class:`Report` of
records (method, parameters, seed, timings, metrics, images, versions); :meth:`Report.to_dict`
is the JSON sidecar and :meth:`Report.to_html` the page (:mod:`texsyn.report.html`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..metrics import METRIC_DESCRIPTIONS
from .html import render_html

__all__ = ["MethodRecord", "MethodRun", "Report"]


@dataclass
class MethodRun:
    """One synthesis: seed, output, where its pixels came from, metrics and wall time."""

    seed: int
    seconds: float
    image: np.ndarray
    map_image: np.ndarray
    map_source: str
    metrics: dict[str, float]


@dataclass
class MethodRecord:
    """Every run of one method, or the error that stopped it."""

    method: str
    summary: str
    reference: str
    params: dict
    runs: list[MethodRun] = field(default_factory=list)
    error: str | None = None

    def median_seconds(self) -> float | None:
        return float(np.median([r.seconds for r in self.runs])) if self.runs else None

    def mean_metrics(self) -> dict[str, float]:
        if not self.runs:
            return {}
        return {k: float(np.mean([r.metrics[k] for r in self.runs])) for k in self.runs[0].metrics}


@dataclass
class Report:
    """A comparison of methods on one exemplar."""

    exemplar: np.ndarray
    exemplar_name: str
    exemplar_map: np.ndarray
    shape: tuple[int, int]
    seeds: list[int]
    records: list[MethodRecord]
    versions: dict[str, str]
    created: str

    def to_dict(self) -> dict:
        """JSON-ready data: everything but the pixels."""
        return {
            "texsyn_report": 1,
            "created": self.created,
            "exemplar": {"name": self.exemplar_name, "shape": list(self.exemplar.shape)},
            "output_shape": list(self.shape),
            "seeds": self.seeds,
            "versions": self.versions,
            "metrics": METRIC_DESCRIPTIONS,
            "methods": [
                {
                    "method": r.method,
                    "reference": r.reference,
                    "params": {k: _jsonable(v) for k, v in r.params.items()},
                    "error": r.error,
                    "median_seconds": r.median_seconds(),
                    "mean_metrics": r.mean_metrics(),
                    "runs": [
                        {
                            "seed": run.seed,
                            "seconds": run.seconds,
                            "map_source": run.map_source,
                            "metrics": run.metrics,
                        }
                        for run in r.runs
                    ],
                }
                for r in self.records
            ],
        }

    def to_html(self) -> str:
        """One self-contained HTML page (no external resources): :func:`texsyn.report.html.render_html`."""
        return render_html(self)


def _jsonable(value):
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    return value
