"""Thread control: the BLAS limit holds even when NumPy was imported before the package."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.threads import get_max_threads, limited_threads, set_max_threads


def _run(code: str, env_threads: str | None = None) -> str:
    import os

    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "PIN_KPI_OED_THREADS"):
        env.pop(var, None)
    if env_threads is not None:
        env["PIN_KPI_OED_THREADS"] = env_threads
    res = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    return res.stdout.strip()


#: One process with NumPy imported first, the three claims in the order their premises allow: SciPy's own BLAS
#: loaded inside an entry point (before anything else loads SciPy); the limit holding when NumPy and its BLAS (given
#: two threads) were there before the package; an entry point with its BLAS given two threads beforehand. One
#: process instead of three: each costs the interpreter's, NumPy's and the package's imports, and no claim's premise
#: is changed by the one before it (the first is the only one that needs SciPy not yet loaded).
NUMPY_FIRST_PROBE = """
    import json
    import numpy as np                      # the user's script imports NumPy first
    from threadpoolctl import threadpool_info, threadpool_limits
    from pin_kpi_oed.threads import limited_threads
    out = {}

    def scipy_blas():
        return [i["num_threads"] for i in threadpool_info() if "scipy.libs" in i["filepath"]]
    with limited_threads():
        import scipy.linalg                 # loaded inside an entry point (as the discrepancy fit does)
        out["scipy_inside"] = max(scipy_blas())
    out["scipy_after"] = max(scipy_blas())

    def blas_threads():
        return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
    threadpool_limits(limits=2)             # and has (or gets by default) more than one BLAS thread
    out["before"] = blas_threads()
    with limited_threads():
        out["inside"] = blas_threads()
    out["after"] = blas_threads()

    threadpool_limits(limits=2)
    import pin_kpi_oed.oed.pool as pool
    seen = []
    real = pool.approximate_design
    def spy(*a, **k):
        seen.append(blas_threads())
        return real(*a, **k)
    pool.approximate_design = spy
    rng = np.random.default_rng(0)
    F = rng.normal(size=(200, 3, 6))
    pool.select(F, 12)
    out["spy_calls"], out["spy_worst"] = len(seen), max(seen, default=0)
    print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def numpy_first() -> dict:
    """What :data:`NUMPY_FIRST_PROBE` saw, in a fresh process without the thread variables."""
    return json.loads(_run(NUMPY_FIRST_PROBE))


@pytest.mark.xdist_group("test_threads_numpy_first")
def test_limit_holds_when_numpy_was_imported_first(numpy_first) -> None:
    assert numpy_first["before"] == 2, "the probe could not give BLAS two threads: the test would prove nothing"
    assert numpy_first["inside"] == 1, "the limit did not hold inside the context"
    assert numpy_first["after"] == numpy_first["before"], "the limit must be lifted on exit"


