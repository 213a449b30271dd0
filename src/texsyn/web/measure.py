"""The measuring step of a web job: the compare report's metrics and the synthesis map of one output.

``texsyn serve`` runs ``python -m texsyn.web.measure EXEMPLAR OUTPUT FOLDER [SOURCE_MAP.npy]``
in its own process after ``texsyn synth`` (so that a cancel stops it like the synthesis). It
writes into FOLDER ``metrics.json`` (every metric of :func:`texsyn.metrics.evaluate` with its
description, ``docs/web.md``) and ``map.png``: where every output pixel came from (Raad,
Desolneux, Morel 2016, Fig. 9), from the method's own source map when it has one, from the
nearest exemplar patches otherwise, as in the comparison report.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from ..data import load_exemplar
from ..io import read_image, write_image
from ..io.arrays import load_npy
from ..metrics import METRIC_DESCRIPTIONS, evaluate, nearest_patch_field, synthesis_map
from ..ops.linalg import fixed_order

__all__ = ["main", "measure"]


@fixed_order
def measure(
    exemplar: np.ndarray, image: np.ndarray, source_map: np.ndarray | None = None
) -> tuple[dict, np.ndarray]:
    """The report's metrics of ``image`` against ``exemplar`` and the picture of its synthesis map.

    Returns
    -------
    metrics : dict
        ``{"values": {name: float}, "descriptions": {name: str}, "map_source": str}``.
    map_image : ndarray, shape (H, W, 3)
        Position colours of each output pixel's source (:func:`texsyn.metrics.synthesis_map`).
    """
    if exemplar.ndim != image.ndim:  # a grey exemplar gives a grey output; keep them alike
        image = image.mean(axis=2) if image.ndim == 3 else image
    image64 = image.astype(np.float64)
    field = nearest_patch_field(image64, exemplar)
    values = evaluate(image64, exemplar, field=field)
    _, map_image = synthesis_map(image64, exemplar, source_map=source_map, field=field)
    metrics = {
        "values": {name: float(value) for name, value in values.items()},
        "descriptions": {name: METRIC_DESCRIPTIONS.get(name, "") for name in values},
        "map_source": "the method's source map" if source_map is not None else "nearest exemplar patches",
    }
    return metrics, map_image


def main(argv: list[str] | None = None) -> int:
    """Entry point: ``EXEMPLAR OUTPUT FOLDER [SOURCE_MAP.npy]``; exit 0, or 1 with one line."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) not in (3, 4):
        sys.stderr.write("usage: python -m texsyn.web.measure EXEMPLAR OUTPUT FOLDER [SOURCE_MAP.npy]\n")
        return 2
    exemplar_name, output, folder = args[:3]
    try:
        exemplar, _ = load_exemplar(exemplar_name)
        image = read_image(output)
        source_map = load_npy(args[3]) if len(args) == 4 else None
        metrics, map_image = measure(exemplar, image, source_map)
        target = Path(folder)
        write_image(target / "map.png", map_image)
        (target / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    except Exception as exc:  # the server shows this line; the synthesis itself succeeded
        sys.stderr.write(f"texsyn: error: measuring failed: {type(exc).__name__}: {exc}\n")
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover - run by texsyn serve as a process
    raise SystemExit(main())
