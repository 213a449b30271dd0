"""Synthesis methods, one class each, and the registry that the front doors read.

Layer 7 (``docs/architecture.md``): each method is a thin class holding its parameters
(the ``__init__`` signature, read as :class:`ParamSpec`), building its model in ``fit`` and
calling its synthesis loop in ``sample``. :data:`METHODS` maps each name to its class.
"""

from __future__ import annotations

from ..errors import InputError
from ..ops.progress import Progress
from ._base import SynthesisResult, TextureSynthesizer
from ._params import ParamSpec
from .efros_leung import EfrosLeung
from .gaussian import CLG, LG, MSLG, RCLG
from .grouplets import Frame, Grouplets
from .heeger_bergen import HeegerBergen
from .patch_wavelet import Modification, PatchWavelet
from .portilla_simoncelli import PortillaSimoncelli
from .quilting import Quilting
from .random_phase import RandomPhase
from .sparse import ConstrainedSparse
from .wavelet_sampling import ComplexWaveletSampling
from .wei_levoy import WeiLevoy

METHODS: dict[str, type[TextureSynthesizer]] = {
    cls.name: cls
    for cls in (
        Quilting,
        EfrosLeung,
        HeegerBergen,
        RandomPhase,
        LG,
        CLG,
        RCLG,
        MSLG,
        ConstrainedSparse,
        ComplexWaveletSampling,
        WeiLevoy,
        PatchWavelet,
        Grouplets,
        PortillaSimoncelli,
    )
}

__all__ = [
    "CLG",
    "ComplexWaveletSampling",
    "ConstrainedSparse",
    "LG",
    "METHODS",
    "MSLG",
    "Modification",
    "RCLG",
    "EfrosLeung",
    "Frame",
    "Grouplets",
    "HeegerBergen",
    "ParamSpec",
    "PatchWavelet",
    "PortillaSimoncelli",
    "Progress",
    "Quilting",
    "RandomPhase",
    "SynthesisResult",
    "TextureSynthesizer",
    "WeiLevoy",
    "get_method",
    "make_method",
]


def get_method(name: str) -> type[TextureSynthesizer]:
    """The method class registered under ``name``; a clear error for unknown names."""
    if not isinstance(name, str) or name not in METHODS:
        raise InputError(f"unknown method {name!r}; choose one of: {', '.join(sorted(METHODS))}")
    return METHODS[name]


def make_method(name: str, **params) -> TextureSynthesizer:
    """Construct a method by name, rejecting unknown parameters with the allowed list.

    Parameters
    ----------
    name : str
        A key of :data:`METHODS`.
    **params
        Hyperparameters (the method's ``__init__`` keywords); deprecated names are renamed
        (:attr:`TextureSynthesizer.deprecated_params`) and deprecated values kept, with a
        ``DeprecationWarning`` naming the caller's line, by the class constructor.

    Returns
    -------
    TextureSynthesizer
        Not fitted yet.

    Raises
    ------
    InputError
        An unknown method or parameter, or a value outside the allowed range (at ``fit``).

    Examples
    --------
    >>> method = make_method("quilting", patch_size=16)
    >>> method.get_params()["patch_size"]
    16
    >>> make_method("quilting", size=3)
    Traceback (most recent call last):
    ...
    texsyn.errors.InputError: unknown parameter 'size' for method 'quilting'; allowed: patch_size, overlap, tolerance, boundary_cut
    """
    cls = get_method(name)
    specs = cls.param_specs()
    unknown = sorted(set(params) - set(specs) - set(cls.deprecated_params))
    if unknown:
        allowed = ", ".join(specs) if specs else "none"
        raise InputError(f"unknown parameter {unknown[0]!r} for method {name!r}; allowed: {allowed}")
    return cls(**params)
