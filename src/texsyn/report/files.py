"""Writing a report: the HTML page and its JSON sidecar, together or not at all."""

from __future__ import annotations

import json
from pathlib import Path

from ..io import OutputSet
from .records import Report

__all__ = ["claim_report", "report_paths", "write_report"]


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
