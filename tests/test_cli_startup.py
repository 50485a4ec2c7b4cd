"""The command line starts at once: a command imports only what it uses, and an interrupt at any moment (the imports
included) is one line and exit code 130, never a traceback.

The import sets are pinned (the modules loaded), not times: the times are ``benchmarks/__main__.py``'s.
"""

from __future__ import annotations

import functools
import json
import os
import resource
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from pin_kpi_oed.cli.app import build_parser
from pin_kpi_oed.cli.commands import COMMANDS, command_in

ROOT = Path(__file__).resolve().parents[1]

#: What neither ``--help`` nor ``info`` may load: scikit-learn, IPOPT, pandas, plotting, SciPy's optimisers and
#: statistics, and the package's design, identification, discrepancy, cell, program and report stacks.
HEAVY = ("sklearn", "cyipopt", "pandas", "matplotlib", "scipy.optimize", "scipy.stats", "scipy.spatial",
         "pin_kpi_oed.design", "pin_kpi_oed.identification", "pin_kpi_oed.discrepancy", "pin_kpi_oed.cell",
         "pin_kpi_oed.program", "pin_kpi_oed.report", "pin_kpi_oed.diagnosis", "pin_kpi_oed.viz",
         "pin_kpi_oed.oed.criteria", "pin_kpi_oed.cli.design", "pin_kpi_oed.cli.identify")


PROBE = """
import json, sys
from pin_kpi_oed.cli.app import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
sys.stdout.flush()
print(json.dumps({"code": code, "modules": sorted(sys.modules)}), file=sys.stderr)
"""


def _modules(*argv: str) -> tuple[int, set[str]]:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    res = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, env=env, timeout=120)
    got = json.loads(res.stderr.strip().splitlines()[-1])
    return int(got["code"] or 0), set(got["modules"])


def _loaded(modules: set[str], prefix: str) -> bool:
    return any(m == prefix or m.startswith(prefix + ".") for m in modules)


def test_help_loads_neither_numpy_nor_any_command_module() -> None:
    code, mods = _modules("--help")
    assert code == 0
    assert _loaded(mods, "pin_kpi_oed.cli.app"), "the probe did not run the command line"
    heavy = [m for m in HEAVY + ("numpy", "pinocchio", "scipy") if _loaded(mods, m)]
    assert not heavy, f"pin-kpi-oed --help loads {heavy}"
    topics = sorted(m for m in mods if m.startswith("pin_kpi_oed.cli.") and m not in
                    ("pin_kpi_oed.cli.app", "pin_kpi_oed.cli.commands", "pin_kpi_oed.cli.interrupts"))
    assert not topics, f"pin-kpi-oed --help imports command modules {topics}"


def test_info_loads_the_robot_model_only() -> None:
    code, mods = _modules("info", "ur10")
    assert code == 0
    assert _loaded(mods, "pinocchio") and _loaded(mods, "pin_kpi_oed.oed.identifiability"), "info did not run"
    heavy = [m for m in HEAVY if _loaded(mods, m)]
    assert not heavy, f"pin-kpi-oed info ur10 loads {heavy}"


def test_a_command_imports_its_own_topic_module_only() -> None:
    code, mods = _modules("identify", "--help")
    assert code == 0 and "pin_kpi_oed.cli.identify" in mods
    others = sorted(m for m in mods if m.startswith("pin_kpi_oed.cli.") and m.split(".")[2] in
                    {t for _, t, _ in COMMANDS if t not in (None, "identify")})
    assert not others, f"identify --help imports {others}"
    assert not _loaded(mods, "cyipopt") and not _loaded(mods, "sklearn")


def test_every_listed_help_line_is_the_one_its_module_declares() -> None:
    """The command table's help lines (what ``--help`` lists without importing the modules) against each topic
    module's own declaration: one name, one line, in the same order."""
    def listed(parser) -> list[tuple[str, str]]:
        sub = next(a for a in parser._actions if a.dest == "command")
        return [(a.dest, a.help) for a in sub._choices_actions]

    full = listed(build_parser())
    assert full == listed(build_parser(None, lazy=True))
    assert full == [(name, help_line) for name, _, help_line in COMMANDS]
    for name, _, _ in COMMANDS:  # a command's own parser declared in full, the others listed the same
        assert listed(build_parser(name, lazy=True)) == full


@pytest.mark.parametrize("argv, command", [
    (["--help"], None), ([], None), (["identify", "--help"], "identify"), (["--threads", "2", "design"], "design"),
    (["--threads=2", "info", "ur10"], "info"), (["--thr", "2", "export"], "export"), (["-h", "info"], "info"),
    (["idnetify"], None), (["design", "--cell", "info"], "design")])
