"""The layer picture of ``docs/architecture.md``, enforced (issue 17).

- a module imports only from lower layers (or from its own package); a function whose
  docstring starts "Deprecated" (a shim keeping an old name working) may import lazily from
  above, and a module whose docstring starts "Deprecated alias" is exempt; dynamic imports
  (``importlib.import_module``, aliased or relative) and modules reached through attribute
  chains (``texsyn.methods`` after ``import texsyn.ops``) count as imports; ``sys.modules``,
  ``exec`` and ``getattr`` with strings are not followed;
- no module uses another module's private (``_name``) names, nor a private module of another
  package (``from texsyn.methods import _base`` outside ``texsyn.methods``);
- no module is over 400 lines without a paragraph at its top saying why.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src" / "texsyn"

#: layer of each top-level part of the package, lowest first (docs/architecture.md)
LAYERS: dict[str, int] = {
    "texsyn.errors": 0,
    "texsyn._version": 0,
    "texsyn._lazy": 0,
    "texsyn._validation": 1,
    "texsyn.io": 2,
    "texsyn.data": 3,
    "texsyn.ops": 3,
    "texsyn.transforms": 4,
    "texsyn.models": 5,
    "texsyn.drivers": 6,
    "texsyn.methods": 7,
    "texsyn.persistence": 8,
    "texsyn.metrics": 8,
    "texsyn.editing": 8,
    "texsyn.materials": 8,
    "texsyn.report": 9,
    "texsyn.web": 10,
    "texsyn.batch": 10,
    "texsyn.cli": 11,
    "texsyn": 12,
}

MAX_LINES = 400
REASON = re.compile(r"^Why this module is long:", re.M)
#: a function whose docstring starts with this word is a deprecation shim: it alone may import
#: lazily from a higher layer (to keep an old name working) or import dynamically
SHIM = "Deprecated"


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(SRC.rglob("*.py")):
        parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((".".join(parts), path))
    return out


def _part(module: str) -> str:
    """The entry of :data:`LAYERS` a module belongs to (its longest matching prefix).

    ``"texsyn"`` itself stands for the package's ``__init__`` only: a new top-level module or
    package must be given a layer in :data:`LAYERS`.
    """
    best = ""
    for key in LAYERS:
        matches = module == key or (key != "texsyn" and module.startswith(key + "."))
        if matches and len(key) > len(best):
            best = key
    assert best, f"module {module} has no layer in LAYERS (docs/architecture.md)"
    return best


@dataclass(frozen=True)
class Import:
    """One import of a texsyn module: ``from target import name`` or ``import target``."""

    line: int
    target: str
    name: str | None
    in_shim: bool  # inside a function whose docstring starts with SHIM
    dynamic: bool = False  # importlib.import_module / __import__


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    if level == 0:
        return name or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def _parents(tree: ast.AST) -> dict[ast.AST, ast.AST]:
    return {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}


def _in_shim(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> bool:
    while node in parents:
        node = parents[node]
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if (ast.get_docstring(node) or "").startswith(SHIM):
                return True
    return False


def _importers(tree: ast.AST) -> tuple[set[str], set[str]]:
    """Local names of ``importlib.import_module`` and of the ``importlib`` module, aliases included."""
    functions, modules = {"__import__"}, {"importlib"}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "importlib":
            functions |= {a.asname or a.name for a in node.names if a.name == "import_module"}
        elif isinstance(node, ast.Import):
            modules |= {a.asname or a.name for a in node.names if a.name == "importlib"}
    return functions, modules


def _dynamic_target(node: ast.Call, module: str, path: Path) -> str:
    """The module a call of ``import_module(name, package)`` / ``__import__`` imports."""
    arg = node.args[0] if node.args else None
    if not (isinstance(arg, ast.Constant) and isinstance(arg.value, str)):
        return "<computed>"
    name = arg.value
    level = len(name) - len(name.lstrip("."))
    if not level:
        return name
    package_arg = (
        node.args[1]
        if len(node.args) > 1
        else next((k.value for k in node.keywords if k.arg == "package"), None)
    )
    if isinstance(package_arg, ast.Constant) and isinstance(package_arg.value, str):
        package = package_arg.value
    elif isinstance(package_arg, ast.Name) and package_arg.id in ("__name__", "__package__"):
        package = module if package_arg.id == "__name__" else _package(module, path)
    else:
        return "<computed>"
    base = package.split(".")
    base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name.lstrip(".")] if name.lstrip(".") else []))


def _bound_modules(module: str, path: Path, tree: ast.AST) -> dict[str, str]:
    """Local names bound to texsyn modules by import statements (``import texsyn.x`` binds ``texsyn``)."""
    bound: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _resolve(module, path.name == "__init__.py", node.level, node.module)
            for alias in node.names:
                if f"{target}.{alias.name}" in NAMES:
                    bound[alias.asname or alias.name] = f"{target}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("texsyn"):
                    bound[alias.asname or alias.name.split(".")[0]] = alias.name if alias.asname else "texsyn"
    return bound


def _imports(module: str, path: Path) -> list[Import]:
    tree = ast.parse(path.read_text())
    parents = _parents(tree)
    is_package = path.name == "__init__.py"
    functions, importlib_names = _importers(tree)
    bound = _bound_modules(module, path, tree)
    out = []
    for node in ast.walk(tree):
        shim = _in_shim(node, parents)
        if isinstance(node, ast.ImportFrom):
            target = _resolve(module, is_package, node.level, node.module)
            if target == "texsyn" or target.startswith("texsyn."):
                out += [Import(node.lineno, target, alias.name, shim) for alias in node.names]
        elif isinstance(node, ast.Import):
            out += [
                Import(node.lineno, alias.name, None, shim)
                for alias in node.names
                if alias.name == "texsyn" or alias.name.startswith("texsyn.")
            ]
        elif isinstance(node, ast.Call) and _is_lazy_table(node):
            out += _lazy_table_imports(node, module, is_package, shim, tree)
        elif isinstance(node, ast.Call):
            func = node.func
            dynamic = (isinstance(func, ast.Name) and func.id in functions) or (
                isinstance(func, ast.Attribute)
                and func.attr == "import_module"
                and isinstance(func.value, ast.Name)
                and func.value.id in importlib_names
            )
            if dynamic:
                out.append(Import(node.lineno, _dynamic_target(node, module, path), None, shim, dynamic=True))
        elif isinstance(node, ast.Attribute) and not isinstance(parents.get(node), ast.Attribute):
            chain = _attribute_chain(node)  # the longest chain only: texsyn.methods.x, not texsyn.methods
            if chain and chain[0] in bound:
                current = bound[chain[0]]
                for attr in chain[1:]:
                    if f"{current}.{attr}" not in NAMES:
                        break
                    current = f"{current}.{attr}"
                    out.append(Import(node.lineno, current, None, shim, dynamic=True))
    return out


#: the one module allowed to import a computed name: it loads the submodules named in the
#: literal tables given to its ``lazy_exports``, which this test reads as imports instead
LAZY_LOADER = "texsyn._lazy"


def _is_lazy_table(node: ast.Call) -> bool:
    func = node.func
    return (isinstance(func, ast.Name) and func.id == "lazy_exports") or (
        isinstance(func, ast.Attribute) and func.attr == "lazy_exports"
    )


def _literal_table(expr: ast.expr | None, assigned: dict[str, ast.expr]) -> list[tuple[str, str]] | None:
    """The (name, submodule) pairs of a literal dict, following ``**NAME`` and module-level names."""
    if isinstance(expr, ast.Name) and expr.id in assigned:
        return _literal_table(assigned[expr.id], assigned)
    if not isinstance(expr, ast.Dict):
        return None
    pairs: list[tuple[str, str]] = []
    for key, value in zip(expr.keys, expr.values, strict=True):
        if key is None:  # {**OTHER, ...}
            inner = _literal_table(value, assigned)
            if inner is None:
                return None
            pairs += inner
        elif (
            isinstance(key, ast.Constant) and isinstance(value, ast.Constant) and isinstance(value.value, str)
        ):
            pairs.append((str(key.value), value.value))
        else:
            return None
    return pairs


def _lazy_table_imports(
    node: ast.Call, module: str, is_package: bool, shim: bool, tree: ast.Module
) -> list[Import]:
    """``lazy_exports(__name__, {name: submodule, ...})`` as the imports it makes.

    The table must be a literal dict (directly, through a module-level name, or merged with
    ``**``) so that its targets can be checked like imports; anything else is ``<computed>``.
    """
    package = module if is_package else module.rpartition(".")[0]
    assigned = {
        target.id: stmt.value
        for stmt in tree.body
        if isinstance(stmt, (ast.Assign, ast.AnnAssign)) and stmt.value is not None
        for target in (stmt.targets if isinstance(stmt, ast.Assign) else [stmt.target])
        if isinstance(target, ast.Name)
    }
    pairs = _literal_table(node.args[1] if len(node.args) > 1 else None, assigned)
    if pairs is None:
        return [Import(node.lineno, "<computed>", None, shim, dynamic=True)]
    return [Import(node.lineno, f"{package}.{submodule}", name, shim) for name, submodule in pairs]


def _is_deprecated_alias(path: Path) -> bool:
    """A module kept only so that an old import path works (it warns and re-exports)."""
    return (ast.get_docstring(ast.parse(path.read_text())) or "").startswith("Deprecated alias")


MODULES = _modules()
NAMES = {name for name, _ in MODULES}


def _package(module: str, path: Path) -> str:
    return module if path.name == "__init__.py" else module.rpartition(".")[0]


def _private_outside(target: str, importer_package: str) -> str | None:
    """The first private segment of ``target`` whose package does not contain the importer."""
    parts = target.split(".")
    for i, part in enumerate(parts):
        if part.startswith("_") and not part.startswith("__"):
            owner = ".".join(parts[:i])
            if not (importer_package == owner or importer_package.startswith(owner + ".")):
                return ".".join(parts[: i + 1])
    return None


def upward_imports(module: str, path: Path) -> list[str]:
    """The imports of ``module`` that do not go down the layers (outside deprecation shims)."""
    if _is_deprecated_alias(path):
        return []
    mine = _part(module)
    wrong = []
    for imp in _imports(module, path):
        if imp.in_shim:
            continue
        if imp.target == "<computed>" and module == LAZY_LOADER:
            continue  # the loader of lazy_exports tables, whose targets are checked where they are given
        if imp.target == "<computed>":
            wrong.append(f"{path.name}:{imp.line} imports a computed module name outside a deprecation shim")
            continue
        full = f"{imp.target}.{imp.name}" if imp.name and f"{imp.target}.{imp.name}" in NAMES else imp.target
        theirs = _part(full)
        if theirs == mine or LAYERS[theirs] < LAYERS[mine]:
            continue
        wrong.append(f"{path.name}:{imp.line} imports {full} (layer {LAYERS[theirs]} >= {LAYERS[mine]})")
    return wrong


@pytest.mark.parametrize("module,path", MODULES, ids=[m for m, _ in MODULES])
def test_imports_only_go_down(module, path):
    wrong = upward_imports(module, path)
    assert not wrong, "\n".join(wrong)


def _attribute_chain(node: ast.Attribute) -> list[str] | None:
    parts = []
    current: ast.expr = node
    while isinstance(current, ast.Attribute):
        parts.append(current.attr)
        current = current.value
    if not isinstance(current, ast.Name):
        return None
    parts.append(current.id)
    return parts[::-1]


def private_uses(module: str, path: Path) -> list[str]:
    """Uses of other modules' private names or private modules by ``module``."""
    package = _package(module, path)
    wrong = []
    tree = ast.parse(path.read_text())
    for imp in _imports(module, path):
        if imp.dynamic:
            continue
        full = f"{imp.target}.{imp.name}" if imp.name else imp.target
        private = _private_outside(full if imp.name is None or full in NAMES else imp.target, package)
        if private:
            wrong.append(f"{path.name}:{imp.line} imports the private module {private}")
        if imp.name and imp.name.startswith("_") and not imp.name.startswith("__") and full not in NAMES:
            wrong.append(f"{path.name}:{imp.line} takes {imp.name} from {imp.target}")
    bound = _bound_modules(module, path, tree)
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute):
            continue
        chain = _attribute_chain(node)
        if not chain or chain[0] not in bound:
            continue
        current = bound[chain[0]]
        for attr in chain[1:]:
            if f"{current}.{attr}" in NAMES:
                current = f"{current}.{attr}"
                private = _private_outside(current, package)
                if private:
                    wrong.append(f"{path.name}:{node.lineno} uses the private module {private}")
                    break
                continue
            if attr.startswith("_") and not attr.startswith("__"):
                wrong.append(f"{path.name}:{node.lineno} uses {current}.{attr}")
            break
    return sorted(set(wrong))


