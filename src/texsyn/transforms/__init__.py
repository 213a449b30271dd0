"""Layer 2, transforms: multiscale representations with ``forward`` and ``inverse``.

Steerable (real and complex), DT-CWT, Gaussian/Laplacian pyramids, grouplets and the
patch-valued wavelet transform. They import only :mod:`texsyn.ops` and the foundation
(``docs/architecture.md``). Levels are 0-based, the finest first.
"""
