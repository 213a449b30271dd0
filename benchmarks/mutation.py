"""Mutation testing of the five paper methods' core modules with mutmut (docs/testing.md).

Usage::

    pip install -e '.[test,mutation]'
    python benchmarks/mutation.py [GROUP ...] [--every N] [--functions GLOB ...]
                                  [--rerun FILE] [--include-memory-model] [--deselect NODEID]
                                  [--max-children 1] [--workdir DIR] [--json FILE]

GROUP is one of ``patch_wavelet``, ``cwt``, ``grouplets``, ``sparse``, ``lg`` (default: all,
in that order). Each group is one ``mutmut run``, in its own scratch copy of the repository
(``DIR/GROUP``, default ``$TMPDIR/texsyn-mutation``; nothing is written into the checkout),
whose ``[tool.mutmut]`` is the one of ``pyproject.toml`` with ``only_mutate`` set to the
group's core modules and the test selection set to the group's own test files (those that
exist: ``tests/test_strength_*.py`` files may be added later) plus
``tests/test_mutation_gaps.py`` (minus :data:`DESELECT`). mutmut then runs, for each
mutant, only the selected tests that call the mutated function (it records which in a
first, instrumented run).

Mutated: every function and method of the group's modules except the memory model
(``memory_terms`` and its helpers, :data:`MEMORY_MODEL`: an estimate of the peak memory,
not the paper's algorithm; ``--include-memory-model`` mutates them too) and the functions
mutmut cannot mutate (decorated ones, listed in the output).

``--rerun FILE`` (a ``--json`` of an earlier run) runs again only the mutants that FILE did
not record as killed, and merges: the counts printed are those of the earlier run with the
retested mutants' new statuses (to measure tests added since, such as
``tests/test_mutation_gaps.py``).

``--every N`` (N in 1, 2, 5, 10) samples the mutants: only those whose number ends in one of
the digits 0..9 step N (``*__mutmut_*[05]`` for N=5) are run, a systematic sample that is
spread over every function of every module. ``--functions GLOB`` restricts the run to the
mutants whose name matches (``texsyn.ops.sparse.x_batch_omp__mutmut_*``). Both are plain
mutmut name globs, so ``mutmut run GLOB`` in the scratch copy reproduces a run.

Printed per module: mutants generated, tested, killed, survived, timeout, suspicious
(crashes of the test process, segfaults), no tests, the score (killed + timeout) / tested
(a mutant that makes the tests run past the time limit is detected), and the
functions mutmut does not mutate (decorated functions: ``@numba.njit``, ``@property``, ...).
Every survivor's diff (``mutmut show``) goes to ``DIR/GROUP/survivors.txt``.

The threads of numpy / numba are limited to one per mutmut child (the runs are meant for a
small shared machine); ``--max-children`` sets how many mutants run at once.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: paper method -> (core modules under src/texsyn, its test files)
GROUPS: dict[str, tuple[list[str], list[str]]] = {
    "patch_wavelet": (
        [
            "transforms/patch_wavelet.py",
            "models/patch_wavelet.py",
            "models/patch_embedding.py",
            "models/patch_search.py",
            "methods/patch_wavelet.py",
        ],
        [
            "tests/test_patch_wavelet.py",
            "tests/test_strength_patch_wavelet.py",
            "tests/test_ops_bounded_search.py",
        ],
    ),
    "cwt": (
        ["transforms/dtcwt.py", "drivers/coarse_to_fine.py", "methods/wavelet_sampling.py"],
        ["tests/test_ops_dtcwt.py", "tests/test_methods_wavelet.py", "tests/test_strength_classic.py"],
    ),
    "grouplets": (
        [
            "transforms/grouplets.py",
            "models/grouplets.py",
            "ops/flow.py",
            "ops/fluid.py",
            "methods/grouplets.py",
        ],
        ["tests/test_grouplets.py", "tests/test_strength_grouplets.py"],
    ),
    "sparse": (
        ["ops/sparse.py", "models/sparse.py", "methods/sparse.py"],
        ["tests/test_sparse.py", "tests/test_strength_classic.py"],
    ),
    "lg": (
        [
            "models/gaussian.py",
            "drivers/raster.py",
            "methods/single_scale_gaussian.py",
            "methods/gaussian.py",
            "methods/multiscale_gaussian.py",
        ],
        ["tests/test_methods_gaussian.py", "tests/test_strength_gaussian.py"],
    ),
}
#: tests left out of a group's selection: slow, and their algorithmic checks are made by
#: faster tests of the same group (the command-line test writes files through modify)
DESELECT: dict[str, list[str]] = {
    "patch_wavelet": ["tests/test_patch_wavelet.py::test_cli_modify_writes_the_texture_and_the_magnitudes"],
}
#: tests written to kill survivors of earlier runs; part of every group
GAP_TESTS = "tests/test_mutation_gaps.py"
#: last digits of the mutant number kept by --every N
SAMPLE_DIGITS = {1: None, 2: "[02468]", 5: "[05]", 10: "0"}
#: exit codes in mutmut's meta files -> status (mutmut.stats.status_by_exit_code)
STATUS = {
    1: "killed",
    3: "killed",
    0: "survived",
    5: "no tests",
    33: "no tests",
    34: "skipped",
    36: "timeout",
    24: "timeout",
    -24: "timeout",
    152: "timeout",
    255: "timeout",
    37: "type check",
    None: "not checked",
}
COLUMNS = ("killed", "survived", "timeout", "suspicious", "no tests")
#: names of the memory-model functions, left out unless --include-memory-model
MEMORY_MODEL = re.compile(r"memory|_terms$|_bytes$|^_width_dims$|^_levels_widths$")


def module_name(module: str) -> str:
    return "texsyn." + module[: -len(".py")].replace("/", ".")


def functions(path: Path) -> list[tuple[str, str, str | None]]:
    """``(mutmut key, readable name, decorators or None)`` of every function and method.

    mutmut leaves alone the functions with a decorator other than staticmethod or
    classmethod (numba.njit, property, fixed_order, ...): its trampoline would replace the
    decorated object. Their decorators are returned; ``None`` for the mutated ones."""
    out = []

    def visit(body, cls=None):
        for node in body:
            if isinstance(node, ast.ClassDef) and cls is None:
                visit(node.body, node.name)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                key = f"x\u01c1{cls}\u01c1{node.name}" if cls else f"x_{node.name}"
                names = [ast.unparse(d) for d in node.decorator_list]
                skipped = names and not (len(names) == 1 and names[0] in ("staticmethod", "classmethod"))
                out.append(
                    (
                        key,
                        f"{cls}.{node.name}" if cls else node.name,
                        "@" + ", @".join(names) if skipped else None,
                    )
                )

    visit(ast.parse(path.read_text()).body)
    return out


def is_memory_model(key: str) -> bool:
    """Functions of the memory model (``memory_terms`` and its helpers; docs/memory.md):
    an estimate of the peak memory, not the paper's algorithm."""
    name = re.split("\u01c1|^x_", key)[-1]
    return bool(MEMORY_MODEL.search(name))


