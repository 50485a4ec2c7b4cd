"""Shared fixtures: robots, a tracker set-up, the path to ../shared."""

from __future__ import annotations

import re
import sys
from pathlib import Path

# Collection's cost: pytest rewrites every test module's asserts and Python compiles every module of the package the
# tests import; where PYTHONDONTWRITEBYTECODE is set neither is cached and every run (every xdist worker) pays both
# again: collection took 10.8 s CPU so, 4.3 s with the bytecode cached (`python -m pytest --collect-only -q`). The
# bytecode goes to __pycache__ (git-ignored); where the checkout is read-only nothing is written and nothing fails.
sys.dont_write_bytecode = False

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import pytest  # noqa: E402

from pin_kpi_oed.model.noise import NoiseModel  # noqa: E402
from pin_kpi_oed.model.tracker import TrackerModel  # noqa: E402
from pin_kpi_oed.model.robot import load_robot  # noqa: E402

SHARED = Path(__file__).resolve().parents[2] / "shared"
REPO = Path(__file__).resolve().parents[1]


def make_model(name: str = "kr15", reflector=(0.05, 0.03, 0.08), noise: NoiseModel | None = None,
               pose6d: bool = False, tcp=(0.0, 0.0, 0.0)) -> TrackerModel:
    """A tracker set-up 3 m in front of the robot, rotated (a generic pose)."""
    rb = load_robot(name)
    T = pin.SE3(pin.rpy.rpyToMatrix(0.1, 0.2, 2.0), np.array([3.0, 1.0, -0.5]))
    return TrackerModel(rb, tracker_T_base=T, reflector_m=np.array(reflector), tcp_m=np.array(tcp),
                        noise=noise or NoiseModel(), pose6d=pose6d)


@pytest.fixture
def kr15_model() -> TrackerModel:
    return make_model("kr15")


# ---------------------------------------------------------------------- one BLAS thread per test process
def pytest_configure(config):
    """One BLAS / OpenMP thread in each test process (the libraries loaded now limited, those loaded later and every
    subprocess through their variables; values the user set are kept), as the command line runs: the tests'
    matrices are small, and ``pytest -n 2`` on two cores with a BLAS thread per core in each worker made the
    libraries spin against each other (a joint-angle fit test: 6 s CPU with one thread, 70 s CPU and 200 s wall
    without). tests/test_threads.py clears the variables for its probes."""
    from pin_kpi_oed.threads import limit_process_threads

    limit_process_threads()
    config.pluginmanager.register(_GroupCheck(), "pin_kpi_oed_group_check")
    _full_collections_rarer()


def _full_collections_rarer() -> None:
    """A full garbage collection after 100 young-generation sweeps instead of 10 (``gc.set_threshold``'s third
    value; the first two as Python's defaults): a test worker holds millions of long-lived objects (NumPy, SciPy,
    scikit-learn, matplotlib, the package's caches), and each full collection walks them all. Over ``make test``
    a worker's collections took 4.2 s CPU (36 full ones, 3.3 s of it) with the defaults and 0.7-0.9 s (5 full ones)
    with this; the young generations are collected as often as before, and a test that needs every object collected
    calls ``gc.collect()`` itself."""
    import gc

    young, middle, _ = gc.get_threshold()
    gc.set_threshold(young, middle, 100)


# ---------------------------------------------------------------------- tests that share one fixture, one worker
#: The suffix pytest-xdist's ``--dist loadgroup`` appends to the id of a test marked ``xdist_group``.
_GROUP_SUFFIX = re.compile(r"@[A-Za-z0-9_]+$")


def test_id(nodeid: str) -> str:
    """A test's id without the ``@group`` suffix ``--dist loadgroup`` gives it (the CPU records' key)."""
    return _GROUP_SUFFIX.sub("", nodeid)


class _GroupCheck:
    """``make test`` runs ``--dist loadgroup`` so that the tests marked ``xdist_group`` (one expensive fixture
    shared) run on one worker. pytest-xdist groups them by a suffix it writes into each test's id; a pytest whose
    node ids are stored elsewhere (9.2 with xdist 3.8) drops it and the marks silently do nothing, each worker
    computing the fixture again: refused here, naming the versions."""

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, config, items):
        if not getattr(config.option, "loadgroup", False) or not hasattr(config, "workerinput"):
            return
        lost = [it.nodeid for it in items if it.get_closest_marker("xdist_group") and "@" not in it.nodeid]
        if lost:
            import xdist

            raise pytest.UsageError(
                f"--dist loadgroup: pytest {pytest.__version__} with pytest-xdist {xdist.__version__} drops the "
                f"group of {len(lost)} marked tests (e.g. {lost[0]}); install the versions pyproject.toml pins "
                f"(make test does)")


