"""Numba-compiled kernels, compiled (or loaded from numba's cache) on their first call.

Importing numba costs about 0.15 s and loading a cached kernel a few milliseconds more; a
command that never calls a kernel (``texsyn synth -m random_phase``) should pay for neither
(``docs/performance.md``, "Start-up"). A kernel is written as a plain function decorated with
:func:`jit`; the decorator returns a :class:`LazyKernel` that imports numba and compiles the
function with ``numba.njit(cache=True)`` when it is first called.

A kernel may call another kernel of its module, a parallel kernel loops over
:data:`prange` (``range`` until compiled, numba's ``prange`` in the compiled code), and a
kernel that threads share reads and writes their flags with :data:`atomic_load`,
:data:`atomic_store` and :data:`atomic_compare_exchange` (:class:`KernelIntrinsic`: plain
indexing until compiled): at compile
time the function is rebuilt over a copy of its module's namespace in which these are
replaced by what numba compiles (numba reads global values as compile-time constants
anyway).
"""

from __future__ import annotations

import functools
import os
import threading
import types
from collections.abc import Callable
from typing import Any

__all__ = [
    "KernelIntrinsic",
    "LazyKernel",
    "atomic_compare_exchange",
    "atomic_load",
    "atomic_store",
    "jit",
    "os_yield",
    "prange",
]

#: the parallel loop of a kernel: ``range`` in Python, numba's ``prange`` once compiled
prange = range


class KernelIntrinsic:
    """An operation kernels call: a plain Python function, replaced in the compiled kernel by a
    numba intrinsic built (numba imported) when the first kernel that calls it is compiled.

    Parameters
    ----------
    python : callable
        What the operation does when the kernel runs as plain Python.
    build : callable
        Returns the numba intrinsic (called once, with numba importable).
    """

    def __init__(self, python: Callable[..., Any], build: Callable[[], Any]) -> None:
        self.python = python
        self._build = build
        self._intrinsic: Any = None
        functools.update_wrapper(self, python)

    def __call__(self, *args: Any) -> Any:
        return self.python(*args)

    def intrinsic(self) -> Any:
        """The numba intrinsic (built on the first call)."""
        if self._intrinsic is None:
            self._intrinsic = self._build()
        return self._intrinsic


@functools.cache
def os_yield() -> Any:
    """The C library's ``sched_yield`` as a ctypes function that a compiled kernel can call
    without the GIL (the thread gives its core to another runnable thread, if any, and goes on
    at once otherwise); None where the C library has none."""
    import ctypes

    try:
        library = ctypes.CDLL(None)
        library.sched_yield  # noqa: B018  (AttributeError where the C library has none)
    except (OSError, AttributeError, TypeError):  # (Windows)
        return None
    return ctypes.CFUNCTYPE(ctypes.c_int)(("sched_yield", library))


def _python_atomic_load(array, index):
    """``array[index]`` (a plain read: Python runs one kernel thread at a time under the GIL)."""
    return array[index]


def _python_atomic_store(array, index, value) -> None:
    """``array[index] = value``."""
    array[index] = value


#: makes the Python form of :data:`atomic_compare_exchange` one step for Python threads
_exchange_lock = threading.Lock()


def _python_atomic_compare_exchange(array, index, expected, value) -> bool:
    """``array[index] = value`` if it holds ``expected`` (under a lock: one step for the threads
    that run kernels as Python); whether it did."""
    with _exchange_lock:
        if array[index] != expected:
            return False
        array[index] = value
        return True


def _element_pointer(context, builder, array_type, array, index, index_type):
    """Pointer to element ``index`` of a 1-D array in generated code."""
    from numba.core import cgutils, types

    ary = context.make_array(array_type)(context, builder, array)
    position = context.cast(builder, index, index_type, types.intp)
    return cgutils.get_item_pointer(context, builder, array_type, ary, [position])