def mutmut_section(group: str, tests: list[str], deselect: list[str]) -> str:
    """The [tool.mutmut] table for one group: pyproject's, with the group's modules/tests."""
    config = dict(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["mutmut"])
    modules, _ = GROUPS[group]
    config["only_mutate"] = [f"src/texsyn/{m}" for m in modules]
    config["pytest_add_cli_args_test_selection"] = tests + [f"--deselect={d}" for d in deselect]
    lines = ["[tool.mutmut]"]
    for key, value in config.items():
        lines.append(f"{key} = {json.dumps(value)}")
    return "\n".join(lines) + "\n"


def prepare(group: str, workdir: Path, deselect: list[str]) -> tuple[Path, list[str]]:
    _, wanted = GROUPS[group]
    tests = [t for t in wanted + [GAP_TESTS] if (REPO / t).exists()]
    missing = [t for t in wanted if t not in tests]
    if missing:
        print(f"[{group}] test files not found (skipped): {', '.join(missing)}")
    here = workdir / group
    if here.exists():
        shutil.rmtree(here)
    here.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", ".hypothesis", ".pytest_cache")
    shutil.copytree(REPO / "src", here / "src", ignore=ignore)
    shutil.copytree(REPO / "tests", here / "tests", ignore=ignore)
    text = (REPO / "pyproject.toml").read_text()
    start = text.index("[tool.mutmut]")
    nxt = re.search(r"^\[", text[start + 1 :], flags=re.MULTILINE)
    end = start + 1 + nxt.start() if nxt else len(text)
    (here / "pyproject.toml").write_text(text[:start] + mutmut_section(group, tests, deselect) + text[end:])
    return here, tests


