"""Comparison report: run several methods on one exemplar, measure, and write HTML + JSON.

The report is data first (DESIGN.md convention 11): :func:`run_comparison` returns a
:class:`Report` of records (method, parameters, seed, timings, metrics, images, versions);
:meth:`Report.to_html` renders one self-contained HTML file (images embedded as PNG data
URIs) and :meth:`Report.to_dict` the JSON sidecar.
"""

from __future__ import annotations

import base64
import html
import json
import platform
import time
import traceback
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .._version import __version__
from ..methods import METHODS, Progress, make_method
from ..metrics import METRIC_DESCRIPTIONS, evaluate, nearest_patch_field, synthesis_map
from ..errors import InputError
from ..ops.linalg import fixed_order

__all__ = ["MethodRun", "MethodRecord", "Report", "claim_report", "report_paths", "run_comparison", "write_report"]


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
                        {"seed": run.seed, "seconds": run.seconds, "map_source": run.map_source, "metrics": run.metrics}
                        for run in r.runs
                    ],
                }
                for r in self.records
            ],
        }

    def to_html(self) -> str:
        """One self-contained HTML page (no external resources)."""
        esc = html.escape
        metric_names = list(METRIC_DESCRIPTIONS)
        head_cells = "".join(
            f'<th title="{esc(METRIC_DESCRIPTIONS[m])}">{esc(m.replace("_", " "))}</th>' for m in metric_names
        )
        rows = []
        for rec in self.records:
            if rec.error is not None:
                rows.append(
                    f'<tr class="failed"><td>{esc(rec.method)}</td><td colspan="{len(metric_names) + 1}">'
                    f"failed: {esc(rec.error)}</td></tr>"
                )
                continue
            means = rec.mean_metrics()
            cells = "".join(f"<td>{means[m]:.4g}</td>" for m in metric_names)
            rows.append(f"<tr><td>{esc(rec.method)}</td><td>{rec.median_seconds():.3f}</td>{cells}</tr>")
        sections = []
        for rec in self.records:
            params = ", ".join(f"{k}={v!r}" for k, v in rec.params.items()) or "none"
            body = [
                f'<section id="{esc(rec.method)}"><h2>{esc(rec.method)}</h2>',
                f"<p>{esc(rec.summary)}. <em>{esc(rec.reference)}</em><br>parameters: <code>{esc(params)}</code></p>",
            ]
            if rec.error is not None:
                body.append(f'<p class="error">This method failed: {esc(rec.error)}</p>')
            for run in rec.runs:
                body.append(
                    '<div class="run">'
                    + _figure(run.image, f"output, seed {run.seed} ({run.seconds:.2f} s)")
                    + _figure(run.map_image, f"synthesis map ({run.map_source})")
                    + "</div>"
                )
            body.append("</section>")
            sections.append("\n".join(body))
        versions = ", ".join(f"{k} {v}" for k, v in self.versions.items())
        h, w = self.shape
        return _PAGE.format(
            title=esc(f"texsyn comparison: {self.exemplar_name}"),
            name=esc(self.exemplar_name),
            created=esc(self.created),
            size=f"{w}x{h}",
            seeds=esc(", ".join(str(s) for s in self.seeds)),
            exemplar=_figure(self.exemplar, f"exemplar {self.exemplar.shape[1]}x{self.exemplar.shape[0]}")
            + _figure(self.exemplar_map, "exemplar coloured by position"),
            head=head_cells,
            rows="\n".join(rows),
            sections="\n".join(sections),
            versions=esc(versions),
            legend="".join(
                f"<li><b>{esc(k.replace('_', ' '))}</b>: {esc(v)}</li>" for k, v in METRIC_DESCRIPTIONS.items()
            ),
        )


def _jsonable(value):
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    return value


def _png_data_uri(image: np.ndarray) -> str:
    import imageio.v3 as iio

    data = np.rint(np.clip(np.asarray(image, dtype=np.float64), 0, 1) * 255).astype(np.uint8)
    buffer = iio.imwrite("<bytes>", data, extension=".png")
    return "data:image/png;base64," + base64.b64encode(buffer).decode("ascii")


def _figure(image: np.ndarray, caption: str) -> str:
    h, w = image.shape[:2]
    return (
        f'<figure><img src="{_png_data_uri(image)}" width="{w}" height="{h}" alt="{html.escape(caption)}">'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
    )


def _versions() -> dict[str, str]:
    import scipy
    import skimage

    return {
        "texsyn": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "scikit-image": skimage.__version__,
        "platform": platform.platform(terse=True),
    }


