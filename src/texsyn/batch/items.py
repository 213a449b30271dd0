"""What a batch makes: one item per (exemplar, method, seed), each with its seed and file name.

:func:`plan` expands the inputs (files, folders, glob patterns, ``builtin:NAME``), refuses
two exemplars with the same stem (their outputs would share a folder), and gives every item
its seed and its output path ``<stem>/<method>-s<seed>.png`` inside the output folder.

Seeds (``docs/batch.md``, "Seeds"): with ``seeds=N`` the seed of the ``k``-th synthesis of
an exemplar by a method is :func:`item_seed` of the batch seed, the exemplar's identity (the
SHA-256 of its file's bytes), the method's name and ``k``: it depends on nothing else (not
on the workers, their number, the order of the inputs or the other items), and
``texsyn synth --seed`` with it gives the item's bytes. ``seed_list`` gives the seeds
themselves.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..data import BUILTIN, BUILTIN_PREFIX
from ..errors import InputError
from ..io import READ_FORMATS
from ..methods import get_method, make_method

__all__ = [
    "MAX_SEED",
    "BatchItem",
    "expand_inputs",
    "file_sha256",
    "item_seed",
    "plan",
]

#: seeds derived by :func:`item_seed` are in ``[0, MAX_SEED]`` (63 bits: a signed 64-bit integer anywhere)
MAX_SEED = 2**63 - 1

#: the text that starts every seed derivation; changing it would change every derived seed
SEED_DOMAIN = "texsyn-batch-seed/1"


@dataclass(frozen=True)
class BatchItem:
    """One output of a batch: which exemplar, which method with which parameters, which seed.

    Attributes
    ----------
    exemplar : str
        The exemplar's path as given (or ``builtin:NAME``).
    exemplar_sha256 : str
        The SHA-256 of the exemplar file's bytes (of ``builtin:NAME`` for a built-in one).
    method : str
    params : dict
        The parameters given (``-p``): the method is made with them, as ``synth -p`` makes it.
    method_params : dict
        Every parameter of the method (its defaults included), as ``get_params`` gives them.
    seed : int
        The seed ``texsyn synth --seed`` takes to make the same bytes.
    seed_index : int
        Position of the seed among the exemplar's seeds (``0 .. N-1``).
    size : (int, int) or None
        Output ``(height, width)``; ``None``: twice the exemplar (as ``synth``).
    outdir : str
        The batch's output folder (its manifest is ``outdir/manifest.jsonl``).
    output : str
        The output file, relative to ``outdir``: ``<stem>/<method>-s<seed>.png``.
    batch_seed : int or None
        The batch seed the seed was derived from (``None`` for a seed given as it is).
    """

    exemplar: str
    exemplar_sha256: str
    method: str
    params: dict = field(hash=False)
    method_params: dict = field(hash=False)
    seed: int
    seed_index: int
    size: tuple[int, int] | None
    outdir: str
    output: str
    batch_seed: int | None = None

    @property
    def id(self) -> str:
        """What identifies the item across runs: a digest of everything that makes its bytes."""
        what = {
            "exemplar_sha256": self.exemplar_sha256,
            "method": self.method,
            "params": self.method_params,
            "seed": self.seed,
            "size": list(self.size) if self.size is not None else None,
        }
        text = json.dumps(what, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:24]

    @property
    def fit_key(self) -> str:
        """What the items sharing one fitted model have in common: exemplar, method, parameters."""
        text = json.dumps(
            [self.exemplar_sha256, self.method, self.method_params], sort_keys=True, default=str
        )
        return hashlib.sha256(text.encode()).hexdigest()[:24]

    @property
    def output_path(self) -> Path:
        return Path(self.outdir) / self.output

    def to_dict(self) -> dict:
        """The item as JSON-ready data (the manifest's first fields)."""
        record = asdict(self)
        del record["outdir"]  # outputs are relative to it: the manifest stays valid if the folder moves
        record["size"] = [self.size[1], self.size[0]] if self.size is not None else None  # WIDTH, HEIGHT
        record["id"] = self.id
        return record


def item_seed(batch_seed: int, exemplar_sha256: str, method: str, index: int) -> int:
    """The seed of the ``index``-th synthesis of an exemplar by ``method`` in a batch.

    The first 8 bytes of the SHA-256 of ``"texsyn-batch-seed/1\\n{batch_seed}\\n{exemplar
    digest}\\n{method}\\n{index}"``, read as a big-endian integer and halved (63 bits):
    ``docs/batch.md``, "Seeds".

    Examples
    --------
    >>> item_seed(0, "ab" * 32, "quilting", 0) == item_seed(0, "ab" * 32, "quilting", 0)
    True
    >>> item_seed(0, "ab" * 32, "quilting", 0) != item_seed(0, "ab" * 32, "quilting", 1)
    True
    """
    text = f"{SEED_DOMAIN}\n{int(batch_seed)}\n{exemplar_sha256}\n{method}\n{int(index)}"
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], "big") >> 1