def mutmut(here: Path, *args: str, capture: bool = False) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).parent / "mutmut"
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        env[var] = "1"
    env.pop("TEXSYN_SABOTAGE", None)
    return subprocess.run(
        [str(exe if exe.exists() else "mutmut"), *args],
        cwd=here,
        env=env,
        capture_output=capture,
        text=True,
        check=False,
    )


def summarise(group: str, here: Path) -> dict:
    modules, _ = GROUPS[group]
    rows = {}
    for module in modules:
        meta = here / "mutants" / "src" / "texsyn" / (module + ".meta")
        codes = json.loads(meta.read_text())["exit_code_by_key"] if meta.exists() else {}
        counts = dict.fromkeys(COLUMNS, 0)
        survivors = []
        statuses = {}
        memory = 0
        for key, code in codes.items():
            if is_memory_model(key.rpartition(".")[2].partition("__mutmut_")[0]):
                memory += 1
            status = STATUS.get(code, "suspicious")
            if status == "not checked":
                continue
            status = "suspicious" if status in ("skipped", "type check") else status
            counts[status] += 1
            statuses[key] = status
            if status != "killed":
                survivors.append((key, status))
        tested = sum(counts.values())
        funcs = functions(REPO / "src" / "texsyn" / module)
        rows[module_name(module)] = {
            "generated": len(codes),
            "memory_model": memory,
            "tested": tested,
            **counts,
            "score": (counts["killed"] + counts["timeout"]) / tested if tested else None,
            "not_mutated": [f"{name} ({deco})" for _, name, deco in funcs if deco],
            "memory_model_functions": [
                name for key, name, deco in funcs if not deco and is_memory_model(key)
            ],
            "survivors": sorted(survivors),
            "status": statuses,
        }
    return rows


def merge(earlier: dict, now: dict) -> dict:
    """An earlier run's rows with its retested mutants' statuses replaced by ``now``'s."""
    out = {}
    for module, row in earlier.items():
        status = now[module]["status"]
        counts = {c: row[c] for c in COLUMNS}
        survivors, killed = [], []
        for key, before in row["survivors"]:
            after = status.get(key, before)
            counts[before] -= 1
            counts[after] += 1
            if after == "killed":
                killed.append(key)
            else:
                survivors.append((key, after))
        tested = sum(counts.values())
        out[module] = {
            **row,
            **counts,
            "tested": tested,
            "score": (counts["killed"] + counts["timeout"]) / tested if tested else None,
            "survivors": survivors,
            "killed_on_rerun": killed,
            "not_mutated": now[module]["not_mutated"],
            "status": status,
        }
    return out


SHOW = """
import sys
from mutmut.mutation.diff_apply import get_diff_for_mutant
from mutmut.mutation.diff_apply import find_mutant
for line in sys.stdin:
    key, status = line.rstrip("\\n").split("\\t")
    print(f"### {key} [{status}]")
    print(get_diff_for_mutant(key, path=find_mutant(key).path))
"""


def write_survivors(here: Path, rows: dict) -> Path:
    """Every survivor's diff, as ``mutmut show`` prints it (one process for all)."""
    out = here / "survivors.txt"
    keys = "".join(f"{key}\t{status}\n" for row in rows.values() for key, status in row["survivors"])
    done = subprocess.run(
        [sys.executable, "-c", SHOW], cwd=here, input=keys, capture_output=True, text=True, check=False
    )
    text = done.stdout
    if done.returncode != 0:  # another mutmut version: one `mutmut show` per mutant
        text = "".join(
            f"### {key} [{status}]\n" + mutmut(here, "show", key, capture=True).stdout + "\n"
            for row in rows.values()
            for key, status in row["survivors"]
        )
    out.write_text(text)
    return out