@pytest.mark.parametrize("module,path", MODULES, ids=[m for m, _ in MODULES])
def test_no_private_names_of_other_modules(module, path):
    wrong = private_uses(module, path)
    assert not wrong, "\n".join(wrong)


#: violations the checks must catch (each written into a fake module of the given package)
VIOLATIONS = [
    ("texsyn.models.fake", "def f():\n    import texsyn.methods as m\n    return m\n", upward_imports),
    (
        "texsyn.models.fake",
        "import importlib\nM = importlib.import_module('texsyn.methods')\n",
        upward_imports,
    ),
    ("texsyn.models.fake", "import importlib\nM = importlib.import_module(NAME)\n", upward_imports),
    ("texsyn.io.fake", "from ..persistence import load\n", upward_imports),
    ("texsyn.ops.fake", "from .. import methods\n", upward_imports),
    ("texsyn.report.fake", "from texsyn.methods import _base\n", private_uses),
    ("texsyn.metrics.fake", "import texsyn.ops.search as s\nX = s._x\n", private_uses),
    ("texsyn.metrics.fake", "import texsyn.ops.search\nX = texsyn.ops.search._x\n", private_uses),
    ("texsyn.metrics.fake", "from texsyn import ops\nX = ops.search._x\n", private_uses),
    ("texsyn.ops.fake", "from .search import _fold_minima\n", private_uses),
    (
        "texsyn.ops.fake",
        "import importlib\nM = importlib.import_module('.methods', 'texsyn')\n",
        upward_imports,
    ),
    (
        "texsyn.ops.fake",
        "from importlib import import_module as im\nM = im('texsyn.methods')\n",
        upward_imports,
    ),
    ("texsyn.ops.fake", "import texsyn.ops\nX = texsyn.methods.METHODS\n", upward_imports),
    (
        "texsyn.ops.fake",
        "import importlib\nM = importlib.import_module('..methods', __package__)\n",
        upward_imports,
    ),
]