def file_sha256(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """The SHA-256 of a file's bytes, as hexadecimal."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def exemplar_sha256(exemplar: str) -> str:
    """An exemplar's identity: its file's SHA-256, or that of the text ``builtin:NAME``."""
    if exemplar.startswith(BUILTIN_PREFIX):
        return hashlib.sha256(exemplar.encode()).hexdigest()
    return file_sha256(exemplar)


def expand_inputs(inputs: Iterable[str]) -> list[str]:
    """The exemplars that ``inputs`` name, in the order given, each once.

    An input is a file, a folder (its image files, sorted by name, not its subfolders), a
    glob pattern (``*``, ``?``, ``[...]``; ``**`` crosses folders; matches sorted) or
    ``builtin:NAME``. A folder or pattern that names no image file, or a missing file, is
    an error.
    """
    found: list[str] = []
    seen: set[str] = set()

    def add(path: str) -> None:
        key = path if path.startswith(BUILTIN_PREFIX) else os.path.realpath(path)
        if key not in seen:
            seen.add(key)
            found.append(path)

    for given in inputs:
        if given.startswith(BUILTIN_PREFIX):
            name = given.split(":", 1)[1]
            if name not in BUILTIN:
                raise InputError(f"unknown built-in exemplar {given!r}; choose one of: {', '.join(BUILTIN)}")
            add(given)
        elif os.path.isdir(given):
            images = sorted(
                str(p) for p in Path(given).iterdir() if p.is_file() and p.suffix.lower() in READ_FORMATS
            )
            if not images:
                raise InputError(f"folder '{given}' holds no image file ({', '.join(READ_FORMATS)})")
            for path in images:
                add(path)
        elif os.path.isfile(given):
            add(given)
        elif glob.has_magic(given):
            matches = sorted(
                p
                for p in glob.glob(given, recursive=True)
                if os.path.isfile(p) and Path(p).suffix.lower() in READ_FORMATS
            )
            if not matches:
                raise InputError(f"pattern '{given}' matches no image file")
            for path in matches:
                add(path)
        else:
            raise InputError(f"input '{given}' is not a file, a folder or a pattern that matches files")
    if not found:
        raise InputError("no input: give image files, folders or glob patterns")
    return found


def stem(exemplar: str) -> str:
    """The name of an exemplar's output folder: the file name without suffix (``brick`` for ``builtin:brick``)."""
    if exemplar.startswith(BUILTIN_PREFIX):
        return exemplar.split(":", 1)[1]
    return Path(exemplar).stem


def plan(
    inputs: Iterable[str],
    outdir: str | os.PathLike,
    methods: Sequence[str],
    *,
    seeds: int = 1,
    seed_list: Sequence[int] | None = None,
    batch_seed: int = 0,
    size: tuple[int, int] | None = None,
    params: Mapping[str, Mapping] | None = None,
) -> list[BatchItem]:
    """Every item of a batch: each exemplar of ``inputs`` by each method with each seed.

    Parameters
    ----------
    inputs : iterable of str
        Files, folders, glob patterns or ``builtin:NAME`` (:func:`expand_inputs`).
    outdir : path
        The output folder; item outputs are ``outdir/<stem>/<method>-s<seed>.png``.
    methods : sequence of str
        Method names (each once).
    seeds : int
        Seeds per (exemplar, method), derived with :func:`item_seed` from ``batch_seed``.
    seed_list : sequence of int, optional
        The seeds themselves (``seeds`` is then ignored).
    batch_seed : int
    size : (int, int), optional
        Output ``(height, width)``; twice each exemplar by default.
    params : mapping, optional
        ``{method: {parameter: value}}``.

    Raises
    ------
    InputError
        Two exemplars with the same stem, an unknown method or parameter, no seed.
    """
    methods = list(dict.fromkeys(methods))
    if not methods:
        raise InputError("no method: give at least one")
    params = dict(params or {})
    unknown = sorted(set(params) - set(methods))
    if unknown:
        raise InputError(
            f"parameters are given for {', '.join(map(repr, unknown))}, which the batch does not run"
        )
    for m in methods:
        get_method(m)
    given = {m: dict(params.get(m, {})) for m in methods}
    full_params = {m: make_method(m, **given[m]).get_params() for m in methods}
    if seed_list is not None:
        explicit = [int(s) for s in seed_list]
        if not explicit:
            raise InputError("the seed list is empty")
        if any(not 0 <= s <= 2**64 - 1 for s in explicit):
            raise InputError(f"seeds must be integers in [0, 2^64 - 1], got {explicit}")
        explicit = list(dict.fromkeys(explicit))
    elif seeds < 1:
        raise InputError(f"seeds must be at least 1, got {seeds}")
    exemplars = expand_inputs(inputs)
    stems: dict[str, str] = {}
    for exemplar in exemplars:
        other = stems.setdefault(stem(exemplar), exemplar)
        if other != exemplar:
            raise InputError(
                f"inputs '{other}' and '{exemplar}' have the same name '{stem(exemplar)}', so their outputs "
                "would share a folder; rename one or run them in separate batches"
            )
    items = []
    for exemplar in exemplars:
        digest = exemplar_sha256(exemplar)
        for method in methods:
            chosen: list[tuple[int, int, int | None]]
            if seed_list is not None:
                chosen = [(k, s, None) for k, s in enumerate(explicit)]
            else:
                chosen = [
                    (k, item_seed(batch_seed, digest, method, k), int(batch_seed)) for k in range(seeds)
                ]
            for index, seed, derived_from in chosen:
                items.append(
                    BatchItem(
                        exemplar=exemplar,
                        exemplar_sha256=digest,
                        method=method,
                        params=given[method],
                        method_params=full_params[method],
                        seed=seed,
                        seed_index=index,
                        size=tuple(size) if size is not None else None,  # type: ignore[arg-type]
                        outdir=os.path.abspath(outdir),
                        output=f"{stem(exemplar)}/{method}-s{seed}.png",
                        batch_seed=derived_from,
                    )
                )
    return items