# ---------------------------------------------------------------------- CPU time per test (printed by the run)
def _cpu_s() -> float:
    import resource

    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """Each test's CPU time (set-up, call and tear-down; its process and finished children), in its reports'
    ``user_properties`` (they travel from xdist workers to the controller)."""
    c0 = _cpu_s()
    item.user_properties.append(("cpu_s", c0))  # replaced by the difference at tear-down
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    if call.when == "teardown":
        props = dict(item.user_properties)
        if "cpu_s" in props:
            item.user_properties[:] = [(k, v) for k, v in item.user_properties if k != "cpu_s"]
            item.user_properties.append(("cpu_s", _cpu_s() - props["cpu_s"]))
            outcome.get_result().user_properties = list(item.user_properties)


_CPU: dict[str, float] = {}


def pytest_runtest_logreport(report):
    if report.when == "teardown":
        cpu = dict(report.user_properties).get("cpu_s")
        if cpu is not None:
            _CPU[test_id(report.nodeid)] = float(cpu)


def pytest_terminal_summary(terminalreporter):
    """The suite's CPU time and its 15 most expensive tests: unlike the wall times of ``--durations``, CPU time does
    not grow when other work holds the cores (``make test`` prints both)."""
    if not _CPU:
        return
    import os

    tr = terminalreporter
    tr.section("CPU time per test (process and children)")
    for nodeid, cpu in sorted(_CPU.items(), key=lambda kv: -kv[1])[:15]:
        tr.write_line(f"{cpu:8.2f} s CPU  {nodeid}")
    tr.write_line(f"{sum(_CPU.values()):8.1f} s CPU in {len(_CPU)} tests; load average "
                  f"{', '.join(f'{x:.2f}' for x in os.getloadavg())} at the end on {os.cpu_count()} cores")


# ---------------------------------------------------------------------- make test-fast: the change-test loop
#: Each test's CPU time (s) as the last runs measured it: written at the end of every run, read by ``--fast``.
CPU_RECORD = REPO / ".pytest_cpu.json"
#: The CPU times (s) of one full run, kept with the tests: what ``--fast`` reads on a fresh clone (the local record,
#: where a test has one, wins).
CPU_BASELINE = REPO / "tests" / "cpu_baseline.json"


def pytest_addoption(parser):
    parser.addoption("--fast", action="store_true",
                     help="leave out the tests whose CPU time, as the last runs recorded it (.pytest_cpu.json), "
                          "exceeds --fast-budget: the change-test loop (make test-fast); make test runs them all")
    parser.addoption("--fast-budget", type=float, default=0.2, help="--fast: largest CPU time of a test kept (s)")


def _read_times(path) -> dict[str, float]:
    import json

    try:
        return {str(k): float(v) for k, v in json.loads(path.read_text()).items()}
    except (OSError, ValueError, AttributeError):
        return {}


def _record() -> dict[str, float]:
    """The local record of each test's CPU time (s) over the kept baseline."""
    return {**_read_times(CPU_BASELINE), **_read_times(CPU_RECORD)}


def pytest_collection_modifyitems(config, items):
    """``--fast``: deselect the tests recorded above the budget (a test never recorded is kept: it is new)."""
    if not config.getoption("--fast"):
        return
    record, budget = _record(), config.getoption("--fast-budget")
    slow = [it for it in items if record.get(test_id(it.nodeid), 0.0) > budget]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [it for it in items if record.get(test_id(it.nodeid), 0.0) <= budget]


def pytest_sessionfinish(session):
    """Merge this run's CPU times into :data:`CPU_RECORD` (by the controller only, atomically; a ``--fast`` run
    records nothing: a fixture shared with the tests it leaves out is paid by a kept one, whose time would then
    drop it from the next fast run)."""
    if not _CPU or hasattr(session.config, "workerinput") or session.config.getoption("--fast"):
        return
    import json
    import os

    merged = {**_read_times(CPU_RECORD), **_CPU}
    tmp = CPU_RECORD.with_name(f"{CPU_RECORD.name}.{os.getpid()}")
    try:
        tmp.write_text(json.dumps(dict(sorted(merged.items())), indent=0))
        os.replace(tmp, CPU_RECORD)
    except OSError:
        pass  # a read-only checkout: nothing recorded, nothing lost