def test_the_command_is_the_first_positional_argument(argv: list[str], command: str | None) -> None:
    assert command_in(argv) == command


def test_usage_errors_are_those_of_the_full_parser(capsys) -> None:
    from pin_kpi_oed.cli.app import main

    for argv in (["idnetify"], [], ["info"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        lazy = (exc.value.code, capsys.readouterr().err)
        with pytest.raises(SystemExit) as exc:
            build_parser().parse_args(argv)
        assert lazy == (exc.value.code, capsys.readouterr().err) and lazy[0] == 2, argv


#: The design of the interrupt tests: with collision avoidance and the pool start, it designs in Python and NumPy
#: (the random design, the pool) after its first lines and only then in IPOPT; without both, IPOPT starts at once.
DESIGN = ["design", "--cell", "kr15", "--measurements", "30", "--criteria", "kpi", "--starts", "3"]
DESIGN_IN_IPOPT = [*DESIGN, "--no-collision", "--start", "random"]


@functools.cache
def _entry_cpu_s() -> float:
    """CPU seconds a process spends until the command line's entry is loaded (interpreter start-up +
    ``pin_kpi_oed.cli.app``): before it no code of the package runs, so no package can turn an interrupt there into
    one line. Measured once per test process, in CPU time: the moments below are the child's CPU seconds, which do not
    stretch when other work holds the cores (wall seconds do). The largest of three runs: one process's start-up
    varies by a fifth from run to run, and a moment taken from a fast run fell inside a slow child's interpreter
    start (``typing`` imported by the package's ``__init__``, before any of its code could catch the interrupt)."""
    costs = []
    for _ in range(3):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-c", "import pin_kpi_oed.cli.app"], check=True, env=_env())
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        costs.append((after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime))
    return max(costs)


@functools.cache
def _first_line_cpu_s() -> float:
    """CPU seconds ``design`` (:data:`DESIGN`, the console-script entry) spends until its first line of output: its
    entry and imports (the cell loaded, then the design stack), before any of its work. The smaller of two runs: the
    imports' moment is half of it, so that it falls inside the imports whatever this machine's speed (a fixed 0.6 s
    fell after the first line once the imports had become cheaper: 0.80-1.17 s on one machine)."""
    import psutil

    costs = []
    for _ in range(2):
        proc = subprocess.Popen([sys.executable, "-c", "from pin_kpi_oed.cli import run; run()", *DESIGN],
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=_env())
        child = psutil.Process(proc.pid)
        proc.stdout.readline()
        costs.append(sum(child.cpu_times()[:2]))
        proc.kill()
        proc.wait()
        proc.stdout.close()
    return min(costs)


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
            "PYTHONUNBUFFERED": "1",  # each line reaches the test when printed: the work's first line is a moment
            "PYTHONFAULTHANDLER": "1"}  # a command that crashes (a fatal signal) prints its Python stack to stderr


def _interrupt_at(argv: list[str], module: bool, cpu_s: float, after_output: bool) -> tuple[int, str, bool]:
    """Run the command line and send SIGINT once it has spent ``cpu_s`` CPU seconds (counted from its first line of
    output when ``after_output``); (exit code, stderr, whether it had printed anything before the signal)."""
    import psutil

    cmd = [sys.executable, "-m", "pin_kpi_oed", *argv] if module else \
        [sys.executable, "-c", "from pin_kpi_oed.cli import run; run()", *argv]  # as the console script
    printed = threading.Event()
    with tempfile.TemporaryFile("w+") as err:
        # SIGINT as Python sees it by default, whatever the test runner's shell did with it (a background job ignores
        # it)
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, text=True, env=_env(),
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        reader = threading.Thread(target=lambda: [printed.set() for _ in proc.stdout], daemon=True)
        reader.start()
        child, start, deadline = psutil.Process(proc.pid), None, time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline:
            used = sum(child.cpu_times()[:2])
            if start is None and (printed.is_set() or not after_output):
                start = used
            if start is not None and used - start >= cpu_s:
                break
            time.sleep(0.005)
        running, had_printed = proc.poll() is None, printed.is_set()
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=120)
        reader.join(timeout=10)
        err.seek(0)
        text = err.read()
    assert running, "the command ended before the interrupt: the test would prove nothing"
    return proc.returncode, text, had_printed


