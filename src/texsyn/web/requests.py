"""What the page asks for, checked, and turned into the command lines a job runs.

A job runs the command line itself (``texsyn synth``, ``compare``, ``animate``) in a process
of its own, so that the page gives the same bytes as the terminal for the same seed, the
same one-line errors, and a cancel that stops the work (``docs/web.md``). This module checks
a request with the same parameter specs as the command line (:meth:`ParamSpec.parse`, whose
messages the command line prints too) and builds:

- the argument lists of the job's steps (no shell: every value is one argument);
- the equivalent command line the page shows, with the user's file name;
- the files the page may download, each by a fixed key (never a path from the client).
"""

from __future__ import annotations

import secrets
import shlex
import sys
from dataclasses import dataclass, field

from ..errors import InputError
from ..methods import METHODS, get_method
from ..ops.canvas import default_output_shape
from .settings import ServerSettings
from .uploads import Exemplar

__all__ = ["MODES", "DownloadFile", "JobPlan", "plan_job"]

MODES = ("synth", "compare", "animate")
MAX_SEED = 2**64 - 1
MAX_TEXT = 200
MAX_FRAMES = 600
#: how a job starts texsyn: this interpreter, so that the same installation runs the work
PYTHON = (sys.executable, "-m")


@dataclass(frozen=True)
class DownloadFile:
    """A file of a job: where it lies in the job's folder, how it downloads, which step makes it."""

    filename: str
    download_name: str
    media_type: str
    step: int = 0


@dataclass
class JobPlan:
    """A checked request: the steps to run and what the page shows and downloads."""

    mode: str
    label: str
    exemplar: Exemplar
    steps: list[list[str]]
    command_line: str
    seed: int | None
    request: dict
    files: dict[str, DownloadFile] = field(default_factory=dict)
    #: the steps from this index on add to a finished result (measuring): their failure
    #: leaves the job done, with a warning, and its output downloadable
    optional_from: int | None = None


def _fail(message: str) -> InputError:
    return InputError(message)


