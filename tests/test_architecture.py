"""The layer picture of ``docs/architecture.md``, enforced (issue 17).

- a module imports only from lower layers (or from its own package);
- no module uses another module's private (``_name``) names;
- no module is over 400 lines without a paragraph at its top saying why.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "texsyn"

#: layer of each top-level part of the package, lowest first (docs/architecture.md)
LAYERS: dict[str, int] = {
    "texsyn.errors": 0,
    "texsyn._version": 0,
    "texsyn._validation": 1,
    "texsyn.io": 2,
    "texsyn.data": 2,
    "texsyn.ops": 3,
    "texsyn.transforms": 4,
    "texsyn.models": 5,
    "texsyn.drivers": 6,
    "texsyn.methods": 7,
    "texsyn.persistence": 8,
    "texsyn.metrics": 8,
    "texsyn.report": 9,
    "texsyn.cli": 10,
    "texsyn.web": 10,
    "texsyn": 11,
}

#: upward imports that exist only to keep a deprecated name working, each with its reason
DEPRECATED_ALIASES: dict[tuple[str, str], str] = {
    ("texsyn.io", "texsyn.persistence"): "texsyn.io.save_fitted/load_fitted, deprecated for texsyn.save/load",
}

MAX_LINES = 400
REASON = re.compile(r"^Why this module is long:", re.M)


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(SRC.rglob("*.py")):
        parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((".".join(parts), path))
    return out


def _part(module: str) -> str:
    """The entry of :data:`LAYERS` a module belongs to (its longest matching prefix)."""
    best = ""
    for key in LAYERS:
        if (module == key or module.startswith(key + ".")) and len(key) > len(best):
            best = key
    assert best, f"module {module} has no layer in LAYERS (docs/architecture.md)"
    return best


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(module: str, path: Path):
    tree = ast.parse(path.read_text())
    is_package = path.name == "__init__.py"
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _resolve(module, is_package, node)
            if target.startswith("texsyn"):
                for alias in node.names:
                    yield node.lineno, target, alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("texsyn"):
                    yield node.lineno, alias.name, None


def _is_deprecated_alias(path: Path) -> bool:
    """A module kept only so that an old import path works (it warns and re-exports)."""
    return (ast.get_docstring(ast.parse(path.read_text())) or "").startswith("Deprecated alias")


MODULES = _modules()
NAMES = {name for name, _ in MODULES}


@pytest.mark.parametrize("module,path", MODULES, ids=[m for m, _ in MODULES])
def test_imports_only_go_down(module, path):
    if _is_deprecated_alias(path):
        return
    mine = _part(module)
    wrong = []
    for line, target, name in _imports(module, path):
        full = f"{target}.{name}" if name and f"{target}.{name}" in NAMES else target
        theirs = _part(full)
        if theirs == mine or full.startswith(mine + ".") and mine != "texsyn":
            continue
        if mine == "texsyn" and module != "texsyn":
            continue  # a top-level module outside LAYERS would have failed in _part
        if LAYERS[theirs] < LAYERS[mine]:
            continue
        if (mine, theirs) in DEPRECATED_ALIASES:
            continue
        wrong.append(f"{path.name}:{line} imports {full} (layer {LAYERS[theirs]} >= {LAYERS[mine]})")
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("module,path", MODULES, ids=[m for m, _ in MODULES])
def test_no_private_names_of_other_modules(module, path):
    wrong = []
    for line, target, name in _imports(module, path):
        if name and name.startswith("_") and not name.startswith("__"):
            if f"{target}.{name}" in NAMES:
                continue  # importing a private *module* of one's own package is allowed
            wrong.append(f"{path.name}:{line} takes {name} from {target}")
    tree = ast.parse(path.read_text())
    imported_modules = {
        (alias.asname or alias.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
        if f"{_resolve(module, path.name == '__init__.py', node)}.{alias.name}" in NAMES
    }
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in imported_modules
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            wrong.append(f"{path.name}:{node.lineno} uses {node.value.id}.{node.attr}")
    assert not wrong, "\n".join(wrong)


@pytest.mark.parametrize("module,path", MODULES, ids=[m for m, _ in MODULES])
def test_long_modules_say_why(module, path):
    text = path.read_text()
    lines = text.count("\n")
    if lines <= MAX_LINES:
        return
    doc = ast.get_docstring(ast.parse(text)) or ""
    assert REASON.search(doc), (
        f"{path.relative_to(SRC.parent)} has {lines} lines; split it or start a paragraph of its "
        f"docstring with 'Why this module is long:'"
    )


ALIASES = {name for name, path in MODULES if _is_deprecated_alias(path)}


@pytest.mark.parametrize("module,path", MODULES, ids=[m for m, _ in MODULES])
def test_nothing_imports_a_deprecated_alias(module, path):
    """The old ``texsyn.ops.<transform>`` paths exist for users only; the package uses the new ones."""
    if module in ALIASES:
        return
    wrong = [
        f"{path.name}:{line} imports {target}"
        for line, target, name in _imports(module, path)
        if target in ALIASES or (name and f"{target}.{name}" in ALIASES)
    ]
    assert not wrong, "\n".join(wrong)


def test_every_method_runs_without_deprecation_warnings():
    """Fitting and sampling with default parameter names warns about nothing of texsyn's."""
    import warnings

    import texsyn

    exemplar = texsyn.data.exemplar("brick", size=64)
    small = {"sparse": {"patch_size": 6, "n_atoms": 16, "ksvd_iterations": 1, "n_outer": 1, "n_scales": 1}}
    for name in sorted(texsyn.METHODS):
        specs = texsyn.get_method(name).param_specs()
        params = {k: v for k, v in small.get(name, {}).items() if k in specs}
        with warnings.catch_warnings():
            warnings.filterwarnings("error", category=DeprecationWarning, module="texsyn")
            warnings.filterwarnings("error", category=DeprecationWarning, message=".*texsyn")
            try:
                texsyn.make_method(name, **params).fit(exemplar).sample((32, 32), rng=0)
            except DeprecationWarning as warning:  # pragma: no cover - the failure message
                raise AssertionError(f"{name}: {warning}") from None
