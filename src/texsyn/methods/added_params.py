"""Parameters the methods gained after model files existed, and the values older files mean.

A saved model holds every parameter its method had when it was written, so a parameter
missing from a file is one the method gained since; :func:`texsyn.load` fills it with the
value listed here (``docs/persistence.md``, "Files older than a parameter").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["ADDED_PARAMS", "DEFAULT", "AddedParam"]


class _Default:
    def __repr__(self) -> str:
        return "DEFAULT"


#: :attr:`AddedParam.old` for a parameter whose current default is what older files get
DEFAULT = _Default()


@dataclass(frozen=True)
class AddedParam:
    """A parameter a method gained after model files existed (``docs/persistence.md``).

    Attributes
    ----------
    after : str
        The last texsyn release whose files lack it.
    old : object
        The value that gives what a model saved without it did; :data:`DEFAULT` where the
        current default does (or where nothing can: the note says why).
    note : str
        Why that value, for the reader of this table.
    """

    after: str
    old: Any
    note: str = ""


_NO_HISTOGRAM = AddedParam("0.2.0", "none", "outputs were the model's draws, not histogram-matched")
_EXACT = AddedParam("0.2.0", 0.0, "the paper's exact conditioning on the overlap")

#: Parameters added to each method since model files exist (texsyn 0.2.0), with the value that
#: reproduces a file written before them. :func:`load` fills a parameter missing from a file
#: with it; where that is not the current default it warns once, naming the parameters. A
#: test checks that every parameter a method gained since 0.2.0 is listed here.
ADDED_PARAMS: dict[str, dict[str, AddedParam]] = {
    "lg": {"histogram": _NO_HISTOGRAM},
    "clg": {"looseness": _EXACT, "histogram": _NO_HISTOGRAM},
    "rclg": {"looseness": _EXACT, "histogram": _NO_HISTOGRAM},
    "mslg": {
        "coarse_seam": AddedParam("0.2.0", "average", "the coarsest patches were averaged (eq. 15)"),
        "histogram": _NO_HISTOGRAM,
        "highpass": AddedParam("0.2.0", "none", "only the pixel histogram was matched"),
    },
    "efros_leung": {
        "search": AddedParam("0.2.0", DEFAULT, "the search was exhaustive ('exact')"),
        "k_coherence": AddedParam("0.2.0", DEFAULT, "used only with search='approximate'"),
    },
    "cwt": {
        "coherence": AddedParam(
            "0.2.0", 0.0, "each coarse block was drawn among all candidates (the paper's rule)"
        )
    },
    "portilla_simoncelli": {
        "record_distance": AddedParam("0.2.0", False, "no diagnostics were returned"),
        "final_highpass": AddedParam("0.2.0", False, "the output was the last iteration's"),
    },
    "sparse": {
        "spectrum_weight": AddedParam(
            "0.2.0", DEFAULT, "used only with lowpass_ref='spectrum', which older files do not hold"
        ),
        "final_rounds": AddedParam(
            "0.2.0", DEFAULT, "used only with lowpass_ref='spectrum', which older files do not hold"
        ),
    },
    "grouplets": {
        name: AddedParam("0.2.0", DEFAULT, "0.2.0's grouplet model and animation are gone (CHANGELOG)")
        for name in ("turbulence", "flow_scale", "spectrum_slope", "advection", "renewal", "layer_iterations")
    },
}