def print_table(rows: dict) -> None:
    head = f"{'module':34} {'mutants':>7} {'memory':>6} {'tested':>6} " + " ".join(
        f"{c:>10}" for c in COLUMNS
    )
    print(head + "   score")
    for module, r in rows.items():
        score = "-" if r["score"] is None else f"{100 * r['score']:.1f}%"
        print(
            f"{module:34} {r['generated']:7d} {r['memory_model']:6d} {r['tested']:6d} "
            + " ".join(f"{r[c]:10d}" for c in COLUMNS)
            + f"   {score}"
        )
        for name in r["not_mutated"]:
            print(f"    not mutated: {name}")
        if r["memory_model_functions"]:
            print(f"    memory model: {', '.join(r['memory_model_functions'])}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "groups",
        nargs="*",
        default=[],
        metavar="GROUP",
        help=f"paper methods to run ({', '.join(GROUPS)}; default all)",
    )
    p.add_argument(
        "--every",
        type=int,
        default=1,
        choices=sorted(SAMPLE_DIGITS),
        help="run every N-th mutant only (by the last digit of its number)",
    )
    p.add_argument(
        "--functions",
        nargs="+",
        default=[],
        metavar="GLOB",
        help="run only the mutants whose name matches one of these mutmut globs",
    )
    p.add_argument(
        "--rerun",
        type=Path,
        metavar="FILE",
        help="retest only the mutants not killed in this earlier --json, and merge",
    )
    p.add_argument(
        "--include-memory-model",
        action="store_true",
        help="mutate the memory model (memory_terms and its helpers) too",
    )
    p.add_argument("--max-children", type=int, default=1)
    p.add_argument(
        "--deselect",
        action="append",
        default=[],
        metavar="NODEID",
        help="leave this test out of the selection (repeatable)",
    )
    p.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()) / "texsyn-mutation")
    p.add_argument(
        "--json",
        type=Path,
        help="write the counts and survivors of every group here (an existing file keeps the groups not run)",
    )
    args = p.parse_args(argv)
    unknown = [g for g in args.groups if g not in GROUPS]
    if unknown:
        p.error(f"unknown group(s) {', '.join(unknown)}; choose from {', '.join(GROUPS)}")

    summary = {}
    for group in args.groups or list(GROUPS):
        here, tests = prepare(group, args.workdir, DESELECT.get(group, []) + args.deselect)
        modules, _ = GROUPS[group]
        digits = SAMPLE_DIGITS[args.every] or ""
        earlier = json.loads(args.rerun.read_text()).get(group) if args.rerun else None
        if args.rerun and earlier is None:
            p.error(f"{args.rerun} has no run of group {group}")
        if earlier:
            names = [key for row in earlier["modules"].values() for key, _ in row["survivors"]]
            if not names:
                print(f"[{group}] nothing to rerun")
                summary[group] = earlier
                continue
        elif args.functions:
            names = [
                n.rstrip("*") + ("*" if "__mutmut_" in n else "*__mutmut_*") + digits for n in args.functions
            ]
        else:
            names = [
                f"{module_name(m)}.{key}__mutmut_*{digits}"
                for m in modules
                for key, _, deco in functions(REPO / "src" / "texsyn" / m)
                if not deco and (args.include_memory_model or not is_memory_model(key))
            ]
        print(f"[{group}] mutating {', '.join(modules)}; tests: {' '.join(tests)}; in {here}")
        started = time.perf_counter()
        run_args = ["run", "--max-children", str(args.max_children)]
        run_args += names
        done = mutmut(here, *run_args)
        wall = time.perf_counter() - started
        rows = summarise(group, here)
        if earlier:
            rows = merge(earlier["modules"], rows)
        if done.returncode != 0 and not any(r["tested"] for r in rows.values()):
            print(f"[{group}] mutmut failed (exit {done.returncode})")
            return done.returncode
        survivors = write_survivors(here, rows)
        print(f"[{group}] {wall:.0f} s wall; survivors' diffs in {survivors}")
        print_table(rows)
        summary[group] = {
            "wall_s": round(wall),
            "every": args.every,
            "functions": args.functions,
            "tests": tests,
            "deselect": DESELECT.get(group, []) + args.deselect,
            "modules": rows,
        }
        if earlier:
            summary[group].update(
                every=earlier["every"],
                functions=earlier["functions"],
                wall_s=earlier["wall_s"],
                rerun_wall_s=round(wall),
            )
    for run in summary.values():
        for row in run["modules"].values():
            row.pop("status", None)
    if args.json:
        if args.json.exists():  # other groups' results are kept, this run's groups replaced
            summary = {**json.loads(args.json.read_text()), **summary}
        args.json.write_text(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