@pytest.mark.parametrize("moment, module", [("entry", True), ("imports", False), ("work", False), ("ipopt", True)])
def test_an_interrupt_at_any_moment_is_one_line_and_130(moment: str, module: bool) -> None:
    """``design`` imports the design stack and then designs: an interrupt in its imports or its work is one line and
    exit code 130.

    The moments are the command's own CPU seconds, not wall seconds (which stretch when other work holds the cores:
    3 s after the start is the work on an idle machine, still the imports on a busy one), each reached at the cost of
    what the command spends before it: as soon as the entry is loaded (1.5 times what loading it costs); in the
    imports (half of what the command spends until its first line); in the work in Python (at its first line: the
    random design and the pool start follow); in IPOPT, the Python code that IPOPT calls back (0.3 s after the first
    line of the design without collision constraints and pool start, whose IPOPT starts 0.1 s after that line and runs
    for a second). Whether the first line came before the interrupt is checked: each moment is the one it says. The two
    entries take turns: ``python -m pin_kpi_oed`` and the console script differ only in how the entry is loaded
    (``__main__``'s guard), which the earliest moment of each tests (the entry, the imports); after it both run
    :func:`pin_kpi_oed.cli.app.run`, so the later moments need one entry each (the work: the console script, IPOPT:
    ``-m``)."""
    moments = {"entry": lambda: (1.5 * _entry_cpu_s(), DESIGN, False),
               "imports": lambda: (0.5 * _first_line_cpu_s(), DESIGN, False),
               "work": lambda: (0.0, DESIGN, True), "ipopt": lambda: (0.3, DESIGN_IN_IPOPT, True)}
    cpu_s, argv, after_output = moments[moment]()
    rc, err, had_printed = _interrupt_at(argv, module, cpu_s, after_output)
    assert had_printed == after_output, f"the interrupt came {'after' if had_printed else 'before'} the first line"
    assert "Traceback" not in err, err
    assert rc == 130 and err.strip().splitlines()[-1] == "interrupted", err


def test_an_extension_interrupted_while_it_initialises_is_an_interrupt(monkeypatch, capsys) -> None:
    """A compiled module interrupted in its initialisation may report another error (ImportError 'initialization
    failed', NumPy's 'could not import module datetime'): after a SIGINT it is one line and 130 as well; the same
    error without an interrupt stays an error. The test process gets Python's own SIGINT handler first: a process
    started in the background by a shell without job control inherits SIGINT ignored, and the command line then
    (rightly) leaves it alone."""
    from pin_kpi_oed.cli import app

    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        def interrupted_init(*_a, **_k):
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1.0)  # the handler raises here
            except KeyboardInterrupt:
                pass
            raise ImportError("PyCapsule_Import could not import module \"datetime\"")

        monkeypatch.setattr(app, "build_parser", interrupted_init)
        assert app.main(["info", "ur10"]) == 130
        assert capsys.readouterr().err == "interrupted\n"
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler, "the handler must be restored"

        def broken(*_a, **_k):
            raise ImportError("no module named x")

        monkeypatch.setattr(app, "build_parser", broken)
        with pytest.raises(ImportError, match="no module named x"):
            app.main(["info", "ur10"])
    finally:
        signal.signal(signal.SIGINT, inherited)


def test_an_interrupt_a_library_swallowed_is_still_an_interrupt_unless_the_command_ends_on_it(monkeypatch,
                                                                                               capsys) -> None:
    """A SIGINT whose KeyboardInterrupt a library caught (seen inside NumPy's lazy imports: the command then ran to
    its end) is one line and 130; a command that ends on Ctrl-C by design (``check --follow``, ``view``'s server)
    consumes it and keeps its own exit code; one swallowed in the imports stops the command before its work. Python's
    own SIGINT handler is installed first, as above."""
    from pin_kpi_oed.cli import app, interrupts

    def swallowing(consumes: bool):
        def run(_args):
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1.0)  # the handler raises here
            except KeyboardInterrupt:
                if consumes:
                    interrupts.consume()
            return 0
        return run

    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        monkeypatch.setattr(app, "_run", swallowing(consumes=False))
        assert app.main(["info", "ur10"]) == 130
        assert capsys.readouterr().err == "interrupted\n"
        monkeypatch.setattr(app, "_run", swallowing(consumes=True))
        assert app.main(["info", "ur10"]) == 0
        assert capsys.readouterr().err == ""
        monkeypatch.undo()
        real = app.build_parser

        def swallowed_in_imports(*a, **k):
            swallowing(consumes=False)(None)
            return real(*a, **k)

        monkeypatch.setattr(app, "build_parser", swallowed_in_imports)
        assert app.main(["info", "ur10"]) == 130
        out, err = capsys.readouterr()
        assert out == "" and err == "interrupted\n", "the command's work ran after an interrupt in its imports"
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler, "the handler must be restored"
    finally:
        signal.signal(signal.SIGINT, inherited)
