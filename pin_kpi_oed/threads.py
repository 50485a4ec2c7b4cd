"""BLAS / OpenMP thread control that works whatever the caller imported first.

The package's dense linear algebra is small (tens of columns: information matrices, Cholesky factors of
C_p, per-pose 3x3 blocks). On such sizes extra BLAS threads only add contention: a 25-column information
matrix took 10 ms with 2 OpenBLAS threads competing with other processes and 0.35 ms with one. Environment
variables (``OMP_NUM_THREADS``) act only if they are set before NumPy is first imported, and user scripts
import NumPy first; so the package limits the threads of the already-loaded BLAS / OpenMP libraries at
run time with threadpoolctl, around each public entry point (:func:`limit_threads`).

threadpoolctl limits only the libraries loaded when the limit is set: SciPy's own OpenBLAS is loaded with
``scipy.linalg``, and scikit-learn's OpenMP runtime with scikit-learn, often after an entry point started. So
:func:`limited_threads` loads SciPy's linear algebra before it sets the limit, and a whole process (the command
line, :func:`limit_process_threads`) also sets the libraries' own variables (``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``; those the user set are kept), which every library loaded later reads.
Without that, the discrepancy fit of ``identify`` ran SciPy's Cholesky factorisations with one BLAS thread per
core, which doubled its CPU time for no gain in wall time and multiplied the wall time when other work held the cores.

The limit is 1 by default. Users with big problems (100,000-candidate pools, long diagnoses) may allow more
with :func:`set_max_threads`, the environment variable ``PIN_KPI_OED_THREADS``, or the CLI's ``--threads``.
"""

from __future__ import annotations

import functools
import os
import sys
from contextlib import contextmanager, nullcontext
from typing import Any, TypeVar
from collections.abc import Callable, Iterator

from pin_kpi_oed.errors import InputError

__all__ = ["get_max_threads", "set_max_threads", "limited_threads", "limit_threads", "limit_process_threads"]

#: The variables BLAS / OpenMP libraries read when they are loaded.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

_F = TypeVar("_F", bound=Callable[..., Any])
_max_threads: int | None = None
_depth = 0


def _parse(value: Any, what: str) -> int:
    try:
        n = int(value)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a positive whole number of threads, got {value!r}") from None
    if n < 1:
        raise InputError(f"{what}: expected a positive whole number of threads, got {value!r}")
    return n


def set_max_threads(n: int | None) -> None:
    """Set the BLAS / OpenMP thread limit used inside the package (``None``: back to the default).

    Raises:
        InputError: If ``n`` is not a positive integer.
    """
    global _max_threads
    _max_threads = None if n is None else _parse(n, "threads")


def get_max_threads() -> int:
    """The thread limit in force: :func:`set_max_threads`, else ``PIN_KPI_OED_THREADS``, else 1."""
    if _max_threads is not None:
        return _max_threads
    env = os.environ.get("PIN_KPI_OED_THREADS")
    return _parse(env, "PIN_KPI_OED_THREADS") if env else 1


#: (the dynamic linker's counts of libraries loaded and unloaded, threadpoolctl's controller of the libraries then
#: loaded): :func:`_controller`'s last scan
_scanned: tuple[tuple[int, int], Any] | None = None


@functools.cache
def _linker_api() -> tuple[Any, Any, Any] | None:
    """(``dl_iterate_phdr``, its callback type, the entry type) from the C library; None where it has none."""
    import ctypes

    class Info(ctypes.Structure):
        _fields_ = [("addr", ctypes.c_void_p), ("name", ctypes.c_char_p), ("phdr", ctypes.c_void_p),
                    ("phnum", ctypes.c_uint16), ("adds", ctypes.c_ulonglong), ("subs", ctypes.c_ulonglong)]

    try:
        iterate = ctypes.CDLL(None).dl_iterate_phdr
    except (AttributeError, OSError):  # no dl_iterate_phdr (macOS, Windows)
        return None
    return iterate, ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(Info), ctypes.c_size_t, ctypes.c_void_p), Info


def _linker_counts() -> tuple[int, int] | None:
    """How many times the dynamic linker loaded and unloaded a library in this process so far (glibc's
    ``dl_iterate_phdr``: ``dlpi_adds``, ``dlpi_subs``); None where the C library does not say."""
    import ctypes

    api = _linker_api()
    if api is None:
        return None
    iterate, callback_type, info_type = api
    seen: list[tuple[int, int]] = []

    def first(info: Any, size: int, _data: Any) -> int:
        if size >= ctypes.sizeof(info_type):
            seen.append((int(info.contents.adds), int(info.contents.subs)))
        return 1  # the counts are the same in every entry: one is enough

    iterate(callback_type(first), None)
    return seen[0] if seen else None


def _controller() -> Any:
    """threadpoolctl's controller of the BLAS / OpenMP libraries loaded now, scanned again only when the dynamic
    linker loaded or unloaded a library since the last scan: a scan reads the process's memory map (2 ms, paid by
    every entry point and every command run in one process; a check of the linker's counts costs 1 µs)."""
    global _scanned
    from threadpoolctl import ThreadpoolController

    counts = _linker_counts()
    last = _scanned
    if counts is not None and last is not None and last[0] == counts:
        return last[1]
    controller = ThreadpoolController()
    if counts is not None:
        _scanned = (counts, controller)  # the counts before the scan: a library loaded meanwhile scans again
    return controller


@contextmanager
def limited_threads() -> Iterator[None]:
    """Context in which the loaded BLAS and OpenMP libraries use at most :func:`get_max_threads` threads.

    Nested uses cost nothing: only the outermost one talks to threadpoolctl.
    """
    global _depth
    if _depth:
        _depth += 1
        try:
            yield
        finally:
            _depth -= 1
        return
    _depth = 1
    try:
        import scipy.linalg  # noqa: F401  (SciPy's own BLAS: loaded now, so the limit below covers it)

        with _controller().limit(limits=get_max_threads()):
            yield
    finally:
        _depth = 0


def limit_threads(func: _F) -> _F:
    """Decorator: run ``func`` inside :func:`limited_threads` (used on the package's public entry points)."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with limited_threads():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def limit_process_threads() -> Any:
    """Limit the BLAS / OpenMP threads of the whole process to :func:`get_max_threads` (the command line does).

    The libraries loaded so far are limited now (threadpoolctl), those loaded later through their variables
    (:data:`THREAD_VARIABLES`, set unless the user set them; subprocesses inherit them). SciPy is not loaded for
    that unless a variable the user set says another number (then its BLAS is loaded now and limited): a command
    that needs no SciPy does not pay for its import.

    Returns:
        threadpoolctl's limiter: used as a context (``with limit_process_threads():``) it restores the loaded
        libraries' limits on exit. When no NumPy or SciPy is loaded yet (``info``, a command line before its
        imports) and the variables say ``n``, there is nothing to limit now: a context that does nothing, and
        threadpoolctl is not loaded.
    """
    n = get_max_threads()
    for var in THREAD_VARIABLES:
        os.environ.setdefault(var, str(n))
    if any(os.environ[var] != str(n) for var in THREAD_VARIABLES):
        # a variable of the user's says otherwise: SciPy's own BLAS would read it, so load it now and limit it
        import scipy.linalg  # noqa: F401
    elif not any(name in sys.modules for name in ("numpy", "scipy")):
        return nullcontext()  # every BLAS / OpenMP library loaded from now on reads the variables just set
    return _controller().limit(limits=n)
