"""Synthesis methods, one class each, and the registry that the front doors read.

Layer 7 (``docs/architecture.md``): each method is a thin class holding its parameters
(the ``__init__`` signature, read as :class:`ParamSpec`), building its model in ``fit`` and
calling its synthesis loop in ``sample``. :data:`METHODS` maps each name to its class.
"""

from __future__ import annotations

from collections.abc import Iterator, MutableMapping
from typing import TYPE_CHECKING

from .._lazy import lazy_exports
from ..errors import InputError
from ..ops.progress import Progress
from ._base import SynthesisResult, TextureSynthesizer
from ._params import ParamSpec

if TYPE_CHECKING:  # the names for type checkers; at run time ``__getattr__`` loads them
    from .efros_leung import EfrosLeung
    from .gaussian import CLG, LG, RCLG
    from .grouplets import Frame, Grouplets
    from .heeger_bergen import HeegerBergen
    from .multiscale_gaussian import MSLG
    from .patch_wavelet import Modification, PatchWavelet
    from .portilla_simoncelli import PortillaSimoncelli
    from .quilting import Quilting
    from .random_phase import RandomPhase
    from .sparse import ConstrainedSparse
    from .wavelet_sampling import ComplexWaveletSampling
    from .wei_levoy import WeiLevoy

#: each method's class and the module defining it, in the registry's order
_CLASSES = {
    "Quilting": "quilting",
    "EfrosLeung": "efros_leung",
    "HeegerBergen": "heeger_bergen",
    "RandomPhase": "random_phase",
    "LG": "gaussian",
    "CLG": "gaussian",
    "RCLG": "gaussian",
    "MSLG": "multiscale_gaussian",
    "ConstrainedSparse": "sparse",
    "ComplexWaveletSampling": "wavelet_sampling",
    "WeiLevoy": "wei_levoy",
    "PatchWavelet": "patch_wavelet",
    "Grouplets": "grouplets",
    "PortillaSimoncelli": "portilla_simoncelli",
}

#: each registered name and its class's name (``tests/test_startup.py`` checks they agree)
_NAMES = {
    "quilting": "Quilting",
    "efros_leung": "EfrosLeung",
    "heeger_bergen": "HeegerBergen",
    "random_phase": "RandomPhase",
    "lg": "LG",
    "clg": "CLG",
    "rclg": "RCLG",
    "mslg": "MSLG",
    "sparse": "ConstrainedSparse",
    "cwt": "ComplexWaveletSampling",
    "wei_levoy": "WeiLevoy",
    "patch_wavelet": "PatchWavelet",
    "grouplets": "Grouplets",
    "portilla_simoncelli": "PortillaSimoncelli",
}

__getattr__, __dir__ = lazy_exports(
    __name__, {**_CLASSES, "Frame": "grouplets", "Modification": "patch_wavelet"}
)


class MethodRegistry(MutableMapping[str, type[TextureSynthesizer]]):
    """Method names to classes, each class imported when first looked up.

    Listing the names costs nothing; reading a class imports its module (and what that
    module needs: numba, scipy's submodules, scikit-learn), so that a command loads only the
    method it runs (``docs/performance.md``, "Start-up"). Entries can be replaced or added
    like a dict's (a plug-in, a test's stand-in).
    """

    def __init__(self, names: dict[str, str]) -> None:
        self._class_names = dict(names)
        self._classes: dict[str, type[TextureSynthesizer]] = {}

    def __getitem__(self, name: str) -> type[TextureSynthesizer]:
        cls = self._classes.get(name)
        if cls is None:
            cls = __getattr__(self._class_names[name])  # KeyError for unknown names
            self._classes[name] = cls
        return cls

    def __setitem__(self, name: str, cls: type[TextureSynthesizer]) -> None:
        self._class_names.setdefault(name, cls.__name__)
        self._classes[name] = cls

    def __delitem__(self, name: str) -> None:
        del self._class_names[name]
        self._classes.pop(name, None)

    def __iter__(self) -> Iterator[str]:
        return iter(self._class_names)

    def __len__(self) -> int:
        return len(self._class_names)

    def __contains__(self, name: object) -> bool:
        return name in self._class_names

    def __repr__(self) -> str:
        return f"MethodRegistry({list(self._class_names)})"


#: every method by its name (``texsyn methods`` lists them); classes load on first lookup
METHODS: MethodRegistry = MethodRegistry(_NAMES)

__all__ = [
    "CLG",
    "ComplexWaveletSampling",
    "ConstrainedSparse",
    "LG",
    "METHODS",
    "MethodRegistry",
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