def _build_atomic_load() -> Any:
    from numba.extending import intrinsic

    @intrinsic
    def atomic_load(typingctx, array, index):
        signature = array.dtype(array, index)

        def codegen(context, builder, sig, args):
            pointer = _element_pointer(context, builder, sig.args[0], args[0], args[1], sig.args[1])
            return builder.load_atomic(pointer, "seq_cst", sig.args[0].dtype.bitwidth // 8)

        return signature, codegen

    return atomic_load


def _build_atomic_store() -> Any:
    from numba.core import types
    from numba.extending import intrinsic

    @intrinsic
    def atomic_store(typingctx, array, index, value):
        signature = types.void(array, index, value)

        def codegen(context, builder, sig, args):
            array_type = sig.args[0]
            pointer = _element_pointer(context, builder, array_type, args[0], args[1], sig.args[1])
            stored = context.cast(builder, args[2], sig.args[2], array_type.dtype)
            builder.store_atomic(stored, pointer, "seq_cst", array_type.dtype.bitwidth // 8)
            return context.get_dummy_value()

        return signature, codegen

    return atomic_store


def _build_atomic_compare_exchange() -> Any:
    from numba.core import types
    from numba.extending import intrinsic

    @intrinsic
    def atomic_compare_exchange(typingctx, array, index, expected, value):
        signature = types.boolean(array, index, expected, value)

        def codegen(context, builder, sig, args):
            array_type = sig.args[0]
            pointer = _element_pointer(context, builder, array_type, args[0], args[1], sig.args[1])
            old = context.cast(builder, args[2], sig.args[2], array_type.dtype)
            new = context.cast(builder, args[3], sig.args[3], array_type.dtype)
            pair = builder.cmpxchg(pointer, old, new, "seq_cst", "seq_cst")
            return builder.extract_value(pair, 1)

        return signature, codegen

    return atomic_compare_exchange


#: ``atomic_load(array, index)``: ``array[index]`` (1-D array of integers), read as a
#: sequentially consistent atomic load in a compiled kernel: a kernel spinning on a flag that
#: another thread sets sees it (the compiler may not keep the value in a register), and what
#: that thread wrote before setting it
atomic_load = KernelIntrinsic(_python_atomic_load, _build_atomic_load)
#: ``atomic_store(array, index, value)``: ``array[index] = value``, a sequentially consistent
#: atomic store in a compiled kernel (what the thread wrote before it is seen by a thread that
#: loads the value)
atomic_store = KernelIntrinsic(_python_atomic_store, _build_atomic_store)
#: ``atomic_compare_exchange(array, index, expected, value)``: ``array[index] = value`` if it
#: holds ``expected``, and whether it did, in one sequentially consistent atomic step in a
#: compiled kernel: of two threads that both expect the value, one only sets it (a job claimed
#: by one thread)
atomic_compare_exchange = KernelIntrinsic(_python_atomic_compare_exchange, _build_atomic_compare_exchange)


class LazyKernel:
    """A function compiled by numba (``njit(cache=True)``) on its first call.

    Parameters
    ----------
    py_func : callable
        The kernel in plain Python (numba's nopython subset).
    parallel : bool
        Compile with ``parallel=True`` (loops over :data:`prange` run on numba's threads).
    nogil : bool
        Compile with ``nogil=True``: the kernel releases the GIL, so that texsyn's thread
        pool (:func:`texsyn.ops.linalg.parallel_map`) can run several calls at once.

    Attributes
    ----------
    py_func : callable
        The Python function, callable without numba (tests, mutation runs).
    """

    def __init__(self, py_func: Callable[..., Any], parallel: bool = False, nogil: bool = False) -> None:
        self.py_func = py_func
        self.parallel = parallel
        self.nogil = nogil
        self._compiled: Any = None
        self._lock = threading.Lock()
        functools.update_wrapper(self, py_func)

    def compiled(self) -> Any:
        """The numba dispatcher (compiling, or loading numba's cache, on the first use)."""
        if self._compiled is None:
            with self._lock:
                if self._compiled is None:
                    self._compiled = self._compile()
        return self._compiled

    @property
    def loaded(self) -> bool:
        """Whether this process has compiled (or loaded) the kernel already."""
        return self._compiled is not None

    def _compile(self) -> Any:
        if self.parallel:
            _passive_openmp()
        _preload_cython_blas()
        import numba

        source = self.py_func
        namespace = dict(source.__globals__)
        for name in source.__code__.co_names:
            value = namespace.get(name)
            if isinstance(value, LazyKernel):
                namespace[name] = value.compiled()
            elif value is prange:
                namespace[name] = numba.prange
            elif isinstance(value, KernelIntrinsic):
                namespace[name] = value.intrinsic()
        rebuilt = types.FunctionType(
            source.__code__, namespace, source.__name__, source.__defaults__, source.__closure__
        )
        rebuilt.__qualname__ = source.__qualname__
        rebuilt.__module__ = source.__module__
        rebuilt.__doc__ = source.__doc__
        return numba.njit(cache=True, parallel=self.parallel, nogil=self.nogil)(rebuilt)

    def __call__(self, *args: Any) -> Any:
        return self.compiled()(*args)

    def __repr__(self) -> str:
        state = "compiled" if self._compiled is not None else "not compiled yet"
        return f"<LazyKernel {self.py_func.__module__}.{self.py_func.__qualname__} ({state})>"


_preload_lock = threading.Lock()


def _preload_cython_blas() -> None:
    """Load SciPy's ``scipy.linalg.cython_blas`` on its own, without the ``scipy.linalg`` package.

    Numba's first compilation or cache load checks that BLAS is there by importing
    ``scipy.linalg.cython_blas``, which imports the whole ``scipy.linalg`` package first (about
    0.13 s of start-up, ``docs/performance.md``, "Start-up"), and later reads only that module's
    function pointers (``importlib.import_module``). Loading the extension module under its
    full name first makes that import a lookup. Nothing changes for a process that has
    ``scipy.linalg`` already, or where the module cannot be found: numba then imports it itself.

    The module stays in ``sys.modules`` only while numba makes its check (the import of
    ``numba.np.arraymath``): left there, a later ``import scipy.linalg`` would take it without
    binding it to the package (``scipy.linalg.cython_blas``, a public module, would raise
    AttributeError). Imported again later, Cython gives the same module object.
    """
    import sys

    name = "scipy.linalg.cython_blas"
    with _preload_lock:
        if name in sys.modules or "scipy.linalg" in sys.modules or "numba.np.arraymath" in sys.modules:
            return
        module = _load_alone(name)
        if module is None:
            return
        try:
            import numba.np.arraymath  # noqa: F401  (numba's BLAS check, which finds the module)
        finally:
            if sys.modules.get(name) is module:
                package = sys.modules.get("scipy.linalg")
                if package is None:
                    del sys.modules[name]
                else:  # imported meanwhile: bind it as the import system would have
                    package.cython_blas = module  # type: ignore[attr-defined]


def _load_alone(name: str) -> types.ModuleType | None:
    """Load the extension module ``name`` of SciPy's ``linalg`` without its package, entered in
    ``sys.modules``; None where it cannot be."""
    import importlib.machinery
    import importlib.util
    import sys

    try:
        scipy_spec = importlib.util.find_spec("scipy")
        if scipy_spec is None or not scipy_spec.submodule_search_locations:
            return None
        places = [os.path.join(place, "linalg") for place in scipy_spec.submodule_search_locations]
        spec = importlib.machinery.PathFinder.find_spec(name, places)
        if spec is None or spec.loader is None:
            return None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        return module
    except Exception:  # pragma: no cover - numba imports it the usual way
        sys.modules.pop(name, None)
        return None


def _passive_openmp() -> None:
    """Let numba's OpenMP threads sleep between parallel loops unless the user chose otherwise.

    GNU OpenMP's default keeps a thread spinning after each parallel loop; on a 2-core
    machine that spinning takes the core from texsyn's own threads (BLAS tiles, FFT lines,
    sorts) and, when other processes share the machine, doubles the CPU time of a parallel
    kernel (``docs/performance.md``, "Threads"). Read when the OpenMP runtime starts, so
    set before numba loads it; ``OMP_WAIT_POLICY`` from the environment wins.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def jit(*, parallel: bool = False, nogil: bool = False) -> Callable[[Callable[..., Any]], LazyKernel]:
    """Decorator: compile the function with numba on its first call (:class:`LazyKernel`).

    Parameters
    ----------
    parallel : bool
        Compile with ``parallel=True``; the kernel's parallel loops use :data:`prange`.
    nogil : bool
        Compile with ``nogil=True`` (the kernel releases the GIL while it runs).

    Examples
    --------
    >>> @jit()
    ... def total(values):
    ...     out = 0.0
    ...     for v in values:
    ...         out += v
    ...     return out
    >>> total.py_func([1.0, 2.0])
    3.0
    """

    def decorate(py_func: Callable[..., Any]) -> LazyKernel:
        return LazyKernel(py_func, parallel, nogil)

    return decorate
