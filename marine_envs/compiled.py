"""The compiled back end: numba, single-threaded, no fastmath, cached on disk.

Every hot loop of the project is a function made by :func:`jit`. Each model's equations are
written once, on one boat's scalars (``rhs(x, u, d, p, out)`` with ``p`` the model's packed
constants), and everything else is generated from them: :func:`rows` applies such a function to
every row of a batch (what ``VehicleModel.rhs`` calls) and :func:`rk4` integrates one boat (what
the environments' step kernel calls). ``error_model="numpy"`` keeps numpy's arithmetic (a
division by zero gives inf, not an exception), so a compiled function means what the numpy
expression it replaces meant.

Caching: machine code is kept on disk beside the sources (numba's ``__pycache__``, or
``NUMBA_CACHE_DIR``), so a machine compiles each function once. numba keys its cache on the
function's own bytecode only: a kernel that calls a model's equations from another file would run
stale machine code after the equations were edited, and a function made by a factory (a closure
over the equations) would miss the cache in every new process (numba hashes the pickled closure,
which holds a random identifier). :func:`jit` keys it instead on the source of the function and
of every compiled function it reaches (globals by name, closure cells), recursively.

First use: a vehicle's kernels take seconds to compile when the disk cache does not hold them.
Code that may compile them runs inside :func:`first_use`; the first time the cache misses in
there, the user is told on stderr, once per vehicle and process ("compiling the USV kernels
(first use, 5-10 s)"), unless the environment variable ``MARINE_ENVS_QUIET`` is set (to anything
but "" or "0"). stderr, not :mod:`warnings` or :mod:`logging`: it is a note of progress,
nothing to fix (a warning made an error by ``-W error`` would fail a run on a cold cache only),
and it must show without a logging configuration (INFO is hidden by default); stdout stays the
program's output.
"""

from __future__ import annotations

import contextlib
import contextvars
import hashlib
import math
import os
import sys
import types
from collections.abc import Callable, Iterator
from functools import cache
from typing import Any, TypeVar

import numba
import numpy as np
from numba.core import cgutils
from numba.core import types as nb_types
from numba.core.registry import CPUDispatcher
from numba.extending import intrinsic

try:
    from numba.core.caching import FunctionCache
except ImportError:  # a numba that moved it: its own cache, keyed on a function's bytecode only
    FunctionCache = None

F = TypeVar("F", bound=Callable[..., Any])
#: Options of every compiled function. ``inline="always"``: a compiled function called from
#: compiled code is merged into its caller (numba passes every array as seven machine words, so a
#: call of a model's equations cost more than the equations); called from Python it runs as
#: usual. ``nogil``: a batch may be stepped in a thread of its own.
OPTIONS = {"inline": "always", "nogil": True, "error_model": "numpy", "fastmath": False}


def jit(func: F | None = None, **options: Any) -> F:
    """``numba.njit`` with the project's options and a source-keyed disk cache.

    :param func: the function (use as ``@jit`` or ``@jit(inline="never")``).
    :param options: further ``numba.njit`` options.
    """
    if func is None:
        return lambda f: jit(f, **options)  # type: ignore[return-value]
    if FunctionCache is None:
        return numba.njit(**{**OPTIONS, "cache": True, **options})(func)
    _file_hash(func.__code__.co_filename)  # the source as imported (a later edit is not it)
    dispatcher = numba.njit(**{**OPTIONS, **options})(func)
    try:
        dispatcher._cache = _SourceKeyedCache(func)
    except RuntimeError:  # no file to keep it beside (an interactive session): compile each time
        pass
    return dispatcher


if FunctionCache is not None:
    class _SourceKeyedCache(FunctionCache):
        """numba's function cache with :func:`fingerprint` as the key (module docstring)."""

        def _index_key(self, sig, codegen):
            return sig, codegen.magic_tuple(), fingerprint(self._py_func)

        def load_overload(self, sig, target_context):
            overload = super().load_overload(sig, target_context)
            if overload is None:  # numba compiles it now
                _announce()
            return overload


#: The vehicle whose kernels may compile now (:func:`first_use`), and those announced.
_USING: contextvars.ContextVar[str | None] = contextvars.ContextVar("marine_envs_using",
                                                                     default=None)
_ANNOUNCED: set[str] = set()


@contextlib.contextmanager
def first_use(vehicle: str) -> Iterator[None]:
    """Within it, the first compilation the disk cache cannot spare says so on stderr, once per
    ``vehicle`` and process (module docstring).

    :param vehicle: the vehicle's name as the user knows it ("USV").
    """
    token = _USING.set(vehicle)
    try:
        yield
    finally:
        _USING.reset(token)