@pytest.mark.parametrize("module,source,check", VIOLATIONS)
def test_the_checks_catch_violations(module, source, check, tmp_path):
    path = tmp_path / "fake.py"
    path.write_text('"""A module that breaks the rules."""\n' + source)
    assert check(module, path), f"not caught: {source!r} in {module}"


def test_a_new_top_level_module_needs_a_layer():
    with pytest.raises(AssertionError, match="no layer"):
        _part("texsyn.extra.x")


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
        f"{path.name}:{imp.line} imports {imp.target}"
        for imp in _imports(module, path)
        if not imp.in_shim and (imp.target in ALIASES or (imp.name and f"{imp.target}.{imp.name}" in ALIASES))
    ]
    assert not wrong, "\n".join(wrong)


def test_every_method_runs_without_deprecation_warnings():
    """Fitting and sampling with the current parameter names warns about nothing of texsyn's."""
    import warnings

    import texsyn

    exemplar = texsyn.data.exemplar("brick", size=64)
    small = {"sparse": {"patch_size": 6, "n_atoms": 16, "ksvd_iterations": 1, "n_outer": 1, "n_scales": 1}}
    ours = re.compile(r"deprecated|texsyn", re.I)
    warned = []
    for name in sorted(texsyn.METHODS):
        specs = texsyn.get_method(name).param_specs()
        params = {k: v for k, v in small.get(name, {}).items() if k in specs}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            texsyn.make_method(name, **params).fit(exemplar).sample((32, 32), rng=0)
        warned += [
            f"{name}: {w.message}"
            for w in caught
            if issubclass(w.category, DeprecationWarning) and ours.search(str(w.message))
        ]
    assert not warned, "\n".join(warned)


def test_the_deprecation_check_sees_an_old_name():
    """The check above can fail: an old parameter name is caught by the same filter."""
    import warnings

    import texsyn

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        texsyn.make_method("efros_leung", epsilon=0.1)
    assert any(re.search(r"deprecated", str(w.message)) for w in caught)