def _integer(value, what: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail(f"{what} must be a whole number in [{low}, {high}], got {_show(value)}")
    if not low <= value <= high:
        raise _fail(f"{what} must be in [{low}, {high}], got {value}")
    return value


def _show(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _size(value, settings: ServerSettings, default: tuple[int, int]) -> tuple[int, int] | None:
    """``[width, height]`` or ``None`` (the command's default, ``default`` as (height, width))."""
    if value is None:
        if max(default) > settings.max_side:  # the largest side holds for the default too
            raise _fail(
                f"size: the default output ({default[1]}x{default[0]}) is over the largest side "
                f"{settings.max_side}; give size [width, height] with sides in [8, {settings.max_side}]"
            )
        return None
    if not isinstance(value, list) or len(value) != 2:
        raise _fail(f"size must be [width, height], got {_show(value)}")
    width = _integer(value[0], "the output width", 8, settings.max_side)
    height = _integer(value[1], "the output height", 8, settings.max_side)
    return width, height


def _params(method: str, values, where: str = "params") -> list[str]:
    """``{name: text}`` checked by the method's parameter specs; ``-p NAME=TEXT`` items."""
    if values is None:
        return []
    if not isinstance(values, dict):
        raise _fail(f"{where} must be an object of NAME: VALUE, got {_show(values)}")
    specs = get_method(method).param_specs()
    items = []
    for name, text in values.items():
        if name not in specs:
            allowed = ", ".join(specs) or "none"
            raise _fail(f"unknown parameter {_show(name)} for method {method!r}; allowed: {allowed}")
        if isinstance(text, bool):
            text = "true" if text else "false"
        elif isinstance(text, (int, float)):
            text = repr(text)
        if not isinstance(text, str) or len(text) > MAX_TEXT or "\n" in text or "\x00" in text:
            raise _fail(f"parameter {name!r} of method {method!r} must be a short text, got {_show(text)}")
        specs[name].parse(text, method)  # the command line's own check and message
        items.append(f"{name}={text.strip()}")
    return items


def _method(name) -> str:
    if not isinstance(name, str) or name not in METHODS:
        raise _fail(f"unknown method {_show(name)}; choose one of: {', '.join(sorted(METHODS))}")
    return name


def _line(command: str, exemplar: str, args: list[str]) -> str:
    """The command line a user types for the same work (``exemplar`` already quoted)."""
    return f"texsyn {command} {exemplar} {shlex.join(args)}"


def _texsyn(*args: str) -> list[str]:
    return [*PYTHON, "texsyn.cli", "--progress", "json", *args]


def plan_job(request, exemplar_of, settings: ServerSettings) -> JobPlan:
    """Check a job request (parsed JSON) and plan its steps.

    Parameters
    ----------
    request : dict
        ``{"mode", "exemplar", "method" | "methods", "params", "size", "seed", "frames", "fps",
        "metrics"}`` (``docs/web.md``, "API"); ``metrics: false`` skips measuring a synthesis
        (the metrics' exact patch search grows with output times exemplar).
    exemplar_of : callable
        Exemplar id -> :class:`~texsyn.web.uploads.Exemplar` (raises when unknown).
    settings : ServerSettings

    Raises
    ------
    InputError
        One line naming the field, what is wrong and what is allowed.
    """
    if not isinstance(request, dict):
        raise _fail("the request must be a JSON object")
    known = {"mode", "exemplar", "method", "methods", "params", "size", "seed", "frames", "fps", "metrics"}
    unknown = sorted(str(key) for key in request if key not in known)
    if unknown:
        raise _fail(f"unknown field {_show(unknown[0])}; allowed: {', '.join(sorted(known))}")
    mode = request.get("mode", "synth")
    if mode not in MODES:
        raise _fail(f"mode must be one of {', '.join(MODES)}, got {_show(mode)}")
    exemplar_id = request.get("exemplar")
    if not isinstance(exemplar_id, str) or len(exemplar_id) > MAX_TEXT:
        raise _fail("exemplar must be the id of an upload or builtin:NAME")
    exemplar = exemplar_of(exemplar_id)
    own_shape = (exemplar.height, exemplar.width)
    default = own_shape if mode == "animate" else default_output_shape(own_shape)
    size = _size(request.get("size"), settings, default)
    size_args = ["--size", f"{size[0]}x{size[1]}"] if size else []
    shown_exemplar = exemplar.name if exemplar.id.startswith("builtin:") else shlex.quote(exemplar.name)

    if mode == "compare":
        methods = request.get("methods")
        if not isinstance(methods, list) or not methods or len(methods) > len(METHODS):
            raise _fail(f"methods must be a list of 1 to {len(METHODS)} method names")
        names = list(dict.fromkeys(_method(m) for m in methods))
        params = request.get("params") or {}
        if not isinstance(params, dict):
            raise _fail("params must be an object of METHOD: {NAME: VALUE}")
        items = []
        for method, values in params.items():
            if method not in names:
                raise _fail(f"params name method {_show(method)}, which is not compared")
            items += [f"{method}.{item}" for item in _params(method, values, f"params of {method}")]
        args = [*[a for m in names for a in ("-m", m)], "--seeds", "1", *size_args]
        args += [a for item in items for a in ("-p", item)]
        plan = JobPlan(
            mode,
            "compare " + ", ".join(names),
            exemplar,
            [_texsyn("compare", exemplar.argument, *args, "-o", "report.html")],
            _line("compare", shown_exemplar, [*args, "-o", "report.html"]),
            None,
            request,
        )
        plan.files = {
            "report": DownloadFile("report.html", "texsyn-report.html", "text/html"),
            "report_json": DownloadFile("report.json", "texsyn-report.json", "application/json"),
        }
        return plan

    seed = request.get("seed")
    seed = secrets.randbelow(2**32) if seed is None else _integer(seed, "seed", 0, MAX_SEED)
    if mode == "animate":
        method = "grouplets"
        frames = _integer(request.get("frames", 48), "frames", 2, MAX_FRAMES)
        fps = request.get("fps", 24)
        if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not 1 <= fps <= 60:
            raise _fail(f"fps must be a number in [1, 60], got {_show(fps)}")
        items = _params(method, request.get("params"))
        args = ["--frames", str(frames), "--fps", f"{fps:g}", *size_args, "--seed", str(seed)]
        args += [a for item in items for a in ("-p", item)]
        video = f"texsyn-grouplets-{seed}.webm"
        plan = JobPlan(
            mode,
            f"animate ({frames} frames)",
            exemplar,
            [_texsyn("animate", exemplar.argument, *args, "-o", "animation.webm")],
            _line("animate", shown_exemplar, [*args, "-o", video]),
            seed,
            request,
        )
        plan.files = {
            "video": DownloadFile("animation.webm", video, "video/webm"),
            "run": DownloadFile("run.json", f"texsyn-grouplets-{seed}.json", "application/json"),
        }
        return plan

    method = _method(request.get("method", "quilting"))
    measured = request.get("metrics", True)
    if not isinstance(measured, bool):
        raise _fail(f"metrics must be true or false, got {_show(measured)}")
    items = _params(method, request.get("params"))
    args = ["-m", method, *size_args, "--seed", str(seed), *[a for item in items for a in ("-p", item)]]
    has_map = get_method(method).has_source_map
    stem = f"texsyn-{method}-{seed}"
    map_args = ["--source-map", "source_map.npy"] if has_map else []
    shown_map = ["--source-map", f"{stem}-map.npy"] if has_map else []
    measure = [*PYTHON, "texsyn.web.measure", exemplar.argument, "texture.png", "."]
    plan = JobPlan(
        mode,
        method,
        exemplar,
        [_texsyn("synth", exemplar.argument, *args, *map_args, "-o", "texture.png")]
        + ([measure + (["source_map.npy"] if has_map else [])] if measured else []),
        _line("synth", shown_exemplar, [*args, *shown_map, "-o", f"{stem}.png"]),
        seed,
        request,
    )
    plan.optional_from = 1
    plan.files = {
        "image": DownloadFile("texture.png", f"{stem}.png", "image/png"),
        "map": DownloadFile("map.png", f"{stem}-map.png", "image/png", step=1),
        "run": DownloadFile("run.json", f"{stem}.json", "application/json"),
    }
    if has_map:
        plan.files["map_array"] = DownloadFile(
            "source_map.npy", f"{stem}-map.npy", "application/octet-stream"
        )
    return plan
