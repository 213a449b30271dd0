"""The report of ``texsyn compare --batch``: every method on every exemplar, from the manifest.

:func:`batch_report` turns the manifest records of a batch run with metrics into the report's
data: a summary (per method: items made and failed, median seconds, mean of each metric over
every exemplar and seed) and, per exemplar, one row per method. :func:`render_batch_html`
lays it out as one HTML page: the summary table, then a table per exemplar with the outputs
shown beside their metrics. The outputs are linked, not embedded (a batch may hold
thousands), by paths relative to the page, so the page and the output folder move together.
"""

from __future__ import annotations

import html
import os
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..metrics import METRIC_DESCRIPTIONS
from ..report import TABLE_STYLE, library_versions

__all__ = ["batch_report", "render_batch_html"]


def _summary(method: str, records: Sequence[dict]) -> dict:
    made = [r for r in records if r.get("status") == "done"]
    measured = [r["metrics"] for r in made if r.get("metrics")]
    return {
        "method": method,
        "done": len(made),
        "failed": len(records) - len(made),
        "median_seconds": float(np.median([r["seconds"] for r in made])) if made else None,
        "mean_metrics": _means(measured),
        "errors": sorted({str(r.get("error")) for r in records if r.get("status") != "done"}),
    }


def _means(measured: Sequence[dict]) -> dict[str, float]:
    """The mean of each metric over the runs where it is a finite number (the manifest has ``null`` otherwise)."""
    means = {}
    for name in METRIC_DESCRIPTIONS:
        values = [x[name] for x in measured if isinstance(x.get(name), (int, float))]
        if values:
            means[name] = float(np.mean(values))
    return means


def batch_report(records: Sequence[dict], outdir: str | os.PathLike, *, metadata: dict | None = None) -> dict:
    """The report's data (the JSON sidecar) from a batch's manifest records.

    Parameters
    ----------
    records : sequence of dict
        What :func:`texsyn.batch.run` returned (with ``metrics=True``).
    outdir : path
        The batch's output folder (the records' ``output`` paths are relative to it).
    metadata : dict, optional
        Added at the top level (the command line, the report's path...).
    """
    methods = list(dict.fromkeys(r["method"] for r in records))
    exemplars = list(dict.fromkeys(r["exemplar"] for r in records))
    blocks: list[dict] = []
    data: dict = {
        "texsyn_batch_report": 1,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "versions": library_versions(),
        "outdir": str(outdir),
        "metrics": METRIC_DESCRIPTIONS,
        "summary": [_summary(m, [r for r in records if r["method"] == m]) for m in methods],
        "exemplars": blocks,
    }
    for exemplar in exemplars:
        rows = []
        for method in methods:
            own = [r for r in records if r["exemplar"] == exemplar and r["method"] == method]
            if not own:
                continue
            row = _summary(method, own)
            row["runs"] = [
                {
                    "seed": r["seed"],
                    "output": r.get("output"),
                    "status": r.get("status"),
                    "seconds": r.get("seconds"),
                    "metrics": r.get("metrics"),
                    "error": r.get("error"),
                }
                for r in own
            ]
            rows.append(row)
        blocks.append({"exemplar": exemplar, "methods": rows})
    if metadata:
        data.update(metadata)
    return data


def render_batch_html(data: dict, page: str | os.PathLike) -> str:
    """One HTML page for the report ``data`` (:func:`batch_report`) written at ``page``.

    Output images are linked by their path relative to ``page``'s folder.
    """
    esc = html.escape
    names = list(METRIC_DESCRIPTIONS)
    head = "".join(
        f'<th title="{esc(METRIC_DESCRIPTIONS[m])}">{esc(m.replace("_", " "))}</th>' for m in names
    )
    folder = Path(page).resolve().parent
    outdir = Path(data["outdir"]).resolve()

    def row(entry: dict, extra: str = "") -> str:
        seconds = entry["median_seconds"]
        cells = "".join(
            f"<td>{entry['mean_metrics'][m]:.4g}</td>" if m in entry["mean_metrics"] else "<td>-</td>"
            for m in names
        )
        failed = f' class="failed" title="{esc("; ".join(entry["errors"]))}"' if entry["failed"] else ""
        return (
            f"<tr{failed}><td>{esc(entry['method'])}</td>{extra}<td>{entry['done']}</td><td>{entry['failed']}</td>"
            f"<td>{'-' if seconds is None else f'{seconds:.3f}'}</td>{cells}</tr>"
        )

    def thumbnails(entry: dict) -> str:
        links = []
        for run in entry["runs"]:
            if run["status"] != "done":
                links.append(f'<span class="error">seed {run["seed"]}: {esc(str(run["error"]))}</span>')
                continue
            href = Path(os.path.relpath(outdir / run["output"], folder)).as_posix()
            links.append(
                f'<a href="{esc(href)}"><img src="{esc(href)}" alt="seed {run["seed"]}" '
                f'title="seed {run["seed"]}" height="64"></a>'
            )
        return f'<td class="outputs">{" ".join(links)}</td>'

    columns = f"<th>done</th><th>failed</th><th>time (s)</th>{head}</tr>"
    sections = []
    for block in data["exemplars"]:
        rows = "\n".join(row(entry, thumbnails(entry)) for entry in block["methods"])
        sections.append(
            f"<section><h2>{esc(block['exemplar'])}</h2>\n<table>\n<tr><th>method</th><th>outputs</th>{columns}\n"
            f"{rows}\n</table></section>"
        )
    legend = "".join(
        f"<li><b>{esc(k.replace('_', ' '))}</b>: {esc(v)}</li>" for k, v in METRIC_DESCRIPTIONS.items()
    )
    versions = ", ".join(f"{k} {v}" for k, v in data["versions"].items())
    return _PAGE.format(
        style=TABLE_STYLE,
        title=esc(f"texsyn batch comparison: {len(data['exemplars'])} exemplars"),
        created=esc(data["created"]),
        summary="\n".join(row(entry) for entry in data["summary"]),
        head="<tr><th>method</th>" + columns,
        legend=legend,
        sections="\n".join(sections),
        versions=esc(versions),
    )


_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
{style}td.outputs {{ text-align: left; white-space: nowrap; }}
td.outputs img {{ image-rendering: pixelated; border: 1px solid #ddd; margin: 1px; }}
</style>
</head>
<body>
<h1>{title}</h1>
<p>Made {created}. Time: median seconds of an item (sampling and writing; the fit each
exemplar and method share is not counted). Metrics: means over every exemplar and seed of
each method, measured on the files as written. The outputs are files of the batch's folder,
linked from here.</p>
<h2>Summary</h2>
<table>
{head}
{summary}
</table>
<ul>{legend}</ul>
{sections}
<footer><p>Versions: {versions}</p></footer>
</body>
</html>
"""
