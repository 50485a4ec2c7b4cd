"""Every subcommand of ``pin-kpi-oed`` by name: the topic module that declares it and its one-line help.

The command line declares the whole parser of one command only, the one it runs (its topic module's
``register``); the others appear as their name and help line, so ``pin-kpi-oed --help`` and a command's run
import none of the other commands' modules. The help lines here are the ones each topic module declares
(``tests/test_cli_startup.py`` compares them).
"""

from __future__ import annotations

__all__ = ["COMMANDS", "topic_of", "command_in"]

#: (command, topic module of ``pin_kpi_oed.cli`` whose ``register`` declares it or None for ``app`` itself, help),
#: in the order ``--help`` lists them.
COMMANDS: tuple[tuple[str, str | None, str], ...] = (
    ("info", None, "joints, limits, parameter count and identifiable rank of a robot"),
    ("evaluate", None, "score measurement configurations (JSON in) under every criterion"),
    ("demo", None, "the main job on the embedded default cell (KR 15)"),
    ("check", "check", "does a calibration still hold? (check design: the poses to measure)"),
    ("monitor", "check", "rows measured during work (a file, or followed as it grows): each predicted first, the "
                         "set-up followed, a check every few rows"),
    ("design", "design", "heuristic and optimum (IPOPT) measurement designs of a cell"),
    ("simulate", "identify", "simulate tracker measurements of a robot with random geometric errors"),
    ("identify", "identify", "identify geometric parameters from measurements, validate, export URDF"),
    ("import-ipa", "identify", "convert IPA UR10 laser-tracker files to the measurement CSV format"),
    ("register", "transfer", "re-fit only the set-up (tracker pose, reflector) of a calibrated model"),
    ("predict", "transfer", "predicted reflector positions of a calibrated model, per CSV row"),
    ("diagnose", "diagnose", "sim-to-real gap diagnosis: noise or gap, where, which unmodelled effect, how far it "
                             "shrinks"),
    ("view", "view", "meshcat preview of a design: cell, poses, laser beam, KPI confidence ellipsoids"),
    ("study", "study", "reproduce the paper's studies (KUKA cells, 90 notional arms) and the weld-seam path KPI "
                       "study"),
    ("compensate", "compensate", "compensated joint values for Cartesian TCP targets or a joint-space program"),
    ("import-tracker", "tracker_export", "convert a tracker point export + joint log to a measurement CSV"),
    ("import-images", "camera_import", "detect a calibration board in images: the camera measurement CSV"),
    ("export", "program", "ordered, collision-checked robot program of a design (csv, urscript, krl, rapid)"),
    ("export-model", "export_model", "write a calibrated model as a UR kinematics file or a calibrated URDF"),
    ("report", "report", "calibration certificate (HTML with embedded figures, JSON, PDF) of a model file"),
)

#: The options of ``pin-kpi-oed`` itself (before the command) that take a value.
VALUE_OPTIONS = ("--threads",)


def topic_of(command: str) -> str | None:
    """The topic module that declares ``command`` (None: ``app`` itself or no such command)."""
    return next((topic for name, topic, _ in COMMANDS if name == command), None)


def command_in(argv: list[str]) -> str | None:
    """The command an argument list runs: its first positional argument when that names a command, else None
    (``--help``, no command, an unknown one: the parser of every command's name then says so).

    Args:
        argv: the arguments after the program name.
    """
    skip = False
    for arg in argv:
        if skip:
            skip = False
            continue
        if arg == "--":
            continue
        if arg.startswith("-"):
            # a value option given without '=' (argparse takes unique prefixes too: --thr 2)
            skip = "=" not in arg and len(arg) > 2 and any(o.startswith(arg) for o in VALUE_OPTIONS)
            continue
        return arg if any(arg == name for name, _, _ in COMMANDS) else None
    return None
