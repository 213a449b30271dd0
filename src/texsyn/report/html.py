"""The comparison report as one self-contained HTML page (images embedded as PNG data URIs).

:func:`render_html` lays out a :class:`~texsyn.report.Report`: the exemplar, a summary table
(median time and mean metrics per method, failures in red), and one section per method with
every output beside its synthesis map. Nothing on the page refers to another file.
"""

from __future__ import annotations

import base64
import html
from typing import TYPE_CHECKING

import numpy as np

from ..metrics import METRIC_DESCRIPTIONS

if TYPE_CHECKING:
    from .records import Report

__all__ = ["TABLE_STYLE", "figure", "png_data_uri", "render_html"]

#: the style of a report's page and tables (the batch report shares it)
TABLE_STYLE = """\
body { font-family: system-ui, sans-serif; margin: 2em; color: #222; }
table { border-collapse: collapse; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
tr.failed td { color: #a00; text-align: left; }
.error { color: #a00; }
"""


def render_html(report: Report) -> str:
    """One self-contained HTML page (no external resources) for ``report``."""
    esc = html.escape
    metric_names = list(METRIC_DESCRIPTIONS)
    head_cells = "".join(
        f'<th title="{esc(METRIC_DESCRIPTIONS[m])}">{esc(m.replace("_", " "))}</th>' for m in metric_names
    )
    rows = []
    for rec in report.records:
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
    for rec in report.records:
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
                + figure(run.image, f"output, seed {run.seed} ({run.seconds:.2f} s)")
                + figure(run.map_image, f"synthesis map ({run.map_source})")
                + "</div>"
            )
        body.append("</section>")
        sections.append("\n".join(body))
    versions = ", ".join(f"{k} {v}" for k, v in report.versions.items())
    h, w = report.shape
    return _PAGE.format(
        style=TABLE_STYLE,
        title=esc(f"texsyn comparison: {report.exemplar_name}"),
        name=esc(report.exemplar_name),
        created=esc(report.created),
        size=f"{w}x{h}",
        seeds=esc(", ".join(str(s) for s in report.seeds)),
        exemplar=figure(report.exemplar, f"exemplar {report.exemplar.shape[1]}x{report.exemplar.shape[0]}")
        + figure(report.exemplar_map, "exemplar coloured by position"),
        head=head_cells,
        rows="\n".join(rows),
        sections="\n".join(sections),
        versions=esc(versions),
        legend="".join(
            f"<li><b>{esc(k.replace('_', ' '))}</b>: {esc(v)}</li>" for k, v in METRIC_DESCRIPTIONS.items()
        ),
    )


def png_data_uri(image: np.ndarray) -> str:
    """``image`` (values in [0, 1], clipped) as an 8-bit PNG ``data:`` URI."""
    import imageio.v3 as iio

    data = np.rint(np.clip(np.asarray(image, dtype=np.float64), 0, 1) * 255).astype(np.uint8)
    buffer = iio.imwrite("<bytes>", data, extension=".png")
    return "data:image/png;base64," + base64.b64encode(buffer).decode("ascii")


def figure(image: np.ndarray, caption: str) -> str:
    """An HTML ``<figure>`` showing ``image`` at its size, with ``caption``."""
    h, w = image.shape[:2]
    return (
        f'<figure><img src="{png_data_uri(image)}" width="{w}" height="{h}" alt="{html.escape(caption)}">'
        f"<figcaption>{html.escape(caption)}</figcaption></figure>"
    )


_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
{style}figure {{ display: inline-block; margin: 0.5em; vertical-align: top; }}
figure img {{ image-rendering: pixelated; border: 1px solid #ddd; }}
figcaption {{ font-size: 0.85em; color: #555; }}
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