def test_user_can_allow_more_threads_by_environment(monkeypatch) -> None:
    """``PIN_KPI_OED_THREADS`` is read when an entry point starts (not when the package is imported): in this
    process as in a fresh one."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from pin_kpi_oed import threads

    def blas_threads():
        return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")

    monkeypatch.setattr(threads, "_max_threads", None)
    monkeypatch.setenv("PIN_KPI_OED_THREADS", "2")
    with threadpool_limits(limits=1):
        before = blas_threads()
        with limited_threads():
            inside = blas_threads()
    assert before == 1 and inside == 2


def test_set_max_threads_validates_and_resets() -> None:
    try:
        set_max_threads(3)
        assert get_max_threads() == 3
        with pytest.raises(InputError, match="threads"):
            set_max_threads(0)
        with pytest.raises(InputError, match="threads"):
            set_max_threads("two")  # type: ignore[arg-type]
    finally:
        set_max_threads(None)
    assert get_max_threads() >= 1


def test_nested_contexts_are_cheap_and_restore() -> None:
    import scipy.linalg  # noqa: F401  (every BLAS the context limits is loaded before ``before``)
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    with threadpool_limits(limits=2):       # the test processes run one thread (conftest): start from two
        before = blas()
        assert max(before) == 2, "BLAS could not be given two threads: the test would prove nothing"
        with limited_threads():
            with limited_threads():
                assert all(n == 1 for n in blas())
            assert all(n == 1 for n in blas())
        assert blas() == before


@pytest.mark.xdist_group("test_threads_numpy_first")
def test_entry_points_run_single_threaded_with_numpy_imported_first(numpy_first) -> None:
    assert numpy_first["spy_calls"] >= 1, "the spy was never called: the test would prove nothing"
    assert numpy_first["spy_worst"] == 1, "an entry point ran BLAS with more than one thread"


def test_cli_threads_option_sets_the_limit_and_rejects_nonsense(monkeypatch):
    from pin_kpi_oed import threads
    from pin_kpi_oed.cli.app import main

    monkeypatch.setattr(threads, "_max_threads", None)
    assert main(["--threads", "2", "info", "kr15", "--json"]) == 0
    assert threads.get_max_threads() == 2
    assert main(["--threads", "0", "info", "kr15"]) == 2
    threads.set_max_threads(None)


@pytest.mark.xdist_group("test_threads_numpy_first")
def test_limit_covers_scipy_blas_loaded_inside_an_entry_point(numpy_first) -> None:
    if numpy_first["scipy_after"] < 2:
        pytest.skip("SciPy's BLAS starts with one thread on this machine: the test would prove nothing")
    assert numpy_first["scipy_inside"] == 1


#: One process for the two claims about libraries loaded after an entry point, in the order their premises allow: the
#: scan of the loaded libraries kept between two entry points while the dynamic linker loads none; the process limit
#: (set while only NumPy is loaded) covering SciPy's BLAS and scikit-learn's OpenMP runtime loaded after it; that
#: OpenMP runtime, loaded after the first entry point's scan, found and limited by the next entry point. One process
#: instead of two (each pays the interpreter's, NumPy's, SciPy's and scikit-learn's imports, more than a second): the
#: process limit's premise (the libraries not yet loaded when it is set) holds after the first entry point, which
#: loads none, and the last claim gives the runtime its two threads itself (``threadpool_limits``), whatever the
#: process limit's variables made it start with.
LOADED_LATER_PROBE = """
    import json
    import numpy as np
    from threadpoolctl import threadpool_info, threadpool_limits
    from pin_kpi_oed import threads
    out = {}
    with threads.limited_threads():              # the first entry point: its scan sees NumPy's BLAS only
        pass
    out["kept"] = threads._controller() is threads._controller()
    threads.limit_process_threads()
    import scipy.linalg, sklearn.gaussian_process   # SciPy's BLAS, scikit-learn's OpenMP: loaded after both
    out["libs"] = len(threadpool_info())
    out["worst"] = max(i["num_threads"] for i in threadpool_info())
    threadpool_limits(limits=2)
    def omp():
        return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "openmp")
    out["before"] = omp()
    with threads.limited_threads():              # the second entry point
        out["inside"] = omp()
    out["after"] = omp()
    print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def loaded_later() -> dict:
    """What :data:`LOADED_LATER_PROBE` saw, in a fresh process without the thread variables."""
    return json.loads(_run(LOADED_LATER_PROBE))


@pytest.mark.xdist_group("test_threads_loaded_later")
def test_process_limit_covers_libraries_loaded_later(loaded_later) -> None:
    assert loaded_later["libs"] >= 3, "NumPy's and SciPy's BLAS and an OpenMP runtime expected: the test would " \
                                      "prove little"
    assert loaded_later["worst"] == 1


@pytest.mark.xdist_group("test_threads_loaded_later")
def test_a_library_loaded_between_two_entry_points_is_limited_by_the_second(loaded_later) -> None:
    """The scan of the loaded libraries is kept while the dynamic linker loads none (two entry points in a row share
    it); scikit-learn's OpenMP runtime, loaded after the first entry point, is found and limited by the second."""
    assert loaded_later["kept"] is True, "the scan was not kept between two entry points"
    assert loaded_later["before"] == 2, "the OpenMP runtime could not be given two threads: the test would prove " \
                                        "nothing"
    assert loaded_later["inside"] == 1 and loaded_later["after"] == 2
