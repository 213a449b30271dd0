"""Layer 3, models: what ``fit`` learns from an exemplar, as frozen dataclasses.

Statistics (Portilla–Simoncelli, histograms of subbands), local Gaussian models, sparse
dictionaries and the exemplar indexes of patch searches. A model is built once by ``fit``
and never changed by ``sample`` (``docs/architecture.md``).
"""