@fixed_order
def run_comparison(
    exemplar: np.ndarray,
    methods: Sequence[str] | None = None,
    *,
    seeds: int = 1,
    shape: tuple[int, int] | None = None,
    exemplar_name: str = "exemplar",
    params: dict[str, dict] | None = None,
    callback: Callable[[Progress], None] | None = None,
) -> Report:
    """Run methods on one exemplar, measure every output, and collect a :class:`Report`.

    Parameters
    ----------
    exemplar : ndarray
    methods : sequence of str, optional
        Method names (all registered methods by default).
    seeds : int
        Number of syntheses per method (seeds 0 .. seeds-1).
    shape : (int, int), optional
        Output size; twice the exemplar by default.
    params : dict, optional
        ``{method: {parameter: value}}`` overrides.
    callback : callable, optional
        Receives a :class:`Progress` (stage ``"methods"``) after each synthesis.

    A method that raises is recorded with its error and the others still run.
    """
    from .._validation import as_exemplar

    ex = as_exemplar(exemplar)
    names = list(methods) if methods else sorted(METHODS)
    if seeds < 1:
        raise InputError(f"seeds must be at least 1, got {seeds}")
    shape = (2 * ex.shape[0], 2 * ex.shape[1]) if shape is None else tuple(shape)
    params = params or {}
    grid = np.stack(np.mgrid[: ex.shape[0], : ex.shape[1]], axis=-1)
    from ..ops import position_colors

    records = []
    total = len(names) * seeds
    done = 0
    for name in names:
        cls = METHODS.get(name)
        record = MethodRecord(
            method=name,
            summary=cls.summary if cls else "",
            reference=cls.reference if cls else "",
            params={},
        )
        try:
            model = make_method(name, **params.get(name, {}))
            record.params = model.get_params()
            start = time.perf_counter()
            model.fit(ex)
            fit_seconds = time.perf_counter() - start
            for seed in range(seeds):
                start = time.perf_counter()
                result = model.sample_with_map(shape, rng=seed)
                seconds = time.perf_counter() - start + fit_seconds
                image = result.image.astype(np.float64)
                field_ = nearest_patch_field(image, ex)
                metrics = evaluate(image, ex, field=field_)
                _, map_image = synthesis_map(image, ex, source_map=result.source_map, field=field_)
                record.runs.append(
                    MethodRun(
                        seed=seed,
                        seconds=seconds,
                        image=result.image,
                        map_image=map_image,
                        map_source="method's source map" if result.source_map is not None else "nearest patches",
                        metrics=metrics,
                    )
                )
                done += 1
                if callback is not None:
                    callback(Progress("methods", done, total))
        except Exception as exc:  # a failing method is reported, the others still run
            record.error = f"{type(exc).__name__}: {exc}"
            record.runs = []
            tb = traceback.extract_tb(exc.__traceback__)
            if tb:
                record.error += f" (at {Path(tb[-1].filename).name}:{tb[-1].lineno})"
            done = names.index(name) * seeds + seeds
            if callback is not None:
                callback(Progress("methods", done, total))
        records.append(record)
    return Report(
        exemplar=ex.astype(np.float32),
        exemplar_name=exemplar_name,
        exemplar_map=position_colors(grid, ex.shape[:2]),
        shape=shape,
        seeds=list(range(seeds)),
        records=records,
        versions=_versions(),
        created=datetime.now(timezone.utc).isoformat(timespec="seconds"),
    )


def report_paths(path: str | Path) -> tuple[Path, Path]:
    """The HTML page and its JSON sidecar (same name, ``.json``) of a report written to ``path``."""
    html_path = Path(path)
    return html_path, html_path.with_suffix(".json")


def claim_report(outputs, path: str | Path) -> tuple[Path, Path]:
    """Check and reserve a report's two files in an :class:`~texsyn.io.OutputSet` (before any work)."""
    html_path, json_path = report_paths(path)
    outputs.claim(html_path, formats={".html": (8,), ".htm": (8,)}, what="report")
    outputs.claim(json_path, formats={".json": (8,)}, what="report sidecar")
    return html_path, json_path


def write_report(
    report: Report,
    path: str | Path,
    *,
    overwrite: bool = False,
    outputs=None,
    metadata: dict | None = None,
) -> tuple[Path, Path]:
    """Write ``report`` as ``path`` (HTML) and its JSON sidecar (same name, ``.json``).

    Both files are written together or not at all. Refuses to replace existing files unless
    ``overwrite``. ``outputs`` is an :class:`~texsyn.io.OutputSet` in which the two files
    were already claimed with :func:`claim_report` (the command line checks them before the
    comparison runs); ``metadata`` adds top-level keys to the JSON (e.g. the command line).
    """
    from ..io import OutputSet

    if outputs is None:
        outputs = OutputSet(overwrite=overwrite)
    html_path, json_path = report_paths(path)
    if not (outputs.claimed(html_path) and outputs.claimed(json_path)):
        claim_report(outputs, path)
    page = report.to_html()
    data = report.to_dict()
    if metadata:
        data.update(metadata)
    with outputs:
        outputs.write_text(html_path, page)
        outputs.write_text(json_path, json.dumps(data, indent=2))
    return html_path, json_path


_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 2em; color: #222; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
th, td {{ border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }}
th:first-child, td:first-child {{ text-align: left; }}
tr.failed td {{ color: #a00; text-align: left; }}
figure {{ display: inline-block; margin: 0.5em; vertical-align: top; }}
figure img {{ image-rendering: pixelated; border: 1px solid #ddd; }}
figcaption {{ font-size: 0.85em; color: #555; }}
.error {{ color: #a00; }}
code {{ font-size: 0.9em; }}
</style>
</head>
<body>
<h1>{title}</h1>
<p>Exemplar <b>{name}</b>; output {size}; seeds {seeds}; made {created}.</p>
<div>{exemplar}</div>
<h2>Summary</h2>
<table>
<tr><th>method</th><th>time (s)</th>{head}</tr>
{rows}
</table>
<ul>{legend}</ul>
{sections}
<footer><p>Versions: {versions}</p></footer>
</body>
</html>
"""