def _announce() -> None:
    vehicle = _USING.get()
    if vehicle is not None and vehicle not in _ANNOUNCED and not _quiet():
        _ANNOUNCED.add(vehicle)
        print(f"compiling the {vehicle} kernels (first use, 5-10 s)", file=sys.stderr, flush=True)


def _quiet() -> bool:
    return os.environ.get("MARINE_ENVS_QUIET", "") not in ("", "0")


def compile_for(dispatcher: Any, *args: Any) -> None:
    """Compile ``dispatcher`` (made by :func:`jit`) for the types of ``args`` now, as a call
    with them would (without running it); loaded from the disk cache when it holds it."""
    dispatcher.compile(tuple(dispatcher.typeof_pyval(a) for a in args))


def fingerprint(func: Callable[..., Any]) -> str:
    """A hash of ``func``'s bytecode and constant closure values, and of the source files of
    ``func`` and of every compiled function it reaches."""
    digest = hashlib.sha256()
    files: set[str] = set()
    for code, cells in _reach(func, files, set()):
        digest.update(code)
        digest.update(cells.encode())
    for path in sorted(files):
        digest.update(_file_hash(path).encode())
    return digest.hexdigest()


def _reach(func: Callable[..., Any], files: set[str], seen: set[int]):
    """``(bytecode, closure constants)`` of ``func`` and of the compiled functions it reaches;
    their source files are added to ``files``."""
    if id(func) in seen:
        return
    seen.add(id(func))
    files.add(func.__code__.co_filename)
    constants = []
    for cell in func.__closure__ or ():
        value = cell.cell_contents
        if isinstance(value, CPUDispatcher):
            yield from _reach(value.py_func, files, seen)
        elif isinstance(value, int | float | bool | str | tuple | type(None)):
            constants.append(repr(value))
        else:
            raise TypeError(f"compiled function {func.__qualname__} closes over a "
                            f"{type(value).__name__}; only compiled functions and plain "
                            "constants can be cached")
    yield func.__code__.co_code, "|".join(constants)
    for name in sorted(_names(func.__code__)):  # a fixed order: set order changes per process
        value = func.__globals__.get(name)
        if isinstance(value, types.ModuleType):
            value = None
        if isinstance(value, CPUDispatcher):
            yield from _reach(value.py_func, files, seen)


def _names(code: types.CodeType) -> set[str]:
    """Global names used by ``code`` and the code objects nested in it."""
    names = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names |= _names(const)
    return names


@cache
def _file_hash(path: str) -> str:
    try:
        with open(path, "rb") as f:
            return hashlib.sha256(f.read()).hexdigest()
    except OSError:  # no source (a frozen or zipped module): its path stands in
        return path


# -- scratch on the stack -----------------------------------------------------------------------
@intrinsic
def _stack_buffer(typingctx, size):
    """A pointer to ``size`` float64 on the stack frame of the outermost compiled caller."""
    if not isinstance(size, nb_types.IntegerLiteral):
        return None
    n = size.literal_value

    def codegen(context, builder, signature, args):
        return cgutils.alloca_once(builder, context.get_value_type(nb_types.float64), size=n)

    return nb_types.CPointer(nb_types.float64)(size), codegen


@jit
def local_array(size):
    """A 1-D float64 array of ``size`` (a literal number) on the stack: scratch for compiled
    code that runs millions of times (numba's ``np.empty`` is a heap allocation each time).
    Uninitialised; valid until the outermost compiled caller returns (never return it)."""
    return numba.carray(_stack_buffer(size), (size,))


# -- generated from one boat's equations ---------------------------------------------------------
#: ``f(x, u, d, p, out)``: one boat's state derivative written to ``out`` (a model's equations).
RightHandSide = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray], None]


def rows(core: RightHandSide) -> Callable[..., None]:
    """The function ``f(X, U, D, P, OUT)`` applying ``core`` to every row of 2-D arrays; ``P``
    has one row per boat or a single row for all."""

    @jit
    def over_rows(X, U, D, P, OUT):
        shared = P.shape[0] == 1
        for b in range(X.shape[0]):
            core(X[b], U[b], D[b], P[0] if shared else P[b], OUT[b])

    return over_rows


