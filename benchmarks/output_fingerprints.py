"""Fingerprints of every public output, to prove a refactoring changes no byte.

Run before and after a change on the same machine and compare::

    python benchmarks/output_fingerprints.py write before.json
    python benchmarks/output_fingerprints.py write after.json
    python benchmarks/output_fingerprints.py compare before.json after.json

Each entry is the SHA-256 of the bytes of one output (image, source map, frame, flow,
statistics) of a small run with a fixed seed: every method's ``sample_with_map`` on a grey
and a colour exemplar, ``modify``, ``animate``, ``synthesize_along``, ``refine``,
``gaussian_resample``, the metrics and a fitted model sampled twice. The hashes are only
comparable on one machine and library build (``docs/determinism.md``); they are never stored
in the repository.
"""

from __future__ import annotations

import hashlib
import json
import sys
import warnings

import numpy as np

import texsyn

#: small settings that keep the whole run under a few minutes on 2 cores
SMALL = {
    "quilting": {"patch_size": 12},
    "efros_leung": {"window_size": 7},
    "heeger_bergen": {},
    "random_phase": {},
    "lg": {"patch_size": 6},
    "clg": {"patch_size": 6},
    "rclg": {"patch_size": 6},
    "mslg": {"patch_size": 6, "n_scales": 2},
    "sparse": {"patch_size": 6, "n_atoms": 32, "ksvd_iterations": 2, "n_outer": 2, "n_scales": 1},
    "cwt": {},
    "wei_levoy": {"window": 5, "levels": 2},
    "patch_wavelet": {"min_width": 4},
    "grouplets": {"n_iterations": 2},
    "portilla_simoncelli": {"n_iterations": 3, "n_scales": 2},
}


def _digest(value) -> str:
    h = hashlib.sha256()
    if value is None:
        h.update(b"none")
    elif isinstance(value, dict):
        for key in sorted(value):
            h.update(key.encode())
            h.update(_digest(value[key]).encode())
    elif isinstance(value, (list, tuple)):
        for item in value:
            h.update(_digest(item).encode())
    else:
        arr = np.ascontiguousarray(np.asarray(value))
        h.update(str(arr.dtype).encode() + str(arr.shape).encode())
        h.update(arr.tobytes())
    return h.hexdigest()[:24]


def _params(name: str) -> dict:
    specs = texsyn.get_method(name).param_specs()
    return {k: v for k, v in SMALL.get(name, {}).items() if k in specs}


def fingerprints() -> dict[str, str]:
    out: dict[str, str] = {}
    grey = texsyn.data.exemplar("gravel", size=32).astype(np.float32)
    grey = grey.mean(axis=-1) if grey.ndim == 3 else grey
    # the built-in exemplars are grey: a colour one with correlated channels, made from three
    colour = np.stack([texsyn.data.exemplar(n, size=32) for n in ("brick", "grass", "gravel")], axis=-1)
    colour = np.clip(colour @ np.array([[0.6, 0.3, 0.1], [0.2, 0.6, 0.2], [0.1, 0.2, 0.7]]), 0, 1)
    for name in sorted(texsyn.METHODS):
        for label, ex in (("grey", grey), ("colour", colour)):
            try:
                model = texsyn.make_method(name, **_params(name)).fit(ex)
                first = model.sample_with_map((40, 44), rng=3)
                again = model.sample_with_map((40, 44), rng=3)
                out[f"{name}/{label}/image"] = _digest(first.image)
                out[f"{name}/{label}/source"] = _digest(first.source_map)
                out[f"{name}/{label}/again"] = _digest(again.image)
            except Exception as exc:  # a method that refuses the small setting is recorded too
                out[f"{name}/{label}/error"] = f"{type(exc).__name__}: {exc}"
    for name in ("portilla_simoncelli", "grouplets"):  # the grey colour option on a colour exemplar
        grey_model = texsyn.make_method(name, colour="grey", **_params(name)).fit(colour)
        out[f"{name}/colour-grey/image"] = _digest(grey_model.sample((40, 44), rng=3))
    pw = texsyn.make_method("patch_wavelet", **_params("patch_wavelet")).fit(colour)
    texture = texsyn.data.exemplar("gravel", size=32)
    result = pw.modify(texture, 0.5)
    out["patch_wavelet/modify"] = _digest([result.image, getattr(result, "source_map", None)])
    gr = texsyn.make_method("grouplets", **_params("grouplets")).fit(grey)
    frames = list(gr.animate(3, (32, 32), rng=1))
    out["grouplets/animate"] = _digest([[f.image, f.flow] for f in frames])
    flow = gr.flow_field((32, 32))
    out["grouplets/synthesize_along"] = _digest(gr.synthesize_along(flow, rng=2))
    ps = texsyn.make_method("portilla_simoncelli", **_params("portilla_simoncelli")).fit(grey)
    start = ps.sample((32, 32), rng=0)
    out["portilla_simoncelli/refine"] = _digest(ps.refine(start, n_iterations=2))
    from texsyn.methods.gaussian import gaussian_resample

    out["gaussian_resample"] = _digest(gaussian_resample(colour, patch_size=6, rng=4))
    from texsyn import metrics

    sample = texsyn.make_method("quilting", **_params("quilting")).fit(colour).sample((40, 40), rng=0)
    out["metrics/evaluate"] = _digest(
        {k: np.float64(v) for k, v in metrics.evaluate(sample, colour).items() if np.isscalar(v)}
    )
    return out


def main(argv: list[str]) -> int:
    warnings.simplefilter("ignore")
    if len(argv) == 2 and argv[0] == "write":
        with open(argv[1], "w") as f:
            json.dump(fingerprints(), f, indent=1, sort_keys=True)
        return 0
    if len(argv) == 3 and argv[0] == "compare":
        a, b = (json.load(open(p)) for p in argv[1:])
        changed = sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))
        for key in changed:
            print(f"{key}: {a.get(key)} -> {b.get(key)}")
        print(f"{len(changed)} of {len(a.keys() | b.keys())} fingerprints differ")
        return 1 if changed else 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
