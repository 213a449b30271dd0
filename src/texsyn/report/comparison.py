"""Running the comparison: every method on one exemplar, each output measured.

:func:`run_comparison` fits each method once, samples it for every seed, and measures
every output with :func:`texsyn.metrics.evaluate` (one nearest-patch search shared by the
patch metrics and the synthesis map). A method that fails is recorded with its error; the
others still run.
"""

from __future__ import annotations

import platform
import time
import traceback
from collections.abc import Callable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import cast

import numpy as np

from .._validation import as_exemplar
from .._version import __version__
from ..errors import InputError
from ..methods import METHODS, make_method
from ..metrics import evaluate, nearest_patch_field, synthesis_map
from ..ops import position_colors
from ..ops.canvas import default_output_shape
from ..ops.linalg import fixed_order
from ..ops.progress import Progress, Reporter
from .records import MethodRecord, MethodRun, Report

__all__ = ["library_versions", "run_comparison"]


def library_versions() -> dict[str, str]:
    """texsyn's version and those of the libraries and platform a report was made with."""
    import scipy
    import skimage

    return {
        "texsyn": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "scikit-image": skimage.__version__,  # type: ignore[attr-defined]
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
    ex = as_exemplar(exemplar)
    names = list(methods) if methods else sorted(METHODS)
    if seeds < 1:
        raise InputError(f"seeds must be at least 1, got {seeds}")
    out_shape = default_output_shape(ex.shape) if shape is None else cast("tuple[int, int]", tuple(shape))
    params = params or {}
    grid = np.stack(list(np.mgrid[: ex.shape[0], : ex.shape[1]]), axis=-1)
    records = []
    report = Reporter(callback, "methods", len(names) * seeds)
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
                result = model.sample_with_map(out_shape, rng=seed)
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
                        map_source="method's source map"
                        if result.source_map is not None
                        else "nearest patches",
                        metrics=metrics,
                    )
                )
                done += 1
                report(done)
        except Exception as exc:  # a failing method is reported, the others still run
            record.error = f"{type(exc).__name__}: {exc}"
            record.runs = []
            tb = traceback.extract_tb(exc.__traceback__)
            if tb:
                record.error += f" (at {Path(tb[-1].filename).name}:{tb[-1].lineno})"
            done = names.index(name) * seeds + seeds
            report(done)
        records.append(record)
    return Report(
        exemplar=ex.astype(np.float32),
        exemplar_name=exemplar_name,
        exemplar_map=position_colors(grid, ex.shape[:2]),
        shape=out_shape,
        seeds=list(range(seeds)),
        records=records,
        versions=library_versions(),
        created=datetime.now(UTC).isoformat(timespec="seconds"),
    )