def rk4(core: RightHandSide) -> Callable[..., None]:
    """The function ``f(x, u, d, p, h, substeps, out, work)``: ``substeps`` classical
    Runge-Kutta steps of ``h`` seconds of ``x_dot = core(x, u, d, p)`` from ``x``, inputs held,
    written to ``out``; ``work`` is scratch of 3 rows of at least ``n_x``. The same arithmetic,
    in the same order, as :func:`marine_envs.models.integrate.rk4`; ``core`` is called from one
    place, so that it is merged into the step once."""

    @jit
    def step(x, u, d, p, h, substeps, out, work):
        n = x.size
        k, total, z = work[0, :n], work[1, :n], work[2, :n]
        for i in range(n):  # (loops, not slice copies: those compile numba's error messages)
            out[i] = x[i]
        for _ in range(substeps):
            for i in range(n):
                z[i] = out[i]
            for stage in range(4):
                core(z, u, d, p, k)
                if stage == 0:  # (branches outside the loops: simple loops vectorise)
                    for i in range(n):
                        total[i] = k[i]
                elif stage == 3:
                    for i in range(n):
                        total[i] += k[i]
                else:
                    for i in range(n):
                        total[i] += 2 * k[i]
                if stage < 3:
                    ahead = 0.5 * h if stage < 2 else h
                    for i in range(n):
                        z[i] = out[i] + ahead * k[i]
            for i in range(n):
                out[i] = out[i] + h / 6 * total[i]

    return step


def step_rows(step: Callable[..., None]) -> Callable[..., None]:
    """The function ``f(X, U, D, P, h, substeps, OUT)`` applying a one-boat step ``step(x, u, d,
    p, h, substeps, out, work)`` (:func:`rk4` of a model's equations,
    :func:`marine_envs.models.integrate.exact_step`) to every row; ``P`` has one
    row per boat or a single row for all."""
    if step not in _STEP_ROWS:  # one batch form per step (compiled once per machine)
        _STEP_ROWS[step] = _step_rows(step)
    return _STEP_ROWS[step]


#: The batch forms made so far, by one-boat step.
_STEP_ROWS: dict[Callable[..., None], Callable[..., None]] = {}


def _step_rows(step: Callable[..., None]) -> Callable[..., None]:
    """:func:`step_rows`, made anew."""

    @jit(inline="never")
    def over_rows(X, U, D, P, h, substeps, OUT):
        work = np.empty((3, X.shape[1] + U.shape[1] + D.shape[1]))
        shared = P.shape[0] == 1
        for b in range(X.shape[0]):
            step(X[b], U[b], D[b], P[0] if shared else P[b], h, substeps, OUT[b], work)

    return over_rows


class Equations:
    """One boat's equations ``core(x, u, d, p, out)`` and the functions generated from them.

    :param core: the compiled function (made by :func:`jit`); ``p`` is the model's packed
        constants (one row for every boat, or one row per boat).
    :ivar over_rows: ``core`` applied to every row (:func:`rows`).
    :ivar rk4: one boat integrated by Runge-Kutta steps (:func:`rk4`).
    """

    def __init__(self, core: RightHandSide) -> None:
        self.core, self.over_rows, self.rk4 = core, rows(core), rk4(core)

    def __call__(self, x: np.ndarray, u: np.ndarray, d: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``x_dot`` over the broadcast batch shape of ``x, u, d, p`` (each ``(..., n)``)."""
        return evaluate(self.over_rows, x, u, d, p)


def evaluate(over_rows: Callable[..., None], x: np.ndarray, u: np.ndarray, d: np.ndarray,
             p: np.ndarray, width: int | None = None) -> np.ndarray:
    """A function made by :func:`rows` over the broadcast batch shape of ``x, u, d, p`` (each
    ``(..., n)``).

    :param width: values written per row (default: the state size).
    :return: shape ``(..., width)``.
    """
    shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], d.shape[:-1], p.shape[:-1])
    out = np.empty((math.prod(shape), x.shape[-1] if width is None else width))
    over_rows(_flat(x, shape), _flat(u, shape), _flat(d, shape),
              _flat(p, ()) if p.ndim == 1 else _flat(p, shape), out)
    return out.reshape(*shape, out.shape[1])


def _flat(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` broadcast to ``shape`` rows, as a writable C-contiguous float array of 2 axes (the
    one layout compiled: read-only or strided arrays would each compile a variant)."""
    if a.shape[:-1] != shape:
        a = np.broadcast_to(a, (*shape, a.shape[-1]))
    a = a.reshape(-1, a.shape[-1])
    if a.dtype != np.float64 or not (a.flags.c_contiguous and a.flags.writeable):
        a = np.array(a, dtype=np.float64, order="C")
    return a
